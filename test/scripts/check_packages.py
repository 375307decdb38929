#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""The bare-machine guard: everything skin3d starts must come from a package that scripts/packages.txt installs.

usage: check_packages.py [--packages FILE] [--root DIR] [--xunit FILE.xml] [--self-test]

A package installed by hand on a development machine hides a missing entry in scripts/packages.txt: the tests
pass there and fail on a bare Debian 12 (it happened: the `nodelet` executable is in libnodeletlib-tools, which
the list missed, and every rostest failed on a fresh machine). This check does not trust what is installed. It
collects what the project starts:
  - every node and test `pkg/type` of launch/*.launch and test/**/*.test (and every `nodelet load PKG/...`
    plugin of another package), plus what roslaunch and rostest start themselves (roscore, rosmaster, rosout);
  - every external command of the shell scripts (scripts/*, .ci/run: the words in command position, found
    with a small quote-aware scanner), every absolute /usr/bin or /bin path named in scripts, tests, launch and
    CMake files, the commands that Python scripts run through subprocess, and the first word of the literal
    commands that C++ tests and tools pass to system() / popen();
  - every module that the Python package, scripts and test nodes import (src/skin3d/*.py, scripts/*.py,
    test/**/*.py), the standard library and the project's own modules (the package skin3d, with its generated
    messages) aside;
finds the file each one is (roslib for nodes, /usr/bin:/bin:/usr/sbin:/sbin for commands, importlib for modules),
asks dpkg which Debian package owns that file, and requires that package to be in the closure of the list:
the listed packages, everything they depend on (apt-cache depends --recurse; Depends and Pre-Depends, every
alternative and every provider of a virtual package), and Debian's Essential / Priority: required base that
every Debian system has. Anything else fails, naming the package to add (or, when nothing on the machine
provides the file, naming what is missing).

--self-test also checks the guard itself: with libnodeletlib-tools, x11-apps or python3-opencv taken off a copy of
the list, the check must fail and name that package.
--xunit writes one JUnit test case per item (scripts/test counts them). Exit status 1 when anything fails.
Needs the environment of a built tree (source build/devel/setup.bash) for the ROS package paths, and apt's
package lists (scripts/setup runs apt-get update before installing).
"""
import argparse
import glob
import importlib.util
import os
import xml.etree.ElementTree as ET
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
SYSTEM_PATH = "/usr/bin:/bin:/usr/sbin:/sbin"
# Started by roslaunch / rostest themselves (no launch file names them): the master and rosout.
IMPLICIT_NODES = [("rosout", "rosout", "roslaunch starts it with every launch")]
IMPLICIT_COMMANDS = [("rostest", "CMake's add_rostest runs it"), ("roscore", "roslaunch starts a master"),
                     ("rosmaster", "roslaunch starts a master"), ("roslaunch", "rostest runs it")]
SHELL_SKIP = {  # keywords and builtins (bash's own), never a package's executable
    "if", "then", "else", "elif", "fi", "do", "done", "while", "until", "for", "in", "case", "esac", "function",
    "select", "!", "{", "}", "[[", "]]", "[", "]", "time", "coproc"}


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def bash_builtins():
    out = run(["/bin/bash", "-c", "compgen -b; compgen -k"]).stdout.split()
    return set(out) | SHELL_SKIP


# ---------------------------------------------------------------------------------------------- the closure
def read_list(path):
    names = []
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0]
            names += line.split()
    return names


def closure(packages):
    """The listed packages, their recursive Depends/Pre-Depends (every alternative, every provider of a virtual
    package) and Debian's base (Essential: yes or Priority: required)."""
    if not packages:
        return set()
    r = run(["apt-cache", "depends", "--recurse", "--no-recommends", "--no-suggests", "--no-conflicts",
             "--no-breaks", "--no-replaces", "--no-enhances"] + packages)
    if r.returncode != 0:
        raise RuntimeError("apt-cache depends failed (run apt-get update first?): " + r.stderr.strip()[:400])
    have = set()
    for line in r.stdout.splitlines():
        if not line.strip():
            continue
        if not line.startswith(" ") or line.startswith("    "):  # a package, or a provider of a virtual one
            name = line.strip().strip("<>").split(":")[0]
            have.add(name)
    base = run(["dpkg-query", "-W", "-f=${Package}\t${Essential}\t${Priority}\n"]).stdout
    for line in base.splitlines():
        parts = line.split("\t")
        if len(parts) == 3 and (parts[1] == "yes" or parts[2] == "required"):
            have.add(parts[0].split(":")[0])
    return have


def owner(path):
    """The Debian package that owns `path` (also through /usr-merge aliases and symlinks), or None."""
    candidates = [path, os.path.realpath(path)]
    for p in list(candidates):
        if p.startswith("/usr/"):
            candidates.append(p[4:])  # /usr/bin/x may be registered as /bin/x
        else:
            candidates.append("/usr" + p)
    for p in candidates:
        r = run(["dpkg-query", "-S", p])
        if r.returncode == 0 and r.stdout:
            for line in r.stdout.splitlines():
                pkgs, _, owned = line.partition(": ")
                if owned.strip() == p and not pkgs.startswith("diversion by"):
                    return pkgs.split(",")[0].strip().split(":")[0]
    return None


# ---------------------------------------------------------------------------------------------- what is started
def launch_items(root):
    """(kind, name, where) for the nodes, tests and foreign nodelet plugins of the launch and test files."""
    items = []
    files = sorted(glob.glob(os.path.join(root, "launch", "*.launch")) +
                   glob.glob(os.path.join(root, "test", "**", "*.test"), recursive=True))
    for path in files:
        rel = os.path.relpath(path, root)
        tree = ET.parse(path)
        for el in tree.iter():
            if el.tag in ("node", "test") and el.get("pkg") and el.get("type") and el.get("pkg") != "skin3d":
                items.append(("node", (el.get("pkg"), el.get("type")), rel))
                m = re.match(r"\s*(?:load|standalone)\s+([\w.-]+)/([\w.-]+)", el.get("args", ""))
                if m and m.group(1) != "skin3d":
                    items.append(("plugin", m.group(1), rel))
    for pkg, typ, why in IMPLICIT_NODES:
        items.append(("node", (pkg, typ), why))
    return items


def shell_words(text):
    """The first word of every simple command in a bash text (quote-aware; $( ), ` ` and pipes included)."""
    commands = []
    segment, word = [], []
    i, n = 0, len(text)
    quoted = False

    def end_word():
        nonlocal quoted
        if word or quoted:
            segment.append(("".join(word), quoted))
        word.clear()
        quoted = False

    def end_segment():
        end_word()
        if segment:
            commands.append(list(segment))
        segment.clear()

    def substitution(j, closer):
        depth, k = 1, j
        while k < n and depth:
            if text[k] == "(" and closer == ")":
                depth += 1
            elif text[k] == closer:
                depth -= 1
            k += 1
        commands.extend(shell_words(text[j:k - 1]))
        return k

    while i < n:
        c = text[i]
        if c == "\\" and i + 1 < n:
            if text[i + 1] != "\n":
                word.append(text[i + 1])
            i += 2
        elif c == "'":
            k = text.find("'", i + 1)
            k = n if k < 0 else k
            word.append(text[i + 1:k])
            quoted = True
            i = k + 1
        elif c == '"':
            i += 1
            quoted = True
            while i < n and text[i] != '"':
                if text[i] == "\\":
                    word.append(text[i + 1:i + 2])  # an escaped character stays (\$( is text, not a substitution)
                    i += 2
                    continue
                if text.startswith("$(", i) and not text.startswith("$((", i):
                    i = substitution(i + 2, ")")
                    word.append("$")
                    continue
                if text[i] == "`":
                    i = substitution(i + 1, "`")
                    word.append("$")
                    continue
                word.append(text[i])
                i += 1
            i += 1
        elif c == "#" and not word:
            k = text.find("\n", i)
            i = n if k < 0 else k
        elif text.startswith("$((", i):
            k = text.find("))", i)
            k = n if k < 0 else k
            for m in re.finditer(r"\$\(([^()]*)\)", text[i + 3:k]):  # command substitutions in arithmetic
                commands.extend(shell_words(m.group(1)))
            word.append("$")
            i = k + 2
        elif text.startswith("$(", i):
            i = substitution(i + 2, ")")
            word.append("$")
        elif c == "`":
            i = substitution(i + 1, "`")
            word.append("$")
        elif c in " \t":
            end_word()
            i += 1
        elif c in "\n;&|()":
            end_segment()
            i += 1
        elif c in "<>":
            end_word()  # a redirection: its target is not a command
            i += 1
            while i < n and text[i] in "<>&":
                i += 1
            while i < n and text[i] in " \t":
                i += 1
            while i < n and text[i] not in " \t\n;&|()":
                i += 1
        else:
            word.append(c)
            i += 1
    end_segment()
    return commands



def strip_heredocs(text):
    """Drops the bodies of here-documents (<<EOF ... EOF, <<'EOF', <<-EOF): data, not commands."""
    out, lines, i = [], text.split("\n"), 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        m = re.search(r"<<(-?)\s*([\'\"]?)(\w+)\2", line) if "<<<" not in line else None
        i += 1
        if m:
            dash, delim = m.group(1), m.group(3)
            while i < len(lines) and (lines[i].lstrip("\t") if dash else lines[i]) != delim:
                i += 1
            i += 1  # the terminator
    return "\n".join(out)


def strip_case_patterns(text):
    """Blanks the patterns of case clauses (`--out)`, `a|b)`): they are not commands."""
    def body(m):
        b = re.sub(r"(^|;;&?|;&)(\s*)\(?[^()$`;\n]*?\)", lambda mm: mm.group(1) + mm.group(2), m.group(2))
        return m.group(1) + b + m.group(3)
    return re.sub(r"(\bcase\b[^\n;]*?\bin\b)(.*?)(\besac\b)", body, text, flags=re.S)


ASSIGNMENT = re.compile(r"^[A-Za-z_]\w*(\[[^]]*\])?\+?=")
# Commands that run another command: the wrapper itself is checked when it is a program, then the wrapped one.
PREFIXES = {"exec", "time", "sudo", "$sudo", "nohup", "env", "xargs", "timeout", "nice", "stdbuf", "command"}


def wrapper_functions(text):
    """{name: arguments it shifts off} for the functions that run their arguments ("$@" in the body)."""
    out = {}
    for m in re.finditer(r"^\s*(?:function\s+)?([\w-]+)\s*\(\)\s*\{(.*?)^\s*\}", text, re.M | re.S):
        body = m.group(2)
        if '"$@"' in body:
            out[m.group(1)] = len(re.findall(r"\bshift\b", body[:body.index('"$@"')]))
    return out


def shell_commands(text, builtins):
    text = strip_case_patterns(strip_heredocs(text))
    functions = set(re.findall(r"^\s*(?:function\s+)?([\w-]+)\s*\(\)", text, re.M))
    wrappers = wrapper_functions(text)
    out = []

    def candidate(w):
        return (w and "$" not in w and not w.startswith("-") and w not in builtins and w not in functions and
                not w.endswith(")") and re.match(r"^[\w./+-]+$", w) and not w.isdigit() and re.search(r"[A-Za-z]", w))

    for seg in shell_words(text):
        words = [w for w, _ in seg]
        if not words or words[0] in ("for", "case", "select", "function") or words[0].endswith("()"):
            continue
        k = 0
        while k < len(words):
            w = words[k]
            if ASSIGNMENT.match(w) or w in SHELL_SKIP:
                k += 1
            elif w in wrappers:
                k += 1 + wrappers[w]
            elif w in PREFIXES:
                if w == "command" and k + 1 < len(words) and words[k + 1].startswith("-"):
                    break  # command -v X: a look-up, not a run
                if w not in ("exec", "time", "command", "$sudo") and candidate(w):
                    out.append(w)
                k += 1
                while k < len(words) and (words[k].startswith("-") or ASSIGNMENT.match(words[k]) or
                                          re.match(r"^[\d.]+[smhd]?$", words[k])):
                    k += 1
            else:
                if candidate(w):
                    out.append(w)
                    if w in ("bash", "sh") and k + 2 < len(words) and words[k + 1] == "-c":
                        out.extend(shell_commands(words[k + 2], builtins))
                break
    return out


def command_items(root, builtins):
    items = []
    shell_files = [os.path.join(root, ".ci", "run")]
    for p in sorted(glob.glob(os.path.join(root, "scripts", "*"))):
        with open(p, errors="replace") as f:
            first = f.readline()
        if first.startswith("#!") and "bash" in first or first.startswith("#!/bin/sh"):
            shell_files.append(p)
    for p in shell_files:
        if not os.path.exists(p):
            continue
        rel = os.path.relpath(p, root)
        with open(p, errors="replace") as f:
            text = f.read()
        for w in shell_commands(text, builtins):
            if "/" in w and not w.startswith("/"):
                continue  # the project's own scripts and binaries (scripts/setup, build/devel/...)
            items.append(("command", w, rel))
    scan = (glob.glob(os.path.join(root, "scripts", "*")) + glob.glob(os.path.join(root, "test", "**", "*"), recursive=True) +
            glob.glob(os.path.join(root, "src", "**", "*.cpp"), recursive=True) +
            glob.glob(os.path.join(root, "src", "**", "*.h"), recursive=True) +
            glob.glob(os.path.join(root, "src", "**", "*.py"), recursive=True) +
            glob.glob(os.path.join(root, "launch", "*")) + [os.path.join(root, "CMakeLists.txt")])
    for p in sorted(set(scan)):
        if not os.path.isfile(p) or p.endswith(("check_packages.py", ".png", ".yaml", ".md")):
            continue
        rel = os.path.relpath(p, root)
        with open(p, errors="replace") as f:
            text = f.read()
        for m in re.finditer(r"(?<![\w./-])(/(?:usr/)?(?:s?bin)/[\w.+-]+)", text):
            items.append(("command", m.group(1), rel))
        if p.endswith(".py"):
            for m in re.finditer(r"subprocess\.\w+\(\s*\[\s*[\"']([\w./+-]+)[\"']", text):
                items.append(("command", m.group(1), rel))
        if p.endswith((".cpp", ".h")):
            for m in re.finditer(r"\b(?:std::)?(?:system|popen)\(\s*\(?\s*\"([\w./+-]+)", text):
                items.append(("command", m.group(1), rel))
    return items


def python_items(root):
    items = []
    files = sorted(glob.glob(os.path.join(root, "src", "skin3d", "**", "*.py"), recursive=True) +
                   glob.glob(os.path.join(root, "scripts", "*.py")) +
                   glob.glob(os.path.join(root, "test", "**", "*.py"), recursive=True))
    # skin3d: the package src/skin3d and the generated messages; the others: test helpers beside their tests
    local = {os.path.splitext(os.path.basename(p))[0] for p in files
             if not os.path.relpath(p, root).startswith("src" + os.sep)} | {"skin3d"}
    for p in files:
        rel = os.path.relpath(p, root)
        with open(p) as f:
            text = f.read()
        for m in re.finditer(r"^\s*(?:import\s+([\w.]+)|from\s+([\w.]+)\s+import)", text, re.M):
            mod = (m.group(1) or m.group(2)).split(".")[0]
            if mod in sys.stdlib_module_names or mod in local or mod == "__future__":
                continue
            items.append(("module", mod, rel))
    return items


# ---------------------------------------------------------------------------------------------- the check
def locate(kind, name):
    """(path or None, detail) of one item on this machine."""
    if kind == "node":
        pkg, typ = name
        try:
            import rospkg
            from roslib.packages import find_node
            paths = find_node(pkg, typ, rospack=rospkg.RosPack())
        except Exception as e:  # rospkg missing or the package unknown
            detail = "ROS package '%s' not found (%s)" % (pkg, str(e).strip().splitlines()[0] if str(e) else type(e).__name__)
            exe = "/usr/lib/%s/%s" % (pkg, typ)  # where Debian puts a ROS package's executables
            if os.path.exists(exe):
                detail += ("; its executable %s is there (Debian package %s) but roslaunch cannot find it without the "
                           "package's package.xml (/usr/share/%s/package.xml, usually in lib%s-dev)"
                           % (exe, owner(exe), pkg, pkg.replace("_", "-")))
            return None, detail
        return (paths[0], "") if paths else (None, "no executable '%s' in ROS package '%s'" % (typ, pkg))
    if kind == "plugin":
        r = run(["rospack", "find", name])
        if r.returncode != 0:
            return None, "ROS package '%s' (a nodelet plugin's) not found" % name
        xml = glob.glob(os.path.join(r.stdout.strip(), "*.xml"))
        return (xml[0] if xml else r.stdout.strip()), ""
    if kind == "module":
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError) as e:
            return None, str(e)
        if spec is None:
            return None, "Python module '%s' not found by /usr/bin/python3" % name
        path = spec.origin if spec.origin and spec.origin not in ("built-in", "frozen") else None
        if path is None and spec.submodule_search_locations:
            path = list(spec.submodule_search_locations)[0]
        return path, ""
    # command
    if name.startswith("/"):
        return (name, "") if os.path.exists(name) else (None, "%s does not exist" % name)
    found = shutil.which(name, path=SYSTEM_PATH)
    if found:
        return found, ""
    elsewhere = shutil.which(name)
    if elsewhere:
        return None, "'%s' is only at %s (not from a Debian package; scripts run with /usr/bin first)" % (name, elsewhere)
    return None, "command '%s' not found" % name


def describe(kind, name):
    return "%s/%s" % name if kind == "node" else name


def check(items, have, listed):
    """[(case name, failure message or None)] per distinct item."""
    results, seen = [], {}
    for kind, name, where in items:
        key = (kind, name)
        if key in seen:
            seen[key].append(where)
            continue
        seen[key] = [where]
    for (kind, name), wheres in seen.items():
        where = ", ".join(sorted(set(wheres)))
        label = "%s %s" % (kind, describe(kind, name))
        path, detail = locate(kind, name)
        if path is None:
            results.append((label, "%s (used by %s): %s; no package of scripts/packages.txt provides it" %
                            (label, where, detail)))
            continue
        pkg = owner(path)
        if pkg is None:
            if path.startswith(ROOT) or "/devel/" in path or "/build/" in path:
                results.append((label, None))  # the project's own build
            else:
                results.append((label, "%s (used by %s) is %s, which no Debian package owns: install it from a "
                                "package and list that package in scripts/packages.txt" % (label, where, path)))
            continue
        if pkg in have:
            results.append((label, None))
        else:
            results.append((label, "%s (used by %s) is %s from the Debian package '%s', which scripts/packages.txt "
                            "does not install (add %s to scripts/packages.txt)" % (label, where, path, pkg, pkg)))
    return results


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--packages", default=os.path.join(ROOT, "scripts", "packages.txt"))
    ap.add_argument("--root", default=ROOT)
    ap.add_argument("--xunit")
    ap.add_argument("--self-test", action="store_true")
    a = ap.parse_args()
    listed = read_list(a.packages)
    items = launch_items(a.root) + command_items(a.root, bash_builtins()) + python_items(a.root)
    have = closure(listed)
    results = check(items, have, listed)
    if a.self_test:
        for victim, label in (("libnodeletlib-tools", "node nodelet/nodelet"), ("x11-apps", "command xwd"),
                              ("python3-opencv", "module cv2")):
            reduced = [p for p in listed if p != victim]
            sub = dict(check([it for it in items if "%s %s" % (it[0], describe(it[0], it[1])) == label],
                             closure(reduced), reduced))
            msg = sub.get(label)
            ok = msg is not None and victim in msg
            results.append(("guard fails without %s" % victim,
                            None if ok else "with %s taken off the list, the check of %s %s" %
                            (victim, label, "passed" if msg is None else "failed without naming it: " + msg)))
    for name, msg in results:
        print(("FAIL  " + msg) if msg else ("ok    " + name))
    failed = sum(1 for _, m in results if m)
    print("packages guard: %d items checked against %d listed packages (%d with dependencies and base), %d failed"
          % (len(results), len(listed), len(have), failed))
    if a.xunit:
        write_xunit(a.xunit, "packages_guard", results)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
