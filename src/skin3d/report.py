# SPDX-License-Identifier: BSD-3-Clause
"""One self-contained HTML page (images embedded) for one or more skin3d results directories.

usage: report.py --out REPORT.html [--title TEXT] [--frame K] RESULTS_DIR[=NAME] [RESULTS_DIR[=NAME] ...]

A results directory is what process_bag (SLAM, --induration or --site) or the eskf_slam / induration / site_fusion
nodelets write
(DESIGN.md, "Results of an offline run"). For each run the page shows the dataset (the bag, and its
generator's ground truth when BAG.truth.yaml lies beside it), the figures of merit, the plots of the thesis
(skin3d_plots.py: Fig. 7.1 pose/velocity/error, Fig. 7.2 covariance trace, Fig. 7.4 correlation matrix, the
sphere fit of Table 7.2; the height map and Table 4.2 for the workpiece; for a site scan its plaques, seams,
pairs, the site's height map and coverage, against the sweep's truth when it lies beside the bag) and every parameter of the run
(parameters.yaml). With several SLAM runs, a Table 7.2 comparison with the thesis' figures and skin3d's
targets comes first. Exit status: 0 written, 1 a directory could not be read, 2 bad command line.
"""
import base64
import datetime
import html
import io
import os
import platform
import socket
import subprocess
import sys

import numpy as np

from skin3d import plots as sp

def esc(x):
    return html.escape(str(x))


def png(fig, dpi=80):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    sp.plt.close(fig)
    return '<img src="data:image/png;base64,%s">' % base64.b64encode(buf.getvalue()).decode()


def png_file(path):
    with open(path, "rb") as f:
        return '<img src="data:image/png;base64,%s">' % base64.b64encode(f.read()).decode()


def table(header, rows):
    out = ["<table><tr>%s</tr>" % "".join("<th>%s</th>" % esc(h) for h in header)]
    for r in rows:
        out.append("<tr>%s</tr>" % "".join("<td>%s</td>" % c for c in r))
    out.append("</table>")
    return "\n".join(out)


def fmt(x, f="%.4f"):
    return f % x if isinstance(x, (int, float)) and x == x else "–"


def verdict(ok):
    return '<span class="ok">met</span>' if ok else '<span class="no">not met</span>'


def slam_comparison(runs):
    rows = [[esc(r["run"]), esc(r["what"]), fmt(r["radius_mm"]), fmt(r["radius_error_mm"], "%+.4f"), fmt(r["rms_mm"]),
             "%.3f / %.4f" % r["thesis"] if r["thesis"] else "–", fmt(r["ate_mm"], "%.3f"),
             "%s / %s" % (fmt(r["trace_rig"], "%.3g"), fmt(r["trace_all"], "%.3g")), fmt(r["corr_vx_wy"], "%+.3f")]
            for r in sp.comparison(runs)]
    return table(["run", "what", "radius (mm)", "radius − 200 (mm)", "RMS residual (mm)", "thesis radius / RMS",
                  "ATE RMSE (mm)", "final trace rig / all", "corr(vx, ωy)"], rows)


def dataset_html(truth, bag):
    if not truth:
        return "<p>Dataset: <code>%s</code> (no ground truth beside it).</p>" % esc(bag)
    keys = [k for k in ("kind", "seed", "frames", "config") if k in truth]
    facts = ", ".join("%s: %s" % (k, esc(truth[k])) for k in keys)
    extra = []
    if "sphere" in truth:
        extra.append("sphere radius %.1f mm" % (1e3 * truth["sphere"]["radius_m"]))
    if "plateaus" in truth:
        extra.append("%d plateaus of %s mm" % (len(truth["plateaus"]),
                                               ", ".join("%.2f" % p["height_mm"] for p in truth["plateaus"])))
    real = truth.get("realism")
    if isinstance(real, dict):
        if real.get("ideal"):
            extra.append("ideal images (realism off)")
        else:
            bits = []
            left = real.get("left") or {}
            if left:
                bits.append("blur %.1f px, read noise %.1f DN, vignetting %.2f" % (
                    left.get("blur_sigma_px", 0), left.get("read_noise_dn", 0), left.get("vignetting", 0)))
            if (real.get("right") or {}).get("gain", 1) != 1:
                bits.append("photometric left/right differences")
            if (real.get("calibration_error") or {}).get("enabled"):
                bits.append("perturbed calibration in camera_info")
            extra.append("realism on: " + ", ".join(bits))
    return "<p>Dataset: <code>%s</code> — simulated, %s%s. Ground truth from the generator (%s).</p>" % (
        esc(bag), facts, "; " + "; ".join(extra) if extra else "", esc(os.path.basename(bag[:-4] + ".truth.yaml")))


def parameters_html(run):
    p = run.parameters
    if not p:
        return "<p class='dim'>No parameters.yaml in this results directory (written by process_bag).</p>"
    rows = [[esc(k), "<code>%s</code>" % esc(str(v).lower() if isinstance(v, bool) else v)]
            for k, v in (p.get("parameters") or {}).items()]
    return ("<details><summary>parameters (%d) and command line</summary><p><code>%s</code></p>%s</details>" %
            (len(rows), esc(p.get("command", "")), table(["key", "value"], rows)))


def slam_section(run, frame):
    s = run.summary
    f = run.sphere or {}
    ate = s.get("ate") or {}
    tr = s.get("final_covariance_trace") or {}
    merit = [
        ["frames", esc(s.get("frames")), "dropped: %s" % esc(s.get("frames_dropped", "–"))],
        ["landmarks in the map / ever seen", "%s / %s" % (esc(s.get("landmarks_in_map")), esc(s.get("landmarks_ever_seen"))), ""],
        ["ATE RMSE / max / final (mm)", "%s / %s / %s" % (fmt(ate.get("rmse_mm"), "%.3f"), fmt(ate.get("max_mm"), "%.3f"),
                                                         fmt(ate.get("final_mm"), "%.3f")),
         "alignment: %s" % esc(ate.get("alignment", "none"))],
        ["ATE RMSE, SE(3)-aligned (mm)", fmt((s.get("ate_se3") or {}).get("rmse_mm"), "%.3f"), "as evo_ape --align"],
        ["rotation RMSE (mrad)", fmt(ate.get("rotation_rmse_mrad"), "%.3f"), ""],
        ["sphere radius (mm)", fmt(f.get("radius_mm")), "± %s (1σ of the fit)" % fmt(f.get("radius_std_mm"))],
        ["sphere RMS residual (mm)", fmt(f.get("rms_residual_mm")), "%s inliers of %s" % (f.get("inliers", "–"), f.get("points", "–"))],
        ["final covariance trace: rig / landmarks / all", "%s / %s / %s" % (
            fmt(tr.get("rig"), "%.3g"), fmt(tr.get("landmarks_m2"), "%.3g"), fmt(tr.get("all"), "%.3g")), ""],
        ["corr(vx, ωy) at the end", fmt(s.get("corr_vx_wy_final"), "%+.3f"), ""],
        ["SLAM time per frame (ms)", fmt(s.get("slam_ms_per_frame"), "%.1f"), "gyro: %s, front end: %s" % (
            esc(str(s.get("gyro")).lower()), esc(s.get("front_end")))],
    ]
    parts = ["<h2>%s — %s</h2>" % (esc(run.name), esc(run.kind())),
             "<p class='dim'>%s</p>" % esc(os.path.abspath(run.dir)),
             dataset_html(run.truth_yaml, str(s.get("bag", "?"))),
             table(["figure of merit", "value", "note"], merit),
             "<h3>Pose, velocities and errors (thesis Fig. 7.1)</h3>", png(sp.fig_pose_velocity(run)),
             "<h3>Covariance trace (Fig. 7.2) and correlation (Fig. 7.4)</h3>", png(sp.fig_trace([run])),
             png(sp.fig_correlation([run], frame)) if run.cov is not None else "",
             "<h3>Sphere fit of the map (Table 7.2)</h3>", png(sp.fig_sphere(run)),
             parameters_html(run)]
    return "\n".join(parts)


def induration_section(run):
    res = run.result
    frames = res.get("frames") or []
    parts = ["<h2>%s — induration (plaque heights)</h2>" % esc(run.name),
             "<p class='dim'>%s</p>" % esc(os.path.abspath(run.dir)),
             dataset_html(run.truth_yaml, str(res.get("source", "?")))]
    rows, extra = run.table()
    if rows:
        t = []
        for r in rows:
            if r["mean_mm"] is None:
                t.append(["%.2f" % r["true_mm"], "not found", "", "", "(%.0f)" % r["true_area_mm2"], ""])
                continue
            t.append(["%.2f" % r["true_mm"], "%.4f" % r["mean_mm"], "%+.4f" % (r["mean_mm"] - r["true_mm"]),
                      fmt(r["std_mm"]), "%.1f (%.0f, %+.1f %%)" % (r["area_mm2"], r["true_area_mm2"],
                                                                100 * (r["area_mm2"] / r["true_area_mm2"] - 1)),
                      "/".join(str(k) for k in r["pasi"])])
        parts.append("<h3>True vs measured plateau heights (thesis Table 4.2), %d frame(s)</h3>" % len(frames))
        parts.append(table(["true height (mm)", "measured (mean over frames)", "error (mm)", "std over frames (mm)",
                            "area mm² (true, error)", "PASI class"], t))
        if extra:
            parts.append("<p>%d detection(s) in all frames match no plateau: %s</p>" % (len(extra), "; ".join(
                "frame %d: %.3f mm, %.1f mm²" % (i, q["mean_height_mm"], q["area_mm2"]) for i, q in extra[:10])))
        else:
            parts.append("<p>No detection outside the true plateaus.</p>")
    if frames:
        last = frames[-1]
        t = [[esc(p.get("id")), "%.1f %.1f %.1f" % tuple(1e3 * np.array(p["centroid_m"])), fmt(p.get("area_mm2"), "%.1f"),
              fmt(p.get("top_height_mm")), fmt(p.get("top_height_sigma_mm")), fmt(p.get("mean_height_mm")),
              fmt(p.get("max_height_mm")), fmt(p.get("std_height_mm")),
              esc(p.get("pasi_class"))] for p in last.get("plaques") or []]
        ref = last.get("reference") or {}
        parts.append("<h3>Last frame: %d plaque(s); reference %s, RMS %s mm over %s points; %.1f %% matched</h3>" % (
            len(t), esc(ref.get("model", "?")), fmt(ref.get("rms_mm")), esc(ref.get("points", "?")),
            100 * float(last.get("valid_fraction", 0))))
        parts.append(table(["plaque", "centroid x y z (mm)", "area (mm²)", "top (mm)", "top σ (mm)", "mean (mm)", "max (mm)",
                            "std (mm)", "PASI"], t))
        w = last.get("warnings") or []
        if w:
            parts.append("<details><summary>%d warning(s)</summary><ul>%s</ul></details>" % (
                len(w), "".join("<li>%s</li>" % esc(x) for x in w)))
    rep = (res.get("repeatability") or {}).get("plaques") if isinstance(res.get("repeatability"), dict) else None
    if rep:
        def ms(r, k):
            v = r.get(k) or {}
            return fmt(v.get("mean")), fmt(v.get("std"))
        t = [[esc(r.get("id")), esc(r.get("frames_found")), *ms(r, "mean_height_mm"), *ms(r, "area_mm2"),
              fmt((r.get("mean_height_sigma_mm") or {}).get("mean"))] for r in rep]
        parts.append("<h3>Repeatability over %s frames (each plaque of frame 0 matched in every frame)</h3>" %
                     esc(res["repeatability"].get("frames")))
        parts.append(table(["plaque", "frames found", "mean height (mm)", "std over frames (mm)", "area (mm²)",
                            "area std", "predicted σ of the mean height (mm)"], t))
    hm = os.path.join(run.dir, "height_map.png")
    if os.path.exists(hm):
        parts.append("<h3>Height map (false colour, scale bar)</h3>" + png_file(hm))
    parts.append(png(sp.fig_height(run)))
    parts.append(parameters_html(run))
    return "\n".join(parts)


def site_section(run):
    """The site scan of a results directory with site.yaml (process_bag --site, the site_fusion nodelet)."""
    site = sp.load_yaml(os.path.join(run.dir, "site.yaml")) or {}
    surf, ref, seams = site.get("surface") or {}, site.get("reference") or {}, site.get("seams") or {}
    parts = ["<h2>%s — site scan (%s pairs fused, %s left out)</h2>" % (
        esc(run.name), esc(site.get("frames_fused")), esc(site.get("frames_left_out"))),
        "<p>Body surface: %s (radius %s mm), cells of %s µm, %s mm² fused. Body model: %s, healthy skin's scatter "
        "about it %s µm; the unrolled map's detection threshold %s mm. Seams between the pairs: %s µm RMS, %s µm "
        "of it the pairs' noise, rigid part (what a pose error leaves) %s µm. Input: %s.</p>" % (
            esc(surf.get("model")), fmt(surf.get("radius_mm"), "%.1f"), fmt(surf.get("cell_um"), "%.0f"),
            fmt(surf.get("fused_area_mm2"), "%.0f"), esc(ref.get("body_model")), fmt(ref.get("body_scatter_um"), "%.1f"),
            fmt(ref.get("detection_threshold_mm"), "%.3f"), fmt(seams.get("rms_um"), "%.1f"),
            fmt(seams.get("noise_um"), "%.1f"), fmt(seams.get("rigid_um"), "%.1f"), esc(site.get("source")))]
    truth = run.truth_yaml or {}
    true_plaques = truth.get("plaques") if truth.get("sweep") else None

    def truth_of(p):
        """The true plaque nearest the site plaque, within max(3 mm, its radius)."""
        best, best_d = None, None
        for q in true_plaques or []:
            d = np.linalg.norm(np.array(p["centroid_m"]) - np.array(q["centroid_left_m"]))
            if d <= max(3e-3, np.sqrt(q.get("area_mm2", 0) / np.pi) * 1e-3) and (best_d is None or d < best_d):
                best, best_d = q, d
        return best

    rows = []
    for p in site.get("plaques") or []:
        q = truth_of(p)
        row = [esc(p.get("id")), "%.1f %.1f %.1f" % tuple(1e3 * np.array(p["centroid_m"])),
               "%s ± %s" % (fmt(p.get("top_height_mm")), fmt(p.get("top_height_sigma_mm"))), fmt(p.get("mean_height_mm")),
               fmt(p.get("area_mm2"), "%.1f"), fmt(p.get("volume_mm3"), "%.2f"), esc(p.get("pasi")), esc(p.get("views")),
               fmt(p.get("spread_um"), "%.0f"), fmt(p.get("best_incidence_deg"), "%.0f"),
               "%.0f %%" % (100 * float(p.get("measured_share") or 0))]
        if true_plaques is not None:
            row.append("%.3f (%+.1f µm)" % (q["height_mm"], 1e3 * (p["top_height_mm"] - q["height_mm"])) if q else "no true plaque")
        rows.append(row)
    head = ["plaque", "centroid x y z (mm, world)", "top (mm)", "mean (mm)", "area (mm²)", "volume (mm³)", "PASI",
            "views", "spread (µm)", "best incidence (°)", "measured"] + (["true top (error)"] if true_plaques is not None else [])
    parts.append("<h3>Plaques, each measured once on the fused site</h3>" + table(head, rows))
    grazing = site.get("seen_only_at_grazing_angles") or []
    if grazing:
        parts.append("<p>Never seen within 45° (not measured as plaques): %s</p>" % esc("; ".join(
            "%.3f mm at %s mm, best %.0f°" % (g["top_height_mm"], [round(1e3 * x, 1) for x in g["centroid_m"]],
                                              g["best_incidence_deg"]) for g in grazing)))
    if true_plaques is not None:
        found = [q for q in true_plaques if any(truth_of(p) is q for p in site.get("plaques") or [])]
        parts.append("<p>The sweep's truth: %d plaques, %d found.</p>" % (len(true_plaques), len(found)))
    frows = [[esc(f.get("index")), "fused" if f.get("fused") else "left out: " + esc(f.get("left_out")),
              "%.0f %%" % (100 * float(f.get("overlap") or 0)), fmt(f.get("seam_rms_um"), "%.1f"),
              fmt(f.get("seam_rigid_um"), "%.1f"), fmt(f.get("registration_correction_mm"), "%.3f"),
              esc(f.get("plaques_own"))] for f in site.get("frames") or []]
    parts.append("<details><summary>%d pairs</summary>%s</details>" % (len(frows), table(
        ["pair", "", "overlap", "seam RMS (µm)", "rigid part (µm)", "registration moved it (mm)", "its own plaques"], frows)))
    for name, caption in (("site_height_map.png", "The site unrolled: heights above the body (false colour, scale bar)"),
                          ("site_coverage.png", "Coverage: pairs fused per cell")):
        path = os.path.join(run.dir, name)
        if os.path.exists(path):
            parts.append("<h3>%s</h3>%s" % (caption, png_file(path)))
    w = site.get("warnings") or []
    if w:
        parts.append("<details><summary>%d warning(s)</summary><ul>%s</ul></details>" % (
            len(w), "".join("<li>%s</li>" % esc(x) for x in w)))
    return "\n".join(parts)


CSS = """
body { font-family: sans-serif; max-width: 1250px; margin: 1em auto; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; }
th { background: #eee; }
img { max-width: 100%; display: block; margin: 0.5em 0; }
.dim { color: #777; font-size: 0.85em; }
.ok { color: #1a7f37; font-weight: bold; } .no { color: #b42318; font-weight: bold; }
h2 { border-top: 2px solid #444; padding-top: 0.6em; margin-top: 1.5em; }
code { font-size: 0.85em; }
"""


def git_commit():
    try:
        here = os.path.dirname(os.path.abspath(__file__))  # the checkout's commit (none from an install space)
        return subprocess.run(["git", "-C", here, "describe", "--always", "--dirty"], capture_output=True, text=True,
                              timeout=5).stdout.strip() or "?"
    except (OSError, subprocess.SubprocessError):
        return "?"


def cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def main(argv=None):
    """The command (scripts/report.py): argv without the program name; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    out, title, frame, dirs = None, "skin3d report", 8, []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--out", "--title", "--frame"):
            if i + 1 >= len(argv):
                print("report: %s needs a value" % a, file=sys.stderr)
                return 2
            v = argv[i + 1]
            if a == "--out":
                out = v
            elif a == "--title":
                title = v
            else:
                frame = int(v)
            i += 2
        elif a in ("-h", "--help"):
            print(__doc__)
            return 0
        else:
            dirs.append(a)
            i += 1
    if not out or not dirs:
        print(__doc__, file=sys.stderr)
        return 2
    runs = []
    for d in dirs:
        path, _, name = d.partition("=")
        try:
            runs.append(sp.load_run(path, name or None))
        except (ValueError, OSError, KeyError, IndexError) as e:
            print("report: cannot read '%s': %s" % (path, e), file=sys.stderr)
            return 1
    slam = [r for r in runs if isinstance(r, sp.SlamRun)]
    body = ["<h1>%s</h1>" % esc(title),
            "<p class='dim'>%s · %s (%s, %d cores) · skin3d %s · %s</p>" % (
                datetime.datetime.now().strftime("%Y-%m-%d %H:%M"), esc(socket.gethostname()), esc(cpu_name()),
                os.cpu_count() or 0, esc(git_commit()), esc(" ".join(["report.py"] + argv)))]
    if len(slam) > 1:
        body.append("<h2>SLAM experiments (thesis Tables 7.1 / 7.2)</h2>")
        body.append(slam_comparison(slam))
        tg = sp.targets(slam)
        if tg:
            body.append(table(["target", "measured", ""],
                              [[esc(a), esc(b), verdict(c) + (" (%s)" % esc(n) if n else "")] for a, b, c, n in tg]))
        body.append(png(sp.fig_trace(slam)))
        withcov = [r for r in slam if r.cov is not None and sp.experiment(r) in (2, 3)] or [r for r in slam if r.cov is not None]
        if withcov:
            body.append("<h3>Correlation of the rig state (Fig. 7.4): without vs with the gyroscope</h3>")
            body.append(png(sp.fig_correlation(withcov, frame)))
    for i, r in enumerate(runs):
        print("report: %d/%d %s" % (i + 1, len(runs), r.name), file=sys.stderr)
        if isinstance(r, sp.SlamRun):
            body.append(slam_section(r, frame))
            continue
        if os.path.exists(os.path.join(r.dir, "site.yaml")):
            body.append(site_section(r))
        body.append(induration_section(r))
    page = ("<!DOCTYPE html>\n<html><head><meta charset='utf-8'><title>%s</title><style>%s</style></head><body>\n%s\n"
            "</body></html>\n" % (esc(title), CSS, "\n".join(body)))
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out, "w") as f:
        f.write(page)
    print("report: wrote %s (%.1f MB)" % (out, len(page) / 1e6), file=sys.stderr)
    return 0

