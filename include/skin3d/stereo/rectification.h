/**
 * @file rectification.h
 * @brief Stereo rectification of a calibrated rig into ROS CameraInfo (K, D, R, P), including strongly
 * converged rigs (the thesis' Part I rig has 54.4 deg between the optical axes).
 *
 * With OpenCV's default CALIB_ZERO_DISPARITY (what ROS camera_calibration uses), a strongly converged
 * rig's scene leaves both rectified images. With points of interest given, rectification uses flags 0
 * (each camera keeps its own principal point; the right P then has a different cx, which skin3d's matching
 * and triangulation take into account as the disparity offset cx_l - cx_r) and alpha 0; if the points of
 * interest do not all fit, OpenCV's alpha > 0 is no help (for a 54.4 deg rig it puts the principal point
 * outside the image and shrinks or flips the focal length), so the rotations are kept and the projections
 * fitted to the points (fitRectifiedProjection).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <stdexcept>
#include <opencv2/core.hpp>
#include <vector>

#include "skin3d/geometry/camera.h"
#include "skin3d/geometry/stereo_rig.h"

namespace skin3d {
namespace stereo {

struct RectifiedPair {
  geometry::CameraInfo left, right;
  double alpha = 0.0;       //!< the free-scaling parameter used
  bool zero_disparity = true;  //!< CALIB_ZERO_DISPARITY used (equal cx in both P)
  bool projection_fitted = false;  //!< P fitted to the points of interest (see fitRectifiedProjection)
};

/**
 * @brief Keeps the rectifying rotations of `p` and fits new projections: one focal length (at most f_max),
 * one row centre and a principal point per camera, so that every left-frame point lies inside both images
 * with `margin` px to spare. False if a point is not in front of both rectified cameras.
 */
bool fitRectifiedProjection(RectifiedPair* p, const std::vector<Eigen::Vector3d>& points, double f_max, double margin);

/**
 * @brief Rectifies `rig` (raw cameras with their distortion) for images of the rig's size.
 * @param points_of_interest left-frame points that must stay inside both rectified images (may be empty).
 * @param margin_px distance those points must keep from the image border.
 * @throws std::runtime_error naming the problem if no alpha keeps the points inside.
 */
RectifiedPair rectifyStereo(const geometry::StereoRig& rig, const std::vector<Eigen::Vector3d>& points_of_interest = {},
                            double margin_px = 2.0);

/**
 * @brief Rectification of one camera's raw images from its CameraInfo (K, D, R, P): the undistort-rectify
 * maps are built once (fixed-point CV_16SC2), then each image is remapped with bilinear interpolation.
 * @throws std::invalid_argument if the CameraInfo has no size or a zero focal length.
 */
class Rectifier {
 public:
  explicit Rectifier(const geometry::CameraInfo& info);
  /** @brief The rectified image (same size and type as the raw one, which must match the CameraInfo size). */
  cv::Mat operator()(const cv::Mat& raw) const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  cv::Mat map1_, map2_;
  int width_ = 0, height_ = 0;
};

/** @brief Rectified pixel of a left-frame point in the left (right = false) or right rectified image. */
Eigen::Vector2d projectRectified(const RectifiedPair& pair, const Eigen::Vector3d& X_left, bool right);

}  // namespace stereo
}  // namespace skin3d
