#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Absolute trajectory error of two TUM trajectories, as the TUM RGB-D benchmark tools and evo compute it.

usage: tum_ate.py ESTIMATE.tum REFERENCE.tum [--max-diff S] [--offset S] [--align se3|none] [--yaml]

An independent check of skin3d's summary.yaml (and a stand-in for `evo_ape tum REF EST --align` where evo is
not installed): it shares no code with skin3d. Both files are `t x y z qx qy qz qw` per line ('#' comments).
- Association by time, as the benchmark's associate.py: every (estimate, reference) pair whose stamps differ by
  less than --max-diff (default 0.01 s, evo's default) is a candidate; candidates are taken greedily from the
  smallest difference, each pose used at most once. No interpolation.
- Alignment: se3 (default) = the rigid motion that best fits the paired reference positions onto the estimate's
  (Horn / Umeyama, no scale; as evaluate_ate.py and evo_ape --align); none = as given.
- Prints the pairs, RMSE, mean, median, max (mm) and, with --yaml, one YAML map on stdout instead.
Exit status 1 when a file cannot be read or nothing pairs.
"""
import argparse
import sys

import numpy as np


def read_tum(path):
    stamps, rows = [], []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = line.replace(",", " ").split()
            if len(parts) != 8:
                raise ValueError("%s line %d: expected 8 numbers (t x y z qx qy qz qw), got %d" % (path, n, len(parts)))
            stamps.append(parts[0])
            rows.append([float(v) for v in parts[1:]])
    return stamps, np.array(rows, dtype=float).reshape(-1, 7)


def to_seconds(stamp_texts):
    # keep the full precision of long epoch stamps: whole seconds and fraction apart
    out = []
    for s in stamp_texts:
        whole, _, frac = s.partition(".")
        out.append((int(whole), float("0." + frac) if frac else 0.0))
    return out


def associate(t_est, t_ref, max_diff, offset):
    base = min([w for w, _ in t_est] + [w for w, _ in t_ref])
    a = np.array([(w - base) + f for w, f in t_est])
    b = np.array([(w - base) + f for w, f in t_ref]) + offset
    candidates = []
    for i, ta in enumerate(a):
        lo, hi = np.searchsorted(b, ta - max_diff), np.searchsorted(b, ta + max_diff, side="right")
        for j in range(lo, hi):
            d = abs(ta - b[j])
            if d < max_diff:
                candidates.append((d, i, j))
    candidates.sort()
    used_a, used_b, pairs = set(), set(), []
    for d, i, j in candidates:
        if i in used_a or j in used_b:
            continue
        used_a.add(i)
        used_b.add(j)
        pairs.append((i, j))
    pairs.sort()
    return pairs


def align_se3(ref, est):
    """R, t minimising sum |est - (R ref + t)|^2 (Horn 1987 / Umeyama 1991, no scale)."""
    mu_r, mu_e = ref.mean(axis=0), est.mean(axis=0)
    H = (ref - mu_r).T @ (est - mu_e)
    U, _, Vt = np.linalg.svd(H)
    S = np.eye(3)
    if np.linalg.det(Vt.T @ U.T) < 0:
        S[2, 2] = -1.0
    R = Vt.T @ S @ U.T
    return R, mu_e - R @ mu_r


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("estimate")
    ap.add_argument("reference")
    ap.add_argument("--max-diff", type=float, default=0.01)
    ap.add_argument("--offset", type=float, default=0.0, help="added to the reference stamps, s")
    ap.add_argument("--align", choices=["se3", "none"], default="se3")
    ap.add_argument("--yaml", action="store_true")
    a = ap.parse_args()
    try:
        s_est, est = read_tum(a.estimate)
        s_ref, ref = read_tum(a.reference)
    except (OSError, ValueError) as e:
        print("tum_ate: %s" % e, file=sys.stderr)
        return 1
    if len(s_ref) and sorted(s_ref, key=float) != s_ref:
        order = np.argsort([float(s) for s in s_ref], kind="stable")
        s_ref, ref = [s_ref[i] for i in order], ref[order]
    pairs = associate(to_seconds(s_est), to_seconds(s_ref), a.max_diff, a.offset)
    if not pairs:
        print("tum_ate: no pose pairs within %.4f s" % a.max_diff, file=sys.stderr)
        return 1
    P = est[[i for i, _ in pairs], :3]
    Q = ref[[j for _, j in pairs], :3]
    if a.align == "se3" and len(pairs) >= 3:
        R, t = align_se3(Q, P)
        Q = Q @ R.T + t
    err = np.linalg.norm(P - Q, axis=1)
    figures = {"pairs": len(pairs), "unique_estimate_stamps": len(set(s_est)), "estimate_poses": len(s_est),
               "rmse_mm": float(1e3 * np.sqrt(np.mean(err ** 2))), "mean_mm": float(1e3 * err.mean()),
               "median_mm": float(1e3 * np.median(err)), "max_mm": float(1e3 * err.max()), "alignment": a.align,
               "max_diff_s": a.max_diff}
    if a.yaml:
        for k, v in figures.items():
            print("%s: %s" % (k, v))
    else:
        print("pairs %d of %d estimate poses (%d unique stamps), alignment %s" %
              (len(pairs), len(s_est), len(set(s_est)), a.align))
        print("ATE: RMSE %.4f mm, mean %.4f, median %.4f, max %.4f mm" %
              (figures["rmse_mm"], figures["mean_mm"], figures["median_mm"], figures["max_mm"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
