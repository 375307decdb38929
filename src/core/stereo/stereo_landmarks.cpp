// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/stereo/stereo_landmarks.h"

#include <Eigen/LU>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "skin3d/geometry/triangulation.h"

namespace skin3d {
namespace stereo {

namespace {
void checkP(const geometry::CameraInfo& c, const char* side) {
  const double fx = c.P(0, 0), fy = c.P(1, 1);
  if (!(fx > 0.0) || !(fy > 0.0) || !c.P.allFinite()) {
    std::ostringstream os;
    os << side << " camera_info P[0] = " << fx << ", P[5] = " << fy << ": not a calibrated, rectified camera";
    throw std::invalid_argument(os.str());
  }
  const double orth = (c.R.transpose() * c.R - Eigen::Matrix3d::Identity()).norm();
  if (!c.R.allFinite() || orth > 1e-6) {
    std::ostringstream os;
    os << side << " camera_info R is not a rotation (|R^T R - I| = " << orth << ")";
    throw std::invalid_argument(os.str());
  }
}
}  // namespace

double estimateLocalisationSigma(const std::vector<StereoMatch>& matches) {
  if (matches.size() < 10) return std::numeric_limits<double>::quiet_NaN();
  std::vector<double> dv;
  dv.reserve(matches.size());
  for (const auto& m : matches) dv.push_back(m.left.y() - m.right.y());
  const auto mid = dv.begin() + dv.size() / 2;
  std::nth_element(dv.begin(), mid, dv.end());
  const double med = *mid;
  for (auto& d : dv) d = std::abs(d - med);
  std::nth_element(dv.begin(), mid, dv.end());
  return 1.4826 * *mid / std::sqrt(2.0);
}

namespace {
// Matches whose disparity disagrees with the plane through their neighbours' disparities. The neighbours are
// taken among the matches not yet rejected, and the test is repeated (up to `passes` times, until nothing
// changes): a cluster of mismatches contaminates its members' planes and spreads in the first pass and is
// exposed once its worst members are gone.
std::vector<bool> disparityOutliers(const std::vector<StereoMatch>& m, int k, double gate, double sigma, int passes = 3) {
  std::vector<bool> out(m.size(), false);
  if (gate <= 0.0 || k < 3 || static_cast<int>(m.size()) < 2 * k) return out;
  std::vector<std::pair<double, size_t>> nb;
  nb.reserve(m.size());
  Eigen::MatrixXd A(k, 3);
  Eigen::VectorXd b(k);
  std::vector<double> res(k);
  std::vector<double> residual(m.size()), spread(m.size());
  for (int pass = 0; pass < passes; ++pass) {
    std::vector<bool> next = out;
    bool changed = false;
    std::vector<double> spreads;
    for (size_t i = 0; i < m.size(); ++i) {
      if (out[i]) continue;
      nb.clear();
      for (size_t j = 0; j < m.size(); ++j)
        if (j != i && !out[j]) nb.emplace_back((m[j].left - m[i].left).squaredNorm(), j);
      if (static_cast<int>(nb.size()) < 2 * k) return out;
      std::partial_sort(nb.begin(), nb.begin() + k, nb.end());
      for (int q = 0; q < k; ++q) {
        const StereoMatch& n = m[nb[q].second];
        A.row(q) << 1.0, n.left.x() - m[i].left.x(), n.left.y() - m[i].left.y();
        b[q] = n.left.x() - n.right.x();
      }
      const Eigen::Vector3d c = A.colPivHouseholderQr().solve(b);
      for (int q = 0; q < k; ++q) res[q] = std::abs(b[q] - A.row(q).dot(c));
      std::nth_element(res.begin(), res.begin() + k / 2, res.end());
      residual[i] = std::abs(m[i].left.x() - m[i].right.x() - c[0]);
      spread[i] = 1.4826 * res[k / 2];
      spreads.push_back(spread[i]);
    }
    // A neighbourhood far more scattered than the frame's typical one is itself contaminated by mismatches:
    // its spread is capped at 3 x the median local spread of the frame.
    std::nth_element(spreads.begin(), spreads.begin() + spreads.size() / 2, spreads.end());
    const double cap = 3.0 * spreads[spreads.size() / 2];
    for (size_t i = 0; i < m.size(); ++i) {
      if (out[i]) continue;
      if (residual[i] > gate * std::max(std::min(spread[i], cap), std::sqrt(2.0) * sigma)) {
        next[i] = true;
        changed = true;
      }
    }
    out.swap(next);
    if (!changed) break;
  }
  return out;
}

// Per kept match: the residual of its disparity against a quadratic surface through its k nearest kept
// neighbours' disparities (left image: a plane would leave the surface's curvature in the residuals), and that
// surface's disparity gradient at the match (px per px).
void localPlanes(const std::vector<StereoMatch>& m, const std::vector<size_t>& kept, int k, std::vector<double>* residual,
                 std::vector<Eigen::Vector2d>* gradient, std::vector<std::vector<size_t>>* neighbours) {
  const size_t n = kept.size();
  residual->assign(n, 0.0);
  gradient->assign(n, Eigen::Vector2d::Zero());
  neighbours->assign(n, std::vector<size_t>(k));
  std::vector<std::pair<double, size_t>> nb(n);
  Eigen::MatrixXd A(k, 6);
  Eigen::VectorXd b(k);
  for (size_t ii = 0; ii < n; ++ii) {
    const StereoMatch& mi = m[kept[ii]];
    for (size_t jj = 0; jj < n; ++jj) nb[jj] = {(m[kept[jj]].left - mi.left).squaredNorm(), jj};
    std::partial_sort(nb.begin(), nb.begin() + k + 1, nb.end());  // nb[0] is ii itself
    const double scale = std::sqrt(std::max(1.0, nb[k].first));  // conditioning of the quadratic terms
    for (int q = 0; q < k; ++q) {
      const StereoMatch& o = m[kept[nb[q + 1].second]];
      (*neighbours)[ii][q] = nb[q + 1].second;
      const double x = (o.left.x() - mi.left.x()) / scale, y = (o.left.y() - mi.left.y()) / scale;
      A.row(q) << 1.0, x, y, x * x, x * y, y * y;
      b[q] = o.left.x() - o.right.x();
    }
    const Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
    (*residual)[ii] = mi.left.x() - mi.right.x() - c[0];
    (*gradient)[ii] = Eigen::Vector2d(c[1], c[2]) / scale;
  }
}

// Localisation variance model var = sum_j c_j phi_j (phi_0 = 1), fitted by least squares to the squared row
// residuals (v_l - v_r)^2 / 2 of the matches that passed the row gate (each residual is the difference of two
// localisation errors). A second moment on purpose: the NEES a covariance must match is one, and the row
// residuals are heavy-tailed, so a median-based spread would make the covariances too small. The slopes
// c_1.. are kept >= 0: a regressor whose slope comes out negative is dropped and the rest refitted, and so is
// one that does not spread (max < 1.5 min + 1e-12: ORB's fixed patch size, or no slant measured). False with
// fewer than 50 residuals (keep the pooled sigma).
bool fitVarianceModel(const std::vector<double>& dv, const std::vector<std::vector<double>>& phi, std::vector<double>* c) {
  const size_t n = dv.size();
  if (n < 50 || phi.empty()) return false;
  const size_t p = phi[0].size();
  std::vector<bool> active(p, true);
  for (size_t j = 1; j < p; ++j) {
    double mn = 1e300, mx = -1e300;
    for (size_t i = 0; i < n; ++i) {
      mn = std::min(mn, phi[i][j]);
      mx = std::max(mx, phi[i][j]);
    }
    active[j] = mx > 1.5 * mn + 1e-12;
  }
  for (int iter = 0; iter < static_cast<int>(p); ++iter) {
    std::vector<size_t> idx;
    for (size_t j = 0; j < p; ++j)
      if (active[j]) idx.push_back(j);
    Eigen::MatrixXd N = Eigen::MatrixXd::Zero(idx.size(), idx.size());
    Eigen::VectorXd g = Eigen::VectorXd::Zero(idx.size());
    for (size_t i = 0; i < n; ++i) {
      Eigen::VectorXd f(idx.size());
      for (size_t q = 0; q < idx.size(); ++q) f[q] = phi[i][idx[q]];
      N += f * f.transpose();
      g += f * (0.5 * dv[i] * dv[i]);
    }
    const Eigen::VectorXd sol = N.ldlt().solve(g);
    if (!sol.allFinite()) return false;
    bool neg = false;
    for (size_t q = 1; q < idx.size(); ++q)
      if (sol[q] < 0.0) {
        active[idx[q]] = false;
        neg = true;
      }
    if (!neg) {
      c->assign(p, 0.0);
      for (size_t q = 0; q < idx.size(); ++q) (*c)[idx[q]] = sol[q];
      return true;
    }
  }
  return false;
}

// Disparity variance model var_d(t) = a + b t^2 (t = tan of the surface slant) fitted robustly to the plane
// residuals: the matches are split into 5 bins by t^2, each bin's variance is estimated as
// median(r^2) / 0.455 (the chi2(1) median) / (1 + h) with h = 6 / k (the quadratic's own prediction variance
// at the centre of k neighbours), and a line is fitted through the bins weighted by their counts. Returns false
// when there are too few matches (fewer than 10 per bin).
bool fitSlantNoise(const std::vector<double>& residual, const std::vector<double>& t2, int k, double* a, double* b) {
  const size_t n = residual.size();
  if (n < 50) return false;
  std::vector<size_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t l, size_t r) { return t2[l] < t2[r]; });
  const int bins = 5;
  const double h = 6.0 / k;
  Eigen::Matrix2d N = Eigen::Matrix2d::Zero();
  Eigen::Vector2d g = Eigen::Vector2d::Zero();
  for (int q = 0; q < bins; ++q) {
    const size_t lo = n * q / bins, hi = n * (q + 1) / bins;
    std::vector<double> r2, tt;
    for (size_t i = lo; i < hi; ++i) {
      r2.push_back(residual[order[i]] * residual[order[i]]);
      tt.push_back(t2[order[i]]);
    }
    std::nth_element(r2.begin(), r2.begin() + r2.size() / 2, r2.end());
    std::nth_element(tt.begin(), tt.begin() + tt.size() / 2, tt.end());
    const double y = r2[r2.size() / 2] / 0.4549 / (1.0 + h), x = tt[tt.size() / 2], w = static_cast<double>(hi - lo);
    N += w * Eigen::Vector2d(1.0, x) * Eigen::RowVector2d(1.0, x);
    g += w * Eigen::Vector2d(1.0, x) * y;
  }
  if (std::abs(N.determinant()) < 1e-12 * N.squaredNorm()) return false;
  const Eigen::Vector2d c = N.ldlt().solve(g);
  *a = c[0];
  *b = std::max(0.0, c[1]);
  return std::isfinite(*a) && std::isfinite(*b);
}
}  // namespace

std::vector<StereoLandmark> triangulateMatches(const geometry::CameraInfo& left, const geometry::CameraInfo& right,
                                               const std::vector<StereoMatch>& matches,
                                               const TriangulateOptions& options, int* dropped, double* sigma_used) {
  checkP(left, "left");
  checkP(right, "right");
  if (!(options.sigma_px >= 0.0)) throw std::invalid_argument("triangulate: sigma_px must be >= 0 (0: estimated)");
  if (!(options.min_sigma_px > 0.0) || !(options.max_sigma_px >= options.min_sigma_px))
    throw std::invalid_argument("triangulate: need 0 < min_sigma_px <= max_sigma_px");
  if (!(options.max_depth > options.min_depth)) throw std::invalid_argument("triangulate: max_depth must be > min_depth");
  if (std::abs(right.P(0, 3)) <= 0.0)
    throw std::invalid_argument("right camera_info P[3] (Tx = -fx * baseline) is 0: not a stereo pair");

  // Rectified cameras in the rectified-left frame: P = K [I | t] with t = K^-1 p4.
  std::vector<geometry::CameraObservation> views(2);
  views[0].K = left.P.leftCols<3>();
  views[0].t = views[0].K.inverse() * left.P.col(3);
  views[1].K = right.P.leftCols<3>();
  views[1].t = views[1].K.inverse() * right.P.col(3);
  double sigma = options.sigma_px;
  if (sigma == 0.0) {
    sigma = estimateLocalisationSigma(matches);
    sigma = std::isnan(sigma) ? 0.5 : std::min(options.max_sigma_px, std::max(options.min_sigma_px, sigma));
  }
  if (sigma_used) *sigma_used = sigma;
  const Eigen::Matrix3d Rt = left.R.transpose();  // raw left <- rectified left
  double median_dv = 0.0;
  if (options.row_gate > 0.0 && !matches.empty()) {
    std::vector<double> dv;
    dv.reserve(matches.size());
    for (const auto& m : matches) dv.push_back(m.left.y() - m.right.y());
    std::nth_element(dv.begin(), dv.begin() + dv.size() / 2, dv.end());
    median_dv = dv[dv.size() / 2];
  }
  const double max_dv = options.row_gate > 0.0 ? options.row_gate * std::sqrt(2.0) * sigma : 1e300;

  std::vector<StereoLandmark> out;
  out.reserve(matches.size());
  int n_dropped = 0;
  const std::vector<bool> inconsistent =
      disparityOutliers(matches, options.neighbours, options.disparity_gate, sigma);
  std::vector<size_t> kept;
  for (size_t i = 0; i < matches.size(); ++i) {
    const StereoMatch& m = matches[i];
    if (inconsistent[i] || std::abs(m.left.y() - m.right.y() - median_dv) > max_dv)
      ++n_dropped;
    else
      kept.push_back(i);
  }
  // The local disparity surface of each kept match (slant), needed by both noise models below.
  const int k = options.neighbours;
  const bool have_planes = options.slant_noise && k >= 3 && kept.size() > static_cast<size_t>(2 * k);
  std::vector<double> res, t2(kept.size(), 0.0);
  if (have_planes) {
    std::vector<Eigen::Vector2d> grad;
    std::vector<std::vector<size_t>> nb;
    localPlanes(matches, kept, k, &res, &grad, &nb);
    const double f = left.P(0, 0), offset = left.P(0, 2) - right.P(0, 2);
    std::vector<double> tan_raw(kept.size());
    for (size_t ii = 0; ii < kept.size(); ++ii) {
      const StereoMatch& m = matches[kept[ii]];
      const double d = std::max(0.5, m.left.x() - m.right.x() - offset);
      tan_raw[ii] = grad[ii].norm() * f / d;
    }
    // The slant varies smoothly over the surface, the gradient of one local quadratic is noisy (and a noisy
    // regressor flattens the fitted slopes): each match takes the median over itself and its neighbours.
    std::vector<double> w(k + 1);
    for (size_t ii = 0; ii < kept.size(); ++ii) {
      w[0] = tan_raw[ii];
      for (int q = 0; q < k; ++q) w[q + 1] = tan_raw[nb[ii][q]];
      std::nth_element(w.begin(), w.begin() + k / 2, w.end());
      t2[ii] = w[k / 2] * w[k / 2];
    }
  }
  std::vector<double> sz(kept.size());
  for (size_t ii = 0; ii < kept.size(); ++ii) sz[ii] = matches[kept[ii]].size;
  double size_ref = 1.0;
  // Scale- and slant-dependent localisation noise (see TriangulateOptions::size_noise), from the kept matches'
  // row residuals: var = c0 + c1 (s / s_med)^2 + c2 (s / s_med)^2 tan^2(theta).
  std::vector<double> var_v(kept.size(), sigma * sigma);
  bool size_model = false;
  if (options.size_noise && options.sigma_px == 0.0 && kept.size() >= 50) {
    std::vector<double> dv(kept.size());
    for (size_t ii = 0; ii < kept.size(); ++ii)
      dv[ii] = matches[kept[ii]].left.y() - matches[kept[ii]].right.y() - median_dv;
    std::vector<double> tmp = sz;
    std::nth_element(tmp.begin(), tmp.begin() + tmp.size() / 2, tmp.end());
    size_ref = tmp[tmp.size() / 2] > 0.0 ? tmp[tmp.size() / 2] : 1.0;
    std::vector<std::vector<double>> phi(kept.size());
    for (size_t ii = 0; ii < kept.size(); ++ii) {
      const double rel2 = std::pow(sz[ii] / size_ref, 2);
      phi[ii] = {1.0, rel2, rel2 * t2[ii]};  // t2 = 0 without the local planes: the slant column is dropped
    }
    std::vector<double> c;
    if (fitVarianceModel(dv, phi, &c)) {
      size_model = true;
      const double lo = options.min_sigma_px * options.min_sigma_px, hi = options.max_sigma_px * options.max_sigma_px;
      for (size_t ii = 0; ii < kept.size(); ++ii) {
        double v = 0.0;
        for (size_t j = 0; j < c.size(); ++j) v += c[j] * phi[ii][j];
        var_v[ii] = std::min(hi, std::max(lo, v));
      }
    }
  }
  // Slant-dependent disparity noise (see TriangulateOptions::slant_noise).
  std::vector<double> var_u = var_v;
  if (have_planes) {
    // The foreshortening that differs between the two views moves a keypoint in proportion to its size: the
    // slant variable is (size / median size)^2 tan^2(theta) when the size model is on, tan^2(theta) otherwise.
    std::vector<double> x(kept.size()), xi(kept.size());
    for (size_t ii = 0; ii < kept.size(); ++ii) {
      const double rel = size_model && sz[ii] > 0.0 ? sz[ii] / size_ref : 1.0;
      x[ii] = rel * rel * t2[ii];
    }
    // var_d,i = 2 var_v,i + b x_i. Normalised by each match's own noise, r_i^2 / (2 var_v,i) = 1 + b xi_i with
    // xi_i = x_i / (2 var_v,i): the fit's slope is b (its intercept, ~1, is not used).
    for (size_t ii = 0; ii < kept.size(); ++ii) {
      res[ii] /= std::sqrt(2.0 * var_v[ii]);
      xi[ii] = x[ii] / (2.0 * var_v[ii]);
    }
    double a = 0.0, b = 0.0;
    if (fitSlantNoise(res, xi, k, &a, &b))
      for (size_t ii = 0; ii < kept.size(); ++ii) var_u[ii] = var_v[ii] + 0.5 * b * x[ii];
  }
  for (size_t ii = 0; ii < kept.size(); ++ii) {
    const StereoMatch& m = matches[kept[ii]];
    views[0].uv = m.left;
    views[1].uv = m.right;
    views[0].cov_uv = views[1].cov_uv = Eigen::Vector2d(var_u[ii], var_v[ii]).asDiagonal();
    const geometry::TriangulationResult r = geometry::triangulateMmse(views);
    if (!r.ok || !(r.X.z() >= options.min_depth) || !(r.X.z() <= options.max_depth)) {
      ++n_dropped;
      continue;
    }
    StereoLandmark l;
    l.position = Rt * r.X;
    l.covariance = Rt * r.C * Rt.transpose();
    l.covariance = 0.5 * (l.covariance + l.covariance.transpose());
    l.descriptor = m.descriptor;
    l.strength = m.strength;
    l.uv_left = m.left;
    l.uv_right = m.right;
    l.size = m.size;
    l.var_u = var_u[ii];
    l.var_v = var_v[ii];
    out.push_back(std::move(l));
  }
  if (dropped) *dropped = n_dropped;
  return out;
}

}  // namespace stereo
}  // namespace skin3d
