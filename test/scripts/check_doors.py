#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""The two doors give the same numbers: one bag through the launch files (the live nodelets) and through
`process_bag` (the offline tool), each with its defaults, gives
- the same trajectory.tum to the last digit (and the same map.ply) through replay_globe.launch, for image bags with
  and without the gyro and for a landmark bag;
- the same induration.yaml through replay_workpiece.launch and `process_bag --induration`, apart from the lines
  that name the input (`source:`) and the processing time of each frame (`seconds:`);
- the same site.yaml (and induration.yaml) through replay_sweep.launch and `process_bag --site`, apart from the
  input's name, the command line and the processing times.

usage: check_doors.py --process-bag PATH --data DIR [--xunit FILE]

DIR holds the bags the build makes (globe_images_10.bag, globe_landmarks_40.bag, workpiece_quarter.bag,
skin_sweep_half.bag). roslaunch runs on a free port
with its own master, so it does not meet another test's. Exit status 1 when a check fails.
"""
import argparse
import os
import re
import socket
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

CASES = [
    # name, bag, process_bag options, launch file and arguments, files compared
    ("images", "globe_images_10.bag", [], ["replay_globe.launch", "images:=true"], ["trajectory.tum", "map.ply"]),
    ("images_gyro", "globe_images_10.bag", ["--gyro"], ["replay_globe.launch", "images:=true", "gyro:=true"],
     ["trajectory.tum", "map.ply"]),
    ("landmarks_gyro", "globe_landmarks_40.bag", ["--gyro"], ["replay_globe.launch", "gyro:=true"],
     ["trajectory.tum", "map.ply"]),
    # the workpiece bag also holds ground_truth/pose, which no induration node reads: no waiting for subscribers
    # (the player would wait for ever), the player's delay gives the nodelet time to subscribe instead
    ("induration", "workpiece_quarter.bag", ["--induration"],
     ["replay_workpiece.launch", "wait_for_subscribers:=false", "delay:=8"], ["induration.yaml"]),
    # the sweep's gyro (imu/data) has no subscriber either
    ("site", "skin_sweep_half.bag", ["--site", "--site-poses", "ground_truth/pose"],
     ["replay_sweep.launch", "wait_for_subscribers:=false", "delay:=8"], ["site.yaml", "induration.yaml"]),
]
# lines that may differ between the doors: the input's name and the wall time of a frame
VARYING = ("source:", "seconds:")


SITE_VARYING = ("source:", "command_line:", "seconds_measure:")


def comparable(name, data):
    if name == "site.yaml":  # each frame's `seconds: {register: .., fuse: ..}` sits inside its flow map
        lines = [l for l in data.decode().splitlines() if not l.strip().startswith(SITE_VARYING)]
        return "\n".join(re.sub(r"seconds: \{[^}]*\}", "seconds: ~", l) for l in lines).encode()
    if name != "induration.yaml":
        return data
    return b"\n".join(l for l in data.splitlines() if not l.strip().decode().startswith(VARYING))


def free_port():
    s = socket.socket()
    s.bind(("localhost", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def read(path):
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError:
        return None


def run_case(tmp, process_bag, data, case):
    name, bag, pb_args, launch_args, files = case
    bag = os.path.join(os.path.abspath(data), bag)
    if not os.path.exists(bag):
        return "the test bag %s is missing (built by the skin3d_*_test_bag targets)" % bag
    off, live = os.path.join(tmp, name + "_process_bag"), os.path.join(tmp, name + "_launch")
    r = subprocess.run([process_bag, "--bag", bag, "--out", off, "--quiet"] + pb_args,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=600)
    if r.returncode != 0:
        return "process_bag failed (%d): %s" % (r.returncode, r.stdout[-2000:])
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://localhost:%d" % port, ROS_HOME=os.path.join(tmp, "ros_home"))
    cmd = ["roslaunch", "-p", str(port), "skin3d", launch_args[0], "bag:=" + bag, "results:=" + live]
    cmd += [a for a in launch_args[1:] if a.startswith("wait_for_subscribers:=")] or ["wait_for_subscribers:=true"]
    cmd += [a for a in launch_args[1:] if not a.startswith("wait_for_subscribers:=")]
    try:
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, timeout=600)
    except subprocess.TimeoutExpired:
        return "roslaunch did not end within 600 s"
    if r.returncode != 0:
        return "roslaunch failed (%d): %s" % (r.returncode, r.stdout[-2000:])
    for f in files:
        a, b = read(os.path.join(off, f)), read(os.path.join(live, f))
        if a is None or b is None:
            return "%s missing (process_bag: %s, launch: %s); launch output: %s" % (
                f, a is not None, b is not None, r.stdout[-2000:])
        a, b = comparable(f, a), comparable(f, b)
        if a != b:
            la, lb = a.decode().splitlines(), b.decode().splitlines()
            first = next((i for i in range(min(len(la), len(lb))) if la[i] != lb[i]), min(len(la), len(lb)))
            return "%s differs: %d lines from process_bag, %d from the launch; first difference at line %d: %r vs %r" % (
                f, len(la), len(lb), first + 1, la[first] if first < len(la) else "", lb[first] if first < len(lb) else "")
    print("check_doors: %s: %s identical through both doors (%d lines)" % (
        name, " and ".join(files), len(read(os.path.join(off, files[0])).splitlines())))
    return ""


def main():
    ap = argparse.ArgumentParser(usage=__doc__.replace("%", "%%"))
    ap.add_argument("--process-bag", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--xunit")
    a = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            results.append((case[0], run_case(tmp, a.process_bag, a.data, case)))
    for name, msg in results:
        print("doors: %s: %s" % (name, "FAIL: " + msg if msg else "ok"))
    if a.xunit:
        write_xunit(a.xunit, "doors", results)
    return 1 if any(m for _, m in results) else 0


if __name__ == "__main__":
    sys.exit(main())
