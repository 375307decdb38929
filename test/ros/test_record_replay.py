#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""A session recorded by someone else, processed offline (record_replay.test).

While launch/replay_globe.launch plays a dataset through the running nodelets (at the root, or under a
namespace with ns:=rig1), this node records everything with `rosbag record -a`, as a user does, so that the
recording stores absolute names (/stereo/landmarks, or /rig1/stereo/landmarks) next to the nodelets' own
outputs. It then checks, against the dataset's ground truth that the recording carries:
- process_bag finds the topics (leading slash; the namespace found by itself and given with --ns) and
  processes the frames it recorded; a wrong --ns fails with a message that lists the bag's topics;
- trajectory.tum has one distinct, full-precision stamp per frame (the dataset's stamps, in nanoseconds);
- the ATE of an independent TUM script (scripts/tum_ate.py: associate.py-style time association, SE(3) fit)
  equals summary.yaml's ate_se3 within 0.1 mm, and the ATE is within the bound of the thesis' experiments;
- with the ground truth moved into a motion-capture world, the ATE is SE(3)-aligned (and says so) and equals
  the one in the dataset's world; unaligned (--ate-align none) it is metres.
Parameters (private): ~ns (the chain's namespace, "" = root), ~out (folder for the recording and results),
~process_bag (the binary), ~tum_ate (the script), ~source_dir, ~configs (config/ files for process_bag),
~expected_frames (frames of the dataset), ~frames_topic (what a frame is in the recording), ~input (process_bag --input), ~ate_bound_mm, ~start_ns (the dataset's
first stamp, ns).
"""
import os
import shutil
import signal
import subprocess
import sys
import time
import unittest

import rospy
import rostest
import yaml

PKG = "skin3d"


def run(cmd, timeout=300):
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    return r.returncode, r.stdout + r.stderr


class RecordReplay(unittest.TestCase):
    recording = None
    log = ""

    @classmethod
    def setUpClass(cls):
        rospy.init_node("record_replay_test", anonymous=True)
        cls.ns = rospy.get_param("~ns", "").strip("/")
        cls.out = rospy.get_param("~out")
        cls.expected = int(rospy.get_param("~expected_frames"))
        cls.input = rospy.get_param("~input", "auto")
        shutil.rmtree(cls.out, ignore_errors=True)
        os.makedirs(cls.out)
        cls.recording = os.path.join(cls.out, "session.bag")
        # `rosbag record -a` records every topic of the graph under its absolute name, as a user's recording.
        rec = subprocess.Popen(["rosbag", "record", "-a", "-O", cls.recording, "__name:=recorder_under_test"],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        seen = {"n": 0, "last": None}

        def on_landmarks(_):
            seen["n"] += 1
            seen["last"] = time.time()

        topic = ("/" + cls.ns if cls.ns else "") + "/stereo/landmarks"
        # AnyMsg: the count needs no message class (run_tests' cached environment may not have the devel space's
        # Python path on a first build)
        rospy.Subscriber(topic, rospy.AnyMsg, on_landmarks, queue_size=100)
        t0 = time.time()
        # until the player is done: every frame seen, or 4 s without a new one after the first
        while time.time() - t0 < 90 and not rospy.is_shutdown():
            if seen["n"] >= cls.expected or (seen["last"] and time.time() - seen["last"] > 4.0):
                break
            time.sleep(0.1)
        time.sleep(1.5)  # the last messages reach the recorder
        rec.send_signal(signal.SIGINT)
        try:
            cls.log, _ = rec.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            rec.kill()
            cls.log, _ = rec.communicate()
        cls.frames_published = seen["n"]

    def process(self, name, extra):
        out = os.path.join(self.out, name)
        configs = []
        for c in rospy.get_param("~configs", "slam_globe.yaml").split():
            configs += ["--config", os.path.join(rospy.get_param("~source_dir"), "config", c)]
        rc, text = run([rospy.get_param("~process_bag"), "--bag", self.recording, "--out", out, "--quiet",
                        "--input", self.input] + configs + extra)
        return rc, text, out

    def test_1_recorded(self):
        self.assertTrue(os.path.exists(self.recording), "rosbag record -a wrote nothing: %s" % self.log[-2000:])
        self.assertGreater(self.frames_published, 0, "the chain published no stereo/landmarks")
        rc, text = run(["rosbag", "info", "--yaml", self.recording])
        self.assertEqual(rc, 0, text)
        info = yaml.safe_load(text)
        counts = {t["topic"]: t["messages"] for t in info.get("topics", [])}
        prefix = "/" + self.ns if self.ns else ""
        frames_topic = prefix + "/" + rospy.get_param("~frames_topic", "stereo/landmarks")
        # rosbag record's own words with it: a recording that holds nothing is a recorder's failure (a full disk, a
        # master it never reached), not the chain's
        self.assertGreaterEqual(counts.get(frames_topic, 0), int(0.9 * self.expected),
                                "recorded: %s; the chain published %d frames; rosbag record said: %s" % (
                                    counts, self.frames_published, self.log[-1500:]))
        self.assertIn(prefix + "/ground_truth/pose", counts)
        self.assertIn(prefix + "/slam/odometry", counts)  # the running nodelets' own output, recorded too
        self.assertIn("/rosout", counts)  # -a: everything

    def check_results(self, out, text):
        with open(os.path.join(out, "summary.yaml")) as f:
            s = yaml.safe_load(f)
        frames = int(s["frames"])
        self.assertGreaterEqual(frames, int(0.9 * self.expected), text)
        # a recording with images and the front end's landmarks is processed from the images (--input auto)
        images = "image_raw" in rospy.get_param("~frames_topic", "stereo/landmarks")
        self.assertEqual(s["front_end"] != "none (landmark bag)", images, "front_end: %s" % s["front_end"])
        with open(os.path.join(out, "trajectory.tum")) as f:
            stamps = [line.split()[0] for line in f if line.strip() and not line.startswith("#")]
        self.assertEqual(len(stamps), frames)
        self.assertEqual(len(set(stamps)), frames, "trajectory.tum stamps are not unique per frame")
        # every stamp with nine decimals, and on the dataset's 10 Hz grid from its first stamp (exact ns)
        start = int(rospy.get_param("~start_ns"))
        for st in stamps:
            whole, _, frac = st.partition(".")
            self.assertEqual(len(frac), 9, st)
            ns = int(whole) * 10**9 + int(frac)
            self.assertEqual((ns - start) % 100000000, 0, "stamp %s is not on the dataset's 0.1 s grid" % st)
        # the independent script against the summary
        rc, ext = run([sys.executable, rospy.get_param("~tum_ate"), os.path.join(out, "trajectory.tum"),
                       os.path.join(out, "ground_truth.tum"), "--yaml"])
        self.assertEqual(rc, 0, ext)
        e = yaml.safe_load(ext)
        self.assertEqual(e["pairs"], s["ate_se3"]["pairs"])
        self.assertEqual(e["pairs"], frames)
        self.assertLess(abs(e["rmse_mm"] - s["ate_se3"]["rmse_mm"]), 0.1, "tum_ate.py %s vs summary %s" % (e, s["ate_se3"]))
        self.assertLess(s["ate"]["rmse_mm"], float(rospy.get_param("~ate_bound_mm")))
        return s

    def test_2_found_namespace(self):
        rc, text, out = self.process("found", [])
        self.assertEqual(rc, 0, text)
        s = self.check_results(out, text)
        self.assertIn("namespace /%s" % self.ns, s["topics"])

    def test_3_given_namespace(self):
        rc, text, out = self.process("given", ["--ns", "/" + self.ns if self.ns else "/"])
        self.assertEqual(rc, 0, text)
        self.check_results(out, text)

    def test_4_wrong_namespace_lists_topics(self):
        rc, text, _ = self.process("wrong", ["--ns", "no_such_rig"])
        self.assertEqual(rc, 1, text)
        self.assertIn("no_such_rig", text)
        self.assertIn("stereo/landmarks", text)  # the listing of the bag's topics
        self.assertIn("skin3d/LandmarkArray", text)

    def test_5_ground_truth_in_another_world(self):
        """The recording's ground truth moved into a motion-capture world (EuRoC-style): the summary states an SE(3)
        alignment and gives the same ATE as in the dataset's own world; unaligned it would be metres."""
        import numpy as np
        import rosbag
        moved = os.path.join(self.out, "mocap_world.bag")
        a = 2.1
        axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
        qw, qv = np.cos(a / 2), np.sin(a / 2) * axis  # the world rotation as a quaternion
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
        t = np.array([2.4, -1.3, 0.9])
        with rosbag.Bag(self.recording) as src, rosbag.Bag(moved, "w") as dst:
            for topic, msg, stamp in src.read_messages():
                if topic.endswith("/ground_truth/pose"):
                    p = msg.pose.position
                    p.x, p.y, p.z = R @ np.array([p.x, p.y, p.z]) + t
                    o = msg.pose.orientation
                    w, v = o.w, np.array([o.x, o.y, o.z])
                    nw, nv = qw * w - qv @ v, qw * v + w * qv + np.cross(qv, v)
                    o.w, o.x, o.y, o.z = nw, nv[0], nv[1], nv[2]
                dst.write(topic, msg, stamp)
        base_rc, base_text, base = self.process("found_again", [])
        self.assertEqual(base_rc, 0, base_text)
        self.recording, original = moved, self.recording
        try:
            rc, text, out = self.process("mocap", [])
            rc_none, text_none, out_none = self.process("mocap_unaligned", ["--ate-align", "none"])
        finally:
            self.recording = original
        self.assertEqual(rc, 0, text)
        self.assertEqual(rc_none, 0, text_none)
        with open(os.path.join(base, "summary.yaml")) as f:
            s0 = yaml.safe_load(f)
        with open(os.path.join(out, "summary.yaml")) as f:
            s1 = yaml.safe_load(f)
        with open(os.path.join(out_none, "summary.yaml")) as f:
            s2 = yaml.safe_load(f)
        self.assertEqual(s1["ate"]["alignment"], "se3", s1["ate"])
        self.assertAlmostEqual(s1["ate"]["rmse_mm"], s0["ate_se3"]["rmse_mm"], delta=1e-3)
        self.assertEqual(s2["ate"]["alignment"], "none")
        self.assertGreater(s2["ate"]["rmse_mm"], 1000.0)


if __name__ == "__main__":
    rostest.rosrun(PKG, "record_replay", RecordReplay, sys.argv)
