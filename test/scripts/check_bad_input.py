#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""The bad-input matrix: faulty bags and command lines through every door, one JUnit test case per (door, case).

usage: check_bad_input.py [--bin DIR] [--data DIR] [--door process_bag|launch ...] [--only NAME ...] [--list] [--keep DIR] [--jobs N]
                          [--xunit FILE.xml]

From two small good bags (made by make_dataset: the 10-frame rendered globe with imu/data, and the 2-frame
quarter-resolution workpiece; taken from --data when there, else made in the temporary directory), the cases
below write faulty copies with the rosbag Python API and run them through a door: process_bag (SLAM mode and
--induration; the default) or launch (`roslaunch skin3d replay_globe.launch`, the live nodelets, for the SLAM-mode
image cases that make sense live; see LaunchDoor). The rule each case checks:
  - no crash: no signal, no uncaught exception ("terminate called");
  - a bad message is dropped, the run goes on: exit 0, the good frames' results written (trajectory.tum has one
    line per good frame; induration.yaml one entry per good frame), stderr names the topic, the stamp (at least
    its first 3 decimals) and the fault, and the results file (summary.yaml / induration.yaml) names the fault;
  - nothing could be done (every frame bad, no usable camera_info, a bag that cannot be read): non-zero exit and
    stderr naming the fault; no empty results directory left behind;
  - a bad command line or output directory: exit 2 (command line) or 3 (output), the option or path named,
    refused before the bag is read (process_bag's "input:" line never printed), no results directory made.
Cases that fail only because a door does not yet call the checks are still failures: the table is the contract.
Through the launch, which cannot exit non-zero for a nodelet's fault, the rule is: the launch ends by itself (no
hang, no "process has died" of the nodelet manager, replay_done.py ended it), the fault is named in roslaunch's
output (the nodelets' log), summary.yaml counts it where the SLAM sees it, trajectory.tum has the good frames, and
where nothing can be processed no results are written. Where live differs from process_bag, the case's `live`
entry says how and why (--list shows it).

--bin: the folder of process_bag and make_dataset (default: build/devel/lib/skin3d of the source tree).
--keep DIR: keep every faulty bag and results directory there (for reading a failure).
--jobs N: the launch door runs N cases at once (each with its own master and ROS_HOME; the CI runs 2).
"""
import argparse
import concurrent.futures
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.normpath(os.path.join(HERE, "..", ".."))

GLOBE = "globe_images_10.bag"      # 10 frames at 1000.0 + 0.1 k s, imu/data at 100 Hz, camera_info per frame
WORKPIECE = "workpiece_quarter.bag"  # 2 frames
GLOBE_FRAMES, WORKPIECE_FRAMES = 10, 2
FRAME_PERIOD = {GLOBE: 0.1, WORKPIECE: 0.5}  # s; both start at 1000 s
L_IMG, R_IMG = "stereo/left/image_raw", "stereo/right/image_raw"
L_INFO, R_INFO = "stereo/left/camera_info", "stereo/right/camera_info"
IMU = "imu/data"
NAN, INF = float("nan"), float("inf")


# ---------------------------------------------------------------- bag editing

def frame_stamp(k, base=GLOBE):
    return 1000.0 + FRAME_PERIOD[base] * k


def stamp_text(t):
    """How a drop names a stamp: at least its first 3 decimals."""
    return re.escape("%.3f" % t)


def rewrite(src, dst, edit):
    """Copies the bag src to dst through edit(index_on_topic, topic, msg, t) -> list of (topic, msg, t) (the message
    may be changed in place; [] drops it)."""
    import rosbag
    counts = {}
    with rosbag.Bag(src) as inp, rosbag.Bag(dst, "w") as out:
        for topic, msg, t in inp.read_messages():
            k = counts.get(topic, 0)
            counts[topic] = k + 1
            for tt, mm, ts in edit(k, topic, msg, t):
                out.write(tt, mm, ts)


def on(topic, index, fn):
    """An edit that applies fn(msg) (returns nothing: in place; or False: drop the message) to message `index`
    (None: every message) of `topic`."""
    def edit(k, t, msg, ts):
        if t == topic and (index is None or k == index):
            if fn(msg) is False:
                return []
        return [(t, msg, ts)]
    return edit


def chain(*edits):
    def edit(k, t, msg, ts):
        out = [(t, msg, ts)]
        for e in edits:
            nxt = []
            for tt, mm, tss in out:
                nxt.extend(e(k, tt, mm, tss))
            out = nxt
        return out
    return edit


def set_entry(field, i, value):
    def fn(msg):
        a = list(getattr(msg, field))
        a[i] = value
        setattr(msg, field, a)
    return fn


def set_encoding(enc):
    def fn(msg):
        msg.encoding = enc
    return fn


def to_16uc1(msg):
    import numpy as np
    a = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)[:, :msg.width]
    b = (a.astype("<u2") << 8)
    msg.encoding, msg.is_bigendian, msg.step, msg.data = "16UC1", 0, msg.width * 2, b.tobytes()


def crop_width(px):
    def fn(msg):
        import numpy as np
        a = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)[:, :msg.width - px]
        msg.width, msg.step, msg.data = msg.width - px, msg.width - px, np.ascontiguousarray(a).tobytes()
    return fn


def set_stamp(sec):
    def fn(msg):
        import rospy
        ns = int(round(sec * 1e9))  # exact: from_sec would round 1000.4 to 1000.399999999
        msg.header.stamp = rospy.Time(ns // 1000000000, ns % 1000000000)
    return fn


def imu_value(axis, value):
    def fn(msg):
        setattr(msg.angular_velocity, axis, value)
    return fn


def imu_singular(msg):
    c = list(msg.angular_velocity_covariance)
    c[8] = 0.0
    msg.angular_velocity_covariance = c


def truncate(fraction):
    def make(src, dst):
        size = os.path.getsize(src)
        with open(src, "rb") as f, open(dst, "wb") as g:
            g.write(f.read(int(size * fraction)))
    return make


def empty_file(src, dst):
    open(dst, "wb").close()


def bag_without_messages(src, dst):
    import rosbag
    rosbag.Bag(dst, "w").close()


# ---------------------------------------------------------------- the cases

class Case:
    """One faulty input and what every door must do with it.

    base: the good bag (GLOBE / WORKPIECE); edit: a message edit (see rewrite) or make: fn(src, dst) writing the
    faulty file; mode: "slam" | "induration"; args: extra command-line arguments ({out} and {tmp} are replaced);
    out: the results directory relative to the case's folder (default "out").
    Expectations: rc: 0, "nonzero" or a number; frames: good frames written (None: not checked); stderr: regexes
    stderr must match (case-insensitive); stderr_not: regexes it must not match; results: regexes the results file
    (summary.yaml / induration.yaml) must match; pre_input: refused before the bag is read; no_results: the results
    file must not be written (a door that cannot exit non-zero, e.g. the launch).
    live: None: the case is not run through the launch (a command-line case, a file rosbag play cannot read, the
    induration mode); else a dict of the expectations that differ live (keys as above, plus "reason": the one-line
    reason it differs, and "launch": extra launch arguments); {}: the same as process_bag.
    """

    def __init__(self, name, why, base=GLOBE, edit=None, make=None, mode="slam", args=(), out="out", rc=0,
                 frames=None, stderr=(), stderr_not=(), results=(), pre_input=False, defect="", live=None,
                 no_results=False):
        self.name, self.why, self.base, self.edit, self.make, self.mode = name, why, base, edit, make, mode
        self.args, self.out, self.rc, self.frames = list(args), out, rc, frames
        self.stderr, self.stderr_not, self.results, self.pre_input = list(stderr), list(stderr_not), list(results), pre_input
        self.defect, self.live, self.no_results = defect, live, no_results
        self.reason, self.launch_args = "", []

    def through_launch(self):
        """The case as the launch door checks it (None: not run live)."""
        if self.live is None:
            return None
        c = Case(self.name, self.why, self.base, self.edit, self.make, self.mode, self.args, self.out, self.rc,
                 self.frames, self.stderr, self.stderr_not, self.results, self.pre_input, self.defect)
        for k, v in self.live.items():
            if k == "launch":
                c.launch_args = list(v)
            elif k in ("stderr", "stderr_not", "results"):
                setattr(c, k, list(v))
            else:
                setattr(c, k, v)
        return c


def dropped(topic, t, fault):
    """The stderr regexes of a drop: topic, stamp and fault (in any order on one line)."""
    return [r"(?m)^(?=.*%s)(?=.*%s)(?=.*%s).*$" % (re.escape(topic), stamp_text(t), fault)]


# the live expectations that differ from process_bag's, with their reason
NOTHING_TIMEOUT = 6  # s: the launch's timeout:= when no frame can be processed (replay_done's --idle needs a first frame)
NOTHING_REASON = ("roslaunch cannot exit non-zero for a nodelet's fault: the launch ends by its timeout:= and the SLAM, "
                  "having processed nothing, writes no results")
UNPAIRED_REASON = ("message_filters' ExactTime policy never pairs an image without its partner: the runner never sees "
                   "the lone image, so it is neither named nor counted")
RESTAMP_REASON = ("the case restamps the images only: their camera_info keeps the frame's stamp, so the ExactTime "
                  "sync never completes the frame and drops it before the runner sees it: neither named nor counted")
FRONT_END_REASON = ("the front end drops the frame before the SLAM sees it; the eskf_slam nodelet's summary.yaml counts "
                    "only what the SLAM dropped (process_bag adds the front end's drops)")


def cases():
    f4, f5, f6, f3 = frame_stamp(4), frame_stamp(5), frame_stamp(6), frame_stamp(3)
    imu42 = 1000.42
    G = GLOBE_FRAMES
    c = [
        Case("good_images", "the good bag: every frame", frames=G, live={}),
        Case("good_induration", "the good workpiece: every frame", base=WORKPIECE, mode="induration",
             frames=WORKPIECE_FRAMES),
        # a. imu/data
        Case("imu_nan_without_gyro", "a NaN gyro sample is never read without --gyro", defect="a",
             edit=on(IMU, 42, imu_value("x", NAN)), frames=G),
        Case("imu_nan_with_gyro", "a NaN gyro sample is dropped, the run goes on", defect="a",
             edit=on(IMU, 42, imu_value("x", NAN)), args=["--gyro"], frames=G,
             stderr=dropped(IMU, imu42, "non-finite angular velocity"), results=["non-finite angular velocity"],
             live={}),
        Case("imu_inf_with_gyro", "an Inf gyro sample is dropped", defect="a",
             edit=on(IMU, 42, imu_value("z", INF)), args=["--gyro"], frames=G,
             stderr=dropped(IMU, imu42, "non-finite angular velocity"), results=["non-finite angular velocity"],
             live={}),
        Case("imu_singular_covariance_with_gyro", "a gyro sample with a singular covariance is dropped", defect="a",
             edit=on(IMU, 42, imu_singular), args=["--gyro"], frames=G,
             stderr=dropped(IMU, imu42, "covariance not positive definite"), results=["not positive definite"],
             live={}),
        Case("imu_backwards_stamp_with_gyro", "a gyro sample stamped before the previous one is dropped",
             edit=on(IMU, 42, set_stamp(1000.305)), args=["--gyro"], frames=G,
             stderr=dropped(IMU, 1000.305, "backwards"), results=["backwards"], live={}),
        # b, f. camera_info
        Case("camera_info_nan_K", "NaN in every left K: nothing can be rectified", defect="b",
             edit=on(L_INFO, None, set_entry("K", 2, NAN)), rc="nonzero", stderr=[r"K\[2\]"],
             live=dict(rc=0, no_results=True, launch=["timeout:=%d" % NOTHING_TIMEOUT],
                       reason=NOTHING_REASON)),
        Case("camera_info_nan_D", "NaN in every right D", defect="b",
             edit=on(R_INFO, None, set_entry("D", 1, NAN)), rc="nonzero", stderr=[r"D\[1\]"],
             live=dict(rc=0, no_results=True, launch=["timeout:=%d" % NOTHING_TIMEOUT],
                       reason=NOTHING_REASON)),
        Case("camera_info_nan_R", "NaN in every left R", defect="b",
             edit=on(L_INFO, None, set_entry("R", 4, NAN)), rc="nonzero", stderr=[r"R\[4\]"],
             live=dict(rc=0, no_results=True, launch=["timeout:=%d" % NOTHING_TIMEOUT],
                       reason=NOTHING_REASON)),
        Case("camera_info_nan_P", "NaN in every right P: named, not taken for a zero nor a disparity offset",
             defect="f", edit=on(R_INFO, None, set_entry("P", 0, NAN)), rc="nonzero", stderr=[r"P\[0\] = nan"],
             stderr_not=[r"P\[0\] = 0\b", r"P\[0\] is 0", "disparity_offset"],
             live=dict(rc=0, no_results=True, launch=["timeout:=%d" % NOTHING_TIMEOUT],
                       reason=NOTHING_REASON)),
        Case("camera_info_nan_P_tx", "NaN in P[3] (the baseline term) of every right camera_info", defect="f",
             edit=on(R_INFO, None, set_entry("P", 3, NAN)), rc="nonzero", stderr=[r"P\[3\]"],
             stderr_not=["disparity_offset"],
             live=dict(rc=0, no_results=True, launch=["timeout:=%d" % NOTHING_TIMEOUT],
                       reason=NOTHING_REASON)),
        Case("camera_info_first_nan", "only the first left camera_info is bad: dropped, the next one is used",
             defect="b", edit=on(L_INFO, 0, set_entry("K", 0, NAN)), frames=G,
             stderr=dropped(L_INFO, frame_stamp(0), r"K\[0\]"), results=["non-finite camera_info"],
             live=dict(frames=G - 1, results=[], reason="a frame has only the camera_info of its own stamp "
                       "(ExactTime): frame 0 is dropped by the front end (named), which the SLAM's summary does not count")),
        Case("camera_info_nan_K_induration", "NaN in every left K, --induration", defect="b", base=WORKPIECE,
             mode="induration", edit=on(L_INFO, None, set_entry("K", 2, NAN)), rc="nonzero", stderr=[r"K\[2\]"]),
        # e. encodings
        Case("images_8UC1", "8UC1 is mono8", defect="e", edit=chain(on(L_IMG, None, set_encoding("8UC1")),
                                                                    on(R_IMG, None, set_encoding("8UC1"))),
             frames=G, stderr_not=["cv_bridge", "8UC1"], live={}),
        Case("images_16UC1", "16UC1 is mono16", edit=chain(on(L_IMG, None, to_16uc1), on(R_IMG, None, to_16uc1)),
             frames=G, stderr_not=["cv_bridge"], live={}),
        Case("images_8UC1_induration", "8UC1 is mono8, --induration", defect="e", base=WORKPIECE, mode="induration",
             edit=chain(on(L_IMG, None, set_encoding("8UC1")), on(R_IMG, None, set_encoding("8UC1"))),
             frames=WORKPIECE_FRAMES, stderr_not=["cv_bridge", "8UC1"]),
        Case("wrong_encoding_one_frame", "one left image in 32FC1: that frame dropped",
             edit=on(L_IMG, 6, set_encoding("32FC1")), frames=G - 1,
             stderr=dropped(L_IMG, f6, "unsupported encoding"), results=["unsupported encoding"],
             live=dict(results=[], reason=FRONT_END_REASON)),
        Case("wrong_encoding_all", "every image in 32FC1: nothing to do", rc="nonzero",
             edit=chain(on(L_IMG, None, set_encoding("32FC1")), on(R_IMG, None, set_encoding("32FC1"))),
             stderr=["unsupported encoding"],
             live=dict(rc=0, no_results=True, launch=["timeout:=%d" % NOTHING_TIMEOUT], reason=NOTHING_REASON)),
        Case("wrong_encoding_all_induration", "every image in 32FC1, --induration: no empty results directory",
             defect="h", base=WORKPIECE, mode="induration", rc="nonzero",
             edit=chain(on(L_IMG, None, set_encoding("32FC1")), on(R_IMG, None, set_encoding("32FC1"))),
             stderr=["unsupported encoding"]),
        Case("mismatched_size", "one right image narrower than its camera_info: that frame dropped",
             edit=on(R_IMG, 3, crop_width(16)), frames=G - 1,
             stderr=dropped(R_IMG, f3, "size differs"), results=["size differs"],
             live=dict(results=[], reason=FRONT_END_REASON)),
        # g. pairing
        Case("missing_right_image", "frame 4 has no right image: dropped and counted", defect="g",
             edit=on(R_IMG, 4, lambda m: False), frames=G - 1,
             stderr=dropped(L_IMG, f4, "no right image"), results=["no right image"],
             live=dict(stderr=[], results=[], reason=UNPAIRED_REASON)),
        Case("missing_left_image_last", "the last frame has no left image", defect="g",
             edit=on(L_IMG, 9, lambda m: False), frames=G - 1,
             stderr=dropped(R_IMG, frame_stamp(9), "no left image"), results=["no left image"],
             live=dict(stderr=[], results=[], reason=UNPAIRED_REASON)),
        Case("missing_right_image_induration", "frame 1 has no right image, --induration", defect="g",
             base=WORKPIECE, mode="induration", edit=on(R_IMG, 1, lambda m: False), frames=1,
             stderr=dropped(L_IMG, frame_stamp(1, WORKPIECE), "no right image"), results=["no right image"]),
        # stamps
        Case("backwards_stamps", "frame 5 stamped before frame 4: dropped",
             edit=chain(on(L_IMG, 5, set_stamp(1000.25)), on(R_IMG, 5, set_stamp(1000.25))), frames=G - 1,
             stderr=dropped(L_IMG, 1000.25, "backwards"), results=["backwards"], 
             live=dict(stderr=[], results=[], reason=RESTAMP_REASON)),
        Case("duplicate_stamps", "frame 5 stamped as frame 4: dropped",
             edit=chain(on(L_IMG, 5, set_stamp(f4)), on(R_IMG, 5, set_stamp(f4))), frames=G - 1,
             stderr=dropped(L_IMG, f4, "duplicate stamp"), results=["duplicate stamp"], 
             live=dict(stderr=[], results=[], reason=RESTAMP_REASON)),
        Case("zero_stamp", "frame 5 with a zero stamp: dropped",
             edit=chain(on(L_IMG, 5, set_stamp(0.0)), on(R_IMG, 5, set_stamp(0.0))), frames=G - 1,
             stderr=dropped(L_IMG, 0.0, "zero stamp"), results=["zero stamp"], 
             live=dict(stderr=[], results=[], reason=RESTAMP_REASON)),
        # h. broken files
        Case("truncated_bag", "a recording cut off: rosbag reindex suggested", defect="h", make=truncate(0.6),
             rc="nonzero", stderr=[r"rosbag reindex"]),
        Case("empty_file", "a 0-byte file", make=empty_file, rc="nonzero", stderr=["empty"]),
        Case("bag_without_messages", "a bag with no topics", make=bag_without_messages, rc="nonzero",
             stderr=["no topics"]),
        Case("truncated_bag_induration", "a recording cut off, --induration: no empty results directory",
             defect="h", base=WORKPIECE, mode="induration", make=truncate(0.6), rc="nonzero",
             stderr=[r"rosbag reindex"]),
        # c, d. command line and output
        Case("frames_negative", "--frames -5", defect="d", args=["--frames", "-5"], rc=2,
             stderr=[re.escape("--frames: '-5' is not a whole number >= 0")], pre_input=True),
        Case("frames_text", "--frames abc", defect="d", args=["--frames", "abc"], rc=2,
             stderr=[re.escape("--frames: 'abc' is not a whole number >= 0")], pre_input=True),
        Case("frames_trailing", "--frames 3x", defect="d", args=["--frames", "3x"], rc=2,
             stderr=[re.escape("--frames: '3x' is not a whole number >= 0")], pre_input=True),
        Case("frames_three", "--frames 3: three frames", args=["--frames", "3"], frames=3),
        Case("frames_trailing_induration", "--frames 3x, --induration", defect="d", base=WORKPIECE,
             mode="induration", args=["--frames", "3x"], rc=2,
             stderr=[re.escape("--frames: '3x' is not a whole number >= 0")], pre_input=True),
        Case("out_under_a_file", "--out below a regular file: refused before the bag is read", defect="c",
             out="a_file/out", rc=3, stderr=[re.escape("a_file/out")], pre_input=True),
        Case("out_missing_parents", "--out with missing parents: made", defect="c", out="new/a/b", frames=G),
        Case("out_under_a_file_induration", "--out below a regular file, --induration", defect="c", base=WORKPIECE,
             mode="induration", out="a_file/out", rc=3, stderr=[re.escape("a_file/out")], pre_input=True),
        Case("bad_config_induration", "an unknown --set key, --induration: refused, no results directory",
             defect="h", base=WORKPIECE, mode="induration", args=["--set", "no_such_key=1"], rc="nonzero",
             stderr=["no_such_key"], pre_input=True),
    ]
    return c


# ---------------------------------------------------------------- doors

class ProcessBagDoor:
    """process_bag: SLAM mode (image bag) and --induration."""
    name = "process_bag"

    def __init__(self, bindir):
        self.exe = os.path.join(bindir, "process_bag")

    def run(self, case, bag, out):
        cmd = [self.exe, "--bag", bag, "--out", out] + (["--induration"] if case.mode == "induration" else []) + case.args
        t0 = time.time()
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=600)
        return r.returncode, r.stdout, r.stderr, time.time() - t0

    def results_file(self, case, out):
        return os.path.join(out, "induration.yaml" if case.mode == "induration" else "summary.yaml")

    def frames_written(self, case, out):
        if case.mode == "induration":
            import yaml
            with open(os.path.join(out, "induration.yaml")) as f:
                return len(yaml.safe_load(f).get("frames") or [])
        with open(os.path.join(out, "trajectory.tum")) as f:
            return sum(1 for line in f if line.strip() and not line.startswith("#"))

    def read_input_line(self, stderr):
        """Whether the door started reading the bag (process_bag prints the topics it found)."""
        return re.search(r"process_bag: namespace ", stderr) is not None


class LaunchDoor:
    """The live nodelets: `roslaunch skin3d replay_globe.launch` (lossless, images, waiting for subscribers; gyro:=true
    when the case uses --gyro), each run on a free port with its own master and ROS_HOME, as check_doors.py runs it.
    The launch ends by itself: replay_done.py once every frame was processed, or --idle s after the last one (frames
    were dropped), or by the case's timeout:=. roslaunch's whole output (the nodelets' log included) is the "stderr"
    checked; the eskf_slam nodelet writes summary.yaml and trajectory.tum on shutdown."""
    name = "launch"
    IDLE = 3        # s without a processed frame after the first: the launch ends (a frame takes well under 1 s)
    TIMEOUT = 120   # s: a hang is a failure, not a stuck CI job
    MANAGER = "skin3d_manager"

    def __init__(self, bindir):
        self.bindir = bindir

    def expect(self, case):
        return case.through_launch()

    def run(self, case, bag, out):
        import socket
        s = socket.socket()
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
        s.close()
        home = tempfile.mkdtemp(prefix="ros_home_")
        env = dict(os.environ, ROS_MASTER_URI="http://localhost:%d" % port, ROS_HOME=home)
        cmd = ["roslaunch", "-p", str(port), "skin3d", "replay_globe.launch", "bag:=" + os.path.abspath(bag),
               "results:=" + os.path.abspath(out),
               "images:=true", "wait_for_subscribers:=true", "idle:=%g" % self.IDLE, "delay:=0.5"]
        cmd += (["gyro:=true"] if "--gyro" in case.args else []) + case.launch_args
        t0 = time.time()
        try:
            r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True,
                               env=env, timeout=self.TIMEOUT)
            rc, text = r.returncode, r.stdout
        except subprocess.TimeoutExpired as e:
            rc, text = 124, (e.stdout.decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or ""))
            text += "\nroslaunch did not end within %d s" % self.TIMEOUT
        finally:
            shutil.rmtree(home, ignore_errors=True)
        # the case's folder (named after the case, e.g. images_8UC1) is no fault the log may not name
        text = text.replace(os.path.dirname(os.path.abspath(out)), "CASE_FOLDER")
        return rc, "", text, time.time() - t0

    def problems(self, case, rc, output):
        """What only the launch can show: the launch did not end by itself, or the nodelet manager died."""
        p = []
        if rc == 124:
            p.append("the launch did not end within %d s" % self.TIMEOUT)
        if re.search(r"\[%s-\d+\] process has died" % re.escape(self.MANAGER), output):
            p.append("the nodelet manager died")
        if not re.search(r"replay_done: (all \d+ frames|\d+ of \d+ frames)", output):
            p.append("replay_done did not end the launch")
        return p

    def results_file(self, case, out):
        return os.path.join(out, "summary.yaml")

    def frames_written(self, case, out):
        return ProcessBagDoor.frames_written(self, case, out)

    def read_input_line(self, stderr):
        return True


DOORS = {"process_bag": ProcessBagDoor, "launch": LaunchDoor}


# ---------------------------------------------------------------- running

def good_bags(data, bindir, tmp):
    """The two good bags: from --data when there, else made here with make_dataset."""
    paths = {}
    for name, args in ((GLOBE, ["globe-images", "--frames", "10"]), (WORKPIECE, ["workpiece"])):
        p = os.path.join(data, name) if data else ""
        if not (p and os.path.exists(p)):
            p = os.path.join(tmp, name)
            extra = []
            if name == WORKPIECE:
                cfg = os.path.join(tmp, "workpiece_quarter.yaml")
                with open(cfg, "w") as f:
                    f.write("workpiece: {resolution_scale: 0.25, frames: 2}\n")
                extra = ["--config", cfg]
            subprocess.run([os.path.join(bindir, "make_dataset")] + args + extra + ["--quiet", "--out", p], check=True)
        paths[name] = p
    return paths


def check_case(door, case, bags, folder):
    """Runs one case through one door; returns '' or the failures."""
    if hasattr(door, "expect"):
        case = door.expect(case)
    os.makedirs(folder, exist_ok=True)
    bag = os.path.join(folder, "input.bag")
    if case.make:
        case.make(bags[case.base], bag)
    elif case.edit:
        rewrite(bags[case.base], bag, case.edit)
    else:
        bag = bags[case.base]
    if case.out.startswith("a_file/"):
        with open(os.path.join(folder, "a_file"), "w") as f:
            f.write("a regular file, not a directory\n")
    out = os.path.join(folder, case.out)
    rc, stdout, stderr, seconds = door.run(case, bag, out)
    problems = door.problems(case, rc, stderr) if hasattr(door, "problems") else []
    if rc < 0:
        problems.append("killed by signal %d" % -rc)
    if "terminate called" in stderr:
        problems.append("uncaught exception")
    if case.rc == "nonzero":
        if rc == 0:
            problems.append("exit 0, expected a failure")
    elif rc != case.rc:
        problems.append("exit %d, expected %d" % (rc, case.rc))
    for pat in case.stderr:
        if not re.search(pat, stderr, re.IGNORECASE):
            problems.append("stderr does not match /%s/" % pat)
    for pat in case.stderr_not:
        if re.search(pat, stderr, re.IGNORECASE):
            problems.append("stderr matches /%s/" % pat)
    if case.no_results and os.path.exists(door.results_file(case, out)):
        problems.append("%s written although nothing could be processed" % os.path.basename(door.results_file(case, out)))
    if case.rc != 0:
        if os.path.isdir(out) and not os.listdir(out):
            problems.append("empty results directory left: %s" % case.out)
        if case.pre_input and os.path.exists(out):
            problems.append("results directory made although the run was refused at start")
        if case.pre_input and door.read_input_line(stderr):
            problems.append("refused only after the bag was opened")
    else:
        if case.frames is not None:
            try:
                n = door.frames_written(case, out)
                if n != case.frames:
                    problems.append("%d frames written, expected %d" % (n, case.frames))
            except (OSError, ValueError, AttributeError, TypeError) as e:
                problems.append("no results: %s" % e)
        if case.results:
            try:
                with open(door.results_file(case, out)) as f:
                    text = f.read()
                for pat in case.results:
                    if not re.search(pat, text, re.IGNORECASE):
                        problems.append("%s does not count /%s/" % (os.path.basename(door.results_file(case, out)), pat))
            except OSError as e:
                problems.append("no results file: %s" % e)
    with open(os.path.join(folder, "stderr.txt"), "w") as f:
        f.write(stderr)
    if problems:
        tail = " | ".join(line for line in stderr.strip().splitlines()[-3:])
        return "; ".join(problems) + " (exit %d, %.1f s; stderr ends: %s)" % (rc, seconds, tail[-400:])
    return ""


def main():
    ap = argparse.ArgumentParser(usage=__doc__.replace("%", "%%"))
    ap.add_argument("--bin", default=os.path.join(SOURCE, "build", "devel", "lib", "skin3d"))
    ap.add_argument("--data", default="")
    ap.add_argument("--door", action="append", choices=sorted(DOORS))
    ap.add_argument("--only", nargs="*", default=[])
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--keep", default="")
    ap.add_argument("--xunit")
    ap.add_argument("--jobs", type=int, default=1,
                    help="cases of the launch door run at once (each has its own master; process_bag's run one by one)")
    a = ap.parse_args()
    if a.jobs < 1:
        ap.error("--jobs must be >= 1")
    table = cases()
    if a.only:
        unknown = [n for n in a.only if n not in {c.name for c in table}]
        if unknown:
            ap.error("no such case: %s" % ", ".join(unknown))
        table = [c for c in table if c.name in a.only]
    if a.list:
        for c in table:
            live = "-" if c.live is None else ("live: " + c.live["reason"] if c.live.get("reason") else "live")
            print("%-34s %-10s %-7s %s [%s]" % (c.name, c.mode, c.defect or "-", c.why, live))
        return 0
    doors = [DOORS[d](a.bin) for d in (a.door or ["process_bag"])]
    results = []
    tmp = a.keep or tempfile.mkdtemp(prefix="skin3d_bad_input_")
    try:
        os.makedirs(tmp, exist_ok=True)
        bags = good_bags(a.data, a.bin, tmp)
        for door in doors:
            todo = [c for c in table if not (hasattr(door, "expect") and door.expect(c) is None)]

            def one(c, door=door):
                t0 = time.time()
                folder = os.path.join(tmp, door.name, c.name)
                shutil.rmtree(folder, ignore_errors=True)
                try:
                    msg = check_case(door, c, bags, folder)
                except Exception as e:  # a broken case must not hide the others
                    msg = "the check itself failed: %r" % e
                print("bad_input: %s.%s: %s (%.1f s)" % (door.name, c.name, "FAIL: " + msg if msg else "ok",
                                                        time.time() - t0), flush=True)
                return ("%s.%s" % (door.name, c.name), msg)

            # the launch door's cases mostly wait (roslaunch, the master, the player): a few at once
            jobs = a.jobs if door.name == "launch" else 1
            with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
                results.extend(pool.map(one, todo))
    finally:
        if not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    failed = sum(1 for _, m in results if m)
    print("bad_input: %d of %d cases pass" % (len(results) - failed, len(results)))
    if a.xunit:
        write_xunit(a.xunit, "bad_input", results)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
