# SPDX-License-Identifier: BSD-3-Clause
"""Table 7.2 of the thesis next to skin3d's SLAM experiments (Markdown), and their plots.

usage: slam_report.py PLOT_DIR NAME=RESULTS_DIR [NAME=RESULTS_DIR ...]

Each RESULTS_DIR is a process_bag / eskf_slam results directory (summary.yaml, state.csv, rig_covariance.csv,
trajectory.tum, ground_truth.tum, sphere_fit.yaml). Prints a Markdown table (radius, RMS residual of the
sphere fit, ATE, final covariance traces, v_x-omega_y correlation) with the thesis' figures, then skin3d's
targets judged on these runs; writes the plots of skin3d_plots.py into PLOT_DIR: fig7_1_<name>.png per run,
fig7_2.png (covariance traces; the loop closure shows as a drop), fig7_4.png (correlation matrices,
experiments 2 and 3 when present), sphere_<name>.png. For one HTML page with all of it: report.py.
"""
import os
import sys

from skin3d import plots as sp


def f(x, spec):
    return spec % x if x is not None else "-"


def main(argv=None):
    """The command (scripts/slam_report.py): argv without the program name; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    if "-h" in argv or "--help" in argv:
        print(__doc__)
        return 0
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    plot_dir = argv[0]
    runs = []
    for arg in argv[1:]:
        name, _, d = arg.partition("=")
        if not d:
            name, d = os.path.basename(os.path.normpath(name)), name
        try:
            runs.append(sp.SlamRun(d, name))
        except (OSError, ValueError, KeyError, IndexError) as e:
            print("slam_report: cannot read '%s': %s" % (d, e), file=sys.stderr)
            return 1
    print("| experiment | radius (mm) | radius error (mm) | RMS residual (mm) | thesis radius / RMS (mm) | ATE RMSE (mm) |"
          " final trace rig / all | corr(v_x, w_y) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in sp.comparison(runs):
        print("| %s | %s | %s | %s | %s | %s | %s / %s | %s |" % (
            r["run"], f(r["radius_mm"], "%.4f"), f(r["radius_error_mm"], "%+.4f"), f(r["rms_mm"], "%.4f"),
            "%.3f / %.4f" % r["thesis"] if r["thesis"] else "-", f(r["ate_mm"], "%.3f"), f(r["trace_rig"], "%.3g"),
            f(r["trace_all"], "%.3g"), f(r["corr_vx_wy"], "%.3f")))
    tg = sp.targets(runs)
    if tg:
        print()
        print("| target | measured | |")
        print("|---|---|---|")
        for target, measured, ok, note in tg:
            print("| %s | %s | %s%s |" % (target, measured, "met" if ok else "NOT met", " (%s)" % note if note else ""))

    def save(fig, name):
        os.makedirs(plot_dir, exist_ok=True)
        fig.savefig(os.path.join(plot_dir, name), dpi=90)
        sp.plt.close(fig)

    for r in runs:
        save(sp.fig_pose_velocity(r), "fig7_1_%s.png" % r.name.split()[0])
        if r.sphere:
            save(sp.fig_sphere(r), "sphere_%s.png" % r.name.split()[0])
    save(sp.fig_trace(runs), "fig7_2.png")
    corr = [r for r in runs if r.cov is not None and sp.experiment(r) in (2, 3)] or [r for r in runs if r.cov is not None]
    if corr:
        save(sp.fig_correlation(corr), "fig7_4.png")
    print("\nslam_report: plots in %s (fig7_1_*.png, fig7_2.png, fig7_4.png, sphere_*.png)" % plot_dir)
    return 0

