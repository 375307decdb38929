// SPDX-License-Identifier: BSD-3-Clause
// The site scan's registration of a frame to the fused surface (site_fusion.h, 2.).
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "skin3d/geometry/quaternion.h"
#include "site_detail.h"

namespace skin3d {
namespace site {
namespace site_detail {

namespace {

/** The point-to-plane residuals (m) of the picked samples under the pose T, their weights 1 / (sigma_sample^2 +
 *  sigma_cell^2) and (if `J`) their Jacobians in the step about `c`; the count of samples on fused skin. */
int residuals(const FusionGrid& g, const View& view, const std::vector<Sample>& samples, const std::vector<int>& pick,
              const Eigen::Isometry3d& T, const Eigen::Vector3d& c, std::vector<double>* r, std::vector<double>* w,
              std::vector<Eigen::Matrix<double, 1, 6>>* J) {
  r->clear();
  w->clear();
  if (J) J->clear();
  for (int k : pick) {
    Eigen::Vector3d Xw, uvw;
    if (incidenceCos(g, view, T, samples[k].X, &Xw, &uvw) < view.cos_max) continue;
    double val, sig, su, sv;
    if (!g.lookup(uvw.x(), uvw.y(), &val, &sig, &su, &sv)) continue;
    Eigen::Vector3d P;
    const Eigen::Vector3d n = g.tangentPlane(uvw, val, su, sv, &P);
    Eigen::Matrix<double, 1, 6> Jk;
    r->push_back(pointToPlane(Xw - c, P - c, n, J ? &Jk : nullptr));
    w->push_back(1.0 / (static_cast<double>(samples[k].sigma) * samples[k].sigma + sig * sig));
    if (J) J->push_back(Jk);
  }
  return static_cast<int>(r->size());
}

/** The mean Huber cost (threshold kh) of weighted residuals; infinite when there are none. */
double huberCost(const std::vector<double>& r, const std::vector<double>& w, double kh) {
  if (r.empty()) return std::numeric_limits<double>::infinity();
  double s = 0;
  for (std::size_t q = 0; q < r.size(); ++q) {
    const double a = std::fabs(r[q]);
    s += w[q] * (a <= kh ? 0.5 * a * a : kh * (a - 0.5 * kh));
  }
  return s / static_cast<double>(r.size());
}

/** The pose after the step d = (dphi, dt) about the point c (world). */
Eigen::Isometry3d stepped(const Eigen::Isometry3d& T, const Eigen::Matrix<double, 6, 1>& d, const Eigen::Vector3d& c) {
  const Eigen::Matrix3d dR = geometry::so3Exp(d.head<3>());
  Eigen::Isometry3d Tn = Eigen::Isometry3d::Identity();
  Tn.linear() = dR * T.linear();
  Tn.translation() = dR * (T.translation() - c) + c + d.tail<3>();
  return Tn;
}

}  // namespace

/**
 * Levenberg-Marquardt on the Huber cost of the point-to-plane residuals, the samples looked up again at every pose
 * tried. A step is taken only when it lowers the cost (else the damping grows and it is tried again): a limb is
 * nearly a cylinder, and sliding along or turning about its axis is held only by the skin's relief, so undamped
 * Gauss-Newton steps along those directions swing back and forth by tens of micrometres. It stops when no step
 * lowers the cost, or when the step moves the samples by under a tenth of their residual scatter (RMS): the
 * alignment is then settled far below what one sample can tell.
 */
bool registerFrame(const FusionGrid& g, const View& view, const std::vector<Sample>& samples, const SiteOptions& o,
                   const Eigen::Isometry3d& T_W_C, SiteFrame* F) {
  Eigen::Isometry3d T = T_W_C;
  const int stride = o.register_stride;
  std::vector<int> pick;
  for (std::size_t k = 0; k < samples.size(); k += static_cast<std::size_t>(stride * stride)) pick.push_back(static_cast<int>(k));
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int k : pick) c += T_W_C * samples[k].X;
  c /= static_cast<double>(pick.size());
  int found = 0;
  double lambda = 1e-4;  // Marquardt's damping, relative to the normal matrix's diagonal
  std::vector<double> res, ws, res2, ws2;
  std::vector<Eigen::Matrix<double, 1, 6>> Js;
  for (int it = 0; it < o.register_iterations; ++it) {
    found = residuals(g, view, samples, pick, T, c, &res, &ws, &Js);
    if (found < 50) break;
    std::vector<double> a(res.size());
    for (std::size_t q = 0; q < res.size(); ++q) a[q] = std::fabs(res[q]);
    std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
    const double scale = std::max(1.4826 * a[a.size() / 2], 1e-6);
    const double kh = 2.0 * scale;
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    for (std::size_t q = 0; q < res.size(); ++q) {
      const double w = ws[q] * (std::fabs(res[q]) <= kh ? 1.0 : kh / std::fabs(res[q]));
      H += w * Js[q].transpose() * Js[q];
      b += w * Js[q].transpose() * res[q];
    }
    const double cost = huberCost(res, ws, kh);
    bool taken = false;
    Eigen::Matrix<double, 6, 1> d;
    for (int tries = 0; tries < 8 && !taken; ++tries) {
      Eigen::Matrix<double, 6, 6> A = H;
      A.diagonal() += lambda * H.diagonal() + Eigen::Matrix<double, 6, 1>::Constant(1e-12 * H.diagonal().maxCoeff());
      d = -A.ldlt().solve(b);
      if (!d.allFinite()) break;
      const Eigen::Isometry3d Tn = stepped(T, d, c);
      if (residuals(g, view, samples, pick, Tn, c, &res2, &ws2, nullptr) >= 50 && huberCost(res2, ws2, kh) < cost) {
        T = Tn;
        taken = true;
        lambda = std::max(lambda / 4, 1e-7);
      } else {
        lambda *= 8;
      }
    }
    if (!taken) break;  // no step lowers the cost: settled
    F->registration_iterations = it + 1;
    double m2 = 0;  // the step's motion of the samples (about c: dphi x (X - c) + dt)
    for (int k : pick) m2 += (d.head<3>().cross(T_W_C * samples[k].X - c) + d.tail<3>()).squaredNorm();
    if (std::sqrt(m2 / static_cast<double>(pick.size())) < 0.1 * scale) break;
  }
  int usable = 0;
  for (int k : pick) {
    Eigen::Vector3d Xw, uvw;
    if (incidenceCos(g, view, T_W_C, samples[k].X, &Xw, &uvw) >= view.cos_max) ++usable;
  }
  F->overlap = usable > 0 ? static_cast<double>(found) / usable : 0.0;
  if (F->overlap < o.min_overlap) {
    F->reason = "it overlaps the fused site on " + std::to_string(static_cast<int>(std::lround(100 * F->overlap))) +
               " % of its samples (site_min_overlap " + std::to_string(static_cast<int>(std::lround(100 * o.min_overlap))) + " %)";
    return false;
  }
  double c2 = 0;
  for (int k : pick) c2 += ((T * samples[k].X) - (T_W_C * samples[k].X)).squaredNorm();
  F->correction_rms = std::sqrt(c2 / pick.size());
  if (F->correction_rms > o.max_correction) {
    F->reason = "its registration moved it by " + std::to_string(F->correction_rms * 1e3) +
               " mm RMS from the pose given (site_max_correction_mm " + std::to_string(o.max_correction * 1e3) + ")";
    return false;
  }
  F->pose = T;
  return true;
}

}  // namespace site_detail
}  // namespace site
}  // namespace skin3d
