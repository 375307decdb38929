/**
 * @file sphere_fit.h
 * @brief Robust least-squares sphere fit of a point cloud (the SLAM map of the globe, thesis Table 7.2).
 *
 * Start: the algebraic (linear) fit |x|^2 = 2 c.x + (r^2 - |c|^2) on all points. Then iteratively
 * re-weighted Gauss-Newton on the geometric residuals e_i = |x_i - c| - r with Tukey biweight weights
 * w_i = (1 - (e_i / (k s))^2)^2 for |e_i| < k s, else 0, k = 4.685 (95 % efficiency at the normal
 * distribution), s = 1.4826 MAD(e) re-estimated every iteration (never below `min_scale`). Points with
 * weight 0 at convergence are outliers. Reported: centre, radius, the RMS of the inliers' residuals, the
 * RMS over all points, the inlier count and the 4x4 covariance of (c, r) from the Gauss-Newton normal
 * equations scaled by the inliers' residual variance.
 *
 * Units: those of the input (metres in skin3d).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <vector>

namespace skin3d {
namespace geometry {

struct SphereFitOptions {
  double tukey_k = 4.685;      //!< Tukey biweight tuning constant, in robust sigmas
  double min_scale = 1e-9;     //!< floor of the robust residual scale (input units)
  int max_iterations = 50;
  double tolerance = 1e-12;    //!< stop when the parameter step is below this (input units)
};

struct SphereFit {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0.0;
  double rms_inliers = 0.0;    //!< RMS of the geometric residuals of the inliers
  double rms_all = 0.0;        //!< RMS over all points
  double robust_scale = 0.0;   //!< 1.4826 MAD of the residuals at convergence
  int inliers = 0;
  int points = 0;
  int iterations = 0;
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();  //!< of (centre, radius)
  std::vector<bool> inlier;    //!< per input point
};

/**
 * @brief Fits a sphere to `points`.
 * @throws std::invalid_argument with fewer than 4 points, a non-finite point, or points that do not
 *         determine a sphere (coplanar / collinear: the linear system is singular).
 */
SphereFit fitSphere(const std::vector<Eigen::Vector3d>& points, const SphereFitOptions& options = SphereFitOptions());

}  // namespace geometry
}  // namespace skin3d
