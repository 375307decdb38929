// SPDX-License-Identifier: BSD-3-Clause
// Robust sphere fit: algebraic start, then IRLS Gauss-Newton with Tukey weights (see sphere_fit.h).
#include "skin3d/geometry/sphere_fit.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace geometry {

namespace {
double median(std::vector<double> v) {
  const auto mid = v.begin() + v.size() / 2;
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}
}  // namespace

SphereFit fitSphere(const std::vector<Eigen::Vector3d>& points, const SphereFitOptions& options) {
  const int n = static_cast<int>(points.size());
  if (n < 4) throw std::invalid_argument("fitSphere: need at least 4 points (got " + std::to_string(n) + ")");
  for (int i = 0; i < n; ++i)
    if (!points[i].allFinite()) throw std::invalid_argument("fitSphere: point " + std::to_string(i) + " is not finite");
  if (!(options.tukey_k > 0.0) || !(options.min_scale > 0.0) || options.max_iterations < 1)
    throw std::invalid_argument("fitSphere: need tukey_k > 0, min_scale > 0, max_iterations >= 1");

  // Centre the data for conditioning.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= n;
  double spread = 0.0;
  for (const auto& p : points) spread = std::max(spread, (p - mean).norm());
  if (!(spread > 0.0)) throw std::invalid_argument("fitSphere: all points coincide");

  // Algebraic fit: [2x 2y 2z 1] [c; d] = |x|^2 with d = r^2 - |c|^2 (in units of spread).
  Eigen::MatrixXd A(n, 4);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d q = (points[i] - mean) / spread;
    A.row(i) << 2.0 * q.x(), 2.0 * q.y(), 2.0 * q.z(), 1.0;
    b[i] = q.squaredNorm();
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  qr.setThreshold(1e-10);
  if (qr.rank() < 4) throw std::invalid_argument("fitSphere: the points are coplanar or collinear (no unique sphere)");
  const Eigen::Vector4d s = qr.solve(b);
  Eigen::Vector3d c = s.head<3>();
  const double r2 = s[3] + c.squaredNorm();
  if (!(r2 > 0.0)) throw std::invalid_argument("fitSphere: the algebraic fit gave no real sphere");
  double r = std::sqrt(r2);
  c = mean + spread * c;
  r *= spread;

  SphereFit out;
  out.points = n;
  std::vector<double> e(n), w(n, 1.0);
  double scale = 0.0;
  Eigen::Matrix4d N = Eigen::Matrix4d::Zero();
  for (int it = 0; it < options.max_iterations; ++it) {
    out.iterations = it + 1;
    for (int i = 0; i < n; ++i) e[i] = (points[i] - c).norm() - r;
    std::vector<double> ae(n);
    for (int i = 0; i < n; ++i) ae[i] = std::abs(e[i]);
    scale = std::max(options.min_scale, 1.4826 * median(ae));
    const double cut = options.tukey_k * scale;
    for (int i = 0; i < n; ++i) {
      const double u = e[i] / cut;
      w[i] = std::abs(u) < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
    }
    // Gauss-Newton on (c, r): de/dc = -(x - c)/|x - c|, de/dr = -1.
    N.setZero();
    Eigen::Vector4d g = Eigen::Vector4d::Zero();
    for (int i = 0; i < n; ++i) {
      if (w[i] == 0.0) continue;
      const Eigen::Vector3d d = points[i] - c;
      const double dn = d.norm();
      if (!(dn > 0.0)) continue;
      Eigen::Vector4d J;
      J << -d / dn, -1.0;
      N.noalias() += w[i] * J * J.transpose();
      g.noalias() += w[i] * J * e[i];
    }
    Eigen::LDLT<Eigen::Matrix4d> ldlt(N);
    if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > 1e-14))
      throw std::invalid_argument("fitSphere: too few inliers to determine a sphere");
    const Eigen::Vector4d step = -ldlt.solve(g);
    c += step.head<3>();
    r += step[3];
    if (step.norm() < options.tolerance) break;
  }
  // Final residuals and statistics.
  double ss_in = 0.0, ss_all = 0.0, sw = 0.0;
  out.inlier.assign(n, false);
  for (int i = 0; i < n; ++i) {
    e[i] = (points[i] - c).norm() - r;
    ss_all += e[i] * e[i];
    if (std::abs(e[i]) < options.tukey_k * scale) {
      out.inlier[i] = true;
      ++out.inliers;
      ss_in += e[i] * e[i];
      sw += 1.0;
    }
  }
  out.centre = c;
  out.radius = r;
  out.robust_scale = scale;
  out.rms_all = std::sqrt(ss_all / n);
  out.rms_inliers = out.inliers > 0 ? std::sqrt(ss_in / out.inliers) : 0.0;
  if (out.inliers > 4) out.covariance = N.inverse() * (ss_in / (sw - 4.0));
  return out;
}

}  // namespace geometry
}  // namespace skin3d
