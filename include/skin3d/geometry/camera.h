/**
 * @file camera.h
 * @brief Pinhole camera with plumb_bob distortion, built from a CameraInfo-like struct.
 *
 * Frames: optical convention (x right, y down, z forward). Pixels: (u, v) with
 * the origin at the centre of the top-left pixel, as OpenCV and ROS use.
 * Lengths are whatever unit the caller uses for points (SI metres on ROS
 * interfaces); pixels are pixels.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace skin3d {
namespace geometry {

/**
 * @brief The geometric content of sensor_msgs/CameraInfo, without ROS.
 *
 * K: intrinsics of the raw image; D: plumb_bob (k1, k2, p1, p2, k3) or empty;
 * R: rectification rotation (rectified <- raw camera frame);
 * P: projection of the rectified image, P(0,3) = -fx' * B for the right camera.
 */
struct CameraInfo {
  int width = 0;
  int height = 0;
  std::string distortion_model = "plumb_bob";
  std::vector<double> D;
  Eigen::Matrix3d K = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Matrix<double, 3, 4> P = Eigen::Matrix<double, 3, 4>::Zero();
};

/** @brief Pinhole camera with optional plumb_bob lens distortion. */
class PinholeCamera {
 public:
  PinholeCamera() = default;
  /**
   * @param K 3x3 intrinsic matrix (K(0,0) = fx > 0, K(1,1) = fy > 0, last row 0 0 1).
   * @param width,height image size in pixels (> 0).
   * @param D plumb_bob coefficients k1 k2 p1 p2 [k3]; empty = no distortion.
   * @throws std::invalid_argument naming the bad field.
   */
  PinholeCamera(const Eigen::Matrix3d& K, int width, int height, std::vector<double> D = {});

  /** @brief Raw (distorted) camera of a CameraInfo: K and D. */
  static PinholeCamera fromCameraInfo(const CameraInfo& info);
  /** @brief Rectified camera of a CameraInfo: left 3x3 of P, no distortion. */
  static PinholeCamera rectifiedFromCameraInfo(const CameraInfo& info);

  const Eigen::Matrix3d& K() const { return K_; }
  const std::vector<double>& D() const { return D_; }
  int width() const { return width_; }
  int height() const { return height_; }
  double fx() const { return K_(0, 0); }
  double fy() const { return K_(1, 1); }
  double cx() const { return K_(0, 2); }
  double cy() const { return K_(1, 2); }
  bool hasDistortion() const;

  /**
   * @brief Pixel of a point in the camera frame (with distortion).
   * @param X point, X.z() > 0.
   * @param J optional 2x3 Jacobian d(uv)/dX.
   */
  Eigen::Vector2d project(const Eigen::Vector3d& X, Eigen::Matrix<double, 2, 3>* J = nullptr) const;

  /** @brief Distorted normalised coordinates of ideal normalised ones; J = d(out)/d(in). */
  Eigen::Vector2d distortNormalized(const Eigen::Vector2d& xn, Eigen::Matrix2d* J = nullptr) const;

  /**
   * @brief Ideal normalised coordinates (x/z, y/z) of a distorted pixel (Newton iterations).
   * @param J optional d(xn)/d(uv).
   */
  Eigen::Vector2d undistortToNormalized(const Eigen::Vector2d& uv, Eigen::Matrix2d* J = nullptr) const;

  /** @brief Ideal (undistorted) pixel K [xn; 1] of a distorted pixel; J = d(out)/d(uv). */
  Eigen::Vector2d undistortPixel(const Eigen::Vector2d& uv, Eigen::Matrix2d* J = nullptr) const;

  /** @brief Viewing ray (x, y, 1) of a pixel in the camera frame; J = d(ray)/d(uv) (3x2). */
  Eigen::Vector3d unproject(const Eigen::Vector2d& uv, Eigen::Matrix<double, 3, 2>* J = nullptr) const;

  /** @brief True when the pixel lies inside [-0.5, width-0.5] x [-0.5, height-0.5]. */
  bool inImage(const Eigen::Vector2d& uv) const;

 private:
  Eigen::Matrix3d K_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d Kinv_ = Eigen::Matrix3d::Identity();
  std::vector<double> D_ = std::vector<double>(5, 0.0);  // k1 k2 p1 p2 k3
  int width_ = 0;
  int height_ = 0;
};

}  // namespace geometry
}  // namespace skin3d
