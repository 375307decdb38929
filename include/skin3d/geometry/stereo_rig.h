/**
 * @file stereo_rig.h
 * @brief Two calibrated cameras and their extrinsics; projection and MMSE triangulation.
 *
 * The reference frame is the left camera's optical frame. The right camera
 * sees a left-frame point X as X_r = R_rl X + t_rl; its optical centre lies at
 * c_r = -R_rl^T t_rl in the left frame (e.g. (0.105, 0, 0.015) m for the SLAM rig).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>

#include "skin3d/geometry/camera.h"
#include "skin3d/geometry/triangulation.h"

namespace skin3d {
namespace geometry {

class StereoRig {
 public:
  StereoRig() = default;
  /**
   * @param R_rl right <- left rotation; @param t_rl right <- left translation.
   * @throws std::invalid_argument for a non-rotation R_rl or a zero baseline.
   */
  StereoRig(const PinholeCamera& left, const PinholeCamera& right, const Eigen::Matrix3d& R_rl,
            const Eigen::Vector3d& t_rl);

  /**
   * @brief Rig from the pose of the right camera in the left frame.
   * @param R_lr orientation of the right camera in the left frame (left <- right).
   * @param centre_right position of the right optical centre in the left frame.
   */
  static StereoRig fromRightPose(const PinholeCamera& left, const PinholeCamera& right,
                                 const Eigen::Matrix3d& R_lr, const Eigen::Vector3d& centre_right);

  /**
   * @brief Raw (distorted) rig from a stereo calibration's two CameraInfo.
   *
   * X_r = R_right^T (R_left X_l - (B, 0, 0)) with B = -P_right(0,3) / P_right(0,0).
   * @throws std::invalid_argument on an uncalibrated or inconsistent pair.
   */
  static StereoRig fromCameraInfo(const CameraInfo& left, const CameraInfo& right);

  const PinholeCamera& left() const { return left_; }
  const PinholeCamera& right() const { return right_; }
  const Eigen::Matrix3d& R_rl() const { return R_rl_; }
  const Eigen::Vector3d& t_rl() const { return t_rl_; }
  /** @brief Right optical centre in the left frame. */
  Eigen::Vector3d rightCentre() const { return -R_rl_.transpose() * t_rl_; }
  /** @brief Distance between the optical centres. */
  double baseline() const { return t_rl_.norm(); }
  /** @brief Angle between the two optical axes (rad). */
  double opticalAxesAngle() const;

  /** @brief Point in the right camera frame. */
  Eigen::Vector3d toRight(const Eigen::Vector3d& X_left) const { return R_rl_ * X_left + t_rl_; }

  /** @brief Pixels (distorted) of a left-frame point in both cameras; false if behind either camera. */
  bool project(const Eigen::Vector3d& X_left, Eigen::Vector2d* uv_left, Eigen::Vector2d* uv_right) const;

  /**
   * @brief MMSE triangulation of a pair of measured (distorted) pixels.
   *
   * Each pixel is undistorted and its isotropic noise sigma_px is propagated
   * through the undistortion Jacobian. Result in the left frame with its 3x3 covariance.
   */
  TriangulationResult triangulate(const Eigen::Vector2d& uv_left, const Eigen::Vector2d& uv_right,
                                  double sigma_px,
                                  const TriangulationOptions& options = TriangulationOptions()) const;

 private:
  PinholeCamera left_, right_;
  Eigen::Matrix3d R_rl_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_rl_ = Eigen::Vector3d::Zero();
};

}  // namespace geometry
}  // namespace skin3d
