// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/geometry/triangulation.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <cmath>
#include <sstream>

namespace skin3d {
namespace geometry {

TriangulationResult triangulateMmse(const std::vector<CameraObservation>& views,
                                    const TriangulationOptions& options) {
  TriangulationResult result;
  if (views.size() < 2) {
    result.message = "triangulation needs at least two views, got " + std::to_string(views.size());
    return result;
  }
  if (!(options.prior_sigma > 0.0)) {
    result.message = "triangulation: prior_sigma must be > 0 (infinity for the vague prior)";
    return result;
  }
  for (size_t i = 0; i < views.size(); ++i) {
    const auto& v = views[i];
    if (!v.uv.allFinite() || !v.K.allFinite() || !v.R.allFinite() || !v.t.allFinite() ||
        !v.cov_uv.allFinite()) {
      result.message = "triangulation: view " + std::to_string(i) + " has a NaN or Inf entry";
      return result;
    }
    if (v.cov_uv.determinant() <= 0.0 || v.cov_uv(0, 0) <= 0.0) {
      result.message = "triangulation: view " + std::to_string(i) + " has a pixel covariance that is not positive definite";
      return result;
    }
  }

  const double prior_info =
      std::isinf(options.prior_sigma) ? 0.0 : 1.0 / (options.prior_sigma * options.prior_sigma);
  std::vector<double> depth(views.size(), 1.0);  // first pass: equal weights
  Eigen::Vector3d X = options.prior_mean;
  Eigen::Matrix3d info;
  const int passes = std::max(1, options.iterations);
  for (int pass = 0; pass <= passes; ++pass) {
    info = prior_info * Eigen::Matrix3d::Identity();
    Eigen::Vector3d eta = prior_info * options.prior_mean;
    for (size_t i = 0; i < views.size(); ++i) {
      const auto& v = views[i];
      const Eigen::RowVector3d k1 = v.K.row(0), k2 = v.K.row(1), k3 = v.K.row(2);
      Eigen::Matrix<double, 2, 3> A;  // rows (k - u k3)^T
      A.row(0) = k1 - v.uv.x() * k3;
      A.row(1) = k2 - v.uv.y() * k3;
      const Eigen::Matrix<double, 2, 3> H = A * v.R;
      const Eigen::Vector2d z = -A * v.t;
      const Eigen::Matrix2d Cn = depth[i] * depth[i] * v.cov_uv;
      const Eigen::Matrix2d Cn_inv = Cn.inverse();
      info += H.transpose() * Cn_inv * H;
      eta += H.transpose() * Cn_inv * z;
    }
    Eigen::LDLT<Eigen::Matrix3d> ldlt(info);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
      result.message = "triangulation: information matrix is singular (parallel rays?)";
      return result;
    }
    X = ldlt.solve(eta);
    if (pass == passes) break;
    for (size_t i = 0; i < views.size(); ++i) {
      const double zi = views[i].K.row(2) * (views[i].R * X + views[i].t);
      if (!(zi > 0.0)) {
        std::ostringstream os;
        os << "triangulation: the point is behind camera " << i << " (depth " << zi << ")";
        result.message = os.str();
        return result;
      }
      depth[i] = zi;
    }
  }
  Eigen::Matrix3d C = info.inverse();
  C = 0.5 * (C + C.transpose());
  if (!X.allFinite() || !C.allFinite()) {
    result.message = "triangulation: result is not finite";
    return result;
  }
  result.ok = true;
  result.X = X;
  result.C = C;
  return result;
}

}  // namespace geometry
}  // namespace skin3d
