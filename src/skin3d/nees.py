# SPDX-License-Identifier: BSD-3-Clause
"""Pose consistency of SLAM runs: the normalised estimation error squared (NEES) of the pose, per frame, from
process_bag results directories with ground truth, and over Monte Carlo runs its average against the chi^2 band.

Usage: slam_nees.py [--confidence 0.95] [--min-inside 0.9] [--plot FILE.png] [--calibrated-frame] [--landmarks]
                    [--trajectory auto|filter|smoother]
                    RESULTS_DIR [RESULTS_DIR ...]

Each RESULTS_DIR holds trajectory.tum, ground_truth.tum (the bag's ground_truth/pose, in the SLAM's world:
process_bag writes it) and rig_covariance.csv; with the batch smoother (smoother: batch) trajectory.tum is the
smoother's, its covariance smoother_covariance.csv, and the filter's trajectory_filter.tum (--trajectory picks one;
the default is the smoother's when the run has it). Per frame k and run i the pose error is
e = [p_true - p_est, Log(R_true R_est^T)] (m, rad: the true state minus the estimate, with the filter's global angular error
R_true = Exp(dtheta) R_est; both parts must have that same sign),
NEES_ik = e^T P^-1 e with P the 6x6 [p, theta] block of the rig covariance (6 dof). Frames whose P is singular
(the first frame: its pose defines the world and is exactly known) are skipped.

--calibrated-frame compares with the true poses of the frame the bag's calibration defines instead of the true
optical frame. A calibration error moves every triangulated point by about the same rigid motion E (plus a scale
and a small non-rigid remainder): no image can tell the frame E defines from the optical one, so a world fixed by
the first camera frame is E's frame, and the poses the SLAM estimates are E T_true E^-1. make_dataset writes E
(the least-squares fit over the working volume, from the true and the perturbed rig: ground truth, not the
filter's output) as realism.calibration_error.measured_frame in BAG.truth.yaml, found from summary.yaml's 'bag'
(as written, or relative to RESULTS_DIR's parent). The scale error stays in the comparison.

--landmarks also prints the landmarks' radial NEES (1 dof) over the final maps of globe runs: the distance of each
landmark from the true sphere against its covariance along the radius (map_covariance.csv; the tangential error has no
truth). It does not change the exit code.

Over N runs the average NEES of a frame, times N, is chi^2 with 6 N dof when the filter is consistent: the
two-sided band at --confidence is [chi2((1-c)/2, 6N), chi2((1+c)/2, 6N)] / N (Bar-Shalom, Li, Kirubarajan 2001,
ch. 5.4). Prints the band, the share of frames inside it, below it (pessimistic) and above it (optimistic),
the mean NEES over all frames and runs, and for each run the share of its frames beyond chi2(c, 6).
Exit code 0 when the share inside is at least --min-inside, 1 when not, 2 on bad input.
"""
import argparse
import math
import os
import sys

import numpy as np

from skin3d.rotations import quat_to_rot as rotation, so3_exp, so3_log
from skin3d.stats import chi2_quantile, normal_quantile
from skin3d.tum import read_tum_poses as read_tum


def read_covariances(path):
    """Per frame t and the 6x6 [p, theta] block of the rig covariance (rig_covariance.csv, row-major)."""
    lines = [l for l in open(path) if not l.startswith("#")]
    header = lines[0].strip().split(",")
    dim = int(round(math.sqrt(len(header) - 1)))
    if dim * dim != len(header) - 1:
        raise ValueError("'%s': %d covariance columns is not a square" % (path, len(header) - 1))
    t, P = [], []
    for l in lines[1:]:
        v = np.array([float(x) for x in l.split(",")])
        t.append(v[0])
        P.append(v[1:].reshape(dim, dim)[:6, :6])
    return np.array(t), P


def bag_truth(d, why):
    """The run's BAG.truth.yaml (path, dict), found from summary.yaml's 'bag'."""
    import yaml
    summary = os.path.join(d, "summary.yaml")
    if not os.path.exists(summary):
        raise ValueError("'%s' has no summary.yaml, so its bag is unknown (%s)" % (d, why))
    bag = (yaml.safe_load(open(summary)) or {}).get("bag", "")
    stem = bag[:-4] if bag.endswith(".bag") else bag
    tried = [stem + ".truth.yaml", os.path.join(os.path.dirname(os.path.abspath(d)), stem + ".truth.yaml")]
    for path in tried:
        if os.path.exists(path):
            return path, yaml.safe_load(open(path)) or {}
    raise ValueError("'%s': the truth of its bag '%s' is not at %s (%s)" % (d, bag, " or ".join(tried), why))


def measured_frame(d):
    """E = (R, t) of the frame the run's calibration defines, from the bag's truth.yaml (see --calibrated-frame)."""
    path, truth = bag_truth(d, "--calibrated-frame")
    f = ((truth.get("realism") or {}).get("calibration_error") or {}).get("measured_frame")
    if f is None:
        raise ValueError("'%s' has no realism.calibration_error.measured_frame (made by an older "
                         "make_dataset? make the bag again)" % path)
    return so3_exp(np.array(f["rotation_rad"], float)), np.array(f["translation_m"], float)


def landmark_nees(d, calibrated_frame=False):
    """Radial NEES (1 dof) of the final map's landmarks of a globe run: e = |m - c| - r against the true sphere
    (centre c moved into the calibrated frame with --calibrated-frame), variance n^T C n with n the radial
    direction. The tangential error has no truth (a feature's true position on the sphere is not known)."""
    path = os.path.join(d, "map_covariance.csv")
    if not os.path.exists(path):
        raise ValueError("'%s' has no map_covariance.csv (a process_bag of this version writes it)" % d)
    tpath, truth = bag_truth(d, "--landmarks")
    sphere = truth.get("sphere") or {}
    if "centre_world_m" not in sphere:
        raise ValueError("'%s' has no sphere.centre_world_m: --landmarks needs a globe dataset" % tpath)
    c, r = np.array(sphere["centre_world_m"], float), float(sphere["radius_m"])
    if calibrated_frame:
        Re, te = measured_frame(d)
        c = Re @ c + te
    rows = [l.split(",") for l in open(path) if l.strip() and not l.startswith("#") and not l.startswith("id")]
    out = []
    for v in rows:
        m = np.array([float(x) for x in v[1:4]])
        cxx, cxy, cxz, cyy, cyz, czz = (float(x) for x in v[4:10])
        C = np.array([[cxx, cxy, cxz], [cxy, cyy, cyz], [cxz, cyz, czz]])
        n = (m - c) / np.linalg.norm(m - c)
        var = float(n @ C @ n)
        if var > 0:
            out.append((np.linalg.norm(m - c) - r) ** 2 / var)
    return np.array(out)


def trajectory_files(d, which="auto"):
    """The trajectory and the covariance that belongs to it: (trajectory file, covariance file) in d.

    which: 'filter' = the causal filter's (trajectory_filter.tum when a smoother wrote trajectory.tum, else
    trajectory.tum; with rig_covariance.csv); 'smoother' = trajectory.tum with smoother_covariance.csv; 'auto' =
    the smoother's when d has smoother_covariance.csv, else the filter's."""
    smoothed = os.path.exists(os.path.join(d, "smoother_covariance.csv"))
    if which == "smoother" or (which == "auto" and smoothed):
        return "trajectory.tum", "smoother_covariance.csv"
    if os.path.exists(os.path.join(d, "trajectory_filter.tum")):
        return "trajectory_filter.tum", "rig_covariance.csv"
    return "trajectory.tum", "rig_covariance.csv"


def run_nees(d, calibrated_frame=False, which="auto"):
    """Per-frame pose NEES of one results directory: dict t -> NEES (frames with a singular P left out)."""
    traj, cov = trajectory_files(d, which)
    for f in (traj, "ground_truth.tum", cov):
        if not os.path.exists(os.path.join(d, f)):
            raise ValueError("'%s' has no %s (process_bag on a bag with ground_truth/pose writes it%s)"
                             % (d, f, "; smoother: batch writes smoother_covariance.csv" if f == cov and which == "smoother" else ""))
    te, pe, qe = read_tum(os.path.join(d, traj))
    tg, pg, qg = read_tum(os.path.join(d, "ground_truth.tum"))
    Rg = [rotation(q) for q in qg]
    if calibrated_frame:  # T' = E T E^-1: R' = Re R Re^T, p' = Re p + te - R' te
        Re, te_ = measured_frame(d)
        Rg = [Re @ R @ Re.T for R in Rg]
        pg = np.array([Re @ p + te_ - R @ te_ for p, R in zip(pg, Rg)])
    tc, P = read_covariances(os.path.join(d, cov))
    out = {}
    for k, t in enumerate(te):
        j = int(np.argmin(np.abs(tg - t)))
        c = int(np.argmin(np.abs(tc - t)))
        if abs(tg[j] - t) > 1e-3 or abs(tc[c] - t) > 1e-6:
            continue
        e = np.concatenate([pg[j] - pe[k], so3_log(Rg[j] @ rotation(qe[k]).T)])
        Pk = 0.5 * (P[c] + P[c].T)
        w = np.linalg.eigvalsh(Pk)
        if w.min() <= 1e-12 * max(w.max(), 1e-300):
            continue
        out[round(t, 6)] = float(e @ np.linalg.solve(Pk, e))
    if not out:
        raise ValueError("'%s': no frame has both a ground-truth pose and a regular pose covariance" % d)
    return out


def main(argv=None):
    """The command (scripts/slam_nees.py): argv without the program name; returns the exit code."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", nargs="+", metavar="RESULTS_DIR")
    ap.add_argument("--confidence", type=float, default=0.95)
    ap.add_argument("--min-inside", type=float, default=0.9)
    ap.add_argument("--plot", default="")
    ap.add_argument("--landmarks", action="store_true",
                    help="also the radial NEES (1 dof) of each run's final map against the true sphere (globe)")
    ap.add_argument("--calibrated-frame", action="store_true",
                    help="compare with the true poses of the frame the bag's calibration defines (see above)")
    ap.add_argument("--trajectory", choices=("auto", "filter", "smoother"), default="auto",
                    help="which trajectory: the smoother's (trajectory.tum + smoother_covariance.csv, the default when "
                         "the run has them) or the causal filter's (trajectory_filter.tum or trajectory.tum + "
                         "rig_covariance.csv)")
    a = ap.parse_args(argv)
    if not 0.5 < a.confidence < 1.0:
        sys.exit("slam_nees: --confidence must be in (0.5, 1)")
    try:
        runs = [run_nees(d, a.calibrated_frame, a.trajectory) for d in a.dirs]
    except (ValueError, OSError) as e:
        print("slam_nees: %s" % e, file=sys.stderr)
        return 2
    frames = sorted(set.intersection(*[set(r) for r in runs]))
    if not frames:
        print("slam_nees: the runs share no frame time (same dataset length and rate?)", file=sys.stderr)
        return 2
    n = len(runs)
    avg = np.array([np.mean([r[t] for r in runs]) for t in frames])
    lo = chi2_quantile(0.5 * (1.0 - a.confidence), 6 * n) / n
    hi = chi2_quantile(0.5 * (1.0 + a.confidence), 6 * n) / n
    inside = np.mean((avg >= lo) & (avg <= hi))
    print("runs: %d, frames compared: %d; %.0f %% band of the average pose NEES (6 dof): [%.2f, %.2f]"
          % (n, len(frames), 100 * a.confidence, lo, hi))
    print("frames inside: %.1f %%, below (pessimistic): %.1f %%, above (optimistic): %.1f %%"
          % (100 * inside, 100 * np.mean(avg < lo), 100 * np.mean(avg > hi)))
    allv = np.array([v for r in runs for v in r.values()])
    print("mean NEES over all frames and runs: %.2f (expected 6); median %.2f (expected %.2f)"
          % (allv.mean(), np.median(allv), chi2_quantile(0.5, 6)))
    single = chi2_quantile(a.confidence, 6)
    for d, r in zip(a.dirs, runs):
        v = np.array(list(r.values()))
        print("  %s: %d frames, mean NEES %.2f, beyond chi2(%.2f, 6) = %.1f: %.1f %% (expected %.0f %%)"
              % (d, len(v), v.mean(), a.confidence, single, 100 * np.mean(v > single), 100 * (1 - a.confidence)))
    if a.landmarks:
        try:
            lm = np.concatenate([landmark_nees(d, a.calibrated_frame) for d in a.dirs])
        except (ValueError, OSError, KeyError) as e:
            print("slam_nees: %s" % e, file=sys.stderr)
            return 2
        q = normal_quantile(0.5 * (1 + a.confidence)) ** 2  # chi^2(1) quantile
        print("landmarks (final maps, radial error against the true sphere, 1 dof): %d; mean NEES %.2f (expected 1), "
              "median %.3f (expected 0.455); beyond chi2(%.2f, 1) = %.2f: %.1f %% (expected %.0f %%)"
              % (len(lm), lm.mean(), np.median(lm), a.confidence, q, 100 * np.mean(lm > q), 100 * (1 - a.confidence)))
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        t0 = frames[0]
        x = np.array(frames) - t0
        fig, ax = plt.subplots(figsize=(8, 3.5))
        ax.semilogy(x, avg, "k-", lw=1, label="average pose NEES over %d runs" % n)
        ax.axhline(lo, color="g", ls="--", label="%.0f %% band [%.2f, %.2f]" % (100 * a.confidence, lo, hi))
        ax.axhline(hi, color="g", ls="--")
        ax.axhline(6, color="0.5", ls=":", label="6 (dof)")
        ax.set_xlabel("time since the first compared frame (s)")
        ax.set_ylabel("NEES")
        ax.set_title("pose NEES: %.0f %% of the frames inside the band" % (100 * inside))
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=100)
    return 0 if inside >= a.min_inside else 1

