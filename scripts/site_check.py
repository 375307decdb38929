#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""A site scan against its truth: a sweep made by `make_dataset skin` with skin.sweep, measured by
`process_bag --site`.

Usage: site_check.py SWEEP.bag RESULTS_DIR [--json FILE]
  SWEEP.bag    reads SWEEP.truth.yaml and SWEEP.visible.png (the coverage truth) beside it
  RESULTS_DIR  reads site.yaml, site_surface.ply and induration.yaml (the first frame's own plaques)
Prints per true plaque: its top height, how the sweep saw it (the first frame's incidence, the best), the site
plaque matched to it (nearest centroid within max(3 mm, its radius)) with the error of its top height, its PASI
class, area (against the truth's area at half height: the outline is drawn there) and volume; the first frame's own
measurement of it; then duplicates and false plaques (site plaques no true plaque claims), the coverage of the skin
some frame sees within 45 deg in both cameras, the seams, and how far each fused pair was placed from its true
pose (the truth's sweep.poses_world_left; position of the pair's camera and of the skin it looks at, 250 mm
ahead, and the rotation). --json writes the same figures for scripts.
"""
import json
import math
import os
import sys

import cv2
import numpy as np
import yaml


def read_ply(path):
    with open(path, "rb") as f:
        n = 0
        while True:
            line = f.readline().decode("ascii").strip()
            if line.startswith("element vertex"):
                n = int(line.split()[2])
            if line == "end_header":
                break
        dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("h", "<f4"), ("s", "<f4"), ("n", "u1")])
        return np.frombuffer(f.read(n * dt.itemsize), dtype=dt, count=n)


def rotation(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def pose_errors(site, truth):
    """Each fused pair's placement against the truth's pose at its stamp (both world <- left optical frame)."""
    true = {round(p["t"], 3): p for p in (truth.get("sweep") or {}).get("poses_world_left", [])}
    t0 = min((f["stamp"] for f in site.get("frames", [])), default=0.0)
    cam, skin, rot = [], [], []
    for f in site.get("frames", []):
        p = true.get(round(f["stamp"] - t0, 3))
        if not f.get("fused") or p is None or "translation_m" not in f:
            continue
        R, Rt = rotation(f["quaternion_wxyz"]), rotation(p["quaternion_wxyz"])
        t, tt = np.array(f["translation_m"]), np.array(p["translation_m"])
        ahead = np.array([0, 0, 0.25])
        cam.append(np.linalg.norm(t - tt))
        skin.append(np.linalg.norm(R @ ahead + t - (Rt @ ahead + tt)))
        c = np.clip((np.trace(R @ Rt.T) - 1) / 2, -1, 1)
        rot.append(math.acos(c))
    if not cam:
        return None
    ms = lambda v, k: (1e3 * k * math.sqrt(np.mean(np.square(v))), 1e3 * k * max(v))
    (cr, cm), (sr, sm), (rr, rm) = ms(cam, 1), ms(skin, 1), ms(rot, 1)
    return {"pairs": len(cam), "camera_rms_mm": cr, "camera_max_mm": cm, "skin_rms_mm": sr, "skin_max_mm": sm,
            "rotation_rms_mrad": rr, "rotation_max_mrad": rm}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if "-h" in argv or "--help" in argv:
        print(__doc__)
        return 0
    js = None
    if "--json" in argv:
        i = argv.index("--json")
        js = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    stem, out = os.path.splitext(argv[0])[0], argv[1]
    for f in (stem + ".truth.yaml", stem + ".visible.png", out + "/site.yaml", out + "/site_surface.ply"):
        if not os.path.exists(f):
            sys.exit("site_check: no '%s'" % f)
    truth = yaml.safe_load(open(stem + ".truth.yaml"))
    site = yaml.safe_load(open(out + "/site.yaml"))
    if "coverage" not in truth:
        sys.exit("site_check: %s is not a sweep (no coverage truth)" % (stem + ".truth.yaml"))
    seen = {p["id"]: p for p in truth.get("plaques_seen") or []}
    first = []
    if os.path.exists(out + "/induration.yaml"):
        frames = (yaml.safe_load(open(out + "/induration.yaml")) or {}).get("frames") or []
        if frames:
            first = frames[0].get("plaques") or []  # frame 0's left optical frame is `world`
    measured = site.get("plaques") or []
    claimed = {}
    rows = []
    print("| id | true top (mm) | first / best incidence (deg) | site top (mm) | error (um) | PASI true/site | area half-height "
          "true/site (mm²) | area error | volume true/site (mm³) | volume error | views | measured | first frame alone: top, error (um) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    bounds = [0.125, 0.375, 0.625, 0.875]
    for p in truth.get("plaques") or []:
        c = np.array(p["centroid_left_m"])
        reach = max(3e-3, math.sqrt(p["area_mm2"] / math.pi) * 1e-3)
        best, bd = None, 1e9
        for q in measured:
            d = np.linalg.norm(np.array(q["centroid_m"]) - c)
            if d < bd:
                best, bd = q, d
        if best is not None and bd > reach:
            best = None
        if best is not None:
            claimed.setdefault(best["id"], []).append(p["id"])
        f0, fd = None, 1e9
        for q in first:
            d = np.linalg.norm(np.array(q["centroid_m"] if "centroid_m" in q else q.get("centroid_left_m", [9, 9, 9])) - c)
            if d < fd:
                f0, fd = q, d
        if f0 is not None and fd > reach:
            f0 = None
        s = seen.get(p["id"], {})
        t = p["height_mm"]
        pasi = sum(t >= b for b in bounds)
        half = p.get("half_height_area_mm2", float("nan"))
        row = {"id": p["id"], "true_top_mm": t, "first_incidence_deg": s.get("first_frame_incidence_deg"),
               "best_incidence_deg": s.get("best_incidence_deg"), "found": best is not None, "true_pasi": pasi,
               "true_half_height_area_mm2": half, "true_volume_mm3": p.get("volume_mm3")}
        if best is not None:
            row.update({"site_top_mm": best["top_height_mm"], "error_um": 1e3 * (best["top_height_mm"] - t),
                        "pasi": best["pasi"], "area_mm2": best["area_mm2"], "volume_mm3": best["volume_mm3"],
                        "area_error": best["area_mm2"] / half - 1 if half == half else float("nan"),
                        "volume_error": best["volume_mm3"] / p["volume_mm3"] - 1, "views": best["views"],
                        "measured_share": best["measured_share"]})
        if f0 is not None:
            row["first_frame_top_mm"] = f0["top_height_mm"]
            row["first_frame_error_um"] = 1e3 * (f0["top_height_mm"] - t)
        rows.append(row)

        def g(k, fmt, scale=1.0):
            return (fmt % (row[k] * scale)) if k in row and row[k] is not None else "-"
        print("| %d | %.3f | %s / %s | %s | %s | %d/%s | %s / %s | %s | %s / %s | %s | %s | %s | %s, %s |" % (
            p["id"], t, g("first_incidence_deg", "%.0f"), g("best_incidence_deg", "%.0f"), g("site_top_mm", "%.3f"),
            g("error_um", "%+.1f"), pasi, g("pasi", "%d"), "%.1f" % half, g("area_mm2", "%.1f"), g("area_error", "%+.1f %%", 100),
            "%.2f" % p["volume_mm3"], g("volume_mm3", "%.2f"), g("volume_error", "%+.1f %%", 100), g("views", "%d"),
            g("measured_share", "%.0f %%", 100), g("first_frame_top_mm", "%.3f"), g("first_frame_error_um", "%+.1f")))
    grazing = site.get("seen_only_at_grazing_angles") or []
    dup = {k: v for k, v in claimed.items() if len(v) > 1}
    false = [q["id"] for q in measured if q["id"] not in claimed]
    # coverage: truth cells seen within 45 deg in both cameras that have a fused point
    cov = truth["coverage"]
    img = cv2.imread(stem + ".visible.png", cv2.IMREAD_UNCHANGED)
    limb = truth["limb"]
    a, b = [x * 1e-3 for x in limb["semi_axes_mm"]]
    o = np.array(limb["axis_point_left_m"])
    R = np.column_stack([limb["axis_direction_left"], limb["semi_axis_y_direction_left"], limb["semi_axis_z_direction_left"]])
    pts = read_ply(out + "/site_surface.ply")
    X = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(np.float64)
    L = (X - o) @ R  # limb frame
    cell, smax, rm = cov["cell_mm"] * 1e-3, cov["s_max_mm"] * 1e-3, cov["r_mean_mm"] * 1e-3
    phi = np.arctan2(L[:, 1] / a, L[:, 2] / b)
    col = np.floor((L[:, 0] + smax) / cell).astype(int)
    row_ = np.floor((phi * rm + math.pi * rm) / cell).astype(int)
    ok = (col >= 0) & (col < img.shape[1]) & (row_ >= 0) & (row_ < img.shape[0])
    fused = np.zeros(img.shape, bool)
    fused[row_[ok], col[ok]] = True
    want = img > 0
    coverage = float((fused & want).sum()) / max(1, want.sum())
    seams = site.get("seams") or {}
    print("\nplaques: %d true, %d found once, %d missed; duplicates %s; false plaques %s"
          % (len(rows), sum(1 for r in rows if r["found"]) - sum(len(v) - 1 for v in dup.values()),
             sum(1 for r in rows if not r["found"]), dup or "none", false or "none"))
    if grazing:
        print("listed apart (never seen within 45 deg): %s" % ", ".join(
            "%.3f mm at %s mm (best %.0f deg)" % (g["top_height_mm"], [round(1e3 * x, 1) for x in g["centroid_m"]],
                                                 g["best_incidence_deg"]) for g in grazing))
    print("coverage: %.1f %% of the skin some frame sees within %g deg in both cameras has a fused height (%d of %d cells of %g mm)"
          % (100 * coverage, cov["max_incidence_deg"], (fused & want).sum(), want.sum(), cov["cell_mm"]))
    def val(k):
        v = seams.get(k)
        return float("nan") if v is None else v
    print("seams: %.1f um RMS, %.1f um from the noise, %.1f um beyond it, rigid part %.1f um; %s frames fused, %s left out"
          % (val("rms_um"), val("noise_um"), val("beyond_noise_um"), val("rigid_um"), site.get("frames_fused"),
             site.get("frames_left_out")))
    poses = pose_errors(site, truth)
    if poses:
        print("poses: camera placed %.3f mm RMS (max %.3f) from the truth, the skin it looks at %.3f mm RMS (max %.3f), "
              "rotation %.3f mrad RMS (max %.3f), over %d pairs"
              % (poses["camera_rms_mm"], poses["camera_max_mm"], poses["skin_rms_mm"], poses["skin_max_mm"],
                 poses["rotation_rms_mrad"], poses["rotation_max_mrad"], poses["pairs"]))
    if js:
        json.dump({"plaques": rows, "duplicates": {str(k): v for k, v in dup.items()}, "false": false,
                   "coverage": coverage, "seams": seams, "grazing": len(grazing), "poses": poses}, open(js, "w"),
                  indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
