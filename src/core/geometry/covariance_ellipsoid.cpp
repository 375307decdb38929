// SPDX-License-Identifier: BSD-3-Clause
// k-sigma ellipsoid of a 3x3 covariance (see covariance_ellipsoid.h).
#include "skin3d/geometry/covariance_ellipsoid.h"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace skin3d {
namespace geometry {

bool covarianceEllipsoid(const Eigen::Matrix3d& C, double sigmas, CovarianceEllipsoid* out) {
  if (!(sigmas > 0.0) || !std::isfinite(sigmas) || !C.allFinite()) return false;
  const double scale = C.cwiseAbs().maxCoeff();
  if (!(scale > 0.0) || (C - C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) return false;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(0.5 * (C + C.transpose()));
  if (es.info() != Eigen::Success) return false;
  const Eigen::Vector3d l = es.eigenvalues();  // ascending
  if (!(l[0] > 0.0)) return false;
  Eigen::Matrix3d R;
  for (int k = 0; k < 3; ++k) {
    R.col(k) = es.eigenvectors().col(2 - k);  // largest first
    out->semi_axes[k] = sigmas * std::sqrt(l[2 - k]);
  }
  if (R.determinant() < 0.0) R.col(2) = -R.col(2);
  out->orientation = Eigen::Quaterniond(R).normalized();
  return true;
}

}  // namespace geometry
}  // namespace skin3d
