#!/usr/bin/python3
"""Save the first stereo pair of a skin3d dataset bag as one side-by-side PNG.

Usage: bag_preview.py FILE.bag OUT.png [--frame N] [--ns NAMESPACE]
Reads stereo/left/image_raw and stereo/right/image_raw (mono8; relative, absolute or namespaced names), frame N (default 0),
and writes them next to each other with a caption (frame, stamp, size). Exit 1 with a
message when the bag has no images (e.g. a landmark-level bag).
"""
import argparse
import sys

import numpy as np
import rosbag
import cv2


def stereo_topics(bag, ns):
    """The stored names of the left and right image topics: relative, absolute or under a namespace (--ns, or the
    only one that has them), as skin3d's C++ tools resolve them."""
    stored = list(bag.get_type_and_topic_info().topics)
    wanted = ("stereo/left/image_raw", "stereo/right/image_raw")
    if ns is not None:
        ns = ns.strip("/")
        names = [(ns + "/" if ns else "") + w for w in wanted]
        found = [[t for t in stored if t.lstrip("/") == n] for n in names]
    else:
        found = [[t for t in stored if t.lstrip("/") == w] for w in wanted]
        if not any(found):
            spaces = sorted({t.lstrip("/")[:-len(w) - 1] for t in stored for w in wanted if t.lstrip("/").endswith("/" + w)})
            if len(spaces) > 1:
                raise RuntimeError("images under several namespaces (%s): choose one with --ns" %
                                   ", ".join("/" + n for n in spaces))
            if spaces:
                found = [[t for t in stored if t.lstrip("/") == spaces[0] + "/" + w] for w in wanted]
    if not all(found):
        raise RuntimeError("no stereo/{left,right}/image_raw (is it an image bag?); its topics: " + ", ".join(sorted(stored)))
    return found[0][0], found[1][0]


def first_images(path, frame, ns=None):
    left, right = [], []
    with rosbag.Bag(path) as bag:
        lt, rt = stereo_topics(bag, ns)
        for topic, msg, _ in bag.read_messages(topics=[lt, rt]):
            (left if topic == lt else right).append(msg)
            if len(left) > frame and len(right) > frame:
                break
    if len(left) <= frame or len(right) <= frame:
        raise RuntimeError(f"{path}: fewer than {frame + 1} stereo images (is it an image bag?)")
    return left[frame], right[frame]


def to_array(msg):
    if msg.encoding != "mono8":
        raise RuntimeError(f"unsupported encoding {msg.encoding} (mono8 expected)")
    return np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)[:, :msg.width]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag")
    ap.add_argument("out")
    ap.add_argument("--frame", type=int, default=0)
    ap.add_argument("--ns", help="namespace of the bag's topics (default: the root, or the only one)")
    ap.add_argument("--max-width", type=int, default=1600, help="scale the pair down to this width")
    a = ap.parse_args()
    try:
        l, r = first_images(a.bag, a.frame, a.ns)
    except Exception as e:  # noqa: BLE001 - one clear line for any unreadable bag
        print(f"bag_preview: {e}", file=sys.stderr)
        return 1
    pair = np.hstack([to_array(l), np.full((l.height, 8), 255, np.uint8), to_array(r)])
    if pair.shape[1] > a.max_width:
        s = a.max_width / pair.shape[1]
        pair = cv2.resize(pair, (a.max_width, int(round(pair.shape[0] * s))), interpolation=cv2.INTER_AREA)
    img = cv2.cvtColor(pair, cv2.COLOR_GRAY2BGR)
    caption = f"{a.bag}  frame {a.frame}  t={l.header.stamp.to_sec():.2f} s  {l.width}x{l.height}  left | right"
    cv2.putText(img, caption, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 255, 255), 2, cv2.LINE_AA)
    if not cv2.imwrite(a.out, img):
        print(f"bag_preview: cannot write {a.out}", file=sys.stderr)
        return 1
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
