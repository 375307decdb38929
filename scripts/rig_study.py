#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""The induration measurement through rigs other than the thesis': each rig of the table below (1-13 MP, baselines
50-250 mm, working distances 0.15-0.6 m, convergence 0-60 deg) renders a limb with plaques (make_dataset skin, its
own seeds), process_bag --induration measures it with the defaults and nothing but the calibration, and
skin_check.py compares the result with the generator's truth. Prints a Markdown table, one row per rig and seed:
coverage of the visible skin (and of the working band), the depth range found, the detection threshold, the
plaques of at least 0.1 mm in the working band found, their worst top-height error and the worst ratio of an
error to the top's stated uncertainty, the false plaques, and whether the reference followed the skin.

Usage: rig_study.py [--out DIR] [--seeds N ...] [--rigs NAME ...] [--bin DIR] [--reuse] [--list]
  --out DIR    work folder (default /tmp/skin3d_rig_study): the bags, truths and results stay there
  --reuse      measure the bags already in DIR again when their scene file is unchanged (no new render)
  --seeds      seeds of the scenes (default 21 22)
  --rigs       only these rigs (default: all; --list shows them)
  --bin        folder of make_dataset and process_bag (default: build/devel/lib/skin3d of this source tree)
Full-resolution renders: a 12-megapixel rig takes minutes per seed on 2 cores.
"""
import argparse
import os
import re
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

# name: (width px, height px, pixel um, focal mm, baseline mm, convergence deg, working distance mm). The axes of
# a converged rig cross near its working distance (2 atan(B / 2 WD)); the parallel ones overlap by about 70 %.
RIGS = {
    "parallel_1mp_60mm": (1280, 1024, 4.8, 6.0, 60, 0.0, 200),
    "parallel_1mp_50mm_near": (1280, 960, 3.75, 4.0, 50, 0.0, 150),
    "converged_2mp_100mm": (1920, 1200, 3.45, 8.0, 100, 14.3, 400),
    "converged_12mp_150mm": (4000, 3000, 1.55, 4.4, 150, 28.1, 300),
    "converged_5mp_250mm_far": (2448, 2048, 3.45, 12.0, 250, 23.5, 600),
    "converged_2mp_60deg": (1920, 1080, 2.9, 3.6, 173, 60.0, 150),
}


def rig_yaml(rig, seed):
    w, h, px, f, b, conv, wd = rig
    return ("seed: %d\nskin:\n  random: true\n  plaque_count: 5\n  working_distance_mm: %g\n  frames: 1\n"
            "rig:\n  focal_length_mm: %g\n  pixel_size_um: %g\n  width_px: %d\n  height_px: %d\n"
            "  baseline_mm: [%g, 0, 0]\n  convergence_deg: %g\n  distortion: []\n" % (seed, wd, f, px, w, h, b, conv))


def run(cmd, log):
    with open(log, "w") as f:
        return subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT).returncode


def figures(check_text, results_dir):
    """The summary figures of skin_check.py's output and induration.yaml."""
    import yaml
    out = {}
    m = re.search(r"visible skin with a disparity: ([\d.]+) % \(seen at <= 60 deg: ([\d.]+) %\)", check_text)
    out["coverage"] = "%s / %s" % (m.group(1), m.group(2)) if m else "?"
    m = re.search(r"plaques >= 0.1 mm in the working band: (\d+), found (\d+), worst error (\S+) mm, "
                  r"worst error / sigma (\S+), PASI right (\d+), extra (\d+)", check_text)
    if m:
        out["plaques"] = "%s of %s" % (m.group(2), m.group(1))
        out["worst"] = m.group(3)
        out["z"] = m.group(4)
        out["extra"] = m.group(6)
    else:
        out["plaques"] = out["worst"] = out["z"] = out["extra"] = "?"
    try:
        with open(os.path.join(results_dir, "induration.yaml")) as f:
            fr = (yaml.safe_load(f).get("frames") or [{}])[-1]
        z = fr.get("depth_range_m") or ["?", "?"]
        out["range"] = "%.3f-%.3f" % tuple(z) if all(isinstance(v, float) for v in z) else "?"
        out["threshold"] = "%.3f" % fr.get("detection_threshold_mm", float("nan"))
        ref = fr.get("reference") or {}
        out["follows"] = "yes" if ref.get("follows_skin", True) else "no (%.1f %%)" % (100 * ref.get("unfollowed_share", 0))
    except (OSError, ValueError, TypeError, AttributeError):
        out["range"] = out["threshold"] = out["follows"] = "?"
    return out


def main():
    ap = argparse.ArgumentParser(usage=__doc__)
    ap.add_argument("--out", default="/tmp/skin3d_rig_study")
    ap.add_argument("--seeds", nargs="*", type=int, default=[21, 22])
    ap.add_argument("--rigs", nargs="*", default=[])
    ap.add_argument("--bin", default=os.path.join(os.path.dirname(HERE), "build", "devel", "lib", "skin3d"))
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--reuse", action="store_true")
    a = ap.parse_args()
    if a.list:
        for name, r in RIGS.items():
            print("%-26s %dx%d px, %.2f um, f %.1f mm, baseline %d mm, convergence %.1f deg, %d mm" % ((name,) + r))
        return 0
    unknown = [r for r in a.rigs if r not in RIGS]
    if unknown:
        ap.error("no such rig: %s (--list shows them)" % ", ".join(unknown))
    for tool in ("make_dataset", "process_bag"):
        if not os.access(os.path.join(a.bin, tool), os.X_OK):
            print("rig_study: no %s in %s (build first: scripts/build)" % (tool, a.bin), file=sys.stderr)
            return 1
    os.makedirs(a.out, exist_ok=True)
    print("| rig | seed | visible skin / band measured (%) | depth range found (m) | detection threshold (mm) | "
          "plaques >= 0.1 mm found | worst top error (mm) | worst error / stated sigma | false plaques | "
          "reference follows |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in (a.rigs or RIGS):
        for seed in a.seeds:
            base = os.path.join(a.out, "%s_%d" % (name, seed))
            scene = rig_yaml(RIGS[name], seed)
            same = a.reuse and os.path.exists(base + ".bag") and os.path.exists(base + ".yaml") and \
                open(base + ".yaml").read() == scene
            with open(base + ".yaml", "w") as f:
                f.write(scene)
            if not same and run([os.path.join(a.bin, "make_dataset"), "skin", "--quiet", "--config", base + ".yaml",
                    "--out", base + ".bag"], base + ".make.log"):
                print("| %s | %d | make_dataset failed: %s.make.log |" % (name, seed, base))
                continue
            rc = run([os.path.join(a.bin, "process_bag"), "--induration", "--quiet", "--bag", base + ".bag",
                      "--out", base], base + ".process.log")
            if rc not in (0, 4):
                print("| %s | %d | process_bag exit %d: %s.process.log |" % (name, seed, rc, base))
                continue
            check = subprocess.run([sys.executable, os.path.join(HERE, "skin_check.py"), base + ".bag", base],
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True).stdout
            with open(base + ".check.txt", "w") as f:
                f.write(check)
            g = figures(check, base)
            print("| %s | %d | %s | %s | %s | %s | %s | %s | %s | %s |" % (
                name, seed, g["coverage"], g["range"], g["threshold"], g["plaques"], g["worst"], g["z"], g["extra"],
                g["follows"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
