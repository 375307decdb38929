#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Table 7.2 of the thesis next to skin3d's SLAM experiments, and their plots.

usage: slam_report.py OUT.png NAME=RESULTS_DIR [NAME=RESULTS_DIR ...]

Each RESULTS_DIR is a process_bag / eskf_slam results directory (summary.yaml, state.csv, trajectory.tum,
ground_truth.tum). Prints a Markdown table (radius, RMS residual of the sphere fit, ATE, final covariance
traces, v_x-omega_y correlation) with the thesis' figures and the issue's targets, and draws OUT.png:
trace of the rig-state covariance (the loop closure shows as a drop near the end), position error against
ground truth, and the v_x-omega_y correlation, per frame.
"""
import csv
import math
import sys

import yaml

THESIS = {  # Table 7.2 (radius mm, RMS mm)
    "2": (200.028, 0.0628),
    "3": (200.009, 0.0017),
    "4": (142.749, 1.9255),
}


def load(d):
    with open(d + "/summary.yaml") as f:
        s = yaml.safe_load(f)
    rows = []
    with open(d + "/state.csv") as f:
        for r in csv.DictReader(f):
            rows.append({k: float(v) for k, v in r.items()})
    traj = read_tum(d + "/trajectory.tum")
    try:
        truth = read_tum(d + "/ground_truth.tum")
    except OSError:
        truth = []
    return s, rows, traj, truth


def read_tum(path):
    out = []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            v = [float(x) for x in line.split()]
            out.append(v)
    return out


def errors(traj, truth):
    if not truth:
        return [], []
    ts = [g[0] for g in truth]
    t_out, e_out = [], []
    j = 0
    for p in traj:
        while j + 1 < len(ts) and abs(ts[j + 1] - p[0]) <= abs(ts[j] - p[0]):
            j += 1
        if abs(ts[j] - p[0]) < 1e-3:
            g = truth[j]
            t_out.append(p[0] - traj[0][0])
            e_out.append(1e3 * math.dist(p[1:4], g[1:4]))
    return t_out, e_out


def main():
    if len(sys.argv) < 3:
        print(__doc__)
        return 2
    out_png = sys.argv[1]
    runs = []
    for arg in sys.argv[2:]:
        name, _, d = arg.partition("=")
        runs.append((name, d) + load(d))
    print("| experiment | radius (mm) | radius error (mm) | RMS residual (mm) | thesis radius / RMS (mm) | ATE RMSE (mm) |"
          " final trace rig / all | corr(v_x, w_y) |")
    print("|---|---|---|---|---|---|---|---|")
    for name, d, s, rows, traj, truth in runs:
        fit = s.get("sphere_fit") or {}
        r = fit.get("radius_mm") if isinstance(fit, dict) else None
        rms = fit.get("rms_residual_mm") if isinstance(fit, dict) else None
        ate = (s.get("ate") or {}).get("rmse_mm")
        tr = s.get("final_covariance_trace") or {}
        key = name.split()[0].lstrip("exp")
        th = THESIS.get(key)
        print("| %s | %s | %s | %s | %s | %s | %.3g / %.3g | %.3f |" % (
            name,
            "%.4f" % r if r is not None else "-",
            "%+.4f" % (r - 200.0) if r is not None else "-",
            "%.4f" % rms if rms is not None else "-",
            "%.3f / %.4f" % th if th else "-",
            "%.3f" % ate if ate is not None else "-",
            tr.get("rig", float("nan")), tr.get("all", float("nan")),
            s.get("corr_vx_wy_final", float("nan"))))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("slam_report: matplotlib missing, no plot", file=sys.stderr)
        return 0
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.5))
    for name, d, s, rows, traj, truth in runs:
        t = [r["t"] - rows[0]["t"] for r in rows]
        ax[0].semilogy(t, [max(r["trace_rig"], 1e-12) for r in rows], label=name)
        te, e = errors(traj, truth)
        if e:
            ax[1].plot(te, e, label=name)
        ax[2].plot(t, [r["corr_vx_wy"] for r in rows], label=name)
    ax[0].set(title="trace of the rig-state covariance\n(loop closure: the drop near the end)", xlabel="t (s)",
              ylabel="trace (mixed units)")
    ax[1].set(title="position error against ground truth", xlabel="t (s)", ylabel="mm")
    ax[2].set(title="correlation of v_x and omega_y", xlabel="t (s)", ylabel="correlation coefficient")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    print("slam_report: wrote %s" % out_png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
