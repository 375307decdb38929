#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""
usage: check_docs.py [--root DIR] [--xunit FILE.xml] [--self-test]

The documentation rules, read from the source tree (text only, nothing is built):
  - README.md has at most 200 lines and names scripts/test as the test command;
  - README.md and docs/*.md link or point only inside the repository: no relative path that leaves it
    (../ beyond the root), no absolute /work/ path, nothing under ../shared; every relative markdown link
    names a file that exists;
  - the product is described as a product: `grep -rniE "<work-log pattern>" README.md docs config launch
    scripts test include src` finds nothing (the pattern: the words session or issue followed by a space and a
    digit); each hit is reported as file:line.
--xunit writes one JUnit test case per rule (scripts/test counts them). Exit status 1 when a rule is broken.
--self-test first checks the rules on small known snippets.
"""
import argparse
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

MAX_README_LINES = 200
WORDING_DIRS = ["README.md", "docs", "config", "launch", "scripts", "test", "include", "src"]
# the same expression as the grep of the docs' rule (-i: case-insensitive, -E: extended)
WORDING = re.compile(r"session [0-9]|issue [0-9]", re.I)
MD_LINK = re.compile(r"\]\(([^)\s]+)\)")
UP_PATH = re.compile(r"(?<![\w.])((?:\.\./)+[\w./-]*)")
FORBIDDEN = re.compile(r"(?<![\w.])/work/|\.\./shared\b")


def doc_files(root):
    """README.md and docs/*.md (relative paths)."""
    files = ["README.md"] if os.path.isfile(os.path.join(root, "README.md")) else []
    d = os.path.join(root, "docs")
    if os.path.isdir(d):
        files += sorted(os.path.join("docs", f) for f in os.listdir(d) if f.endswith(".md"))
    return files


def inside(root, path):
    root = os.path.realpath(root)
    p = os.path.realpath(path)
    return p == root or p.startswith(root + os.sep)


def link_problems(root, rel, text):
    """'file:line: problem' for every link or path of one markdown file that leaves the repository."""
    out = []
    base = os.path.dirname(os.path.join(root, rel))
    for n, line in enumerate(text.splitlines(), 1):
        where = "%s:%d" % (rel, n)
        for m in FORBIDDEN.finditer(line):
            out.append("%s: points outside the repository (%s)" % (where, m.group(0)))
        for m in UP_PATH.finditer(line):
            if not inside(root, os.path.join(base, m.group(1))):
                out.append("%s: path leaves the repository (%s)" % (where, m.group(1)))
        for m in MD_LINK.finditer(line):
            target = m.group(1)
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
                continue  # a URL, mailto:, or an anchor in the same file
            path = target.split("#", 1)[0]
            full = os.path.join(root, path.lstrip("/")) if path.startswith("/") else os.path.join(base, path)
            if path.startswith("/") or not inside(root, full):
                out.append("%s: link leaves the repository (%s)" % (where, target))
            elif not os.path.exists(full):
                out.append("%s: link to a missing file (%s)" % (where, target))
    return out


def wording_hits(root):
    """'file:line: text' for every line the wording grep finds, as grep -rniE would (files in sorted order)."""
    hits = []
    for top in WORDING_DIRS:
        start = os.path.join(root, top)
        if os.path.isfile(start):
            paths = [start]
        elif os.path.isdir(start):
            paths = []
            for d, dirs, files in os.walk(start):
                dirs.sort()
                paths += [os.path.join(d, f) for f in sorted(files)]
        else:
            continue
        for p in paths:
            try:
                with open(p, "rb") as f:
                    data = f.read()
            except OSError:
                continue
            text = data.decode("utf-8", errors="replace")
            for n, line in enumerate(text.splitlines(), 1):
                if WORDING.search(line):
                    hits.append("%s:%d: %s" % (os.path.relpath(p, root), n, line.strip()[:120]))
    return hits


def check(root):
    """(name, failure message or '') per rule."""
    results = []
    readme = os.path.join(root, "README.md")
    if not os.path.isfile(readme):
        results.append(("readme", "README.md is missing"))
    else:
        with open(readme, encoding="utf-8", errors="replace") as f:
            text = f.read()
        n = len(text.splitlines())
        msgs = []
        if n > MAX_README_LINES:
            msgs.append("README.md has %d lines (at most %d: the rest belongs in docs/)" % (n, MAX_README_LINES))
        if "scripts/test" not in text:
            msgs.append("README.md does not name scripts/test, the test command .ci/run runs")
        results.append(("readme", "; ".join(msgs)))
    problems = []
    for rel in doc_files(root):
        with open(os.path.join(root, rel), encoding="utf-8", errors="replace") as f:
            problems += link_problems(root, rel, f.read())
    results.append(("links_inside_repository", "\n".join(problems)))
    hits = wording_hits(root)
    results.append(("product_wording", ("%d line(s) describe work, not the product:\n" % len(hits) + "\n".join(hits))
                    if hits else ""))
    return results


def self_test():
    """The rules on small known snippets; raises AssertionError when one misjudges."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        root = os.path.join(tmp, "repo")
        os.makedirs(os.path.join(root, "docs"))
        for f in ("README.md", os.path.join("docs", "a.md")):
            open(os.path.join(root, f), "w").close()
        ok = "[a](a.md) [r](../README.md#x) [w](https://example.org/x) `../CMakeLists.txt` [s](#here)\n"
        assert link_problems(root, "docs/b.md", ok) == [], link_problems(root, "docs/b.md", ok)
        for bad in ["[t](../../shared/DESIGN.md)", "see ../shared/reference", "`/work/shared/x`",
                    "[m](missing.md)", "[u](../../x.md)"]:
            assert link_problems(root, "docs/b.md", bad), bad
        assert link_problems(root, "README.md", "[u](../x.md)"), "README ../"
        # (the snippets are built from pieces, so that this file does not match the grep itself)
        s, i = "session", "issue"
        for line, hit in [("measured in %s 5" % s, True), ("%s 18: x" % i.title(), True), ("%s 15's" % i, True),
                          ("a %s ended" % s, False), ("%ss 3" % i, False), ("%s 7" % i.upper(), True),
                          ("%ss 12" % s, False)]:
            assert bool(WORDING.search(line)) == hit, line
        with open(os.path.join(root, "README.md"), "w") as f:
            f.write("scripts/test\n" * (MAX_README_LINES + 1))
        os.makedirs(os.path.join(root, "src"))
        with open(os.path.join(root, "src", "x.cpp"), "w") as f:
            f.write("// fine\n// from %s 3\n" % s)
        r = dict(check(root))
        assert "201 lines" in r["readme"], r
        assert "src/x.cpp:2:" in r["product_wording"], r
        assert r["links_inside_repository"] == "", r


def main():
    ap = argparse.ArgumentParser(usage=__doc__)
    ap.add_argument("--root", default=os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                                     "..", "..")))
    ap.add_argument("--xunit")
    ap.add_argument("--self-test", action="store_true")
    a = ap.parse_args()
    results = []
    if a.self_test:
        try:
            self_test()
            results.append(("self_test", ""))
        except AssertionError as e:
            results.append(("self_test", "the rules misjudge a known snippet: %s" % e))
    results += check(a.root)
    for name, msg in results:
        print("docs: %s: %s" % (name, "FAIL: " + msg if msg else "ok"))
    if a.xunit:
        write_xunit(a.xunit, "docs", results)
    return 1 if any(m for _, m in results) else 0


if __name__ == "__main__":
    sys.exit(main())
