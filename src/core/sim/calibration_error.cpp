// SPDX-License-Identifier: BSD-3-Clause
// The calibration error of the rendered datasets: either a simulated chessboard calibration (the default) or
// independently drawn parameter errors.
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include <Eigen/Geometry>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/dataset.h"
#include "skin3d/stereo/calibration.h"

namespace skin3d {
namespace sim {

std::string calibrationErrorModelName(CalibrationErrorModel m) {
  return m == CalibrationErrorModel::Chessboard ? "chessboard" : "independent";
}

CalibrationErrorModel parseCalibrationErrorModel(const std::string& name) {
  if (name == "chessboard") return CalibrationErrorModel::Chessboard;
  if (name == "independent") return CalibrationErrorModel::Independent;
  throw SimConfigError("images.calibration_error.model",
                       "field 'images.calibration_error.model' = '" + name + "': known models are chessboard, independent");
}

namespace {

geometry::StereoRig independentErrors(const geometry::StereoRig& truth, const CalibrationPerturbation& p,
                                      std::uint64_t seed, PerturbedCalibration* out) {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 0xCA11B);
  std::normal_distribution<double> n(0.0, 1.0);
  out->baseline_scale = 1.0 + p.baseline_rel * n(rng);
  // rotation: RMS magnitude of the 3-axis error vector (per axis rotation / sqrt(3)).
  out->rotation_error = p.rotation / std::sqrt(3.0) * Eigen::Vector3d(n(rng), n(rng), n(rng));
  out->principal_left = p.principal_point * Eigen::Vector2d(n(rng), n(rng));
  out->principal_right = p.principal_point * Eigen::Vector2d(n(rng), n(rng));
  out->focal_scale_left = 1.0 + p.focal_rel * n(rng);
  out->focal_scale_right = 1.0 + p.focal_rel * n(rng);
  const auto perturbK = [](const geometry::PinholeCamera& cam, double fs, const Eigen::Vector2d& dpp) {
    Eigen::Matrix3d K = cam.K();
    K(0, 0) *= fs;
    K(1, 1) *= fs;
    K(0, 2) += dpp.x();
    K(1, 2) += dpp.y();
    return geometry::PinholeCamera(K, cam.width(), cam.height(), cam.D());
  };
  return geometry::StereoRig(perturbK(truth.left(), out->focal_scale_left, out->principal_left),
                             perturbK(truth.right(), out->focal_scale_right, out->principal_right),
                             geometry::so3Exp(out->rotation_error) * truth.R_rl(), truth.t_rl() * out->baseline_scale);
}

// A chessboard calibration of the true rig: board poses drawn around the working distance with both images
// seeing every corner, corners projected with the true (distorted) cameras plus Gaussian noise, then the core's
// stereo calibration, exactly as calibrate_stereo runs it on detected corners.
geometry::StereoRig chessboardCalibration(const geometry::StereoRig& truth, const CalibrationPerturbation& p,
                                          std::uint64_t seed, double working_distance, PerturbedCalibration* out) {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 0xB0A4D);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> n(0.0, 1.0);
  const geometry::PinholeCamera& L = truth.left();
  const geometry::PinholeCamera& R = truth.right();
  stereo::ChessboardPattern pattern;
  pattern.cols = p.board_cols;
  pattern.rows = p.board_rows;
  pattern.square_m = p.board_fill * working_distance * L.width() / L.fx() / (p.board_cols - 1);
  out->board_square_m = pattern.square_m;
  const std::vector<cv::Point3f> board = stereo::boardObjectPoints(pattern);
  const Eigen::Vector3d board_centre(0.5 * (p.board_cols - 1) * pattern.square_m,
                                     0.5 * (p.board_rows - 1) * pattern.square_m, 0.0);
  const double margin = 10.0;  // px: findChessboardCorners needs the board clear of the border
  const auto inside = [margin](const geometry::PinholeCamera& c, const Eigen::Vector2d& uv) {
    return uv.x() >= margin && uv.y() >= margin && uv.x() <= c.width() - 1 - margin && uv.y() <= c.height() - 1 - margin;
  };

  stereo::StereoCorners corners;
  corners.image_size = cv::Size(L.width(), L.height());
  int attempts = 0;
  while (static_cast<int>(corners.left.size()) < p.views) {
    if (++attempts > 200000)
      throw std::runtime_error("calibration_error (chessboard model): cannot place a " + std::to_string(p.board_cols) +
                               "x" + std::to_string(p.board_rows) +
                               " board inside both images around the working distance; reduce board_fill");
    const double z = working_distance * (p.min_distance_rel + (p.max_distance_rel - p.min_distance_rel) * uni(rng));
    // Board centre on the ray of a random left pixel; tilt about x and y, a small turn in the plane.
    const Eigen::Vector3d centre =
        z * L.unproject(Eigen::Vector2d(uni(rng) * (L.width() - 1), uni(rng) * (L.height() - 1)));  // (x, y, 1)
    const Eigen::Matrix3d Rb = geometry::so3Exp(Eigen::Vector3d(p.max_tilt * (2.0 * uni(rng) - 1.0),
                                                                p.max_tilt * (2.0 * uni(rng) - 1.0),
                                                                0.25 * (2.0 * uni(rng) - 1.0)));
    std::vector<cv::Point2f> l, r;
    bool ok = true;
    for (const cv::Point3f& q : board) {
      const Eigen::Vector3d X = centre + Rb * (Eigen::Vector3d(q.x, q.y, q.z) - board_centre);
      Eigen::Vector2d ul, ur;
      if (!truth.project(X, &ul, &ur) || !inside(L, ul) || !inside(R, ur)) {
        ok = false;
        break;
      }
      l.emplace_back(static_cast<float>(ul.x() + p.corner_sigma_px * n(rng)),
                     static_cast<float>(ul.y() + p.corner_sigma_px * n(rng)));
      r.emplace_back(static_cast<float>(ur.x() + p.corner_sigma_px * n(rng)),
                     static_cast<float>(ur.y() + p.corner_sigma_px * n(rng)));
    }
    if (!ok) continue;
    corners.names.push_back(std::to_string(corners.left.size() + 1));
    corners.left.push_back(std::move(l));
    corners.right.push_back(std::move(r));
  }
  stereo::CalibrationOptions options;
  options.k_coefficients = p.k_coefficients;
  const stereo::StereoCalibration calib = stereo::calibrateStereo(corners, pattern, options);
  out->calibration_rms_px = calib.rms_px;
  const geometry::StereoRig& m = calib.rig;
  out->baseline_scale = m.baseline() / truth.baseline();
  out->rotation_error = geometry::so3Log(m.R_rl() * truth.R_rl().transpose());
  out->principal_left = Eigen::Vector2d(m.left().cx() - L.cx(), m.left().cy() - L.cy());
  out->principal_right = Eigen::Vector2d(m.right().cx() - R.cx(), m.right().cy() - R.cy());
  out->focal_scale_left = m.left().fx() / L.fx();
  out->focal_scale_right = m.right().fx() / R.fx();
  return m;
}

// The similarity X_measured ~ s R X + t over the working volume (PerturbedCalibration::frame_*).
void fitMeasuredFrame(const geometry::StereoRig& truth, double working_distance, PerturbedCalibration* out) {
  const geometry::PinholeCamera& L = truth.left();
  std::vector<Eigen::Vector3d> src, dst;
  for (int k = 0; k <= 4; ++k)
    for (int i = 0; i <= 8; ++i)
      for (int j = 0; j <= 8; ++j) {
        const Eigen::Vector2d uv(L.width() * (0.5 + i) / 9.0, L.height() * (0.5 + j) / 9.0);
        const Eigen::Vector3d X = (0.8 + 0.1 * k) * working_distance * L.unproject(uv);
        Eigen::Vector2d ul, ur;
        if (!truth.project(X, &ul, &ur) || !truth.right().inImage(ur)) continue;
        const geometry::TriangulationResult t = out->rig.triangulate(ul, ur, 0.5);
        if (!t.ok) continue;
        src.push_back(X);
        dst.push_back(t.X);
      }
  out->frame_points = static_cast<int>(src.size());
  if (src.size() < 3) return;
  Eigen::Matrix3Xd A(3, src.size()), B(3, dst.size());
  for (size_t i = 0; i < src.size(); ++i) {
    A.col(i) = src[i];
    B.col(i) = dst[i];
  }
  const Eigen::Matrix4d T = Eigen::umeyama(A, B, true);
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  out->frame_scale = std::cbrt(sR.determinant());
  out->frame_rotation = geometry::so3Log(sR / out->frame_scale);
  out->frame_translation = T.topRightCorner<3, 1>();
  double ss = 0.0;
  for (size_t i = 0; i < src.size(); ++i) ss += (sR * src[i] + out->frame_translation - dst[i]).squaredNorm();
  out->frame_residual_rms_m = std::sqrt(ss / static_cast<double>(src.size()));
}

}  // namespace

PerturbedCalibration perturbCalibration(const geometry::StereoRig& truth, const CalibrationPerturbation& p,
                                        std::uint64_t seed, double working_distance) {
  PerturbedCalibration out;
  out.rig = truth;
  if (!p.enabled) return out;
  out.rig = p.model == CalibrationErrorModel::Chessboard ? chessboardCalibration(truth, p, seed, working_distance, &out)
                                                         : independentErrors(truth, p, seed, &out);
  // The depth the measured calibration gives a point on the left optical axis at the working distance.
  // And the largest error over a grid of the left image where the right camera sees the point too.
  const geometry::PinholeCamera& L = truth.left();
  for (int i = 0; i <= 8; ++i)
    for (int j = 0; j <= 8; ++j) {
      const Eigen::Vector2d uv = i == 4 && j == 4 ? Eigen::Vector2d(L.cx(), L.cy())
                                                  : Eigen::Vector2d(L.width() * (0.5 + i) / 9.0, L.height() * (0.5 + j) / 9.0);
      const Eigen::Vector3d X = working_distance * L.unproject(uv);
      Eigen::Vector2d ul, ur;
      if (!truth.project(X, &ul, &ur) || !truth.right().inImage(ur)) continue;
      const geometry::TriangulationResult t = out.rig.triangulate(ul, ur, 0.5);
      if (!t.ok) continue;
      const double e = t.X.z() - X.z();
      if (i == 4 && j == 4) out.depth_error_m = e;
      if (std::abs(e) > std::abs(out.depth_error_max_m)) out.depth_error_max_m = e;
    }
  fitMeasuredFrame(truth, working_distance, &out);
  return out;
}

}  // namespace sim
}  // namespace skin3d
