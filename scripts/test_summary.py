#!/usr/bin/python3
"""Summarise the JUnit XML files that catkin's run_tests wrote.

Usage: test_summary.py RESULTS_DIR
Prints each failed or errored test case, then the closing line
``N passed, N failed[, N skipped]``. Exit status 1 when anything failed or
no test ran at all (also when RESULTS_DIR does not exist), else 0;
2 on a bad command line. A rostest launch contributes its wrapper case
(the launch itself) besides the gtest cases of its test node.
"""
import glob
import os
import sys
import xml.etree.ElementTree as ET


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if "-h" in argv or "--help" in argv:
        print(__doc__)
        return 0
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    root = argv[0]
    if not os.path.isdir(root):
        print(f"test_summary: no directory '{root}' (no test ran, or the tests wrote their results elsewhere)",
              file=sys.stderr)
        print("0 passed, 1 failed")
        return 1
    files = sorted(glob.glob(os.path.join(root, "**", "*.xml"), recursive=True))
    passed = failed = skipped = 0
    for path in files:
        try:
            tree = ET.parse(path)
        except ET.ParseError as e:
            print(f"FAILED  {path}: unreadable result file ({e})")
            failed += 1
            continue
        # A suite can fail outside its cases (e.g. a Python unittest whose setUpClass raised: tests="0" errors="1",
        # no <testcase>): count what the suite reports beyond its failing cases.
        for suite in tree.iter("testsuite"):
            listed = sum(1 for c in suite.findall("testcase") if c.findall("failure") + c.findall("error"))
            reported = int(suite.get("errors", 0) or 0) + int(suite.get("failures", 0) or 0)
            if reported > listed:
                failed += reported - listed
                text = " ".join((suite.findtext("system-err") or suite.findtext("system-out") or "").split())[:300]
                print(f"FAILED  {suite.get('name', '?')} ({os.path.basename(path)}): {reported - listed} error(s) "
                      f"outside its test cases {text}")
        for case in tree.iter("testcase"):
            name = f"{case.get('classname', '')}.{case.get('name', '')}"
            problems = case.findall("failure") + case.findall("error")
            if problems:
                failed += 1
                msg = (problems[0].get("message") or problems[0].text or "").strip().splitlines()
                print(f"FAILED  {name} ({os.path.basename(path)}): {msg[0] if msg else ''}")
            elif case.find("skipped") is not None or case.get("status") == "notrun":
                skipped += 1
            else:
                passed += 1
    if passed + failed == 0:
        print(f"no test results found under {root}")
        failed = 1
    line = f"{passed} passed, {failed} failed"
    if skipped:
        line += f", {skipped} skipped"
    print(line)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
