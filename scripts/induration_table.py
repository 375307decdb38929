#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""True vs measured plaque heights (the thesis' Table 4.2) from a results directory and the dataset's truth.

Usage: induration_table.py RESULTS/induration.yaml DATASET.truth.yaml
Matches every true plateau to the measured plaque whose centroid is nearest (within 3 mm) in each frame and
prints a markdown table: true height, measured mean over the frames, error, std over the frames (the
repeatability), area and PASI class; plaques that match no plateau are listed after it.
(The matching is skin3d_plots.IndurationRun.table, which report.py uses too.)
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import skin3d_plots as sp  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    if not os.path.exists(sys.argv[2]):
        sys.exit("induration_table: no truth file '%s'" % sys.argv[2])
    run = sp.IndurationRun(os.path.dirname(os.path.abspath(sys.argv[1])), truth=sys.argv[2], result=sys.argv[1])
    rows, extra = run.table()
    n = len(run.result.get("frames") or [])
    print("| true height (mm) | measured (mm, mean of %d frames) | error (mm) | std over frames (mm) | "
          "area (mm², true) | PASI |" % n)
    print("|---|---|---|---|---|---|")
    for r in rows:
        if r["mean_mm"] is None:
            print("| %.2f | not found | | | (%.0f) | |" % (r["true_mm"], r["true_area_mm2"]))
            continue
        print("| %.2f | %.4f | %+.4f | %.4f | %.1f (%.0f) | %s |" % (
            r["true_mm"], r["mean_mm"], r["mean_mm"] - r["true_mm"], r["std_mm"] if r["std_mm"] is not None else float("nan"),
            r["area_mm2"], r["true_area_mm2"], "/".join(str(k) for k in r["pasi"])))
    for i, q in extra:
        print("frame %d: plaque %d (%.3f mm, %.1f mm²) matches no plateau" % (i, q["id"], q["mean_height_mm"], q["area_mm2"]))


if __name__ == "__main__":
    main()
