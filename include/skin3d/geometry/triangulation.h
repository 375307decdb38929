/**
 * @file triangulation.h
 * @brief MMSE triangulation of a 3D point from several calibrated views (thesis §2.8, Algorithm 2.1).
 *
 * Each camera i sees the reference-frame point X as X_i = R_i X + t_i and
 * measures the ideal (undistorted) pixel (u, v) = K_i X_i / z_i. Rearranged,
 * each view gives two equations linear in X,
 *     (k1 - u k3)^T R_i X = (u k3 - k1)^T t_i,   (k2 - v k3)^T R_i X = (v k3 - k2)^T t_i,
 * whose noise is the pixel noise scaled by the depth z_i: C_n = z_i^2 C_uv.
 * The views are fused by the Kalman/MMSE update of Algorithm 2.1 from a
 * vague prior (sigma >> depth range), re-weighted with z_i of the previous
 * estimate. The update is evaluated in information form
 * (C^-1 = C0^-1 + sum H^T C_n^-1 H), which is the same estimator but does not
 * lose the small posterior covariance to cancellation against the huge prior.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

namespace skin3d {
namespace geometry {

/** @brief One camera's view of the point. */
struct CameraObservation {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  //!< intrinsics of the ideal (undistorted) image
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  //!< camera <- reference rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      //!< camera <- reference translation
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();     //!< measured ideal pixel
  Eigen::Matrix2d cov_uv = Eigen::Matrix2d::Identity() * 0.25;  //!< pixel covariance (px^2)
};

struct TriangulationOptions {
  /** Prior std-dev per axis (same unit as t). The default, infinity, is the vague-prior limit of
   *  Algorithm 2.1 (sigma >> depth range) whatever the unit; a finite value adds a real prior. */
  double prior_sigma = std::numeric_limits<double>::infinity();
  Eigen::Vector3d prior_mean = Eigen::Vector3d::Zero();
  int iterations = 3;                                //!< re-weighting passes with the estimated depths
};

struct TriangulationResult {
  bool ok = false;
  Eigen::Vector3d X = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Matrix3d C = Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
  std::string message;  //!< why ok is false
};

/** @brief MMSE triangulation of one point from two or more views. */
TriangulationResult triangulateMmse(const std::vector<CameraObservation>& views,
                                    const TriangulationOptions& options = TriangulationOptions());

}  // namespace geometry
}  // namespace skin3d
