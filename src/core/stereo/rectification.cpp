// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/stereo/rectification.h"

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <sstream>

namespace skin3d {
namespace stereo {

namespace {

geometry::CameraInfo baseInfo(const geometry::PinholeCamera& cam) {
  geometry::CameraInfo info;
  info.width = cam.width();
  info.height = cam.height();
  info.distortion_model = "plumb_bob";
  info.D = cam.D();
  info.K = cam.K();
  return info;
}

RectifiedPair rectifyWith(const geometry::StereoRig& rig, int flags, double alpha) {
  cv::Mat K1, K2, R, T;
  cv::eigen2cv(rig.left().K(), K1);
  cv::eigen2cv(rig.right().K(), K2);
  cv::eigen2cv(rig.R_rl(), R);
  cv::eigen2cv(rig.t_rl(), T);
  const cv::Mat D1(rig.left().D()), D2(rig.right().D());
  const cv::Size size(rig.left().width(), rig.left().height());
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(K1, D1, K2, D2, size, R, T, R1, R2, P1, P2, Q, flags, alpha, size);
  RectifiedPair out;
  out.left = baseInfo(rig.left());
  out.right = baseInfo(rig.right());
  cv::cv2eigen(R1, out.left.R);
  cv::cv2eigen(R2, out.right.R);
  cv::cv2eigen(P1, out.left.P);
  cv::cv2eigen(P2, out.right.P);
  out.alpha = alpha;
  out.zero_disparity = (flags & cv::CALIB_ZERO_DISPARITY) != 0;
  return out;
}

bool inside(const RectifiedPair& p, const Eigen::Vector3d& X, double margin) {
  for (bool right : {false, true}) {
    const Eigen::Vector2d uv = projectRectified(p, X, right);
    const auto& info = right ? p.right : p.left;
    if (!uv.allFinite() || uv.x() < margin || uv.y() < margin || uv.x() > info.width - 1 - margin ||
        uv.y() > info.height - 1 - margin)
      return false;
  }
  return true;
}

}  // namespace

Eigen::Vector2d projectRectified(const RectifiedPair& pair, const Eigen::Vector3d& X_left, bool right) {
  const Eigen::Vector3d Xr = pair.left.R * X_left;  // rectified left frame
  const Eigen::Matrix<double, 3, 4>& P = right ? pair.right.P : pair.left.P;
  const Eigen::Vector3d h = P.leftCols<3>() * Xr + P.col(3);
  return h.head<2>() / h.z();
}

RectifiedPair rectifyStereo(const geometry::StereoRig& rig, const std::vector<Eigen::Vector3d>& points_of_interest,
                            double margin_px) {
  if (points_of_interest.empty()) return rectifyWith(rig, cv::CALIB_ZERO_DISPARITY, 0.0);
  for (double alpha : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    const RectifiedPair p = rectifyWith(rig, 0, alpha);
    bool ok = true;
    for (const auto& X : points_of_interest) ok = ok && inside(p, X, margin_px);
    if (ok) return p;
  }
  std::ostringstream os;
  os << "rectification: no alpha in [0, 1] keeps all " << points_of_interest.size()
     << " points of interest inside both rectified images (flags 0); the working area is not seen by both "
        "cameras, or the output size is too small";
  throw std::runtime_error(os.str());
}

}  // namespace stereo
}  // namespace skin3d
