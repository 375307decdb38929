#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""A skin dataset's measurement against its truth: how much of the visible skin got a disparity, and each true
plaque's nearest measured plaque (within 3 mm of its centroid) in the last frame.

Usage: skin_check.py DATASET.bag RESULTS_DIR
  DATASET.bag  made by `make_dataset skin` (reads DATASET.truth.yaml and DATASET.visible.png beside it)
  RESULTS_DIR  of `process_bag --induration` on it (reads induration.yaml and the last frame's disparity.tiff)
Prints the coverage (all co-visible skin, and skin seen at <= 60 deg incidence by both cameras: the working band),
the matched disparities against the true ones (DATASET.disparity.tiff, when the dataset has it) by incidence,
and per plaque: true top and mean height, angle around the limb, incidence in the left / right camera, measured
top height with its stated standard uncertainty, its error and the error over that uncertainty, the measured mean over the interior and over the footprint (volume / area), PASI class
(measured/true), area and measured share; then a summary line over the plaques of
at least 0.1 mm in the working band (the ones the instrument must measure). A plaque not found whose centre lies
where the measurement says the reference does not follow the skin (reference_unfollowed.png: relief, a fold) is
"not found, marked"; the summary counts them.
"""
import os
import sys

import cv2
import numpy as np
import yaml


def marked_pixel(bag_path, out):
    """A test of whether a point (left camera frame, m) projects into reference_unfollowed.png (the bag's left
    CameraInfo: R and P, the rectified camera the measurement used; 10 px around); always False without rosbag, a
    camera_info or the image."""
    unf = cv2.imread(out + "/reference_unfollowed.png", cv2.IMREAD_GRAYSCALE)
    if unf is None:
        return lambda c: False
    try:
        import rosbag
        with rosbag.Bag(bag_path) as bag:
            ci = next((m for t, m, _ in bag.read_messages() if m._type == "sensor_msgs/CameraInfo" and "left" in t), None)
    except Exception:  # no ROS python, or not a bag: no marks
        return lambda c: False
    if ci is None or not ci.width:
        return lambda c: False
    R, P = np.array(ci.R).reshape(3, 3), np.array(ci.P).reshape(3, 4)
    sx, sy = unf.shape[1] / ci.width, unf.shape[0] / ci.height

    def test(c):
        x = P @ np.append(R @ c, 1.0)
        if x[2] <= 0:
            return False
        u, v = int(round(x[0] / x[2] * sx)), int(round(x[1] / x[2] * sy))
        return bool((unf[max(0, v - 10):v + 11, max(0, u - 10):u + 11] > 0).any())
    return test


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if "-h" in argv or "--help" in argv:
        print(__doc__)
        return 0
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    stem = os.path.splitext(argv[0])[0]
    out = argv[1]
    for f in (stem + ".truth.yaml", stem + ".visible.png", out + "/induration.yaml", out + "/disparity.tiff"):
        if not os.path.exists(f):
            sys.exit("skin_check: no '%s'" % f)
    vis = cv2.imread(stem + ".visible.png", cv2.IMREAD_UNCHANGED)
    disp = cv2.imread(out + "/disparity.tiff", cv2.IMREAD_UNCHANGED)
    if vis is None or disp is None or vis.shape != disp.shape:
        sys.exit("skin_check: the visible-skin mask and the disparity map differ in size (same dataset?)")
    m, k = vis > 0, np.isfinite(disp)
    m60 = m & (vis <= 61)
    print("visible skin with a disparity: %.1f %% (seen at <= 60 deg: %.1f %%); known pixels outside it: %d"
          % (100.0 * (k & m).sum() / max(1, m.sum()), 100.0 * (k & m60).sum() / max(1, m60.sum()), (k & ~m).sum()))
    true_disp = cv2.imread(stem + ".disparity.tiff", cv2.IMREAD_UNCHANGED) if os.path.exists(stem + ".disparity.tiff") else None
    if true_disp is not None and true_disp.shape == disp.shape:
        sig = cv2.imread(out + "/disparity_sigma.tiff", cv2.IMREAD_UNCHANGED) if os.path.exists(
            out + "/disparity_sigma.tiff") else None
        parts = []
        for lo, hi in ((0, 30), (30, 45), (45, 60), (60, 90)):
            sel = k & np.isfinite(true_disp) & (vis > lo + (lo > 0)) & (vis <= hi + 1)
            if sel.sum() < 100:
                continue
            e = disp[sel] - true_disp[sel]
            z = e / sig[sel] if sig is not None and sig.shape == disp.shape else None
            parts.append("%d-%d deg: median %+.3f px, robust sigma %.3f px, > 1 px %.1f %%%s" % (
                lo, hi, np.median(e), 1.4826 * np.median(np.abs(e - np.median(e))), 100.0 * (np.abs(e) > 1).mean(),
                ", error / stated sigma: robust sigma %.2f" % (1.4826 * np.median(np.abs(z - np.median(z))))
                if z is not None else ""))
        print("disparity against the truth (matched visible skin, by incidence): " + "; ".join(parts))
    truth = yaml.safe_load(open(stem + ".truth.yaml"))
    frames = (yaml.safe_load(open(out + "/induration.yaml")) or {}).get("frames") or []
    if not frames:
        sys.exit("skin_check: no frame in %s/induration.yaml" % out)
    last = frames[-1]
    measured = last.get("plaques") or []
    ref = last.get("reference") or {}
    print("reference: %s (candidates: %s)" % (ref.get("model"), ", ".join(
        "%s %.4f mm" % (c["model"], c["scale_mm"]) for c in ref.get("candidates") or [])))
    print("| true top (mm) | true mean (mm) | around limb (deg) | incidence L/R (deg) | measured top ± sigma (mm) | error (mm) "
          "| error / sigma | measured mean: interior, footprint (mm) | PASI | area (mm², true) | share |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    right = np.array(truth["rig_true"]["right_centre_in_left_m"])
    marked_at = marked_pixel(argv[0], out)
    required = found = pasi_ok = marked = 0
    worst = worst_z = 0.0
    for p in truth.get("plaques") or []:
        c = np.array(p["centroid_left_m"])
        n = np.array(p["normal_left"])
        inc_l = np.degrees(np.arccos(np.clip(n @ (-c / np.linalg.norm(c)), -1, 1)))
        inc_r = np.degrees(np.arccos(np.clip(n @ ((right - c) / np.linalg.norm(right - c)), -1, 1)))
        req = p["height_mm"] >= 0.1 and max(inc_l, inc_r) <= 60
        required += req
        inc = "%.0f/%.0f%s" % (inc_l, inc_r, "" if max(inc_l, inc_r) <= 60 else " (outside)")
        best = min(measured, key=lambda q: np.linalg.norm(np.array(q["centroid_m"]) - c), default=None)
        if best is None or np.linalg.norm(np.array(best["centroid_m"]) - c) > 3e-3:
            is_marked = marked_at(c)
            marked += req and is_marked
            print("| %.3f | %.3f | %.0f | %s | not found%s | | | | %d | (%.0f) | |" % (
                p["height_mm"], p["mean_height_mm"], p["angle_around_limb_deg"], inc, ", marked" if is_marked else "",
                p["pasi_class"], p["area_mm2"]))
            continue
        top = best.get("top_height_mm", best["mean_height_mm"])  # results before the top height: the mean
        err = top - p["height_mm"]
        sigma = best.get("top_height_sigma_mm")
        z = err / sigma if sigma else float("nan")
        if req:
            found += 1
            worst = max(worst, abs(err))
            worst_z = max(worst_z, abs(z)) if np.isfinite(z) else worst_z
            pasi_ok += best["pasi_class"] == p["pasi_class"]
        print("| %.3f | %.3f | %.0f | %s | %.4f ± %.4f | %+.4f | %+.1f | %.3f, %.3f | %d/%d | %.0f (%.0f) | %.2f |" % (
            p["height_mm"], p["mean_height_mm"], p["angle_around_limb_deg"], inc, top, sigma if sigma else float("nan"),
            err, z, best["mean_height_mm"],
            best.get("volume_mm3", float("nan")) / best["area_mm2"],
            best["pasi_class"], p["pasi_class"], best["area_mm2"], p["area_mm2"], best.get("measured_share", float("nan"))))
    print("measured plaques: %d" % len(measured))
    plaques = truth.get("plaques") or []
    centres = [np.array(p["centroid_left_m"]) for p in plaques]
    # reach of a true plaque: its outline's larger radius plus the ramp
    reach = [1e-3 * (max(p["shape"]["radii_mm"]) + p["shape"]["ramp_mm"]) if "shape" in p else 3e-3 for p in plaques]
    unmatched = [q for q in measured if all(np.linalg.norm(np.array(q["centroid_m"]) - c) > 3e-3 for c in centres)]
    # a region more than 3 mm from every true centroid but on a true plaque: part of that plaque, measured
    partial = [q for q in unmatched
               if any(np.linalg.norm(np.array(q["centroid_m"]) - c) <= r for c, r in zip(centres, reach))]
    extra = [q for q in unmatched if q not in partial]
    describe = lambda q: "\n  %.1f mm², mean %.3f mm, measured share %.2f, box %s" % (
        q["area_mm2"], q["mean_height_mm"], q.get("measured_share", float("nan")), q.get("bbox_px"))
    def host(q):
        return min((np.linalg.norm(np.array(q["centroid_m"]) - c) / r, p["height_mm"])
                   for c, r, p in zip(centres, reach, plaques))[1]
    print("on a true plaque but > 3 mm from its centroid (part of it measured): %d%s" % (
        len(partial), "".join(describe(q) + ", on the %.3f mm plaque" % host(q) for q in partial)))
    print("extra plaques (on no true plaque): %d%s" % (len(extra), "".join(describe(q) for q in extra)))
    # healthy relief (ridges): a reference fitted to the limb cannot follow it; the measurement must say so
    # (follows_skin false, the region in reference_unfollowed.png), and report no plaque on it
    ridges = truth.get("ridges") or []
    on_ridge = 0
    for r in ridges:
        pts = [np.array(r[k]) for k in ("start_left_m", "centre_left_m", "end_left_m")]
        def dist(q):
            x = np.array(q["centroid_m"])
            best = np.inf
            for a, b in zip(pts[:-1], pts[1:]):
                t = np.clip((x - a) @ (b - a) / max((b - a) @ (b - a), 1e-18), 0, 1)
                best = min(best, np.linalg.norm(x - (a + t * (b - a))))
            return best
        near = [q for q in extra if dist(q) <= 3e-3 * r["width_mm"] + 2e-3]
        on_ridge += len(near)
        print("ridge %.2f mm high, %.1f mm wide (sigma), %.0f mm long at %.0f deg around the limb: %d extra plaque(s) on it"
              % (r["height_mm"], r["width_mm"], r["length_mm"], r["angle_around_limb_deg"], len(near)))
    if ridges or not ref.get("follows_skin", True):
        unf = cv2.imread(out + "/reference_unfollowed.png", cv2.IMREAD_GRAYSCALE)
        print("reference follows the skin: %s (unfollowed share of the working band %.1f %%; %s)" % (
            "yes" if ref.get("follows_skin", True) else "no", 100 * ref.get("unfollowed_share", 0.0),
            "reference_unfollowed.png: %d px" % (unf > 0).sum() if unf is not None else "no reference_unfollowed.png"))
    print("plaques >= 0.1 mm in the working band: %d, found %d, worst error %.4f mm, worst error / sigma %.1f, "
          "PASI right %d, extra %d%s%s"
          % (required, found, worst, worst_z, pasi_ok, len(extra), " (%d on a ridge)" % on_ridge if ridges else "",
             ", not found but marked %d" % marked if marked else ""))


if __name__ == "__main__":
    sys.exit(main())
