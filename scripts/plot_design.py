#!/usr/bin/python3
"""Plot the figures of a skin3d stereo design report.

Usage:
    plot_design.py REPORT.yaml --out DIR [--quiet]

Input:
    REPORT.yaml  the ``report.yaml`` written by ``stereo_design`` (lengths in mm,
                 angles in degrees, areas in mm^2).  Rig frame: origin midway
                 between the optical centres, x right, y down, z forward; the
                 working plane is z = stereo.working_distance_mm.

Output (PNG files written into DIR, which is created if missing):
    depth_resolution.png            depth resolution (mm per px of disparity)
                                    vs baseline and vs working distance
                                    (thesis Fig. 3.1)
    fields_of_view.png              both camera footprints and their overlap on
                                    the working plane, plus an x-z view of the
                                    cameras, optical axes and corner rays
    projected_grid.png              the uncertainty grid as each camera sees it,
                                    in pixels (thesis Fig. 3.2b)
    reconstruction_uncertainty.png  magnified 1-sigma uncertainty ellipses of
                                    the reconstructed grid, x-y and x-z views
                                    (thesis Fig. 3.2c)

Unless --quiet is given, one line "wrote DIR/NAME.png" is printed per file.
Exit codes: 0 success, 1 unreadable/invalid report or unwritable output
(one-line message on stderr), 2 bad command line.

Runs with Debian's /usr/bin/python3 and needs only numpy, PyYAML, matplotlib.
"""

import argparse
import math
import os
import sys

import numpy as np
import yaml

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (backend must be chosen first)
from matplotlib import cm, colors  # noqa: E402
from matplotlib.patches import Ellipse, Polygon, Rectangle  # noqa: E402

DPI = 120
PROG = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "plot_design.py"
LEFT_COLOUR = "tab:blue"
RIGHT_COLOUR = "tab:red"
OVERLAP_COLOUR = "tab:green"
ELLIPSE_TARGET = 0.4  # largest magnified ellipse (full major axis) / grid spacing


class ReportError(Exception):
    """A problem with the report file; the message names the file and key."""


# --------------------------------------------------------------------------- #
# Report access
# --------------------------------------------------------------------------- #
class Report:
    """Typed, key-checked access to a parsed report.yaml."""

    def __init__(self, path):
        self.path = path
        try:
            with open(path, "r", encoding="utf-8") as f:
                data = yaml.safe_load(f)
        except OSError as e:
            raise ReportError("%s: cannot read: %s" % (path, e.strerror or e))
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            problem = getattr(e, "problem", None)
            if mark is not None and problem:
                msg = "line %d, column %d: %s" % (mark.line + 1, mark.column + 1, problem)
            else:
                msg = " ".join(str(e).split())
            raise ReportError("%s: cannot parse as YAML: %s" % (path, msg))
        if not isinstance(data, dict):
            raise ReportError("%s: not a stereo design report (top level is not a mapping)" % path)
        self.data = data

    def _fail(self, key, what):
        raise ReportError("%s: key '%s' %s" % (self.path, key, what))

    def get(self, key, node=None, prefix=""):
        """Value at a dotted key, e.g. 'stereo.baseline_mm' (relative to node)."""
        cur = self.data if node is None else node
        walked = prefix
        for part in key.split("."):
            walked = walked + "." + part if walked else part
            if not isinstance(cur, dict) or part not in cur:
                self._fail(walked, "is missing")
            cur = cur[part]
        return cur

    def number(self, key, node=None, prefix=""):
        v = self.get(key, node, prefix)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self._fail(_join(prefix, key), "is not a number: %r" % (v,))
        return float(v)

    def text(self, key):
        return str(self.get(key))

    def vector(self, key, n, node=None, prefix=""):
        v = self.get(key, node, prefix)
        try:
            arr = np.asarray(v, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.size != n:
            self._fail(_join(prefix, key), "is not a list of %d numbers" % n)
        return arr

    def points(self, key, dim=2, node=None, prefix=""):
        """A list of [a, b, ...] rows as an (N, dim) array; empty/null gives (0, dim)."""
        v = self.get(key, node, prefix)
        if v is None or (isinstance(v, list) and not v):
            return np.zeros((0, dim))
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.ndim != 2 or arr.shape[1] != dim:
            self._fail(_join(prefix, key), "is not a list of [%s] rows" % ", ".join(["number"] * dim))
        return arr

    def grid(self):
        """The uncertainty grid as a dict of arrays (N rows each)."""
        raw = self.get("uncertainty.grid")
        if raw is None:
            raw = []
        if not isinstance(raw, list):
            self._fail("uncertainty.grid", "is not a list")
        pts, uvl, uvr, cov, sd = [], [], [], [], []
        for i, g in enumerate(raw):
            pre = "uncertainty.grid[%d]" % i
            if not isinstance(g, dict):
                self._fail(pre, "is not a mapping")
            pts.append(self.vector("point_mm", 3, g, pre))
            uvl.append(self.vector("uv_left", 2, g, pre))
            uvr.append(self.vector("uv_right", 2, g, pre))
            cov.append(self.vector("covariance_mm2", 9, g, pre).reshape(3, 3))
            sd.append(self.number("sigma_depth_mm", g, pre))
        n = len(pts)
        return {
            "point": np.array(pts).reshape(n, 3),
            "uv_left": np.array(uvl).reshape(n, 2),
            "uv_right": np.array(uvr).reshape(n, 2),
            "cov": np.array(cov).reshape(n, 3, 3),
            "sigma_depth": np.array(sd).reshape(n),
        }


def _join(prefix, key):
    return prefix + "." + key if prefix else key


# --------------------------------------------------------------------------- #
# Helpers
# --------------------------------------------------------------------------- #
def rodrigues(rotvec_deg):
    """Rotation matrix from a rotation vector given in degrees."""
    w = np.radians(np.asarray(rotvec_deg, dtype=float))
    theta = np.linalg.norm(w)
    if theta < 1e-12:
        return np.eye(3)
    k = w / theta
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * K + (1.0 - math.cos(theta)) * (K @ K)


def fmt_len(v, unit="mm"):
    """A length for labels; infinite values print as the infinity sign."""
    if math.isinf(v):
        return "∞" if v > 0 else "-∞"
    if math.isnan(v):
        return "n/a"
    return "%.4g %s" % (v, unit) if unit else "%.4g" % v


def nice_floor(x):
    """Largest 'nice' number (1, 2, 2.5, 5 x 10^k) not above x."""
    if not (x > 0 and math.isfinite(x)):
        return 1.0
    exp = math.floor(math.log10(x))
    for m in (5.0, 2.5, 2.0, 1.0):
        if m * 10.0 ** exp <= x * (1 + 1e-9):
            return m * 10.0 ** exp
    return 10.0 ** exp


def finite_rows(a):
    return a[np.all(np.isfinite(a), axis=1)] if a.size else a


def grid_lines(points_xy, values_2d):
    """Polylines joining grid points in the same row (same y) and column (same x).

    points_xy are the rig-frame (x, y) used for grouping; values_2d the
    coordinates to draw (e.g. pixels).  Returns a list of (M, 2) arrays.
    """
    lines = []
    for axis in (0, 1):  # axis 1 -> rows of equal y ordered by x; axis 0 -> columns
        keys = np.round(points_xy[:, axis], 3)
        for k in np.unique(keys):
            idx = np.where(keys == k)[0]
            if idx.size < 2:
                continue
            order = idx[np.argsort(points_xy[idx, 1 - axis])]
            lines.append(values_2d[order])
    return lines


def grid_spacing(points_xy, fallback):
    """Smallest spacing between distinct grid x or y values."""
    gaps = []
    for axis in (0, 1):
        vals = np.unique(np.round(points_xy[:, axis], 3))
        if vals.size > 1:
            gaps.append(np.min(np.diff(vals)))
    gaps = [g for g in gaps if g > 0]
    return min(gaps) if gaps else fallback


def ellipse_params(cov2):
    """(semi-major, semi-minor, angle deg) of the 1-sigma ellipse of a 2x2 covariance."""
    cov2 = 0.5 * (cov2 + cov2.T)
    vals, vecs = np.linalg.eigh(cov2)
    vals = np.clip(vals, 0.0, None)
    major = vecs[:, 1]
    return math.sqrt(vals[1]), math.sqrt(vals[0]), math.degrees(math.atan2(major[1], major[0]))


def no_data(ax, text):
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center",
            fontsize=12, color="0.4", bbox=dict(boxstyle="round", fc="white", ec="0.6"))


def add_polygon(ax, poly, **kw):
    poly = finite_rows(poly)
    if len(poly) >= 3:
        ax.add_patch(Polygon(poly, closed=True, **kw))
        return True
    return False


def save(fig, out_dir, name, quiet):
    path = os.path.join(out_dir, name)
    try:
        fig.savefig(path, dpi=DPI)
    except OSError as e:
        plt.close(fig)
        raise ReportError("%s: cannot write: %s" % (path, e.strerror or e))
    plt.close(fig)
    if not quiet:
        print("wrote %s" % path)


# --------------------------------------------------------------------------- #
# Figure 1: depth resolution (thesis Fig. 3.1)
# --------------------------------------------------------------------------- #
def plot_depth_resolution(rep, out_dir, quiet):
    name = rep.text("name")
    required = rep.number("input.depth_resolution_mm")
    res_now = rep.number("stereo.depth_resolution_mm_per_px")
    baseline = rep.number("stereo.baseline_mm")
    distance = rep.number("stereo.working_distance_mm")
    min_base = rep.number("stereo.min_baseline_at_working_distance_mm")
    optimum = rep.number("stereo.optimum_working_distance_mm")
    near = rep.number("depth_of_field.near_mm")
    far = rep.number("depth_of_field.far_mm")
    vs_base = finite_rows(rep.points("curves.resolution_vs_baseline_mm"))
    vs_dist = finite_rows(rep.points("curves.resolution_vs_distance_mm"))

    fig, (ax_b, ax_d) = plt.subplots(1, 2, figsize=(13, 5.6))
    met = "met" if res_now <= required else "NOT met"
    fig.suptitle("%s\nDepth resolution: %.4g mm/px at b = %.4g mm, Z = %.4g mm "
                 "(required %.4g mm/px: %s)" % (name, res_now, baseline, distance, required, met),
                 fontsize=11)

    def common(ax, curve, label, xvalue, xlabel):
        ax.axhspan(0, required, color=OVERLAP_COLOUR, alpha=0.07, lw=0)
        if len(curve):
            ax.plot(curve[:, 0], curve[:, 1], "-", color="k", lw=1.6, label=label)
        else:
            no_data(ax, "no curve data")
        ax.axhline(required, color=OVERLAP_COLOUR, ls="--", lw=1.4,
                   label="required %.4g mm/px (shaded: met)" % required)
        if math.isfinite(xvalue):
            ax.axvline(xvalue, color=LEFT_COLOUR, ls="-", lw=1.0, alpha=0.8)
            ax.plot([xvalue], [res_now], "o", color=LEFT_COLOUR, ms=7, zorder=5,
                    label="configured %s = %.4g mm → %.4g mm/px" % (xlabel, xvalue, res_now))
        ax.set_ylabel("depth resolution (mm per px of disparity)")
        ax.grid(True, alpha=0.3)
        # Keep the interesting region readable: the curves run off to large values.
        ys = [required, res_now] + ([float(np.max(curve[:, 1]))] if len(curve) else [])
        top = min(max(ys), 3.0 * max(required, res_now))
        ax.set_ylim(0, top * 1.05)
        if len(curve):
            ax.set_xlim(float(np.min(curve[:, 0])), float(np.max(curve[:, 0])))

    common(ax_b, vs_base, "at Z = %.4g mm" % distance, baseline, "baseline")
    if math.isfinite(min_base):
        ax_b.axvline(min_base, color="tab:orange", ls=":", lw=1.6)
        ax_b.plot([min_base], [required], "s", color="tab:orange", ms=7, zorder=5,
                  label="minimum baseline %.4g mm" % min_base)
    ax_b.set_xlabel("baseline b (mm)")
    ax_b.set_title("vs baseline (working distance %.4g mm)" % distance, fontsize=10)
    ax_b.legend(loc="upper right", fontsize=8.5)

    common(ax_d, vs_dist, "at b = %.4g mm" % baseline, distance, "working distance")
    if math.isfinite(near):
        x_hi = ax_d.get_xlim()[1]
        ax_d.axvspan(near, min(far, x_hi), color="0.5", alpha=0.12, lw=0,
                     label="depth of field %s – %s" % (fmt_len(near, ""), fmt_len(far)))
    if math.isfinite(optimum):
        ax_d.axvline(optimum, color="tab:purple", ls=":", lw=1.4,
                     label="optimum working distance %.4g mm" % optimum)
    ax_d.set_xlabel("working distance Z (mm)")
    ax_d.set_title("vs working distance (baseline %.4g mm)" % baseline, fontsize=10)
    ax_d.legend(loc="upper left", fontsize=8.5)

    fig.tight_layout()
    save(fig, out_dir, "depth_resolution.png", quiet)


# --------------------------------------------------------------------------- #
# Figure 2: fields of view on the working plane + x-z view of the rig
# --------------------------------------------------------------------------- #
def plot_fields_of_view(rep, grid, out_dir, quiet):
    name = rep.text("name")
    Z = rep.number("stereo.working_distance_mm")
    cams = {}
    for side in ("left", "right"):
        pre = "cameras." + side
        cams[side] = {
            "centre": rep.vector(pre + ".centre_mm", 3),
            "R": rodrigues(rep.vector(pre + ".rotation_vector_deg", 3)),
            "footprint": finite_rows(rep.points(pre + ".footprint_mm")),
            "area": rep.number(pre + ".footprint_area_mm2"),
        }
    overlap = finite_rows(rep.points("overlap.polygon_mm"))
    ov_area = rep.number("overlap.area_mm2")
    ov_frac = rep.number("overlap.fraction_of_left_view")
    near = rep.number("depth_of_field.near_mm")
    far = rep.number("depth_of_field.far_mm")
    pts = grid["point"]

    # Common x range for both panels.
    xs = [c["centre"][0] for c in cams.values()]
    for c in cams.values():
        xs.extend(c["footprint"][:, 0].tolist())
    ys = [0.0]
    for c in cams.values():
        ys.extend(c["footprint"][:, 1].tolist())
    if len(pts):
        xs.extend(pts[:, 0].tolist())
        ys.extend(pts[:, 1].tolist())
    x_lo, x_hi = min(xs), max(xs)
    pad = 0.06 * max(x_hi - x_lo, 1.0)
    x_lo, x_hi = x_lo - pad, x_hi + pad
    y_lo, y_hi = min(ys), max(ys)
    ypad = 0.06 * max(y_hi - y_lo, 1.0)
    y_lo, y_hi = y_lo - ypad, y_hi + ypad
    z_vals = [c["centre"][2] for c in cams.values()] + [0.0]
    z_lo = min(z_vals) - 0.08 * Z
    z_hi = 1.2 * Z

    # Explicit layout (inches): both panels share the x scale and keep equal aspect.
    ax_w = 7.5
    mm_per_in = (x_hi - x_lo) / ax_w
    min_side_in = 2.6  # room for the side view's legend
    if (z_hi - z_lo) / mm_per_in < min_side_in:
        z_hi = z_lo + min_side_in * mm_per_in
    h_top, h_bot = (y_hi - y_lo) / mm_per_in, (z_hi - z_lo) / mm_per_in
    m_left, m_right, m_top, m_gap, m_bottom = 0.9, 3.9, 1.0, 0.95, 0.6
    fig_w, fig_h = m_left + ax_w + m_right, m_top + h_top + m_gap + h_bot + m_bottom
    fig = plt.figure(figsize=(fig_w, fig_h))
    ax = fig.add_axes([m_left / fig_w, (m_bottom + h_bot + m_gap) / fig_h, ax_w / fig_w, h_top / fig_h])
    ax_s = fig.add_axes([m_left / fig_w, m_bottom / fig_h, ax_w / fig_w, h_bot / fig_h])
    fig.suptitle("%s\nFields of view on the working plane z = %.4g mm" % (name, Z), fontsize=11,
                 y=1.0 - 0.15 / fig_h, va="top")

    # -- plan view on the working plane
    add_polygon(ax, overlap, fc=OVERLAP_COLOUR, ec=OVERLAP_COLOUR, alpha=0.3, lw=1.0,
                label="overlap %.0f mm² = %.1f %% of left view" % (ov_area, 100.0 * ov_frac))
    for side, colour in (("left", LEFT_COLOUR), ("right", RIGHT_COLOUR)):
        c = cams[side]
        if not add_polygon(ax, c["footprint"], fill=False, ec=colour, lw=2.0,
                           label="%s footprint %.0f mm²" % (side, c["area"])):
            ax.plot([], [], color=colour, label="%s footprint: none" % side)
    if len(pts):
        ax.plot(pts[:, 0], pts[:, 1], ".", color="k", ms=5, label="grid points (%d)" % len(pts))
    else:
        ax.text(0.5, 0.04, "no grid points", transform=ax.transAxes, ha="center", color="0.4")
    ax.plot([0], [0], "+", color="0.3", ms=10, label="rig axis (x = y = 0)")
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_hi, y_lo)  # y points down (optical convention)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x, right (mm)")
    ax.set_ylabel("y, down (mm)")
    ax.set_title("working plane seen from the cameras (along +z)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8.5, borderaxespad=0)

    # -- x-z view of the rig (seen from above, i.e. looking along +y)
    ax_s.axhline(Z, color="0.35", lw=1.5, label="working plane z = %.4g mm" % Z)
    dof_labelled = False
    for side, colour in (("left", LEFT_COLOUR), ("right", RIGHT_COLOUR)):
        c = cams[side]
        o = c["centre"]
        axis = c["R"] @ np.array([0.0, 0.0, 1.0])
        for k, corner in enumerate(c["footprint"]):
            ax_s.plot([o[0], corner[0]], [o[2], Z], "-", color=colour, lw=0.7, alpha=0.6,
                      label=("%s corner rays" % side) if k == 0 else None)
        # optical axis up to the working plane (or a fixed length if it misses it)
        t = (Z - o[2]) / axis[2] if axis[2] > 1e-9 else 1.1 * Z
        end = o + t * axis
        ax_s.plot([o[0], end[0]], [o[2], end[2]], "--", color=colour, lw=1.5,
                  label="%s optical axis" % side)
        if math.isfinite(near):
            t_far = far if math.isfinite(far) else 10.0 * (z_hi - z_lo)
            a = o + near * axis
            b = o + t_far * axis
            # clip to the panel so an infinite far limit stays drawable
            if axis[2] > 1e-9 and b[2] > z_hi:
                b = o + ((z_hi - o[2]) / axis[2]) * axis
            ax_s.plot([a[0], b[0]], [a[2], b[2]], "-", color="goldenrod", lw=6, alpha=0.45,
                      solid_capstyle="butt",
                      label=None if dof_labelled else
                      "depth of field on the axes %s – %s" % (fmt_len(near, ""), fmt_len(far)))
            dof_labelled = True
        ax_s.plot([o[0]], [o[2]], "o", color=colour, ms=8, mec="k", zorder=5,
                  label="%s centre (%.4g, %.4g, %.4g)" % (side, o[0], o[1], o[2]))
    ax_s.set_xlim(x_lo, x_hi)
    ax_s.set_ylim(z_lo, z_hi)
    ax_s.set_aspect("equal", adjustable="box")
    ax_s.set_xlabel("x, right (mm)")
    ax_s.set_ylabel("z, forward (mm)")
    ax_s.set_title("x–z view of the rig (corner rays projected onto x–z)", fontsize=10)
    ax_s.grid(True, alpha=0.3)
    ax_s.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8.5, borderaxespad=0)

    save(fig, out_dir, "fields_of_view.png", quiet)


# --------------------------------------------------------------------------- #
# Figure 3: the grid in each image (thesis Fig. 3.2b)
# --------------------------------------------------------------------------- #
def plot_projected_grid(rep, grid, out_dir, quiet):
    name = rep.text("name")
    W = rep.number("input.width_px")
    H = rep.number("input.height_px")
    pts = grid["point"]

    ax_w = 6.0
    ax_h = ax_w * H / W  # same 4 % margins on u and v keep this ratio
    m_left, m_mid, m_right, m_top, m_bottom = 0.9, 0.9, 0.3, 0.9, 0.65
    fig_w, fig_h = m_left + 2 * ax_w + m_mid + m_right, m_top + ax_h + m_bottom
    fig = plt.figure(figsize=(fig_w, fig_h))
    axes = [fig.add_axes([(m_left + k * (ax_w + m_mid)) / fig_w, m_bottom / fig_h,
                          ax_w / fig_w, ax_h / fig_h]) for k in (0, 1)]
    fig.suptitle("%s\nGrid points as the cameras see them (%d points, image %d × %d px, "
                 "+ marks the image centre)" % (name, len(pts), W, H), fontsize=11,
                 y=1.0 - 0.12 / fig_h, va="top")
    for ax, key, side, colour in ((axes[0], "uv_left", "left", LEFT_COLOUR),
                                  (axes[1], "uv_right", "right", RIGHT_COLOUR)):
        uv = grid[key]
        ax.add_patch(Rectangle((0, 0), W, H, fill=True, fc="0.96", ec="k", lw=1.5))
        ax.plot([W / 2.0], [H / 2.0], "+", color="0.5", ms=12)
        if len(uv):
            for line in grid_lines(pts[:, :2], uv):
                ax.plot(line[:, 0], line[:, 1], "-", color=colour, lw=0.8, alpha=0.5)
            ax.plot(uv[:, 0], uv[:, 1], "o", color=colour, ms=4)
            good = finite_rows(uv)
            u_lo, u_hi = min(0.0, good[:, 0].min()), max(W, good[:, 0].max())
            v_lo, v_hi = min(0.0, good[:, 1].min()), max(H, good[:, 1].max())
        else:
            no_data(ax, "no grid points")
            u_lo, u_hi, v_lo, v_hi = 0.0, W, 0.0, H
        pu, pv = 0.04 * (u_hi - u_lo), 0.04 * (v_hi - v_lo)
        ax.set_xlim(u_lo - pu, u_hi + pu)
        ax.set_ylim(v_hi + pv, v_lo - pv)  # image v axis points down
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("u (px)")
        ax.set_ylabel("v, down (px)")
        ax.set_title("%s camera" % side, fontsize=10)
        ax.grid(True, alpha=0.3)
    save(fig, out_dir, "projected_grid.png", quiet)


# --------------------------------------------------------------------------- #
# Figure 4: reconstruction uncertainty (thesis Fig. 3.2c)
# --------------------------------------------------------------------------- #
def magnification(ellipses, spacing):
    """Nice factor making the largest ellipse's full major axis ~ELLIPSE_TARGET * spacing."""
    largest = max([e[0] for e in ellipses if math.isfinite(e[0])] or [0.0])
    if largest <= 0:
        return 1.0, 0.0
    return nice_floor(ELLIPSE_TARGET * spacing / (2.0 * largest)), largest


def draw_ellipses(ax, centres, params, values, factor, cmap, norm, alpha):
    for c, (a, b, ang), s in zip(centres, params, values):
        ax.add_patch(Ellipse((c[0], c[1]), 2 * factor * a, 2 * factor * b, angle=ang,
                             fc=cmap(norm(s)) if math.isfinite(s) else "0.6",
                             ec="k", lw=0.6, alpha=alpha))
    if len(centres):
        ax.scatter(centres[:, 0], centres[:, 1], c=values, cmap=cmap, norm=norm, s=9,
                   ec="k", lw=0.4, zorder=5)


def plot_reconstruction_uncertainty(rep, grid, out_dir, quiet):
    name = rep.text("name")
    Z = rep.number("stereo.working_distance_mm")
    sigma_px = rep.number("uncertainty.pixel_sigma_px")
    overlap = finite_rows(rep.points("overlap.polygon_mm"))
    pts, covs, sd = grid["point"], grid["cov"], grid["sigma_depth"]
    n = len(pts)

    # Each view gets its own magnification: depth uncertainty is several times
    # the lateral one, so a common factor would shrink the x-y ellipses to dots.
    xy = [ellipse_params(c[:2, :2]) for c in covs]
    xz = [ellipse_params(c[np.ix_([0, 2], [0, 2])]) for c in covs]
    extent = overlap if len(overlap) else (pts[:, :2] if n else np.zeros((0, 2)))
    fallback = 0.1 * float(np.ptp(extent[:, 0])) if len(extent) else 10.0
    spacing = grid_spacing(pts[:, :2], fallback) if n else fallback
    f_xy, big_xy = magnification(xy, spacing)
    f_xz, big_xz = magnification(xz, spacing)

    # Plot ranges (mm).
    parts = [a for a in (overlap, pts[:, :2]) if len(a)]
    src = np.vstack(parts) if parts else np.array([[-100.0, -100.0], [100.0, 100.0]])
    reach = max(f_xy * big_xy, f_xz * big_xz)
    pad = 0.04 * max(float(np.ptp(src[:, 0])), float(np.ptp(src[:, 1])), 1.0) + reach
    x_lo, x_hi = src[:, 0].min() - pad, src[:, 0].max() + pad
    y_lo, y_hi = src[:, 1].min() - pad, src[:, 1].max() + pad
    if n:
        z_mid = float(np.mean(pts[:, 2]))
        z_half = max(float(np.ptp(pts[:, 2])) / 2.0 + 1.3 * f_xz * big_xz, 0.09 * (x_hi - x_lo))
    else:
        z_mid, z_half = Z, 0.09 * (x_hi - x_lo)

    # Explicit layout (inches) so both equal-aspect panels fill their boxes.
    ax_w = 8.0
    mm_per_in = (x_hi - x_lo) / ax_w
    h_top, h_bot = (y_hi - y_lo) / mm_per_in, 2.0 * z_half / mm_per_in
    m_left, m_right, m_top, m_gap, m_bottom, cb_gap, cb_w = 1.0, 1.5, 1.05, 0.95, 0.6, 0.3, 0.25
    fig_w, fig_h = m_left + ax_w + m_right, m_top + h_top + m_gap + h_bot + m_bottom
    fig = plt.figure(figsize=(fig_w, fig_h))
    ax = fig.add_axes([m_left / fig_w, (m_bottom + h_bot + m_gap) / fig_h, ax_w / fig_w, h_top / fig_h])
    ax_z = fig.add_axes([m_left / fig_w, m_bottom / fig_h, ax_w / fig_w, h_bot / fig_h])
    cax = fig.add_axes([(m_left + ax_w + cb_gap) / fig_w, m_bottom / fig_h, cb_w / fig_w,
                        (h_top + m_gap + h_bot) / fig_h])
    scale = ("ellipses ×%g (x–y), ×%g (x–z)" % (f_xy, f_xz)) if n else "no grid points"
    fig.suptitle("%s\nReconstruction uncertainty: 1σ ellipses for %.3g px image noise, %s"
                 % (name, sigma_px, scale), fontsize=11, y=1.0 - 0.12 / fig_h, va="top")

    finite_sd = sd[np.isfinite(sd)] if n else sd
    if finite_sd.size:
        lo, hi = float(finite_sd.min()), float(finite_sd.max())
        if hi - lo < 1e-9 * max(abs(hi), 1.0):
            lo, hi = lo - 0.01 * abs(lo) - 1e-12, hi + 0.01 * abs(hi) + 1e-12
        norm = colors.Normalize(lo, hi)
    else:
        norm = colors.Normalize(0.0, 1.0)
    cmap = plt.get_cmap("viridis")

    # -- x-y view on the working plane
    add_polygon(ax, overlap, fc=OVERLAP_COLOUR, ec=OVERLAP_COLOUR, alpha=0.08, lw=1.0)
    if n:
        draw_ellipses(ax, pts[:, :2], xy, sd, f_xy, cmap, norm, 0.8)
    else:
        no_data(ax, "no grid points")
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_hi, y_lo)  # y points down
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x, right (mm)")
    ax.set_ylabel("y, down (mm)")
    ax.set_title("working plane z = %.4g mm, x–y view (%s; overlap shaded)"
                 % (Z, "ellipses ×%g; largest 1σ semi-axis %.3g mm" % (f_xy, big_xy) if n
                    else "no grid points"), fontsize=10)
    ax.grid(True, alpha=0.3)

    # -- x-z view: depth uncertainty (points of equal x overlay each other)
    ax_z.axhline(Z, color="0.5", lw=0.8)
    if n:
        draw_ellipses(ax_z, pts[:, [0, 2]], xz, sd, f_xz, cmap, norm, 0.45)
    else:
        no_data(ax_z, "no grid points")
    ax_z.set_xlim(x_lo, x_hi)
    ax_z.set_ylim(z_mid - z_half, z_mid + z_half)
    ax_z.set_aspect("equal", adjustable="box")
    ax_z.set_xlabel("x, right (mm)")
    ax_z.set_ylabel("z, fwd (mm)")
    ax_z.set_title("x–z view, depth uncertainty (%s)"
                   % ("ellipses ×%g; largest 1σ semi-axis %.3g mm; rows of equal x overlaid"
                      % (f_xz, big_xz) if n else "no grid points"), fontsize=10)
    ax_z.grid(True, alpha=0.3)

    sm = cm.ScalarMappable(norm=norm, cmap=cmap)
    sm.set_array([])
    cb = fig.colorbar(sm, cax=cax)
    cb.set_label("depth 1σ (mm)")
    if not finite_sd.size:
        cax.set_visible(False)
    save(fig, out_dir, "reconstruction_uncertainty.png", quiet)


# --------------------------------------------------------------------------- #
def main(argv=None):
    parser = argparse.ArgumentParser(
        description="Plot the figures of a stereo_design report.yaml into PNG files.")
    parser.add_argument("report", metavar="REPORT.yaml", help="report written by stereo_design")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    parser.add_argument("--quiet", action="store_true", help="do not list the files written")
    args = parser.parse_args(argv)

    try:
        rep = Report(args.report)
        grid = rep.grid()
        try:
            os.makedirs(args.out, exist_ok=True)
        except OSError as e:
            raise ReportError("%s: cannot create directory: %s" % (args.out, e.strerror or e))
        plot_depth_resolution(rep, args.out, args.quiet)
        plot_fields_of_view(rep, grid, args.out, args.quiet)
        plot_projected_grid(rep, grid, args.out, args.quiet)
        plot_reconstruction_uncertainty(rep, grid, args.out, args.quiet)
    except ReportError as e:
        print("%s: error: %s" % (PROG, e), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
