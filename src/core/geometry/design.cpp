// SPDX-License-Identifier: BSD-3-Clause
#include "../common/text.h"
#include "skin3d/geometry/design.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <Eigen/LU>
#include <cmath>
#include <sstream>

#include "skin3d/geometry/quaternion.h"

namespace skin3d {
namespace geometry {

namespace {

constexpr double kDeg = M_PI / 180.0;

using common::num;

[[noreturn]] void fail(const std::string& field, const std::string& value, const std::string& why) {
  throw DesignConfigError(field, "field '" + field + "' = " + value + ": " + why);
}

void requirePositive(const std::string& field, double v) {
  if (!std::isfinite(v)) fail(field, num(v), "must be a finite number");
  if (!(v > 0.0)) fail(field, num(v), "must be > 0");
}

void requireFinite(const std::string& field, const Eigen::Vector3d& v) {
  if (!v.allFinite()) {
    std::ostringstream os;
    os << "[" << v.x() << ", " << v.y() << ", " << v.z() << "]";
    fail(field, os.str(), "every component must be a finite number");
  }
}

Eigen::Matrix3d rotY(double a) {
  Eigen::Matrix3d R;
  R << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
  return R;
}

double depthResolution(double Z, double b, double f, double pixel) { return Z * Z * pixel / (b * f); }

}  // namespace

double polygonArea(const std::vector<Eigen::Vector2d>& poly) {
  double a = 0.0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const auto& p = poly[i];
    const auto& q = poly[(i + 1) % poly.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return 0.5 * a;
}

namespace {
double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }
}  // namespace

bool insideConvex(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  if (poly.size() < 3) return false;
  for (size_t i = 0; i < poly.size(); ++i) {
    const auto& a = poly[i];
    const auto& b = poly[(i + 1) % poly.size()];
    if (cross2(b - a, p - a) < -1e-12) return false;
  }
  return true;
}

std::vector<Eigen::Vector2d> convexIntersection(const std::vector<Eigen::Vector2d>& subject,
                                                const std::vector<Eigen::Vector2d>& clip) {
  std::vector<Eigen::Vector2d> out = subject;
  for (size_t i = 0; i < clip.size() && !out.empty(); ++i) {
    const Eigen::Vector2d a = clip[i];
    const Eigen::Vector2d b = clip[(i + 1) % clip.size()];
    const auto side = [&](const Eigen::Vector2d& p) { return cross2(b - a, p - a); };
    std::vector<Eigen::Vector2d> in = out;
    out.clear();
    for (size_t j = 0; j < in.size(); ++j) {
      const Eigen::Vector2d p = in[j];
      const Eigen::Vector2d q = in[(j + 1) % in.size()];
      const double sp = side(p), sq = side(q);
      if (sp >= 0.0) out.push_back(p);
      if ((sp >= 0.0) != (sq >= 0.0)) {
        const double t = sp / (sp - sq);
        out.push_back(p + t * (q - p));
      }
    }
  }
  if (out.size() < 3 || std::abs(polygonArea(out)) <= 0.0) return {};
  return out;
}

void validateDesignConfig(const DesignConfig& c) {
  if (c.width_px <= 0) fail("sensor.width_px", std::to_string(c.width_px), "must be > 0");
  if (c.height_px <= 0) fail("sensor.height_px", std::to_string(c.height_px), "must be > 0");
  requirePositive("sensor.pixel_size_um", c.pixel_size_mm * 1000.0);
  if (!std::isnan(c.sensor_width_mm)) requirePositive("sensor.width_mm", c.sensor_width_mm);
  if (!std::isnan(c.sensor_height_mm)) requirePositive("sensor.height_mm", c.sensor_height_mm);
  requirePositive("lens.focal_length_mm", c.focal_length_mm);
  requirePositive("lens.f_number", c.f_number);
  if (!std::isnan(c.coc_mm)) requirePositive("lens.circle_of_confusion_mm", c.coc_mm);
  requireFinite("geometry.baseline_mm", c.baseline_mm);
  if (!(c.baseline_mm.norm() > 0.0)) fail("geometry.baseline_mm", "[0, 0, 0]", "the two cameras must not coincide");
  if (!std::isfinite(c.convergence_deg)) fail("geometry.convergence_deg", num(c.convergence_deg), "must be a finite number");
  if (c.convergence_deg < 0.0 || c.convergence_deg >= 180.0)
    fail("geometry.convergence_deg", num(c.convergence_deg), "must be in [0, 180)");
  requireFinite("geometry.left_rotation_deg", c.left_rotation_deg);
  requireFinite("geometry.right_rotation_deg", c.right_rotation_deg);
  if (!std::isnan(c.working_distance_mm)) requirePositive("geometry.working_distance_mm", c.working_distance_mm);
  requirePositive("requirement.depth_resolution_mm", c.depth_resolution_mm);
  requirePositive("requirement.object_size_mm", c.object_size_mm);
  if (c.grid_nx < 1 || c.grid_nx > 100) fail("analysis.grid", std::to_string(c.grid_nx), "nx must be in 1..100");
  if (c.grid_ny < 1 || c.grid_ny > 100) fail("analysis.grid", std::to_string(c.grid_ny), "ny must be in 1..100");
  requirePositive("analysis.pixel_sigma_px", c.pixel_sigma_px);
}

StereoRig designRig(const DesignReport& r) {
  const DesignConfig& c = r.config;
  const double fpx = c.focal_length_mm / c.pixel_size_mm;
  Eigen::Matrix3d K;
  K << fpx, 0, 0.5 * (c.width_px - 1), 0, fpx, 0.5 * (c.height_px - 1), 0, 0, 1;
  const PinholeCamera cam(K, c.width_px, c.height_px);
  const Eigen::Matrix3d R_lr = r.R_rig_left.transpose() * r.R_rig_right;
  const Eigen::Vector3d centre = r.R_rig_left.transpose() * (r.c_right - r.c_left);
  return StereoRig::fromRightPose(cam, cam, R_lr, centre);
}

namespace {

std::vector<Eigen::Vector2d> footprint(const PinholeCamera& cam, const Eigen::Matrix3d& R_rig_cam,
                                       const Eigen::Vector3d& centre, double plane_z, const char* which) {
  const double w = cam.width(), h = cam.height();
  const Eigen::Vector2d corners[4] = {{-0.5, -0.5}, {w - 0.5, -0.5}, {w - 0.5, h - 0.5}, {-0.5, h - 0.5}};
  std::vector<Eigen::Vector2d> poly;
  for (const auto& uv : corners) {
    const Eigen::Vector3d d = R_rig_cam * cam.unproject(uv);
    const double t = (plane_z - centre.z()) / d.z();
    if (!(d.z() > 0.0) || !(t > 0.0)) {
      throw DesignConfigError("geometry", std::string("impossible geometry: the ") + which +
                                              " camera's view does not meet the working plane z = " + num(plane_z) +
                                              " mm in every image corner (camera turned too far, or plane behind it)");
    }
    const Eigen::Vector3d P = centre + t * d;
    poly.emplace_back(P.x(), P.y());
  }
  if (polygonArea(poly) < 0.0) std::reverse(poly.begin(), poly.end());
  return poly;
}

}  // namespace

DesignReport computeDesign(const DesignConfig& c) {
  validateDesignConfig(c);
  DesignReport r;
  r.config = c;
  const double f = c.focal_length_mm;
  const double pix = c.pixel_size_mm;

  // Sensor metrics.
  r.sensor_width_mm = std::isnan(c.sensor_width_mm) ? c.width_px * pix : c.sensor_width_mm;
  r.sensor_height_mm = std::isnan(c.sensor_height_mm) ? c.height_px * pix : c.sensor_height_mm;
  r.sensor_diagonal_mm = std::hypot(r.sensor_width_mm, r.sensor_height_mm);
  r.megapixels = double(c.width_px) * c.height_px / 1e6;
  r.focal_length_px = f / pix;

  // Lens metrics (eq. 2.1).
  r.aov_h_deg = 2.0 * std::atan(r.sensor_width_mm / (2.0 * f)) / kDeg;
  r.aov_v_deg = 2.0 * std::atan(r.sensor_height_mm / (2.0 * f)) / kDeg;
  r.aov_d_deg = 2.0 * std::atan(r.sensor_diagonal_mm / (2.0 * f)) / kDeg;

  // Stereo geometry (eq. 2.23-2.27).
  r.baseline_mm = c.baseline_mm.norm();
  r.optimum_working_distance_mm = f * c.object_size_mm / r.sensor_width_mm;
  r.working_distance_mm = std::isnan(c.working_distance_mm) ? r.optimum_working_distance_mm : c.working_distance_mm;
  const double Z = r.working_distance_mm;
  if (!(Z > f)) fail("geometry.working_distance_mm", num(Z), "must be larger than the focal length");
  r.depth_resolution_mm = depthResolution(Z, r.baseline_mm, f, pix);
  const double ratio = c.object_size_mm / r.sensor_width_mm;
  r.min_baseline_mm = f * (pix / c.depth_resolution_mm) * ratio * ratio;
  r.min_baseline_at_working_distance_mm = Z * Z * pix / (f * c.depth_resolution_mm);
  r.recommended_convergence_deg = 2.0 * std::atan(r.baseline_mm / (2.0 * Z)) / kDeg;

  // Field of view at the working distance (eq. 2.2).
  r.fov_w_mm = 2.0 * Z * std::tan(0.5 * r.aov_h_deg * kDeg);
  r.fov_h_mm = 2.0 * Z * std::tan(0.5 * r.aov_v_deg * kDeg);
  r.fov_d_mm = 2.0 * Z * std::tan(0.5 * r.aov_d_deg * kDeg);

  // Depth of field from the hyperfocal distance.
  const double coc = std::isnan(c.coc_mm) ? 2.0 * pix : c.coc_mm;
  r.config.coc_mm = coc;
  r.hyperfocal_mm = f * f / (c.f_number * coc) + f;
  const double H = r.hyperfocal_mm;
  r.near_mm = Z * (H - f) / (H + Z - 2.0 * f);
  r.far_mm = Z < H ? Z * (H - f) / (H - Z) : std::numeric_limits<double>::infinity();
  r.depth_of_field_mm = r.far_mm - r.near_mm;

  // Camera poses in the rig frame.
  if (c.per_camera_rotation) {
    r.R_rig_left = so3Exp(c.left_rotation_deg * kDeg);
    r.R_rig_right = so3Exp(c.right_rotation_deg * kDeg);
  } else {
    r.R_rig_left = rotY(0.5 * c.convergence_deg * kDeg);
    r.R_rig_right = rotY(-0.5 * c.convergence_deg * kDeg);
  }
  r.c_left = -0.5 * c.baseline_mm;
  r.c_right = 0.5 * c.baseline_mm;
  const double cosang = r.R_rig_left.col(2).dot(r.R_rig_right.col(2));
  r.optical_axes_angle_deg = std::acos(std::max(-1.0, std::min(1.0, cosang))) / kDeg;

  // Footprints and their overlap on the working plane.
  const StereoRig rig = designRig(r);
  r.footprint_left = footprint(rig.left(), r.R_rig_left, r.c_left, Z, "left");
  r.footprint_right = footprint(rig.right(), r.R_rig_right, r.c_right, Z, "right");
  r.footprint_left_area_mm2 = polygonArea(r.footprint_left);
  r.footprint_right_area_mm2 = polygonArea(r.footprint_right);
  r.overlap = convexIntersection(r.footprint_left, r.footprint_right);
  if (r.overlap.empty())
    throw DesignConfigError("geometry", "impossible geometry: the two cameras' fields of view do not overlap on the "
                                        "working plane at " + num(Z) + " mm (check geometry.baseline_mm, "
                                        "geometry.convergence_deg and geometry.working_distance_mm)");
  r.overlap_area_mm2 = polygonArea(r.overlap);
  r.overlap_min = r.overlap_max = r.overlap.front();
  for (const auto& p : r.overlap) {
    r.overlap_min = r.overlap_min.cwiseMin(p);
    r.overlap_max = r.overlap_max.cwiseMax(p);
  }
  r.overlap_fraction = r.overlap_area_mm2 / r.footprint_left_area_mm2;

  // Reconstruction uncertainty of a grid of points in the overlap (MMSE, Algorithm 2.1).
  const Eigen::Vector2d span = r.overlap_max - r.overlap_min;
  const Eigen::Vector2d lo = r.overlap_min + 0.05 * span, hi = r.overlap_max - 0.05 * span;
  double sum_depth = 0.0;
  for (int j = 0; j < c.grid_ny; ++j) {
    for (int i = 0; i < c.grid_nx; ++i) {
      const double sx = c.grid_nx == 1 ? 0.5 : double(i) / (c.grid_nx - 1);
      const double sy = c.grid_ny == 1 ? 0.5 : double(j) / (c.grid_ny - 1);
      const Eigen::Vector2d xy = lo + Eigen::Vector2d(sx * (hi.x() - lo.x()), sy * (hi.y() - lo.y()));
      if (!insideConvex(r.overlap, xy)) continue;
      DesignGridPoint g;
      g.X = Eigen::Vector3d(xy.x(), xy.y(), Z);
      const Eigen::Vector3d Xl = r.R_rig_left.transpose() * (g.X - r.c_left);
      if (!rig.project(Xl, &g.uv_left, &g.uv_right)) continue;
      if (!rig.left().inImage(g.uv_left) || !rig.right().inImage(g.uv_right)) continue;
      const TriangulationResult tr = rig.triangulate(g.uv_left, g.uv_right, c.pixel_sigma_px);
      if (!tr.ok) continue;
      g.X_est = r.R_rig_left * tr.X + r.c_left;
      g.cov = r.R_rig_left * tr.C * r.R_rig_left.transpose();
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(g.cov);
      for (int k = 0; k < 3; ++k) {
        g.axes[k] = std::sqrt(std::max(0.0, es.eigenvalues()[2 - k]));
        g.axis_dirs.col(k) = es.eigenvectors().col(2 - k);
      }
      g.sigma_depth = std::sqrt(g.cov(2, 2));
      r.max_axis_mm = std::max(r.max_axis_mm, g.axes[0]);
      r.max_depth_sigma_mm = std::max(r.max_depth_sigma_mm, g.sigma_depth);
      sum_depth += g.sigma_depth;
      r.grid.push_back(g);
    }
  }
  if (!r.grid.empty()) r.mean_depth_sigma_mm = sum_depth / r.grid.size();

  // Curves for the plots (thesis Fig. 3.1).
  const int n = 60;
  const double b_hi = 2.0 * std::max(r.baseline_mm, r.min_baseline_at_working_distance_mm);
  for (int k = 1; k <= n; ++k) {
    const double b = b_hi * k / n;
    r.resolution_vs_baseline.emplace_back(b, depthResolution(Z, b, f, pix));
  }
  for (int k = 0; k <= n; ++k) {
    const double z = Z * (0.25 + 1.75 * k / n);
    r.resolution_vs_distance.emplace_back(z, depthResolution(z, r.baseline_mm, f, pix));
  }
  return r;
}

}  // namespace geometry
}  // namespace skin3d
