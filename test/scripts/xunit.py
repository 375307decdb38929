# SPDX-License-Identifier: BSD-3-Clause
"""One JUnit XML file of named checks (scripts/test counts its test cases), for the guard scripts."""
import os
import xml.etree.ElementTree as ET


def write_xunit(path, suite_name, results):
    """results: (name, failure message or '') per check."""
    suite = ET.Element("testsuite", name=suite_name, tests=str(len(results)),
                       failures=str(sum(1 for _, m in results if m)), errors="0")
    for name, msg in results:
        case = ET.SubElement(suite, "testcase", classname=suite_name, name=name)
        if msg:
            ET.SubElement(case, "failure", message=msg).text = msg
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    ET.ElementTree(suite).write(path, encoding="utf-8", xml_declaration=True)


def run_checks(suite_name, doc, checks):
    """The main() of a check script: parses --xunit, runs checks(tmp) in a temporary directory, prints one line per
    check, writes the JUnit file and returns the exit code (1 if any check failed)."""
    import argparse
    import tempfile
    ap = argparse.ArgumentParser(usage=doc.replace("%", "%%"))
    ap.add_argument("--xunit")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        results = checks(tmp)
    for name, msg in results:
        print("%s: %s: %s" % (suite_name, name, "FAIL: " + msg if msg else "ok"))
    if a.xunit:
        write_xunit(a.xunit, suite_name, results)
    return 1 if any(m for _, m in results) else 0
