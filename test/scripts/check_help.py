#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Every user script of scripts/ answers --help and -h.

usage: check_help.py [--xunit FILE.xml]

Runs each executable of scripts/ (the Python tools and the shell entry points: setup, build, test, demo, ...) with
--help and with -h, in a scratch working directory, and checks: exit status 0, a line with "usage" on stdout, and
nothing created or changed (neither in the scratch directory nor in the source tree: no results/, no build
products). Also: test_summary.py given a results directory that does not exist says so and exits non-zero.
The Python tools import the package skin3d: run with the devel space's environment (run_tests has it, or
source build/devel/setup.bash).
"""
import os
import re
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import run_checks  # noqa: E402

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
SCRIPTS = os.path.join(ROOT, "scripts")
# The source tree's top level and scripts/: a --help that started a build, a demo or a benchmark would change them.
WATCHED = [ROOT, SCRIPTS]


def user_scripts():
    return sorted(f for f in os.listdir(SCRIPTS)
                  if os.path.isfile(os.path.join(SCRIPTS, f)) and os.access(os.path.join(SCRIPTS, f), os.X_OK))


def snapshot(dirs):
    """path -> (size, mtime) of every file directly in dirs, None for a directory (whose mtime the build and git
    change on their own: a new directory such as results/ still shows as a new entry)."""
    out = {}
    for d in dirs:
        for name in os.listdir(d):
            p = os.path.join(d, name)
            try:
                st = os.stat(p)
            except OSError:
                continue
            out[p] = None if os.path.isdir(p) else (st.st_size, st.st_mtime_ns)
    return out


def tree(d):
    return sorted(os.path.relpath(os.path.join(r, f), d) for r, ds, fs in os.walk(d) for f in fs + ds)


def run(cmd, cwd, timeout=60):
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")  # no __pycache__ in the source tree
    return subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True,
                          timeout=timeout, env=env)


def help_check(script, flag, scratch):
    path = os.path.join(SCRIPTS, script)
    cmd = ["/usr/bin/python3", path, flag] if script.endswith(".py") else [path, flag]
    before = snapshot(WATCHED)
    try:
        r = run(cmd, scratch)
    except subprocess.TimeoutExpired:
        return "%s %s did not finish within 60 s (it does more than print its usage)" % (script, flag)
    changed = sorted(p for p, v in snapshot(WATCHED).items() if p not in before or before[p] != v)
    created = tree(scratch)
    problems = []
    if r.returncode != 0:
        problems.append("exit status %d" % r.returncode)
    if not re.search(r"^\s*usage\b", r.stdout, re.IGNORECASE | re.MULTILINE):
        problems.append("no 'usage' line on stdout")
    if changed:
        problems.append("changed %s" % ", ".join(os.path.relpath(p, ROOT) for p in changed))
    if created:
        problems.append("created %s in the working directory" % ", ".join(created))
    if problems:
        tail = (r.stderr.strip().splitlines() or [""])[-1]
        return "%s %s: %s%s" % (script, flag, "; ".join(problems), (" (stderr: %s)" % tail) if tail else "")
    return ""


def checks(tmp):
    results = []
    scripts = user_scripts()
    if len(scripts) < 10:
        results.append(("user scripts found", "only %d executables in %s" % (len(scripts), SCRIPTS)))
    for script in scripts:
        for flag in ("--help", "-h"):
            scratch = os.path.join(tmp, "%s%s" % (script, flag))
            os.makedirs(scratch)
            results.append(("%s %s" % (script, flag), help_check(script, flag, scratch)))
    missing = os.path.join(tmp, "no_such_results_dir")
    r = run(["/usr/bin/python3", os.path.join(SCRIPTS, "test_summary.py"), missing], tmp)
    msg = ""
    if r.returncode == 0:
        msg = "exit status 0 for a directory that does not exist"
    elif missing not in r.stdout + r.stderr or not re.search(r"no directory|does not exist|not found",
                                                                r.stdout + r.stderr):
        msg = "does not say that '%s' does not exist: %r" % (missing, (r.stdout + r.stderr).strip())
    elif os.path.exists(missing):
        msg = "created %s" % missing
    results.append(("test_summary.py on a missing directory", msg))
    return results


if __name__ == "__main__":
    sys.exit(run_checks("help", __doc__, checks))
