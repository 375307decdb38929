# SPDX-License-Identifier: BSD-3-Clause
"""The gyroscope's bias from a recording of the rig standing still, as SLAM parameters.

Usage: gyro_bias.py BAG [--ns NS] [--out FILE.yaml] [--min-duration 3] [--window 1] [--max-shift 1]

While the rig does not move, every imu/data sample (sensor_msgs/Imu angular_velocity, rad/s, the rig frame) is the
bias plus white noise, so the bias is their mean, known to sigma / sqrt(n) per axis (sigma: the samples' own spread).
Why it matters: during a scan the images cannot tell a slow turn from a gyro bias in the first seconds (a narrow
view of a curved surface turns into a sideways shift almost as well), so a bias estimated by the SLAM from the scan
itself is off by ~0.3 mrad/s for tens of seconds, millimetres over an orbit (README, "Through the images"). Five
still seconds at 100 Hz give it to ~0.1 mrad/s.

Stillness checks (exit code 1, naming what moved: record again without touching the rig):
- the recording is cut into --window second pieces; a still rig's piece means scatter as its white noise says. If
  they scatter more (chi-square test at 99.9 %), the rig shook or the bias drifted;
- a steady turn passes that test (its mean is constant, like a bias), so when the bag holds stereo/left/image_raw
  (same namespace) no left image (the first against ten spread over the recording) may be shifted by more than
  --max-shift pixels (phase correlation; 1 px at f = 800 px over 5 s is 0.25 mrad/s). Without images (or with an
  encoding other than mono8/mono16/bgr8/rgb8/bgra8/rgba8) only the first check is made, and it says so.

Writes (stdout, or --out) the keys process_bag --config and the eskf_slam nodelet read:
  initial_gyro_bias_x/_y/_z (the mean) and initial_gyro_bias_std (the largest axis' standard error).
Use them with --gyro; README "Through the images" says with which estimate_gyro_bias setting.
Exit codes: 0 written, 1 the rig was not still, 2 bad input (no such bag, no imu/data topic, too short).

The topic is imu/data under the root or under one namespace (as process_bag finds it); --ns chooses one.
"""
import argparse
import math
import sys

import numpy as np

from skin3d.stats import chi2_quantile  # Wilson-Hilferty; no scipy on the rig


def fail(msg, code=2):
    print("gyro_bias.py: " + msg, file=sys.stderr)
    sys.exit(code)


def imu_topic(bag, ns):
    topics = bag.get_type_and_topic_info().topics
    found = [t for t, info in topics.items() if info.msg_type == "sensor_msgs/Imu"
             and (t.lstrip("/") == "imu/data" or t.endswith("/imu/data"))]
    if ns is not None:
        want = (ns.strip("/") + "/imu/data").lstrip("/")
        found = [t for t in found if t.lstrip("/") == want]
        if not found:
            fail("no sensor_msgs/Imu topic %s in the bag (Imu topics: %s)" % (
                want, ", ".join(t for t, i in topics.items() if i.msg_type == "sensor_msgs/Imu") or "none"))
    if not found:
        fail("no sensor_msgs/Imu topic imu/data in the bag (topics: %s)" % (", ".join(sorted(topics)) or "none"))
    root = [t for t in found if t.lstrip("/") == "imu/data"]
    if len(found) > 1 and not root:
        fail("imu/data under several namespaces (%s): choose one with --ns" % ", ".join(sorted(found)))
    return root[0] if root else found[0]


def image_array(m):
    """sensor_msgs/Image -> 2-D float array (mono8/mono16/bgr8/rgb8/bgra8/rgba8), None for other encodings."""
    dtype = {"mono8": np.uint8, "8UC1": np.uint8, "mono16": np.uint16, "16UC1": np.uint16, "bgr8": np.uint8,
             "rgb8": np.uint8, "bgra8": np.uint8, "rgba8": np.uint8}.get(m.encoding)
    if dtype is None:
        return None
    a = np.frombuffer(m.data, dtype=dtype)
    if dtype == np.uint16 and m.is_bigendian:
        a = a.byteswap()
    ch = max(1, a.size // (m.height * m.width))
    a = a[:m.height * m.step // np.dtype(dtype).itemsize].reshape(m.height, -1)[:, :m.width * ch]
    return a.reshape(m.height, m.width, ch).astype(float).mean(axis=2)


def image_shift(a, b):
    """Translation (px) between two images by phase correlation, with a parabolic sub-pixel peak."""
    win = np.outer(np.hanning(a.shape[0]), np.hanning(a.shape[1]))
    A, B = np.fft.fft2((a - a.mean()) * win), np.fft.fft2((b - b.mean()) * win)
    R = A * np.conj(B)
    r = np.real(np.fft.ifft2(R / np.maximum(np.abs(R), 1e-12)))
    i, j = np.unravel_index(np.argmax(r), r.shape)
    shift = []
    for k, n, axis in ((i, r.shape[0], 0), (j, r.shape[1], 1)):
        m1 = r[(k - 1) % n, j] if axis == 0 else r[i, (k - 1) % n]
        p1 = r[(k + 1) % n, j] if axis == 0 else r[i, (k + 1) % n]
        den = m1 - 2 * r[i, j] + p1
        frac = 0.5 * (m1 - p1) / den if den < 0 else 0.0
        shift.append(((k + n // 2) % n - n // 2) + frac)
    return math.hypot(shift[0], shift[1])


def read_samples(path, ns):
    try:
        import rosbag
    except ImportError:
        fail("the ROS Python modules are missing: run it with /usr/bin/python3 (README, Set-up)")
    try:
        bag = rosbag.Bag(path)
    except Exception as e:  # rosbag raises several kinds (missing file, not a bag)
        fail("cannot read bag '%s': %s" % (path, e))
    topic = imu_topic(bag, ns)
    t, w = [], []
    for _, m, _ in bag.read_messages(topics=[topic]):
        v = (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z)
        if all(math.isfinite(x) for x in v):
            t.append(m.header.stamp.to_sec())
            w.append(v)
    image_topic = topic[:-len("imu/data")] + "stereo/left/image_raw"
    shift = None
    if image_topic in bag.get_type_and_topic_info().topics:
        n = bag.get_message_count(image_topic)
        picks = set(int(round(k * (n - 1) / 10.0)) for k in range(11))  # the first and ten more, evenly spread
        first = None
        for k, (_, m, _) in enumerate(bag.read_messages(topics=[image_topic])):
            if k not in picks:
                continue
            img = image_array(m)
            if img is None:
                break
            if first is None:
                first, t0 = img, m.header.stamp.to_sec()
            elif img.shape == first.shape:
                s = (image_topic, image_shift(first, img), m.header.stamp.to_sec() - t0)
                shift = s if shift is None or s[1] > shift[1] else shift
    bag.close()
    return topic, np.array(t), np.array(w), shift


def measure(t, w, window, min_duration):
    """Returns (bias, standard error per axis, sample noise per axis, stillness chi-square, its 99.9 % bound,
    largest deviation of a piece's mean from the whole, duration in s, number of pieces)."""
    if len(t) < 20:
        fail("only %d gyro samples: record at least %g s of the rig standing still" % (len(t), min_duration))
    duration = t[-1] - t[0]
    if duration < min_duration:
        fail("the recording holds %.2f s of gyro samples: at least %g s are needed (--min-duration)" % (
            duration, min_duration))
    bias = w.mean(axis=0)
    sigma = w.std(axis=0, ddof=1)
    sigma = np.maximum(sigma, 1e-12)
    se = sigma / math.sqrt(len(w))
    pieces = max(2, int(duration / window))
    idx = np.minimum(((t - t[0]) / duration * pieces).astype(int), pieces - 1)
    stat, dof, worst = 0.0, 0, 0.0
    for k in range(pieces):
        sel = w[idx == k]
        if len(sel) < 2:
            continue
        d = sel.mean(axis=0) - bias
        stat += float(np.sum(d * d / (sigma * sigma / len(sel))))
        dof += 3
        worst = max(worst, float(np.max(np.abs(d))))
    dof -= 3  # the overall mean was estimated from the same samples
    return bias, se, sigma, stat, chi2_quantile(0.999, max(dof, 1)), worst, duration, pieces


def main(argv=None):
    """The command (scripts/gyro_bias.py): argv without the program name; returns the exit code."""
    ap = argparse.ArgumentParser(usage=__doc__.replace("%", "%%"))
    ap.add_argument("bag")
    ap.add_argument("--ns", default=None, help="namespace of imu/data (default: the root, or the only one)")
    ap.add_argument("--out", default=None, help="write the YAML here instead of stdout")
    ap.add_argument("--min-duration", type=float, default=3.0, help="s of still samples at least (default 3)")
    ap.add_argument("--window", type=float, default=1.0, help="s per piece of the stillness check (default 1)")
    ap.add_argument("--max-shift", type=float, default=1.0,
                    help="px: left images may be shifted from the first by at most this much (default 1)")
    a = ap.parse_args(argv)
    if not (a.min_duration > 0 and a.window > 0 and a.max_shift > 0):
        fail("--min-duration, --window and --max-shift must be > 0")
    topic, t, w, shift = read_samples(a.bag, a.ns)
    bias, se, sigma, stat, bound, worst, duration, pieces = measure(t, w, a.window, a.min_duration)
    print("gyro_bias.py: %s: %d samples over %.2f s; bias %s mrad/s, standard error %s mrad/s; sample noise %s "
          "mrad/s" % (topic, len(w), duration, np.array2string(1e3 * bias, precision=3),
                      np.array2string(1e3 * se, precision=3), np.array2string(1e3 * sigma, precision=2)),
          file=sys.stderr)
    if stat > bound:
        fail("the rig was not still: the means of the %d pieces of %.2f s differ from the whole by up to %.3f mrad/s, "
             "chi-square %.1f > %.1f (99.9 %% for white noise). Record again without touching the rig." % (
                 pieces, duration / pieces, 1e3 * worst, stat, bound), code=1)
    if shift is None:
        print("gyro_bias.py: no usable stereo/left/image_raw beside %s (none, one image, or an unknown encoding): "
              "stillness checked by the gyro alone (a steady turn would pass it)" % topic, file=sys.stderr)
    else:
        print("gyro_bias.py: %s: images shifted by up to %.2f px from the first (%.2f s later; at most %g)" % (
            shift[0], shift[1], shift[2], a.max_shift), file=sys.stderr)
        if shift[1] > a.max_shift:
            fail("the rig was not still: a left image is shifted by %.1f px from the first (at most %g px, "
                 "--max-shift). Record again without touching the rig." % (shift[1], a.max_shift), code=1)
    text = ("# gyroscope bias measured by gyro_bias.py on %s (%s: %d samples over %.2f s, the rig still;\n"
            "# stillness chi-square %.1f <= %.1f). Use with process_bag --gyro --config THIS_FILE.\n"
            "initial_gyro_bias_x: %.9g\ninitial_gyro_bias_y: %.9g\ninitial_gyro_bias_z: %.9g\n"
            "initial_gyro_bias_std: %.9g\n") % (a.bag, topic, len(w), duration, stat, bound, bias[0], bias[1], bias[2],
                                                 float(se.max()))
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)
    return 0

