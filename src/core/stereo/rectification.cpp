// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/stereo/rectification.h"

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
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

/*
 * Rectified projections fitted to points of interest (left frame): the rotations of `p` are kept; one focal
 * length (at most f_max), one row centre, and a principal point per camera put every point inside both images
 * with `margin` px to spare. False if a point is not in front of both rectified cameras.
 */
bool fitRectifiedProjection(RectifiedPair* p, const std::vector<Eigen::Vector3d>& pts, double f_max, double margin) {
  const double f0 = f_max, B = -p->right.P(0, 3) / p->right.P(0, 0);
  const double W = p->left.width, H = p->left.height;
  double xl[2] = {1e300, -1e300}, xr[2] = {1e300, -1e300}, y[2] = {1e300, -1e300};
  for (const auto& X : pts) {
    const Eigen::Vector3d Xl = p->left.R * X;
    if (!(Xl.z() > 1e-9 * X.norm())) return false;
    const double a = Xl.x() / Xl.z(), b = (Xl.x() - B) / Xl.z(), c = Xl.y() / Xl.z();
    xl[0] = std::min(xl[0], a), xl[1] = std::max(xl[1], a);
    xr[0] = std::min(xr[0], b), xr[1] = std::max(xr[1], b);
    y[0] = std::min(y[0], c), y[1] = std::max(y[1], c);
  }
  // Usable pixels are [margin, size - 1 - margin].
  double f = f0;
  if (xl[1] > xl[0]) f = std::min(f, (W - 1 - 2 * margin) / (xl[1] - xl[0]));
  if (xr[1] > xr[0]) f = std::min(f, (W - 1 - 2 * margin) / (xr[1] - xr[0]));
  if (y[1] > y[0]) f = std::min(f, (H - 1 - 2 * margin) / (y[1] - y[0]));
  f *= 0.999;  // rounding
  if (!(f > 0.0) || !std::isfinite(f)) return false;
  const double cxl = 0.5 * (W - 1) - f * 0.5 * (xl[0] + xl[1]), cxr = 0.5 * (W - 1) - f * 0.5 * (xr[0] + xr[1]);
  const double cy = 0.5 * (H - 1) - f * 0.5 * (y[0] + y[1]);
  p->left.P << f, 0, cxl, 0, 0, f, cy, 0, 0, 0, 1, 0;
  p->right.P << f, 0, cxr, -f * B, 0, f, cy, 0, 0, 0, 1, 0;
  p->zero_disparity = false;
  p->projection_fitted = true;
  return true;
}


Eigen::Vector2d projectRectified(const RectifiedPair& pair, const Eigen::Vector3d& X_left, bool right) {
  const Eigen::Vector3d Xr = pair.left.R * X_left;  // rectified left frame
  const Eigen::Matrix<double, 3, 4>& P = right ? pair.right.P : pair.left.P;
  const Eigen::Vector3d h = P.leftCols<3>() * Xr + P.col(3);
  return h.head<2>() / h.z();
}

RectifiedPair rectifyStereo(const geometry::StereoRig& rig, const std::vector<Eigen::Vector3d>& points_of_interest,
                            double margin_px) {
  if (points_of_interest.empty()) return rectifyWith(rig, cv::CALIB_ZERO_DISPARITY, 0.0);
  for (const auto& X : points_of_interest) {
    Eigen::Vector2d uvl, uvr;
    if (!rig.project(X, &uvl, &uvr) || !rig.left().inImage(uvl) || !rig.right().inImage(uvr)) {
      std::ostringstream os;
      os << "rectification: the point of interest (" << X.transpose() << ") m is not seen by both raw cameras; the "
         << "working area must lie in both images";
      throw std::runtime_error(os.str());
    }
  }
  RectifiedPair p = rectifyWith(rig, 0, 0.0);
  bool ok = true;
  for (const auto& X : points_of_interest) ok = ok && inside(p, X, margin_px);
  if (ok) return p;
  // OpenCV's alpha > 0 degenerates for strongly converged rigs (principal point outside the image, focal
  // length tiny or negative): keep its rotations and fit the projections to the points instead.
  const double f_raw = 0.25 * (rig.left().fx() + rig.left().fy() + rig.right().fx() + rig.right().fy());
  if (fitRectifiedProjection(&p, points_of_interest, f_raw, margin_px)) {
    ok = true;
    for (const auto& X : points_of_interest) ok = ok && inside(p, X, margin_px * 0.5);
    if (ok) return p;
  }
  std::ostringstream os;
  os << "rectification: neither alpha 0 nor a fitted projection keeps all " << points_of_interest.size()
     << " points of interest inside both rectified images (flags 0); the working area is not seen by both "
        "cameras, or the output size is too small";
  throw std::runtime_error(os.str());
}

Rectifier::Rectifier(const geometry::CameraInfo& c) : width_(c.width), height_(c.height) {
  if (c.width <= 0 || c.height <= 0) throw std::invalid_argument("rectifier: camera_info has no image size");
  if (!(c.K(0, 0) > 0.0) || !(c.P(0, 0) > 0.0))
    throw std::invalid_argument("rectifier: camera_info is not calibrated (K[0] or P[0] is 0)");
  cv::Mat K, R, P;
  const Eigen::Matrix3d P3 = c.P.leftCols<3>();
  cv::eigen2cv(c.K, K);
  cv::eigen2cv(c.R, R);
  cv::eigen2cv(P3, P);
  cv::initUndistortRectifyMap(K, cv::Mat(c.D), R, P, cv::Size(c.width, c.height), CV_16SC2, map1_, map2_);
}

cv::Mat Rectifier::operator()(const cv::Mat& raw) const {
  if (raw.cols != width_ || raw.rows != height_) {
    std::ostringstream os;
    os << "rectifier: image is " << raw.cols << "x" << raw.rows << " but camera_info says " << width_ << "x" << height_;
    throw std::invalid_argument(os.str());
  }
  cv::Mat out;
  cv::remap(raw, out, map1_, map2_, cv::INTER_LINEAR);
  return out;
}

}  // namespace stereo
}  // namespace skin3d
