#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""True vs measured plaque heights (the thesis' Table 4.2) from a results directory and the dataset's truth.

Usage: induration_table.py RESULTS/induration.yaml DATASET.truth.yaml
Matches every true plateau to the measured plaque whose centroid is nearest (within 3 mm) in each frame and
prints a markdown table: true height, measured mean over the frames, error, std over the frames (the
repeatability), area and PASI class; plaques that match no plateau are listed after it.
"""
import sys

import numpy as np
import yaml


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    res = yaml.safe_load(open(sys.argv[1]))
    truth = yaml.safe_load(open(sys.argv[2]))
    frames = res.get("frames") or []
    print("| true height (mm) | measured (mm, mean of %d frames) | error (mm) | std over frames (mm) | "
          "area (mm², true) | PASI |" % len(frames))
    print("|---|---|---|---|---|---|")
    used = [set() for _ in frames]
    for p in truth["plateaus"]:
        c = np.array(p["centroid_left_m"])
        h, a, k = [], [], []
        for i, f in enumerate(frames):
            best, best_d = None, 3e-3
            for j, q in enumerate(f.get("plaques") or []):
                d = np.linalg.norm(np.array(q["centroid_m"]) - c)
                if d < best_d:
                    best, best_d = j, d
            if best is None:
                continue
            used[i].add(best)
            q = f["plaques"][best]
            h.append(q["mean_height_mm"]), a.append(q["area_mm2"]), k.append(q["pasi_class"])
        if not h:
            print("| %.2f | not found | | | (%.0f) | |" % (p["height_mm"], p["area_mm2"]))
            continue
        sd = np.std(h, ddof=1) if len(h) > 1 else float("nan")
        print("| %.2f | %.4f | %+.4f | %.4f | %.1f (%.0f) | %s |" % (
            p["height_mm"], np.mean(h), np.mean(h) - p["height_mm"], sd, np.mean(a), p["area_mm2"],
            "/".join(str(x) for x in sorted(set(k)))))
    for i, f in enumerate(frames):
        for j, q in enumerate(f.get("plaques") or []):
            if j not in used[i]:
                print("frame %d: plaque %d (%.3f mm, %.1f mm²) matches no plateau" % (
                    i, q["id"], q["mean_height_mm"], q["area_mm2"]))


if __name__ == "__main__":
    main()
