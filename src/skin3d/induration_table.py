# SPDX-License-Identifier: BSD-3-Clause
"""True vs measured plaque heights (the thesis' Table 4.2) from a results directory and the dataset's truth.

Usage: induration_table.py RESULTS/induration.yaml DATASET.truth.yaml
Matches every true plateau to the measured plaque whose centroid is nearest (within 3 mm) in each frame and
prints a markdown table: true height, measured mean over the frames, error, std over the frames (the
repeatability), area and PASI class; plaques that match no plateau are listed after it.
(The matching is skin3d.plots.IndurationRun.table, which report.py uses too.)
"""
import os
import sys

from skin3d import plots as sp


def main(argv=None):
    """The command (scripts/induration_table.py): argv without the program name; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    if "-h" in argv or "--help" in argv:
        print(__doc__)
        return 0
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    if not os.path.exists(argv[1]):
        print("induration_table: no truth file '%s'" % argv[1], file=sys.stderr)
        return 1
    run = sp.IndurationRun(os.path.dirname(os.path.abspath(argv[0])), truth=argv[1], result=argv[0])
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
    return 0
