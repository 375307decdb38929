/**
 * @file covariance_ellipsoid.h
 * @brief The k-sigma ellipsoid of a 3x3 covariance: semi-axes and orientation, for display (rviz SPHERE
 * markers of the SLAM landmarks) and reports.
 *
 * With C = V diag(l1, l2, l3) V^T (l1 >= l2 >= l3 > 0, V's columns the unit eigenvectors), the k-sigma
 * ellipsoid { x : x^T C^-1 x = k^2 } has semi-axes k sqrt(l_i) along V's columns. `orientation` is the
 * rotation R (a right-handed V: the third column flipped when det V < 0) that takes the ellipsoid's own
 * x, y, z axes to those directions, so that C = R diag(a_i / k)^2 R^T. An rviz SPHERE marker of this
 * ellipsoid has pose.orientation = orientation and scale = 2 * semi_axes (the marker's scale is its diameter).
 *
 * Units: semi-axes in the square root of the covariance's unit (m for m^2).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace skin3d {
namespace geometry {

struct CovarianceEllipsoid {
  Eigen::Vector3d semi_axes = Eigen::Vector3d::Zero();              //!< k-sigma semi-axes, largest first
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  //!< ellipsoid axes -> covariance frame
};

/**
 * @brief The `sigmas`-sigma ellipsoid of C.
 * @return false (and `out` untouched) when `sigmas` is not a positive finite number, or C has a NaN/Inf, is
 *         not symmetric (|C - C^T| above 1e-9 of its largest entry) or not positive definite. A symmetric C
 *         is symmetrised before the decomposition.
 */
bool covarianceEllipsoid(const Eigen::Matrix3d& C, double sigmas, CovarianceEllipsoid* out);

}  // namespace geometry
}  // namespace skin3d
