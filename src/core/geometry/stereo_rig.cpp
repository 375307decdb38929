// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/geometry/stereo_rig.h"

#include <Eigen/LU>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace geometry {

namespace {
void checkRotation(const Eigen::Matrix3d& R, const char* name) {
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (!R.allFinite() || orth > 1e-6 || std::abs(R.determinant() - 1.0) > 1e-6) {
    std::ostringstream os;
    os << "stereo rig: " << name << " is not a rotation matrix (|R^T R - I| = " << orth << ")";
    throw std::invalid_argument(os.str());
  }
}
}  // namespace

StereoRig::StereoRig(const PinholeCamera& left, const PinholeCamera& right, const Eigen::Matrix3d& R_rl,
                     const Eigen::Vector3d& t_rl)
    : left_(left), right_(right), R_rl_(R_rl), t_rl_(t_rl) {
  checkRotation(R_rl, "R_rl");
  if (!t_rl.allFinite() || !(t_rl.norm() > 0.0))
    throw std::invalid_argument("stereo rig: the baseline must be finite and non-zero");
}

StereoRig StereoRig::fromRightPose(const PinholeCamera& left, const PinholeCamera& right,
                                   const Eigen::Matrix3d& R_lr, const Eigen::Vector3d& centre_right) {
  checkRotation(R_lr, "R_lr");
  return StereoRig(left, right, R_lr.transpose(), -R_lr.transpose() * centre_right);
}

StereoRig StereoRig::fromCameraInfo(const CameraInfo& left, const CameraInfo& right) {
  const PinholeCamera cl = PinholeCamera::fromCameraInfo(left);
  const PinholeCamera cr = PinholeCamera::fromCameraInfo(right);
  checkRotation(left.R, "left R");
  checkRotation(right.R, "right R");
  const double fx = right.P(0, 0);
  if (!(fx > 0.0)) throw std::invalid_argument("stereo rig: right P[0] (fx') must be > 0 (uncalibrated?)");
  const double B = -right.P(0, 3) / fx;
  if (!(std::abs(B) > 0.0) || !std::isfinite(B))
    throw std::invalid_argument("stereo rig: right P[3] (Tx = -fx' B) gives no baseline");
  if (std::abs(right.P(1, 3)) > 1e-9 * std::abs(right.P(0, 3)) + 1e-12)
    throw std::invalid_argument("stereo rig: vertical stereo (right P[7] != 0) is not supported");
  const Eigen::Matrix3d R_rl = right.R.transpose() * left.R;
  const Eigen::Vector3d t_rl = -right.R.transpose() * Eigen::Vector3d(B, 0.0, 0.0);
  return StereoRig(cl, cr, R_rl, t_rl);
}

double StereoRig::opticalAxesAngle() const {
  // Right optical axis in the left frame is R_rl^T e_z.
  const Eigen::Vector3d zr = R_rl_.transpose().col(2);
  return std::acos(std::max(-1.0, std::min(1.0, zr.z())));
}

bool StereoRig::project(const Eigen::Vector3d& X_left, Eigen::Vector2d* uv_left, Eigen::Vector2d* uv_right) const {
  const Eigen::Vector3d Xr = toRight(X_left);
  if (!(X_left.z() > 0.0) || !(Xr.z() > 0.0)) return false;
  if (uv_left) *uv_left = left_.project(X_left);
  if (uv_right) *uv_right = right_.project(Xr);
  return true;
}

TriangulationResult StereoRig::triangulate(const Eigen::Vector2d& uv_left, const Eigen::Vector2d& uv_right,
                                           double sigma_px, const TriangulationOptions& options) const {
  if (!(sigma_px > 0.0) || !std::isfinite(sigma_px)) {
    TriangulationResult r;
    r.message = "triangulation: sigma_px must be finite and > 0";
    return r;
  }
  std::vector<CameraObservation> views(2);
  Eigen::Matrix2d J;
  views[0].K = left_.K();
  views[0].uv = left_.undistortPixel(uv_left, &J);
  views[0].cov_uv = sigma_px * sigma_px * J * J.transpose();
  views[1].K = right_.K();
  views[1].R = R_rl_;
  views[1].t = t_rl_;
  views[1].uv = right_.undistortPixel(uv_right, &J);
  views[1].cov_uv = sigma_px * sigma_px * J * J.transpose();
  return triangulateMmse(views, options);
}

}  // namespace geometry
}  // namespace skin3d
