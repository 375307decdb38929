# SPDX-License-Identifier: BSD-3-Clause
"""The thesis' plots from skin3d results directories (matplotlib; a module for report.py, and a command).

usage: skin3d_plots.py RESULTS_DIR [RESULTS_DIR ...] [--out DIR] [--frame K]

For every SLAM results directory (process_bag or the eskf_slam nodelet: summary.yaml, state.csv,
rig_covariance.csv, trajectory.tum, ground_truth.tum when the dataset had one, map.ply, sphere_fit.yaml) writes
  fig7_1_<name>.png  pose, velocities (reference and estimate) and their errors with the 3-sigma bounds (the filter's, or the smoother's)
  fig7_2.png         trace of the error-state covariance: rig state / landmarks / all (every run in one plot)
  fig7_4.png         correlation matrix of the rig state at frame K (default 8, as in the thesis) and the end
  sphere_<name>.png  the map and the fitted sphere (Table 7.2): residuals over the sphere and their histogram
and for an induration results directory (induration.yaml) height_<name>.png: the height map and, with the
dataset's truth (BAG.truth.yaml beside the bag), measured vs true plateau heights (Table 4.2).
Default --out: each results directory itself.

Conventions: the rig's error state is [dp, dtheta, dv, dw] (DESIGN.md; dtheta the global angular error,
world frame), velocities in the camera (left optical) frame. Reference velocities are the central
differences of the dataset's ground-truth poses (the generator's, not the filter's).
"""
import csv
import math
import os
import sys

import numpy as np
import yaml

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from skin3d.rotations import euler_zyx_deg, quat_to_rot, so3_log  # noqa: E402,F401  (also for users of this module)
from skin3d.tum import read_tum  # noqa: E402,F401

THESIS = {2: (200.028, 0.0628), 3: (200.009, 0.0017), 4: (142.749, 1.9255)}  # Table 7.2: radius, RMS (mm)
TRUE_RADIUS_MM = 200.0  # the globe of the simulated datasets (make_dataset)
RIG_NAMES = ["px", "py", "pz", "θx", "θy", "θz", "vx", "vy", "vz", "ωx", "ωy", "ωz", "bgx", "bgy", "bgz"]


# ---------------------------------------------------------------------------------------------------------
# loading

def read_ply_xyz(path):
    pts = []
    with open(path) as f:
        n = 0
        for line in f:
            if line.startswith("element vertex"):
                n = int(line.split()[2])
            if line.strip() == "end_header":
                break
        for _ in range(n):
            v = f.readline().split()
            pts.append([float(x) for x in v[:3]])
    return np.array(pts).reshape(-1, 3)


def load_yaml(path):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return yaml.safe_load(f)


class SlamRun:
    """A SLAM results directory."""

    def __init__(self, d, name=None):
        self.dir = d
        self.name = name or os.path.basename(os.path.normpath(d))
        self.summary = load_yaml(os.path.join(d, "summary.yaml")) or {}
        self.parameters = load_yaml(os.path.join(d, "parameters.yaml"))
        self.sphere = load_yaml(os.path.join(d, "sphere_fit.yaml"))
        with open(os.path.join(d, "state.csv")) as f:
            rows = list(csv.DictReader(f))
        self.state = {k: np.array([float(r[k]) for r in rows]) for k in (rows[0].keys() if rows else [])}
        self.traj = read_tum(os.path.join(d, "trajectory.tum"))
        self.truth = read_tum(os.path.join(d, "ground_truth.tum"))
        self.cov_t, self.cov = self._read_cov(os.path.join(d, "rig_covariance.csv"))
        # the batch smoother's trajectory.tum comes with its own pose covariances ([p, theta] per frame)
        self.pose_cov_t, self.pose_cov = self._read_cov(os.path.join(d, "smoother_covariance.csv"))
        self.map = read_ply_xyz(os.path.join(d, "map.ply")) if os.path.exists(os.path.join(d, "map.ply")) else None
        bag = self.summary.get("bag")
        self.truth_yaml = load_yaml(bag[:-4] + ".truth.yaml") if isinstance(bag, str) and bag.endswith(".bag") else None

    @staticmethod
    def _read_cov(path):
        if not os.path.exists(path):
            return None, None
        a = np.loadtxt(path, delimiter=",", comments="#", skiprows=2, ndmin=2)
        n = int(round(math.sqrt(a.shape[1] - 1)))
        return a[:, 0], a[:, 1:].reshape(-1, n, n)

    def kind(self):
        s = self.summary
        if str(s.get("known_map")).lower() == "true":
            return "ES-EKF with known landmarks (experiment 1)"
        images = "landmark bag" not in str(s.get("front_end", "none (landmark bag)"))
        gyro = str(s.get("gyro")).lower() == "true"
        if images:
            return "SLAM on rendered/recorded images through the front end (experiment 4)" + (" + gyroscope" if gyro else "")
        return "SLAM with gyroscope (experiment 3)" if gyro else "SLAM without gyroscope (experiment 2)"

    def paired(self):
        """Estimate and reference poses paired by stamp (1 ms): t, p_est, R_est, p_ref, R_ref, row index."""
        if len(self.truth) == 0 or len(self.traj) == 0:
            return None
        ts = self.truth[:, 0]
        out = []
        for i, row in enumerate(self.traj):
            j = int(np.argmin(np.abs(ts - row[0])))
            if abs(ts[j] - row[0]) < 1e-3:
                out.append((row[0], row[1:4], quat_to_rot(row[4:8]), self.truth[j, 1:4], quat_to_rot(self.truth[j, 4:8]), i))
        return out

    def reference_velocities(self):
        """Central differences of the ground-truth poses: t, v (m/s) and w (rad/s) in the camera frame."""
        g = self.truth
        if len(g) < 3:
            return None
        t, v, w = [], [], []
        for k in range(1, len(g) - 1):
            dt = g[k + 1, 0] - g[k - 1, 0]
            if dt <= 0:
                continue
            R = quat_to_rot(g[k, 4:8])
            v.append(R.T @ (g[k + 1, 1:4] - g[k - 1, 1:4]) / dt)
            w.append(so3_log(quat_to_rot(g[k - 1, 4:8]).T @ quat_to_rot(g[k + 1, 4:8])) / dt)
            t.append(g[k, 0])
        return np.array(t), np.array(v), np.array(w)


class IndurationRun:
    """An induration results directory (induration.yaml, height_map.png/tiff)."""

    def __init__(self, d, name=None, truth=None, result=None):
        """d: the directory; truth: the dataset's truth YAML (default: beside the bag named in induration.yaml);
        result: the induration.yaml (default: d/induration.yaml)."""
        self.dir = d
        self.name = name or os.path.basename(os.path.normpath(d))
        self.result = load_yaml(result or os.path.join(d, "induration.yaml")) or {}
        self.parameters = load_yaml(os.path.join(d, "parameters.yaml"))
        src = self.result.get("source")
        if truth is None and isinstance(src, str) and src.endswith(".bag"):
            truth = src[:-4] + ".truth.yaml"
        self.truth_yaml = load_yaml(truth) if truth else None

    def table(self, radius_m=3e-3):
        """True vs measured plateaus (the thesis' Table 4.2): list of dicts, and the unmatched plaques."""
        frames = self.result.get("frames") or []
        rows, used = [], [set() for _ in frames]
        for p in (self.truth_yaml or {}).get("plateaus") or (self.truth_yaml or {}).get("plaques") or []:
            c = np.array(p["centroid_left_m"])
            h, a, k = [], [], []
            for i, f in enumerate(frames):
                best, best_d = None, radius_m
                for j, q in enumerate(f.get("plaques") or []):
                    dd = np.linalg.norm(np.array(q["centroid_m"]) - c)
                    if dd < best_d:
                        best, best_d = j, dd
                if best is None:
                    continue
                used[i].add(best)
                q = f["plaques"][best]
                h.append(q.get("top_height_mm", q["mean_height_mm"])), a.append(q["area_mm2"]), k.append(q["pasi_class"])
            rows.append({"true_mm": p["height_mm"], "true_area_mm2": p["area_mm2"], "found": len(h), "frames": len(frames),
                         "mean_mm": float(np.mean(h)) if h else None,
                         "std_mm": float(np.std(h, ddof=1)) if len(h) > 1 else None,
                         "area_mm2": float(np.mean(a)) if a else None, "pasi": sorted(set(k))})
        extra = [(i, q) for i, f in enumerate(frames) for j, q in enumerate(f.get("plaques") or []) if j not in used[i]]
        return rows, extra


def experiment(run):
    """Thesis experiment number of a SLAM run (1-4) from its summary, or None for other recordings."""
    k = run.kind()
    for n in (1, 2, 3, 4):
        if "experiment %d" % n in k:
            return n
    return None


def comparison(runs):
    """Table 7.2 side by side: one dict per SLAM run (None where the run has no such figure)."""
    out = []
    for r in runs:
        f = r.sphere or {}
        tr = r.summary.get("final_covariance_trace") or {}
        out.append({"run": r.name, "what": r.kind(), "radius_mm": f.get("radius_mm"),
                    "radius_error_mm": f["radius_mm"] - TRUE_RADIUS_MM if f else None,
                    "rms_mm": f.get("rms_residual_mm"), "thesis": THESIS.get(experiment(r)),
                    "ate_mm": (r.summary.get("ate") or {}).get("rmse_mm"), "trace_rig": tr.get("rig"),
                    "trace_all": tr.get("all"), "corr_vx_wy": r.summary.get("corr_vx_wy_final")})
    return out


def partial_orbit(run):
    """A note when the run covers less than the dataset's full orbit (the targets are stated for the full loop)."""
    o = (run.truth_yaml or {}).get("orbit") or {}
    if not o.get("rate_rad_s") or not o.get("fps"):
        return ""
    full = 2 * math.pi / o["rate_rad_s"] * o["fps"]
    n = run.summary.get("frames") or 0
    return "%d of the %.0f frames of a full orbit: the targets are stated for the full loop" % (n, full) if n < 0.95 * full else ""


def targets(runs):
    """skin3d's targets for experiments 2-4 on the runs at hand: (target, measured, met, note)."""
    by = {experiment(r): r for r in runs}
    out = []

    def ate(r):
        return (r.summary.get("ate") or {}).get("rmse_mm")

    if 2 in by and by[2].sphere and ate(by[2]) is not None:
        f, a = by[2].sphere, ate(by[2])
        out.append(("experiment 2: radius within 0.03 mm of 200 mm, ATE below 1 mm",
                    "radius %+.4f mm, ATE %.3f mm" % (f["radius_mm"] - TRUE_RADIUS_MM, a),
                    abs(f["radius_mm"] - TRUE_RADIUS_MM) <= 0.03 and a < 1.0, partial_orbit(by[2])))
    if 2 in by and 3 in by and by[2].sphere and by[3].sphere:
        e2, e3 = (abs(by[k].sphere["radius_mm"] - TRUE_RADIUS_MM) for k in (2, 3))
        a2, a3 = ate(by[2]), ate(by[3])
        t2, t3 = ((by[k].summary.get("final_covariance_trace") or {}).get("all") for k in (2, 3))
        if None not in (a2, a3, t2, t3):
            out.append(("experiment 3 better than 2 on radius error, ATE and covariance trace",
                        "radius error %.4f vs %.4f mm, ATE %.3f vs %.3f mm, trace %.3g vs %.3g" % (e3, e2, a3, a2, t3, t2),
                        e3 < e2 and a3 < a2 and t3 < t2, partial_orbit(by[3])))
    if 4 in by and by[4].sphere:
        f = by[4].sphere
        rel = abs(f["radius_mm"] - TRUE_RADIUS_MM) / TRUE_RADIUS_MM
        out.append(("experiment 4: radius within 0.5 %, RMS below 0.5 mm",
                    "radius %+.2f %%, RMS %.3f mm" % (100 * (f["radius_mm"] / TRUE_RADIUS_MM - 1), f["rms_residual_mm"]),
                    rel <= 0.005 and f["rms_residual_mm"] < 0.5, partial_orbit(by[4])))
    return out


def load_run(d, name=None):
    if os.path.exists(os.path.join(d, "induration.yaml")):
        return IndurationRun(d, name)
    if os.path.exists(os.path.join(d, "state.csv")):
        return SlamRun(d, name)
    raise ValueError("'%s' is not a skin3d results directory (no state.csv or induration.yaml)" % d)


# ---------------------------------------------------------------------------------------------------------
# figures (each returns a matplotlib Figure; the caller saves and closes it)

def _sigma(run, rows, idx):
    """3-sigma bounds of error-state variables idx at the trajectory rows (None without rig_covariance.csv): the
    pose's (idx < 6) from smoother_covariance.csv when trajectory.tum is the smoother's."""
    cov = run.pose_cov if run.pose_cov is not None and max(idx) < 6 else run.cov
    if cov is None or len(cov) != len(run.traj):
        return None
    return 3 * np.sqrt(np.maximum(cov[rows][:, idx, idx], 0))


def fig_pose_velocity(run):
    """Thesis Fig. 7.1 for one run: (a) pose, (b) velocities, (c) errors; reference dashed, estimate solid."""
    fig, ax = plt.subplots(3, 2, figsize=(13, 10))
    t0 = run.traj[0, 0] if len(run.traj) else 0.0
    colors = ["tab:red", "tab:green", "tab:blue"]
    pr = run.paired()
    # (a) pose: position (mm) and orientation angles (deg, ZYX, unwrapped)
    te = run.traj[:, 0] - t0
    eul = np.unwrap(np.radians([euler_zyx_deg(quat_to_rot(q)) for q in run.traj[:, 4:8]]), axis=0)
    for i, c in enumerate(colors):
        ax[0, 0].plot(te, 1e3 * run.traj[:, 1 + i], color=c, label="xyz"[i] + " estimate")
        ax[0, 1].plot(te, np.degrees(eul[:, i]), color=c, label=["roll x", "pitch y", "yaw z"][i] + " estimate")
    if len(run.truth):
        tg = run.truth[:, 0] - t0
        eg = np.unwrap(np.radians([euler_zyx_deg(quat_to_rot(q)) for q in run.truth[:, 4:8]]), axis=0)
        for i, c in enumerate(colors):
            ax[0, 0].plot(tg, 1e3 * run.truth[:, 1 + i], "--", color=c, alpha=0.7, label="xyz"[i] + " reference")
            ax[0, 1].plot(tg, np.degrees(eg[:, i]), "--", color=c, alpha=0.7, label="xyz"[i] + " reference")
    ax[0, 0].set(title="(a) position of the rig in the world", ylabel="mm")
    ax[0, 1].set(title="(a) orientation (world ← camera; ZYX angles)", ylabel="deg")
    # (b) velocities in the camera frame
    ts = run.state["t"] - t0
    for i, c in enumerate(colors):
        ax[1, 0].plot(ts, 1e3 * run.state["v" + "xyz"[i]], color=c, label="v" + "xyz"[i] + " estimate")
        ax[1, 1].plot(ts, np.degrees(run.state["w" + "xyz"[i]]), color=c, label="ω" + "xyz"[i] + " estimate")
    ref = run.reference_velocities()
    if ref is not None:
        tr, vr, wr = ref
        for i, c in enumerate(colors):
            ax[1, 0].plot(tr - t0, 1e3 * vr[:, i], "--", color=c, alpha=0.7, label="v" + "xyz"[i] + " reference")
            ax[1, 1].plot(tr - t0, np.degrees(wr[:, i]), "--", color=c, alpha=0.7, label="ω" + "xyz"[i] + " reference")
    ax[1, 0].set(title="(b) linear velocity (camera frame)", ylabel="mm/s")
    ax[1, 1].set(title="(b) angular velocity (camera frame)", ylabel="deg/s")
    # (c) errors with the estimator's 3-sigma bounds (the smoother's when it wrote trajectory.tum)
    if pr:
        tp = np.array([p[0] for p in pr]) - t0
        rows = np.array([p[5] for p in pr])
        ep = np.array([p[3] - p[1] for p in pr]) * 1e3
        eth = np.array([so3_log(p[4] @ p[2].T) for p in pr]) * 1e3
        sp, sth = _sigma(run, rows, [0, 1, 2]), _sigma(run, rows, [3, 4, 5])
        for i, c in enumerate(colors):
            ax[2, 0].plot(tp, ep[:, i], color=c, label="δp" + "xyz"[i])
            ax[2, 1].plot(tp, eth[:, i], color=c, label="δθ" + "xyz"[i])
            if sp is not None:
                ax[2, 0].plot(tp, 1e3 * sp[:, i], ":", color=c, lw=0.8)
                ax[2, 0].plot(tp, -1e3 * sp[:, i], ":", color=c, lw=0.8)
                ax[2, 1].plot(tp, 1e3 * sth[:, i], ":", color=c, lw=0.8)
                ax[2, 1].plot(tp, -1e3 * sth[:, i], ":", color=c, lw=0.8)
        ax[2, 0].set(title="(c) position error (reference − estimate), dotted: ±3σ of the " + ("smoother" if run.pose_cov is not None else "filter"), ylabel="mm")
        ax[2, 1].set(title="(c) orientation error Log(R_ref R_estᵀ), dotted: ±3σ", ylabel="mrad")
    else:
        for a in ax[2]:
            a.text(0.5, 0.5, "no ground truth in this run", ha="center", va="center", transform=a.transAxes)
    for a in ax.flat:
        a.grid(True, alpha=0.3)
        if a.lines:
            a.legend(fontsize=7, ncol=2)
    for a in ax[2]:
        a.set_xlabel("t (s)")
    fig.suptitle("%s — %s (thesis Fig. 7.1)" % (run.name, run.kind()))
    fig.tight_layout()
    return fig


def fig_trace(runs):
    """Thesis Fig. 7.2: trace of the error-state covariance, state / landmarks / all, every run."""
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for run in runs:
        t = run.state["t"] - run.state["t"][0]
        for a, key in zip(ax, ("trace_rig", "trace_landmarks", "trace_all")):
            a.semilogy(t, np.maximum(run.state[key], 1e-15), label=run.name)
    for a, title in zip(ax, ("(a) rig state variables only", "(b) landmarks only (m²)", "(c) whole state vector")):
        a.set(title=title, xlabel="t (s)", ylabel="trace (mixed units)" if a is not ax[1] else "trace (m²)")
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("Trace of the error-state covariance (thesis Fig. 7.2); a loop closure shows as a drop")
    fig.tight_layout()
    return fig


def correlation(P):
    s = np.sqrt(np.maximum(np.diag(P), 1e-300))
    return P / np.outer(s, s)


def fig_correlation(runs, frame=8):
    """Thesis Fig. 7.4: correlation matrix of the rig state at frame `frame` and at the end, per run."""
    runs = [r for r in runs if r.cov is not None and len(r.cov)]
    fig, ax = plt.subplots(len(runs), 2, figsize=(10, 4.3 * len(runs)), squeeze=False, layout="constrained")
    im = None
    for i, run in enumerate(runs):
        for j, k in enumerate((min(frame, len(run.cov) - 1), len(run.cov) - 1)):
            C = correlation(run.cov[k].astype(float))
            n = C.shape[0]
            im = ax[i, j].imshow(C, cmap="RdBu_r", vmin=-1, vmax=1)
            ax[i, j].set_xticks(range(n))
            ax[i, j].set_yticks(range(n))
            ax[i, j].set_xticklabels(RIG_NAMES[:n], fontsize=8)
            ax[i, j].set_yticklabels(RIG_NAMES[:n], fontsize=8)
            ax[i, j].set_title("%s: frame %d (t = %.1f s); corr(vx, ωy) = %+.2f" % (
                run.name, k, run.cov_t[k] - run.cov_t[0], C[6, 10]), fontsize=9)
    if im is not None:
        fig.colorbar(im, ax=ax.ravel().tolist(), shrink=0.6, label="correlation coefficient")
    fig.suptitle("Correlation of the rig's error state (thesis Fig. 7.4: without vs with the gyroscope)")
    return fig


def fig_sphere(run):
    """The map and its robust sphere fit (Table 7.2): residual over the sphere, and their histogram."""
    fig = plt.figure(figsize=(12, 4.8))
    s = run.sphere
    if run.map is None or not s or len(run.map) < 4:
        ax = fig.add_subplot(111)
        ax.text(0.5, 0.5, "no sphere fit in this run", ha="center", va="center")
        ax.axis("off")
        return fig
    c = np.array(s["centre_m"])
    d = run.map - c
    r = np.linalg.norm(d, axis=1)
    res = 1e3 * (r - s["radius_mm"] / 1e3)
    az = np.degrees(np.arctan2(d[:, 0], -d[:, 2]))  # 0: the side that faced the camera at the start
    el = np.degrees(np.arcsin(np.clip(-d[:, 1] / np.maximum(r, 1e-12), -1, 1)))
    lim = max(3 * s["rms_residual_mm"], 1e-3)
    ax = fig.add_subplot(121)
    sc = ax.scatter(az, el, c=res, s=6, cmap="coolwarm", vmin=-lim, vmax=lim)
    fig.colorbar(sc, ax=ax, label="residual (mm)")
    ax.set(title="map on the fitted sphere (radius %.3f mm)" % s["radius_mm"], xlabel="azimuth (deg)",
           ylabel="elevation (deg)")
    ax.grid(True, alpha=0.3)
    ax = fig.add_subplot(122)
    ax.hist(np.clip(res, -5 * lim, 5 * lim), bins=60, color="tab:gray")
    ax.axvline(-s["rms_residual_mm"], color="tab:red", ls=":")
    ax.axvline(s["rms_residual_mm"], color="tab:red", ls=":", label="± RMS over inliers %.4f mm" % s["rms_residual_mm"])
    ax.set(title="residuals (%d inliers of %d points)" % (s["inliers"], s["points"]), xlabel="mm (clipped)",
           ylabel="landmarks")
    ax.legend(fontsize=8)
    fig.suptitle("%s: robust sphere fit of the SLAM map" % run.name)
    fig.tight_layout()
    return fig


def fig_height(run):
    """Height map of the last frame and, with the truth, measured vs true plateau heights (Table 4.2)."""
    rows, _ = run.table()
    fig = plt.figure(figsize=(13, 5))
    hm = os.path.join(run.dir, "height_map.tiff")
    ax = fig.add_subplot(121 if rows else 111)
    img = None
    if os.path.exists(hm):
        try:
            import cv2
            img = cv2.imread(hm, cv2.IMREAD_UNCHANGED)
        except ImportError:
            img = None
    if img is not None:
        v = 1e3 * img.astype(float)
        known = np.isfinite(v)
        if known.any():  # crop to the measured part (with a margin)
            r, c = np.where(known)
            m = 20
            v = v[max(r.min() - m, 0):r.max() + m, max(c.min() - m, 0):c.max() + m]
        hi = np.nanpercentile(v, 99.5) if np.isfinite(v).any() else 1
        im = ax.imshow(v, cmap="viridis", vmin=min(0, np.nanpercentile(v, 0.5)), vmax=hi)
        fig.colorbar(im, ax=ax, label="height above the healthy skin (mm)")
        ax.set(title="height map (last frame; blank: unknown)", xlabel="px", ylabel="px")
    else:
        ax.text(0.5, 0.5, "no height_map.tiff", ha="center", va="center")
    if rows:
        ax = fig.add_subplot(122)
        tr = [r["true_mm"] for r in rows if r["mean_mm"] is not None]
        me = [r["mean_mm"] for r in rows if r["mean_mm"] is not None]
        sd = [r["std_mm"] or 0 for r in rows if r["mean_mm"] is not None]
        top = max(tr + me + [1.0]) * 1.1
        ax.plot([0, top], [0, top], "k:", lw=0.8, label="measured = true")
        for k in range(1, 5):
            ax.axhspan(0.25 * k - 0.125, 0.25 * k + 0.125, color="C%d" % k, alpha=0.07)
        ax.errorbar(tr, me, yerr=sd, fmt="o", capsize=3, label="mean over frames ± std")
        ax.set(title="measured vs true plateau height (Table 4.2); bands: PASImeter classes", xlabel="true (mm)",
               ylabel="measured (mm)", xlim=(0, top), ylim=(0, top))
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("%s: induration" % run.name)
    fig.tight_layout()
    return fig


def main(argv=None):
    """The command (scripts/skin3d_plots.py): argv without the program name; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    out, frame, dirs = None, 8, []
    i = 0
    while i < len(argv):
        if argv[i] == "--out":
            out, i = argv[i + 1], i + 2
        elif argv[i] == "--frame":
            frame, i = int(argv[i + 1]), i + 2
        elif argv[i] in ("-h", "--help"):
            print(__doc__)
            return 0
        else:
            dirs.append(argv[i])
            i += 1
    if not dirs:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        runs = [load_run(d) for d in dirs]
    except (ValueError, OSError) as e:
        print("skin3d_plots: %s" % e, file=sys.stderr)
        return 1

    def save(fig, d, name):
        os.makedirs(d, exist_ok=True)
        path = os.path.join(d, name)
        fig.savefig(path, dpi=90)
        plt.close(fig)
        print("skin3d_plots: wrote %s" % path)

    slam = [r for r in runs if isinstance(r, SlamRun)]
    for r in runs:
        d = out or r.dir
        if isinstance(r, SlamRun):
            save(fig_pose_velocity(r), d, "fig7_1_%s.png" % r.name)
            save(fig_sphere(r), d, "sphere_%s.png" % r.name)
        else:
            save(fig_height(r), d, "height_%s.png" % r.name)
    if slam:
        d = out or slam[0].dir
        save(fig_trace(slam), d, "fig7_2.png")
        if any(r.cov is not None for r in slam):
            save(fig_correlation(slam, frame), d, "fig7_4.png")
    return 0

