#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""
usage: check_layout.py [--root DIR] [--xunit FILE.xml] [--self-test]

The house rules, read from the source tree (text only, nothing is built):
  - no file under src/nodelets includes a file under src/tools, and no tool includes a nodelet file
    (what both need lives in skin3d_ros, include/skin3d/ros/, or in the core);
  - every nodelet file is at most 60 lines (a nodelet only constructs its runner in src/ros);
  - no C++ file in src/ or include/ is longer than 700 lines;
  - no function in src/, include/ (or bench/) has a body longer than 150 lines (from its opening brace to the
    matching closing brace, both lines counted; comments, string and character literals do not take part in the
    matching; lambdas and local classes count in the function that holds them; a member function defined in a
    class body is a function, the class body and a namespace are not);
  - the core and the simulator (src/core, include/skin3d/ except ros/) include no ROS header.
  - the Python code is the package src/skin3d/ (catkin_python_setup, setup.py): it has an __init__.py, no msg/ or
    srv/ of its own (catkin generates skin3d.msg / skin3d.srv beside it) and no C++; no other .py under src/; the
    Python scripts and the package import it as a package, never through sys.path (tests may import their helpers).
(That the measurement libraries do not link the simulator is enforced by the build: -Wl,--no-undefined.)
--xunit writes one JUnit test case per rule (scripts/test counts them). Exit status 1 when a rule is broken.
--self-test first checks the function measure on small known snippets, and that the file and function length
checks fail on oversize synthetic files and pass on good ones.
"""
import argparse
import os
import re
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

MAX_NODELET_LINES = 60
MAX_FUNCTION_LINES = 150
MAX_FILE_LINES = 700
CPP_EXTS = (".cpp", ".cc", ".cxx", ".h", ".hpp", ".hh")
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


def blank_preprocessor(code):
    """Preprocessor lines (with their backslash continuations) blanked, newlines kept: they take no part in the
    statements (a macro's braces are not a body)."""
    return re.sub(r"^[ \t]*#(?:[^\n]*\\\n)*[^\n]*", lambda m: "\n" * m.group(0).count("\n"), code, flags=re.M)


def function_name(stmt):
    """The name in a function definition's head (the text from its statement's start to the body's brace)."""
    head = re.sub(r"\s+", " ", stmt).strip()
    m = re.search(r"([~\w:]*operator\s*(?:\(\s*\)|\[\s*\]|[^\s(]+))\s*\(", head)
    if m:
        return m.group(1).replace(" ", "")
    # the name before the parameter list: the last word before the first '(' not inside a template's <>
    depth = 0
    for k, ch in enumerate(head):
        if ch == "<":
            depth += 1
        elif ch == ">" and depth > 0:
            depth -= 1
        elif ch == "(" and depth == 0:
            words = re.findall(r"[~\w:]+", head[:k])
            return words[-1] if words else "?"
    return "?"


def functions(text):
    """(name, first line, body's first line, last line) of every function definition at namespace or class level:
    first line is that of the definition's first character, the body runs from the line of its opening brace to
    the line of the matching closing brace."""
    code = blank_preprocessor(strip_code(text))
    # kinds of the open braces: 'scope' (namespace, class, extern), 'func', 'init' (a brace initialiser in a
    # constructor's initialiser list) or 'other'
    stack = []
    stmt_start = 0
    found = []
    func_open = None  # (name, first line, brace line) of the function being read
    line = 1

    def at_scope():
        return not ("func" in stack or "other" in stack or "init" in stack)

    for i, c in enumerate(code):
        if c == "\n":
            line += 1
        elif c == "{":
            if not at_scope():
                stack.append("other")
                continue
            stmt = code[stmt_start:i]
            words = stmt.strip()
            if re.search(r"\b(namespace|extern)\b", words) and ")" not in words:
                stack.append("scope")
            elif re.search(r"\b(class|struct|union|enum)\b", words) and "(" not in words.split(":")[0]:
                stack.append("scope")
            elif re.search(r"\)[^:;]*(?<!:):(?!:)", words) and re.search(r"[\w>]\s*$", words):
                # S::S() : a_{1}, b_(2) {: the brace of a member's initialiser, the body follows
                stack.append("init")
                continue
            elif ")" in words and not words.rstrip().endswith("="):
                # first line: the line of the statement's first non-blank character
                lead = len(stmt) - len(stmt.lstrip())
                first = line - code.count("\n", stmt_start + lead, i)
                func_open = (function_name(words), first, line)
                stack.append("func")
            else:
                # an initialiser (= {...}, x{...}, a default argument's {}): part of its statement
                stack.append("other")
                continue
            stmt_start = i + 1
        elif c == "}":
            kind = stack.pop() if stack else "other"
            if kind == "func" and func_open:
                found.append((func_open[0], func_open[1], func_open[2], line))
                func_open = None
            if kind in ("scope", "func") and at_scope():
                stmt_start = i + 1
        elif c == ";" and at_scope():
            stmt_start = i + 1
        elif c == ":" and at_scope():
            # access specifiers (public:) end a statement; a constructor's initialiser list does not
            if re.search(r"\b(public|private|protected)\s*$", code[stmt_start:i]):
                stmt_start = i + 1
    return found


def files(root, folder, exts=CPP_EXTS):
    for d, _, names in os.walk(os.path.join(root, folder)):
        for n in sorted(names):
            if n.endswith(exts):
                yield os.path.join(d, n)


def rel(root, path):
    return os.path.relpath(path, root)


def line_count(text):
    """Lines of a text as an editor numbers them (wc -l, plus a last line without its newline)."""
    return len(text.splitlines())


def long_files_of(root, folders, limit=MAX_FILE_LINES):
    """'file has N lines (at most limit)' for every C++ file in the folders (under root) longer than limit."""
    out = []
    for p in [q for folder in folders for q in files(root, folder)]:
        n = line_count(open(p, encoding="utf-8").read())
        if n > limit:
            out.append("%s:1 has %d lines (at most %d)" % (rel(root, p), n, limit))
    return out


def long_functions_of(root, folders, limit=MAX_FUNCTION_LINES):
    """'file:line name is N lines (at most limit)' for every function body in the folders longer than limit."""
    out = []
    for p in [q for folder in folders for q in files(root, folder)]:
        for name, first, body, last in functions(open(p, encoding="utf-8").read()):
            n = last - body + 1
            if n > limit:
                out.append("%s:%d %s is %d lines (body, at most %d)" % (rel(root, p), first, name, n, limit))
    return out


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
    # 2. nodelet files at most 60 lines
    long_files = []
    for p in files(root, "src/nodelets"):
        n = sum(1 for _ in open(p, encoding="utf-8"))
        if n > MAX_NODELET_LINES:
            long_files.append("%s has %d lines (at most %d)" % (rel(root, p), n, MAX_NODELET_LINES))
    results.append(("nodelet_files_short", "; ".join(long_files)))
    # 3. C++ files at most 700 lines, functions at most 150 lines
    results.append(("files_short", "; ".join(long_files_of(root, ("src", "include")))))
    results.append(("functions_short", "; ".join(long_functions_of(root, ("src", "include", "bench")))))
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
    want = [("f", 3, 3, 5), ("g", 8, 9, 16), ("S::S", 18, 18, 19)]
    if got != want:
        return "function measure on the snippet: got %s, want %s" % (got, want)
    # braces in character literals, block comments, raw strings and macros; a local class and a brace
    # initialiser in a constructor's initialiser list; operator(); an extern "C" block
    snippet2 = "\n".join([
        "#define OPEN {",                      # 1
        "#define BLOCK(x) \\",                 # 2
        "  do { x; } while (0)",               # 3
        "extern \"C\" {",                      # 4
        "int c_api(void);",                    # 5
        "}",                                   # 6
        "class T {",                           # 7
        " public:",                            # 8
        "  T() : a_{1}, b_(2) {",              # 9
        "    char c = '{';",                   # 10
        "  }",                                 # 11
        "  int operator()(int v) const { return v; }",  # 12
        " private:",                           # 13
        "  int a_, b_;",                       # 14
        "};",                                  # 15
        "void h() {",                          # 16
        "  /* } */ struct L { void m() {} };", # 17
        "  const char* r = R\"x(})x\";",       # 18
        "}",                                   # 19
        "void d(std::vector<int> v = {},",     # 20
        "       int w = int{2}) {",            # 21
        "}",                                   # 22
    ])
    got = functions(snippet2)
    want = [("T", 9, 9, 11), ("operator()", 12, 12, 12), ("h", 16, 16, 19), ("d", 20, 21, 22)]
    if got != want:
        return "function measure on the second snippet: got %s, want %s" % (got, want)
    # the two length checks on synthetic trees: an oversize file / function fails, a good one passes
    def body(lines):
        return "\n".join(["int big() {"] + ["  x += %d;" % k for k in range(lines - 2)] + ["}"]) + "\n"
    cases = [
        # (name, files {path: text}, check, expect a failure, text the failure must hold)
        ("oversize file", {"src/core/big.cpp": "// x\n" * (MAX_FILE_LINES + 1)}, long_files_of, True,
         "src/core/big.cpp:1 has %d lines" % (MAX_FILE_LINES + 1)),
        ("oversize header", {"include/skin3d/big.h": "// x\n" * (MAX_FILE_LINES + 5)}, long_files_of, True,
         "include/skin3d/big.h:1 has %d lines" % (MAX_FILE_LINES + 5)),
        ("good file", {"src/core/ok.cpp": "// x\n" * MAX_FILE_LINES}, long_files_of, False, ""),
        ("oversize function", {"src/tools/f.cpp": "// head\n" + body(MAX_FUNCTION_LINES + 1)}, long_functions_of, True,
         "src/tools/f.cpp:2 big is %d lines" % (MAX_FUNCTION_LINES + 1)),
        ("oversize member", {"include/skin3d/m.h": "struct M {\n" + body(MAX_FUNCTION_LINES + 3) + "};\n"},
         long_functions_of, True, "include/skin3d/m.h:2 big is %d lines" % (MAX_FUNCTION_LINES + 3)),
        # a body of exactly the limit (its head on three lines before it), in a namespace, with a long comment
        ("good function", {"src/core/g.cpp": "namespace n {\nint f(int a,\n      int b)\n{\n" +
                           "  a += b;\n" * (MAX_FUNCTION_LINES - 2) + "}\n}  // namespace n\n" + "// c {\n" * 300},
         long_functions_of, False, ""),
        ("long class of short functions", {"src/core/c.cpp": "class C {\n" + body(100) + body(100).replace("big", "big2") +
                                           "};\n"}, long_functions_of, False, ""),
    ]
    for name, tree, fn, fail, text in cases:
        with tempfile.TemporaryDirectory() as root:
            for path, content in tree.items():
                os.makedirs(os.path.dirname(os.path.join(root, path)), exist_ok=True)
                with open(os.path.join(root, path), "w", encoding="utf-8") as f:
                    f.write(content)
            got = fn(root, ("src", "include"))
        if fail and not any(text in g for g in got):
            return "%s: want a failure holding '%s', got %s" % (name, text, got)
        if not fail and got:
            return "%s: want none, got %s" % (name, got)
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
