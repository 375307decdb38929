#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Checks of scripts/report.py and scripts/skin3d_plots.py (skin3d.report, skin3d.plots) on real results
directories (test_reports runs it).

usage: check_report.py REPORT.html SLAM_DIR_NO_GYRO SLAM_DIR_GYRO INDURATION_DIR

Exits 1 naming the first failed check. What is checked, against files the tools wrote and the dataset
generator's truth (never against the plotting code's own output):
- the page is self-contained (every image a data: URI, nothing loaded from elsewhere) and has the figures;
- its figures of merit are those of summary.yaml / sphere_fit.yaml / induration.yaml, and every parameter of
  parameters.yaml is listed;
- the reference velocities the plots derive from the ground-truth poses agree with the generator's constant
  rig velocities (truth.yaml), i.e. the rotation conventions of the plots are right;
- the 3-sigma bounds drawn in Fig. 7.1 (the smoother's from smoother_covariance.csv when it wrote trajectory.tum, else the
  filter's from rig_covariance.csv) contain most of the errors;
- the workpiece table matches the truth's plateaus.
"""
import re
import sys

import numpy as np

from skin3d import plots as sp  # the devel space's PYTHONPATH (source build/devel/setup.bash; run_tests has it)

failures = []


def check(ok, what):
    print("%s: %s" % ("ok  " if ok else "FAIL", what))
    if not ok:
        failures.append(what)


def main(html_path, d2, d3, dind):
    page = open(html_path, encoding="utf-8").read()
    srcs = re.findall(r'src\s*=\s*["\']([^"\']*)', page)
    check(len(srcs) >= 10, "report has at least 10 images (%d)" % len(srcs))
    check(all(s.startswith("data:image/png;base64,") for s in srcs), "every image is embedded (data: URI)")
    check(not re.search(r'<(link|script)[^>]*(href|src)=', page), "no external stylesheet or script")
    for d in (d2, d3):
        r = sp.SlamRun(d)
        s, f = r.summary, r.sphere
        check("%.4f" % f["radius_mm"] in page, "%s: sphere radius %.4f mm is in the report" % (r.name, f["radius_mm"]))
        check("%.3f" % s["ate"]["rmse_mm"] in page, "%s: ATE %.3f mm is in the report" % (r.name, s["ate"]["rmse_mm"]))
        for k in r.parameters["parameters"]:
            if "<td>%s</td>" % k not in page:
                check(False, "%s: parameter %s listed" % (r.name, k))
                break
        else:
            check(True, "%s: all %d parameters listed" % (r.name, len(r.parameters["parameters"])))
        # reference velocities from the ground truth vs the generator's constants
        t, v, w = r.reference_velocities()
        o = r.truth_yaml["orbit"]
        v_true, w_true = np.array(o["linear_velocity_rig_m_s"]), np.array(o["angular_velocity_rig_rad_s"])
        ev = np.max(np.abs(v - v_true)) / np.linalg.norm(v_true)
        ew = np.max(np.abs(w - w_true)) / np.linalg.norm(w_true)
        check(ev < 1e-3 and ew < 1e-3, "%s: reference v, w from the ground truth match the generator (rel. %.1e, %.1e)"
              % (r.name, ev, ew))
        # the covariance file: one SPD-diagonal matrix per frame, and the errors mostly within 3 sigma
        check(r.cov is not None and len(r.cov) == len(r.traj), "%s: rig_covariance.csv has one matrix per frame" % r.name)
        pr = r.paired()
        rows = np.array([p[5] for p in pr])[5:]
        ep = np.array([p[3] - p[1] for p in pr])[5:]
        eth = np.array([sp.so3_log(p[4] @ p[2].T) for p in pr])[5:]
        # trajectory.tum's own covariance: the smoother's (smoother_covariance.csv) when it wrote it, else the filter's
        cov, who = (r.pose_cov, "smoother's") if r.pose_cov is not None else (r.cov, "filter's")
        check(len(cov) == len(r.traj), "%s: the %s covariance has one matrix per pose" % (r.name, who))
        sd = np.sqrt(np.array([np.diag(cov[k])[:6] for k in rows]))
        inside = np.mean(np.abs(np.c_[ep, eth]) <= 3 * sd)
        check(inside > 0.9, "%s: %.1f %% of the pose error components inside the %s 3 sigma" % (r.name, 100 * inside, who))
    c2 = sp.SlamRun(d2)
    check("experiment 2" in c2.kind() and "experiment 3" in sp.SlamRun(d3).kind(), "runs classified as experiments 2 and 3")
    # induration
    ir = sp.IndurationRun(dind)
    rows, _ = ir.table()
    truth_heights = sorted(p["height_mm"] for p in ir.truth_yaml["plateaus"])
    check(sorted(r["true_mm"] for r in rows) == truth_heights, "induration table has every true plateau")
    found = [r for r in rows if r["mean_mm"] is not None]
    check(len(found) >= len(rows) - 1, "at least all but one plateau found (%d of %d)" % (len(found), len(rows)))
    for r in found:
        if r["true_mm"] >= 0.2:
            check(abs(r["mean_mm"] - r["true_mm"]) < 0.05 and ("%.4f" % r["mean_mm"]) in page,
                  "plateau %.2f mm: measured %.4f mm, in the report" % (r["true_mm"], r["mean_mm"]))
    check(page.count("<h2>") >= 4, "a section per run plus the comparison")
    if failures:
        print("check_report: %d check(s) failed" % len(failures))
        return 1
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    sys.exit(main(*sys.argv[1:]))
