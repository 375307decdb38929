#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Checks scripts/slam_nees.py on synthetic results directories whose truth is known here.

usage: check_nees.py [--xunit FILE.xml]

20 runs x 60 frames: a curved true trajectory, a random correlated 6x6 pose covariance per frame (position and
attitude strongly coupled, as on an orbit), and an estimate whose error true - estimate is drawn from that
covariance (seeded). A consistent filter must be judged consistent; the same errors with the attitude part's
sign flipped (the sign mistake the first version of slam_nees.py made), and a covariance 4x too small, must not;
a directory without ground truth is a clear error (exit 2). With a smoother's files, the smoother's trajectory is
judged with its own covariance and the filter's (--trajectory filter) with the filter's. Runs made in the frame of a miscalibrated rig are
consistent with --calibrated-frame and not without it. The landmarks' radial NEES (--landmarks) reads ~1 for
errors drawn from their covariances and ~4 for covariances 4x too small.
"""
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import run_checks  # noqa: E402

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "slam_nees.py")


def exp_so3(w):
    a = np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if a < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + math.sin(a) / a * K + (1 - math.cos(a)) / a ** 2 * K @ K


def quat(R):
    w = math.sqrt(max(1e-12, 1 + np.trace(R))) / 2
    return np.array([(R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w), w])


def write_run(d, rng, frames, angle_sign=1.0, cov_scale=1.0, frame=None, smoother_scale=None):
    """frame = (Re, te): the filter ran in the frame a calibration defines; the ground truth is written in the
    optical frame (T = E^-1 T' E) and the frame into BAG.truth.yaml beside d, as make_dataset writes it.
    smoother_scale: also a smoother's run, as process_bag writes it with smoother: batch: the filter's estimate in
    trajectory_filter.tum, the smoother's in trajectory.tum with errors drawn from P / 9, and smoother_covariance.csv
    = smoother_scale P / 9."""
    os.makedirs(d)
    smoothed = []
    if frame is not None:
        bag = d + ".bag"
        open(d + "/summary.yaml", "w").write("bag: %s\n" % os.path.basename(bag))
        w = so3_log_np(frame[0])
        open(d + ".truth.yaml", "w").write(
            "realism:\n  calibration_error:\n    measured_frame:\n      rotation_rad: [%r, %r, %r]\n"
            "      translation_m: [%r, %r, %r]\n      scale: 1.0\n" % (tuple(w) + tuple(frame[1])))
    head = "# skin3d trajectory: t x y z qx qy qz qw\n"
    names = ["P_%d_%d" % (i, j) for i in range(12) for j in range(12)]
    with open(d + "/trajectory.tum", "w") as fe, open(d + "/ground_truth.tum", "w") as fg, \
            open(d + "/rig_covariance.csv", "w") as fc:
        fe.write(head)
        fg.write(head)
        fc.write("# synthetic\nt," + ",".join(names) + "\n")
        for k in range(frames):
            t = 1000.0 + 0.1 * k
            ang = 0.2 * 0.1 * k
            p = np.array([0.2 * math.sin(ang), 0.0, 0.2 * (1 - math.cos(ang))])
            R = exp_so3(np.array([0.0, -ang, 0.0]))
            # correlated pose covariance: position error ~ lever arm x attitude error + small independent parts
            A = np.zeros((6, 6))
            A[3:, 3:] = np.diag(rng.uniform(0.5e-3, 2e-3, 3))
            lever = np.array([0.0, 0.0, 0.2])
            A[:3, 3:] = -np.array([[0, -lever[2], lever[1]], [lever[2], 0, -lever[0]], [-lever[1], lever[0], 0]]) @ A[3:, 3:]
            A[:3, :3] = np.diag(rng.uniform(0.05e-3, 0.1e-3, 3))
            P = A @ A.T
            e = np.linalg.cholesky(P) @ rng.standard_normal(6)  # true - estimate
            pe = p - e[:3]
            Re = exp_so3(-angle_sign * e[3:]) @ R  # R_true = Exp(dtheta) R_est
            if frame is not None:  # the optical frame's truth: R = Re^T R' Re, p = Re^T (p' + R' te - te)
                Rf, tf = frame
                p, R = Rf.T @ (p + R @ tf - tf), Rf.T @ R @ Rf
            fg.write("%.9f %s %s\n" % (t, " ".join("%.12g" % v for v in p), " ".join("%.12g" % v for v in quat(R))))
            fe.write("%.9f %s %s\n" % (t, " ".join("%.12g" % v for v in pe), " ".join("%.12g" % v for v in quat(Re))))
            full = np.zeros((12, 12))
            full[:6, :6] = cov_scale * P
            full[6:, 6:] = np.eye(6) * 1e-4
            fc.write("%.9f," % t + ",".join("%.17g" % v for v in full.ravel()) + "\n")
            if smoother_scale is not None:
                es = np.linalg.cholesky(P / 9.0) @ rng.standard_normal(6)
                smoothed.append((t, p - es[:3], exp_so3(-es[3:]) @ R, smoother_scale * P / 9.0))
    if smoother_scale is not None:
        os.rename(d + "/trajectory.tum", d + "/trajectory_filter.tum")
        with open(d + "/trajectory.tum", "w") as fe, open(d + "/smoother_covariance.csv", "w") as fc:
            fe.write(head)
            fc.write("# synthetic\nt," + ",".join("P_%d_%d" % (i, j) for i in range(6) for j in range(6)) + "\n")
            for t, ps, Rs, Ps in smoothed:
                fe.write("%.9f %s %s\n" % (t, " ".join("%.12g" % v for v in ps), " ".join("%.12g" % v for v in quat(Rs))))
                fc.write("%.9f," % t + ",".join("%.17g" % v for v in Ps.ravel()) + "\n")


def so3_log_np(R):
    c = max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0)))
    a = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return 0.5 * v if a < 1e-9 else a / (2.0 * math.sin(a)) * v


def run_script(dirs, extra=()):
    r = subprocess.run([sys.executable, SCRIPT] + list(extra) + dirs, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                       universal_newlines=True)
    return r.returncode, r.stdout


def inside_share(text):
    for line in text.splitlines():
        if line.startswith("frames inside:"):
            return float(line.split()[2])
    return -1.0


def checks(tmp):
    results = []
    rng = np.random.default_rng(7)
    for name, sign, scale in (("consistent", 1.0, 1.0), ("angle_sign_flipped", -1.0, 1.0),
                              ("overconfident_4x", 1.0, 0.25)):
        dirs = []
        for i in range(20):
            d = os.path.join(tmp, "%s_%02d" % (name, i))
            write_run(d, rng, 60, sign, scale)
            dirs.append(d)
        rc, text = run_script(dirs)
        share = inside_share(text)
        if name == "consistent":
            ok = rc == 0 and share >= 90.0
        else:
            ok = rc == 1 and share < 50.0
        results.append((name, "" if ok else "exit %d, %.1f %% inside:\n%s" % (rc, share, text)))
        print("check_nees: %s: exit %d, %.1f %% of frames inside" % (name, rc, share))
    # Runs with a smoother: its trajectory with its own covariance by default, the filter's with --trajectory filter.
    # Consistent smoother covariances read consistent; 4x too small read inconsistent while the filter's, untouched,
    # still read consistent (so the script pairs each trajectory with its own covariance).
    for name, scale in (("smoother_consistent", 1.0), ("smoother_overconfident_4x", 0.25)):
        dirs = []
        for i in range(20):
            d = os.path.join(tmp, "%s_%02d" % (name, i))
            write_run(d, rng, 60, smoother_scale=scale)
            dirs.append(d)
        rc_s, text_s = run_script(dirs)
        rc_f, text_f = run_script(dirs, ["--trajectory", "filter"])
        ok = rc_f == 0 and inside_share(text_f) >= 90.0 and (
            (rc_s == 0 and inside_share(text_s) >= 90.0) if scale == 1.0 else (rc_s == 1 and inside_share(text_s) < 50.0))
        results.append((name, "" if ok else "smoother: exit %d\n%s\nfilter: exit %d\n%s" % (rc_s, text_s, rc_f, text_f)))
        print("check_nees: %s: %.1f %% inside (smoother), %.1f %% (--trajectory filter)"
              % (name, inside_share(text_s), inside_share(text_f)))
    # A run in the frame of a calibration 10 mrad and 1 mm off the optical one: consistent there, so consistent
    # with --calibrated-frame and not without it; a missing truth.yaml is a clear error.
    E = (exp_so3(np.array([0.006, -0.008, 0.002])), np.array([0.0004, -0.0003, 0.0009]))
    dirs = []
    for i in range(20):
        d = os.path.join(tmp, "calibrated_%02d" % i)
        write_run(d, rng, 60, frame=E)
        dirs.append(d)
    rc_f, text_f = run_script(dirs, ["--calibrated-frame"])
    rc_o, text_o = run_script(dirs)
    ok = rc_f == 0 and inside_share(text_f) >= 90.0 and rc_o == 1
    results.append(("calibrated_frame", "" if ok else "with: exit %d\n%s\nwithout: exit %d\n%s"
                    % (rc_f, text_f, rc_o, text_o)))
    print("check_nees: calibrated_frame: %.1f %% inside with --calibrated-frame, %.1f %% without"
          % (inside_share(text_f), inside_share(text_o)))
    os.remove(dirs[0] + ".truth.yaml")
    rc, text = run_script(dirs, ["--calibrated-frame"])
    ok = rc == 2 and "truth" in text and "calibrated_00" in text
    results.append(("calibrated_frame_without_truth", "" if ok else "exit %d: %s" % (rc, text)))
    # Landmarks on the true sphere (in the calibrated frame) with errors drawn from their covariances: the radial
    # NEES must average ~1; covariances 4x too small must read ~4.
    for name, scale, lo, hi in (("landmarks_consistent", 1.0, 0.85, 1.15), ("landmarks_overconfident_4x", 0.25, 3.4, 4.6)):
        dirs = []
        for i in range(5):
            d = os.path.join(tmp, "%s_%02d" % (name, i))
            write_run(d, rng, 10, frame=E)
            open(d + ".truth.yaml", "a").write("sphere:\n  centre_world_m: [0, 0, 0.6]\n  radius_m: 0.2\n")
            c = E[0] @ np.array([0.0, 0.0, 0.6]) + E[1]
            with open(d + "/map_covariance.csv", "w") as f:
                f.write("# synthetic\nid,x,y,z,c_xx,c_xy,c_xz,c_yy,c_yz,c_zz,observations\n")
                for j in range(300):
                    n = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), -1.0])
                    n /= np.linalg.norm(n)
                    A = rng.standard_normal((3, 3)) * 1e-4
                    C = A @ A.T + np.eye(3) * 1e-10
                    m = c + 0.2 * n + np.linalg.cholesky(C) @ rng.standard_normal(3)
                    Cw = scale * C
                    f.write("%d,%r,%r,%r,%r,%r,%r,%r,%r,%r,5\n" % (j, m[0], m[1], m[2], Cw[0, 0], Cw[0, 1], Cw[0, 2],
                                                                  Cw[1, 1], Cw[1, 2], Cw[2, 2]))
            dirs.append(d)
        rc, text = run_script(dirs, ["--calibrated-frame", "--landmarks"])
        mean = -1.0
        for line in text.splitlines():
            if line.startswith("landmarks (final maps"):
                mean = float(line.split("mean NEES ")[1].split()[0])
        ok = lo <= mean <= hi
        results.append((name, "" if ok else "mean %.2f not in [%.2f, %.2f]:\n%s" % (mean, lo, hi, text)))
        print("check_nees: %s: landmark mean NEES %.2f" % (name, mean))
    bad = os.path.join(tmp, "no_truth")
    os.makedirs(bad)
    open(bad + "/trajectory.tum", "w").write("1000 0 0 0 0 0 0 1\n")
    rc, text = run_script([bad])
    ok = rc == 2 and "ground_truth.tum" in text
    results.append(("missing_ground_truth", "" if ok else "exit %d: %s" % (rc, text)))
    return results


if __name__ == "__main__":
    sys.exit(run_checks("nees", __doc__, checks))
