#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Checks scripts/gyro_bias.py on synthetic bags whose gyro bias is known here.

usage: check_gyro_bias.py [--xunit FILE.xml]

Bags of sensor_msgs/Imu at 100 Hz (seeded white noise of 2 mrad/s around a known bias) and, in some, a textured
left image at 10 Hz:
- still, 5 s, with images: exit 0; each axis of the bias within 4 standard errors of the truth (and the written
  standard error within 15 % of 2 mrad/s / sqrt(500)); the YAML keys are the ones process_bag reads;
- the same under the namespace rig1 (found without --ns, and with --ns rig1);
- a steady turn of 20 mrad/s with images that move with it (1 px per frame): exit 1, the images named;
- a shaking rig (the rate swings by 10 mrad/s at 0.5 Hz): exit 1, by the gyro's own check;
- 1 s of samples: exit 2; a bag without imu/data: exit 2.
"""
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import run_checks  # noqa: E402

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "gyro_bias.py")
NOISE = 0.002
BIAS = np.array([0.0012, -0.0004, 0.08])  # one axis as large as real recordings show


def write_bag(path, seconds, rate=lambda t: np.zeros(3), image_shift_px=0.0, images=True, ns="", imu=True, seed=1):
    import rosbag
    import rospy
    from sensor_msgs.msg import Image, Imu
    rng = np.random.default_rng(seed)
    texture = (rng.random((60, 100)) * 255).astype(np.uint8)
    t0 = 1000.0
    with rosbag.Bag(path, "w") as bag:
        n = int(round(seconds * 100))
        for k in range(n):
            t = k / 100.0
            if imu:
                m = Imu()
                m.header.stamp = rospy.Time.from_sec(t0 + t)
                w = BIAS + rate(t) + rng.normal(0.0, NOISE, 3)
                m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = w
                m.orientation_covariance[0] = -1
                bag.write(ns + "imu/data", m, m.header.stamp)
            if images and k % 10 == 0:
                img = Image()
                img.header.stamp = rospy.Time.from_sec(t0 + t)
                img.height, img.width, img.encoding, img.step = 60, 100, "mono8", 100
                img.data = np.roll(texture, int(round(image_shift_px * k / 10)), axis=1).tobytes()
                bag.write(ns + "stereo/left/image_raw", img, img.header.stamp)


def run(args):
    r = subprocess.run([sys.executable, SCRIPT] + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                       universal_newlines=True)
    return r.returncode, r.stdout, r.stderr


def parse(yaml_text):
    d = {}
    for line in yaml_text.splitlines():
        if line and not line.startswith("#"):
            k, v = line.split(":")
            d[k.strip()] = float(v)
    return d


def checks(tmp):
    results = []
    still = os.path.join(tmp, "still.bag")
    write_bag(still, 5.0)
    rc, out, err = run([still])
    msg = ""
    if rc != 0:
        msg = "exit %d: %s" % (rc, err)
    else:
        d = parse(out)
        b = np.array([d["initial_gyro_bias_x"], d["initial_gyro_bias_y"], d["initial_gyro_bias_z"]])
        se_true = NOISE / np.sqrt(500)
        if np.any(np.abs(b - BIAS) > 4 * se_true):
            msg = "bias %s, truth %s (4 standard errors: %.2g)" % (b, BIAS, 4 * se_true)
        elif abs(d["initial_gyro_bias_std"] / se_true - 1) > 0.15:
            msg = "standard error %.3g, expected %.3g" % (d["initial_gyro_bias_std"], se_true)
        print("check_gyro_bias: still: bias error %s mrad/s, standard error %.3f mrad/s" % (
            np.array2string(1e3 * (b - BIAS), precision=3), 1e3 * d["initial_gyro_bias_std"]))
    results.append(("still", msg))

    ns_bag = os.path.join(tmp, "ns.bag")
    write_bag(ns_bag, 5.0, ns="/rig1/", seed=2)
    for name, extra in (("namespace_found", []), ("namespace_chosen", ["--ns", "rig1"])):
        rc, out, err = run([ns_bag] + extra)
        ok = rc == 0 and "initial_gyro_bias_z" in out and "rig1/imu/data" in out
        results.append((name, "" if ok else "exit %d: %s%s" % (rc, out, err)))

    turn = os.path.join(tmp, "turn.bag")
    write_bag(turn, 5.0, rate=lambda t: np.array([0.0, 0.02, 0.0]), image_shift_px=1.0, seed=3)
    rc, out, err = run([turn])
    ok = rc == 1 and "shifted" in err
    results.append(("steady_turn_seen_in_the_images", "" if ok else "exit %d: %s" % (rc, err)))

    shake = os.path.join(tmp, "shake.bag")
    write_bag(shake, 5.0, rate=lambda t: np.array([0.01 * np.sin(np.pi * t), 0.0, 0.0]), seed=4)
    rc, out, err = run([shake])
    ok = rc == 1 and "chi-square" in err
    results.append(("shaking_seen_by_the_gyro", "" if ok else "exit %d: %s" % (rc, err)))

    short = os.path.join(tmp, "short.bag")
    write_bag(short, 1.0, seed=5)
    rc, out, err = run([short])
    ok = rc == 2 and "at least" in err
    results.append(("too_short", "" if ok else "exit %d: %s" % (rc, err)))

    no_imu = os.path.join(tmp, "no_imu.bag")
    write_bag(no_imu, 2.0, imu=False, seed=6)
    rc, out, err = run([no_imu])
    ok = rc == 2 and "imu/data" in err
    results.append(("no_imu_topic", "" if ok else "exit %d: %s" % (rc, err)))
    return results


if __name__ == "__main__":
    sys.exit(run_checks("gyro_bias", __doc__, checks))
