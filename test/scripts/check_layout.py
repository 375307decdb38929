#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""
usage: check_layout.py [--root DIR] [--xunit FILE.xml] [--self-test]

The house rules of the source tree, read from the source tree (text only, nothing is built):
  - no file under src/nodelets includes a file under src/tools, and no tool includes a nodelet file
    (what both need lives in skin3d_ros, include/skin3d/ros/, or in the core);
  - every nodelet file is at most 250 lines;
  - no function in src/ (or bench/) is longer than 150 lines (from the line of its opening brace's statement to its
    closing brace; lambdas count in the function that holds them);
  - the core and the simulator (src/core, include/skin3d/ except ros/) include no ROS header;
  - the Python code is the package src/skin3d/ (catkin_python_setup, setup.py): it has an __init__.py, no msg/ or
    srv/ of its own (catkin generates skin3d.msg / skin3d.srv beside it) and no C++; no other .py under src/; the
    Python scripts and the package import it as a package, never through sys.path (tests may import their helpers).
(That the measurement libraries do not link the simulator is enforced by the build: -Wl,--no-undefined.)
--xunit writes one JUnit test case per rule (scripts/test counts them). Exit status 1 when a rule is broken.
--self-test first checks the function measure on small known snippets.
"""
import argparse
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

MAX_NODELET_LINES = 250
MAX_FUNCTION_LINES = 150
ROS_HEADERS = re.compile(r'#\s*include\s*[<"](ros/|sensor_msgs/|std_msgs/|geometry_msgs/|nav_msgs/|nodelet/|'
                         r'rosbag/|tf2_ros/|cv_bridge/|image_transport/|message_filters/|visualization_msgs/|'
                         r'skin3d/[A-Z])')


def strip_code(text):
    """The text with comments, string and character literals blanked (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif c == 'R' and text.startswith('R"', i):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            end = ")" + m.group(1) + '"'
            j = text.find(end, i + m.end())
            j = n if j < 0 else j + len(end)
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(c + c)
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(text):
    """(name, first line, last line) of every function body at namespace or class level."""
    code = strip_code(text)
    # preprocessor lines do not take part in the statements
    code = re.sub(r"^[ \t]*#.*$", "", code, flags=re.M)
    stack = []  # kinds of the open braces: 'scope' (namespace, class, extern) or 'func' or 'other'
    stmt_start = 0
    found = []
    func_open = None  # (name, start line) of the function being read
    line = 1
    for i, c in enumerate(code):
        if c == "\n":
            line += 1
        elif c == "{":
            if "func" in stack or "other" in stack:
                stack.append("other")
            else:
                stmt = code[stmt_start:i]
                words = stmt.strip()
                if re.search(r"\b(namespace|extern)\b", words) and ")" not in words:
                    stack.append("scope")
                elif re.search(r"\b(class|struct|union|enum)\b", words) and "(" not in words.split(":")[0]:
                    stack.append("scope")
                elif ")" in words and not words.rstrip().endswith("="):
                    head = words.split("(")[0].split()
                    name = head[-1] if head else "?"
                    # first line: the line of the statement's first non-blank character
                    lead = len(code[stmt_start:i]) - len(code[stmt_start:i].lstrip())
                    first = line - code.count("\n", stmt_start + lead, i)
                    func_open = (name, first)
                    stack.append("func")
                else:
                    stack.append("other")
            stmt_start = i + 1
        elif c == "}":
            kind = stack.pop() if stack else "other"
            if kind == "func" and func_open:
                found.append((func_open[0], func_open[1], line))
                func_open = None
            if not ("func" in stack or "other" in stack):
                stmt_start = i + 1
        elif c == ";" and not ("func" in stack or "other" in stack):
            stmt_start = i + 1
        elif c == ":" and not ("func" in stack or "other" in stack):
            # access specifiers (public:) end a statement; a constructor's initialiser list does not
            if re.search(r"\b(public|private|protected)\s*$", code[stmt_start:i]):
                stmt_start = i + 1
    return found


def files(root, folder, exts=(".cpp", ".h", ".hpp")):
    for d, _, names in os.walk(os.path.join(root, folder)):
        for n in sorted(names):
            if n.endswith(exts):
                yield os.path.join(d, n)


def rel(root, path):
    return os.path.relpath(path, root)


def check(root):
    results = []
    # 1. nodelets and tools do not include each other's files
    bad = []
    for folder, other in (("src/nodelets", "tools"), ("src/tools", "nodelets")):
        for p in files(root, folder):
            for k, l in enumerate(open(p, encoding="utf-8"), 1):
                m = re.match(r'\s*#\s*include\s*"([^"]+)"', l)
                if not m:
                    continue
                target = os.path.normpath(os.path.join(os.path.dirname(p), m.group(1)))
                if ("/src/%s/" % other) in target or m.group(1).startswith(("src/%s/" % other, "%s/" % other)):
                    bad.append("%s:%d includes %s" % (rel(root, p), k, m.group(1)))
                elif not m.group(1).startswith("skin3d/") and os.path.exists(os.path.join(root, "src", other, os.path.basename(m.group(1)))) \
                        and not os.path.exists(os.path.join(os.path.dirname(p), m.group(1))):
                    bad.append("%s:%d includes %s (a file of src/%s)" % (rel(root, p), k, m.group(1), other))
    results.append(("nodelets_and_tools_apart", "; ".join(bad)))
    # 2. nodelet files at most 250 lines
    long_files = []
    for p in files(root, "src/nodelets"):
        n = sum(1 for _ in open(p, encoding="utf-8"))
        if n > MAX_NODELET_LINES:
            long_files.append("%s has %d lines (at most %d)" % (rel(root, p), n, MAX_NODELET_LINES))
    results.append(("nodelet_files_short", "; ".join(long_files)))
    # 3. functions at most 150 lines
    long_functions = []
    for p in [q for folder in ("src", "bench") for q in files(root, folder, (".cpp", ".h", ".hpp"))]:
        for name, first, last in functions(open(p, encoding="utf-8").read()):
            if last - first + 1 > MAX_FUNCTION_LINES:
                long_functions.append("%s:%d %s is %d lines (at most %d)" % (rel(root, p), first, name, last - first + 1,
                                                                          MAX_FUNCTION_LINES))
    results.append(("functions_short", "; ".join(long_functions)))
    # 4. no ROS header in the core or the simulator
    ros = []
    for folder in ["src/core"] + ["include/skin3d/" + d for d in sorted(os.listdir(os.path.join(root, "include/skin3d")))
                                  if d != "ros" and os.path.isdir(os.path.join(root, "include/skin3d", d))]:
        for p in files(root, folder):
            for k, l in enumerate(open(p, encoding="utf-8"), 1):
                if ROS_HEADERS.match(l.strip()):
                    ros.append("%s:%d %s" % (rel(root, p), k, l.strip()))
    results.append(("core_without_ros", "; ".join(ros)))
    # 5. the Python package
    results.append(("python_package", "; ".join(python_package_problems(root))))
    return results


def python_package_problems(root):
    bad = []
    pkg = os.path.join(root, "src", "skin3d")
    if not os.path.isfile(os.path.join(pkg, "__init__.py")):
        bad.append("src/skin3d/__init__.py is missing (the Python package of setup.py)")
    for sub in ("msg", "srv"):
        if os.path.exists(os.path.join(pkg, sub)):
            bad.append("src/skin3d/%s would hide the generated skin3d.%s" % (sub, sub))
    bad += ["%s: C++ in the Python package" % rel(root, p) for p in files(root, "src/skin3d")]
    for p in files(root, "src", (".py",)):
        if not os.path.abspath(p).startswith(pkg + os.sep):
            bad.append("%s: Python outside the package src/skin3d/" % rel(root, p))
    sources = list(files(root, "src/skin3d", (".py",))) + list(files(root, "scripts", (".py",)))
    for p in sources:
        for k, l in enumerate(open(p, encoding="utf-8"), 1):
            if re.search(r"\bsys\.path\.(insert|append)\(|\bsys\.path\s*(\+?=|\[)", l.split("#")[0]):
                bad.append("%s:%d changes sys.path (import the package skin3d instead)" % (rel(root, p), k))
    return bad


def self_test():
    snippet = "\n".join([
        "namespace a {",                       # 1
        "struct S {",                          # 2
        "  int f() const {",                   # 3
        "    return 1;",                       # 4
        "  }",                                 # 5
        "};",                                  # 6
        "// a comment with { braces",          # 7
        "int g(int x,",                        # 8
        "      int y) {",                      # 9
        "  auto l = [&](int z) { return z; };",  # 10
        "  const char* s = \"}\";",            # 11
        "  if (x) {",                          # 12
        "    return y;",                       # 13
        "  }",                                 # 14
        "  return 0;",                         # 15
        "}",                                   # 16
        "const int t[] = {1, 2};",             # 17
        "S::S() : v_(0) {",                    # 18
        "}",                                   # 19
        "}  // namespace a",                   # 20
    ])
    got = functions(snippet)
    want = [("f", 3, 5), ("g", 8, 16), ("S::S", 18, 19)]
    if got != want:
        return "function measure on the snippet: got %s, want %s" % (got, want)
    return ""


def main():
    ap = argparse.ArgumentParser(usage=__doc__)
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    ap.add_argument("--xunit")
    ap.add_argument("--self-test", action="store_true")
    a = ap.parse_args()
    results = []
    if a.self_test:
        results.append(("self_test", self_test()))
    results += check(os.path.abspath(a.root))
    for name, msg in results:
        print("layout: %s: %s" % (name, "FAIL: " + msg if msg else "ok"))
    if a.xunit:
        write_xunit(a.xunit, "layout", results)
    return 1 if any(m for _, m in results) else 0


if __name__ == "__main__":
    sys.exit(main())
