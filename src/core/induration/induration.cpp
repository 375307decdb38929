// SPDX-License-Identifier: BSD-3-Clause
// Induration measurement: see include/skin3d/induration/induration.h.
#include "skin3d/induration/induration.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <numeric>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "../common/parallel.h"
#include "../common/text.h"
#include "reference_ransac.h"

namespace skin3d {
namespace induration {

using common::num;

void IndurationOptions::validate() const {
  if (reference_model != "plane" && reference_model != "quadratic" && reference_model != "quadric" && reference_model != "auto")
    throw IndurationError("reference_model '" + reference_model + "' is not auto, plane, quadric or quadratic");
  if (!(min_height > 0)) throw IndurationError("min_height " + num(min_height) + " m must be > 0");
  if (!(min_area >= 0)) throw IndurationError("min_area " + num(min_area) + " m^2 must be >= 0");
  if (!(smoothing_px >= 0) || smoothing_px > 50) throw IndurationError("smoothing_px " + num(smoothing_px) + " must be 0 ... 50");
  if (!(max_smoothing_px >= smoothing_px) || max_smoothing_px > 100)
    throw IndurationError("max_smoothing_px " + num(max_smoothing_px) + " must be smoothing_px ... 100");
  if (!(edge_fraction > 0 && edge_fraction < 1)) throw IndurationError("edge_fraction " + num(edge_fraction) + " must be in (0, 1)");
  if (!(min_measured_share >= 0 && min_measured_share <= 1))
    throw IndurationError("min_measured_share " + num(min_measured_share) + " must be 0 ... 1");
  if (exclusion_margin_px < 0 || exclusion_margin_px > 200)
    throw IndurationError("exclusion_margin_px " + std::to_string(exclusion_margin_px) + " must be 0 ... 200");
  if (!(sor_std_ratio > 0)) throw IndurationError("sor_std_ratio " + num(sor_std_ratio) + " must be > 0");
  if (!(ransac_threshold > 0)) throw IndurationError("ransac_threshold " + num(ransac_threshold) + " m must be > 0");
  if (!(max_height > min_height)) throw IndurationError("max_height " + num(max_height) + " m must be > min_height");
  if (!(max_incidence_deg > 0) || max_incidence_deg > 90)
    throw IndurationError("max_incidence_deg " + num(max_incidence_deg) + " must be in (0, 90]");
  if (interior_margin_px < 0 || interior_margin_px > 200)
    throw IndurationError("interior_margin_px " + std::to_string(interior_margin_px) + " must be 0 ... 200");
  if (fit_points < 100) throw IndurationError("fit_points " + std::to_string(fit_points) + " must be >= 100");
  if (max_iterations < 1) throw IndurationError("max_iterations " + std::to_string(max_iterations) + " must be >= 1");
  if (!(min_reference_fraction > 0 && min_reference_fraction < 1))
    throw IndurationError("min_reference_fraction " + num(min_reference_fraction) + " must be in (0, 1)");
  if (pasi_boundaries.size() != 4) throw IndurationError("pasi_boundaries must hold 4 heights (classes 0-4)");
  for (std::size_t i = 0; i < pasi_boundaries.size(); ++i)
    if (!(pasi_boundaries[i] > 0) || (i > 0 && !(pasi_boundaries[i] > pasi_boundaries[i - 1])))
      throw IndurationError("pasi_boundaries must be positive and increasing (m)");
}

int pasiClass(double height, const std::vector<double>& boundaries) {
  int k = 0;
  for (double b : boundaries)
    if (height >= b) ++k;
  return k;
}

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
/** A plaque whose outline borders unmeasured skin along more than this share may extend beyond what was
 *  measured: a warning says so. */
constexpr double kOpenOutline = 0.1;

inline bool known(const cv::Vec3f& p) { return !std::isnan(p[0]); }

/** Statistical outlier removal on the organised cloud: mean distance to the known 8 neighbours. */
int removeOutliers(cv::Mat& xyz, double std_ratio) {
  cv::Mat md(xyz.size(), CV_32F, cv::Scalar(kNaN));
  double sum = 0, sum2 = 0;
  long n = 0;
  for (int y = 0; y < xyz.rows; ++y) {
    for (int x = 0; x < xyz.cols; ++x) {
      const cv::Vec3f& p = xyz.at<cv::Vec3f>(y, x);
      if (!known(p)) continue;
      double s = 0;
      int k = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (!dx && !dy) continue;
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || xx < 0 || yy >= xyz.rows || xx >= xyz.cols) continue;
          const cv::Vec3f& q = xyz.at<cv::Vec3f>(yy, xx);
          if (!known(q)) continue;
          s += cv::norm(p - q);
          ++k;
        }
      if (k == 0) continue;  // isolated: judged below
      const double m = s / k;
      md.at<float>(y, x) = static_cast<float>(m);
      sum += m;
      sum2 += m * m;
      ++n;
    }
  }
  if (n < 10) return 0;
  const double mean = sum / n, sd = std::sqrt(std::max(0.0, sum2 / n - mean * mean));
  const double limit = mean + std_ratio * sd;
  int removed = 0;
  for (int y = 0; y < xyz.rows; ++y)
    for (int x = 0; x < xyz.cols; ++x) {
      cv::Vec3f& p = xyz.at<cv::Vec3f>(y, x);
      if (!known(p)) continue;
      const float m = md.at<float>(y, x);
      if (std::isnan(m) || m > limit) {
        p = cv::Vec3f(kNaN, kNaN, kNaN);
        ++removed;
      }
    }
  return removed;
}

/** Tukey biweight of r with scale c. */
inline double tukey(double r, double c) {
  const double u = r / c;
  return std::fabs(u) >= 1 ? 0.0 : (1 - u * u) * (1 - u * u);
}

/** Heights of every known point above `ref` (NaN elsewhere). */
cv::Mat heights(const cv::Mat& xyz, const ReferenceSurface& ref) {
  cv::Mat h(xyz.size(), CV_32F, cv::Scalar(kNaN));
  cv::parallel_for_(cv::Range(0, xyz.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const cv::Vec3f* p = xyz.ptr<cv::Vec3f>(y);
      float* o = h.ptr<float>(y);
      for (int x = 0; x < xyz.cols; ++x)
        if (known(p[x])) o[x] = static_cast<float>(ref.height(Eigen::Vector3d(p[x][0], p[x][1], p[x][2])));
    }
  });
  return h;
}

/** smoothNaN of one map at several sigmas: the known mask, the zero-filled map and their reductions are made
 *  once (the adaptive smoothing tries a few sigmas on the same heights). */
class NanSmoother {
 public:
  explicit NanSmoother(const cv::Mat& h) : h_(h) {
    k_ = (h == h);
    v_ = h.clone();
    v_.setTo(0, ~k_);
    k_.convertTo(w_, CV_32F, 1.0 / 255.0);
  }

  cv::Mat operator()(double sigma) {
    if (sigma <= 0) return h_.clone();
    cv::Mat vs, ws;
    int f = 1;
    while (sigma / f > 4 && std::min(h_.rows, h_.cols) / (2 * f) >= 16) f *= 2;
    if (f == 1) {
      runTasks({[&] { cv::GaussianBlur(v_, vs, cv::Size(), sigma, sigma, cv::BORDER_REFLECT); },
                [&] { cv::GaussianBlur(w_, ws, cv::Size(), sigma, sigma, cv::BORDER_REFLECT); }});
    } else {
      // sigma^2 = (f sigma_r)^2 + (area kernel f and bilinear return, about f^2 / 6 together): the reduced
      // map's Gaussian makes up the rest
      const double sr = std::sqrt(std::max(1.0, sigma * sigma / (f * f) - 1.0 / 6.0));
      auto& red = reduced_[f];
      const cv::Size small((h_.cols + f - 1) / f, (h_.rows + f - 1) / f);
      const bool first = red.first.empty();
      auto one = [&](const cv::Mat& full, cv::Mat& reduced, cv::Mat& back) {
        if (first) cv::resize(full, reduced, small, 0, 0, cv::INTER_AREA);
        cv::Mat b;
        cv::GaussianBlur(reduced, b, cv::Size(), sr, sr, cv::BORDER_REFLECT);
        cv::resize(b, back, h_.size(), 0, 0, cv::INTER_LINEAR);
      };
      runTasks({[&] { one(v_, red.first, vs); }, [&] { one(w_, red.second, ws); }});
    }
    cv::Mat out = vs / ws;
    out.setTo(kNaN, ~k_);
    return out;
  }

 private:
  cv::Mat h_, k_, v_, w_;
  std::map<int, std::pair<cv::Mat, cv::Mat>> reduced_;  // reduction factor: the zero-filled map and its weights
};

/** NaN-aware Gaussian smoothing (normalised convolution). A wide Gaussian (sigma > 4 px) is applied on a
 *  map reduced by a power of two f (area averages; sigma / f in [2, 4] px there) and brought back bilinearly:
 *  the same smoothing within a few per cent, at a fraction of the cost on a 13-megapixel map. */
cv::Mat smoothNaN(const cv::Mat& h, double sigma) { return NanSmoother(h)(sigma); }

/** Smoothed map with small gaps (up to a few times `gap_px` wide) filled from their surroundings: where the
 *  matcher leaves a plaque's step edge unknown, the boundary at half height then falls in the gap's middle. */
cv::Mat smoothFilled(const cv::Mat& h, double sigma, double gap_px) {
  cv::Mat out = smoothNaN(h, sigma);
  cv::Mat k = (out == out), v = out.clone(), w;
  v.setTo(0, ~k);
  k.convertTo(w, CV_32F, 1.0 / 255.0);
  for (double g = 0.5 * gap_px; g <= 2 * gap_px; g *= 2) {
    cv::Mat vs, ws;
    runTasks({[&] { cv::GaussianBlur(v, vs, cv::Size(), g, g, cv::BORDER_REFLECT); },
              [&] { cv::GaussianBlur(w, ws, cv::Size(), g, g, cv::BORDER_REFLECT); }});
    for (int y = 0; y < out.rows; ++y)
      for (int x = 0; x < out.cols; ++x)
        if (std::isnan(out.at<float>(y, x)) && ws.at<float>(y, x) > 0.05f) out.at<float>(y, x) = vs.at<float>(y, x) / ws.at<float>(y, x);
  }
  return out;
}

/** A regular subsample (at most about `max_points`) of the known points where `use` is set. */
std::vector<Eigen::Vector3d> subsample(const cv::Mat& xyz, const cv::Mat& use, int max_points, int* total) {
  std::vector<Eigen::Vector3d> pts;
  *total = cv::countNonZero(use);
  const int step = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(*total) / max_points))));
  for (int y = 0; y < xyz.rows; y += step) {
    const uchar* u = use.ptr<uchar>(y);
    const cv::Vec3f* p = xyz.ptr<cv::Vec3f>(y);
    for (int x = 0; x < xyz.cols; x += step)
      if (u[x] && known(p[x])) pts.emplace_back(p[x][0], p[x][1], p[x][2]);
  }
  return pts;
}

using Vec10 = Eigen::Matrix<double, 10, 1>;

Vec10 monomials(const Eigen::Vector3d& y) {
  Vec10 m;
  m << y.x() * y.x(), y.y() * y.y(), y.z() * y.z(), y.x() * y.y(), y.x() * y.z(), y.y() * y.z(), y.x(), y.y(), y.z(), 1.0;
  return m;
}

/** Gradients of the monomials with respect to y (10 x 3). */
Eigen::Matrix<double, 10, 3> monomialGradients(const Eigen::Vector3d& y) {
  Eigen::Matrix<double, 10, 3> J = Eigen::Matrix<double, 10, 3>::Zero();
  J.row(0) << 2 * y.x(), 0, 0;
  J.row(1) << 0, 2 * y.y(), 0;
  J.row(2) << 0, 0, 2 * y.z();
  J.row(3) << y.y(), y.x(), 0;
  J.row(4) << y.z(), 0, y.x();
  J.row(5) << 0, y.z(), y.y();
  J.row(6) << 1, 0, 0;
  J.row(7) << 0, 1, 0;
  J.row(8) << 0, 0, 1;
  return J;
}

/** F(y) = monomials(y) . theta, written out (the per-pixel height calls it a few times per pixel). */
inline double quadricValue(const Vec10& t, const Eigen::Vector3d& y) {
  const double a = y.x(), b = y.y(), c = y.z();
  return t(0) * a * a + t(1) * b * b + t(2) * c * c + t(3) * a * b + t(4) * a * c + t(5) * b * c + t(6) * a + t(7) * b + t(8) * c + t(9);
}

/** grad F(y) = monomialGradients(y)^T theta, written out. */
inline Eigen::Vector3d quadricGradient(const Vec10& t, const Eigen::Vector3d& y) {
  const double a = y.x(), b = y.y(), c = y.z();
  return Eigen::Vector3d(2 * t(0) * a + t(3) * b + t(4) * c + t(6), 2 * t(1) * b + t(3) * a + t(5) * c + t(7),
                         2 * t(2) * c + t(4) * a + t(5) * b + t(8));
}

/** Weighted Taubin fit of an implicit quadric (normalised coordinates): min sum w F^2 / sum w |grad F|^2. */
bool taubinQuadric(const std::vector<Eigen::Vector3d>& ys, const std::vector<double>& w, Vec10* theta) {
  using Mat10 = Eigen::Matrix<double, 10, 10>;
  // sums over fixed chunks of points in parallel, added in chunk order: the same result on any number of threads
  constexpr std::size_t kChunk = 8192;
  const std::size_t chunks = (ys.size() + kChunk - 1) / kChunk;
  std::vector<Mat10, Eigen::aligned_allocator<Mat10>> Ms(chunks, Mat10::Zero()), Ns(chunks, Mat10::Zero());
  std::vector<double> wss(chunks, 0.0);
  forEachIndex(chunks, [&](std::size_t c) {
    for (std::size_t i = c * kChunk; i < std::min(ys.size(), (c + 1) * kChunk); ++i) {
      if (w[i] <= 0) continue;
      const Vec10 m = monomials(ys[i]);
      const Eigen::Matrix<double, 10, 3> J = monomialGradients(ys[i]);
      Ms[c].noalias() += w[i] * m * m.transpose();
      Ns[c].noalias() += (w[i] * J).lazyProduct(J.transpose());  // coefficient-wise: a GEMM call per point costs more
      wss[c] += w[i];
    }
  });
  Mat10 M = Mat10::Zero(), N = Mat10::Zero();
  double ws = 0;
  for (std::size_t c = 0; c < chunks; ++c) {
    M += Ms[c];
    N += Ns[c];
    ws += wss[c];
  }
  if (ws <= 0) return false;
  // eliminate the constant term (no gradient): c = -M_c9 theta' / M_99
  const double m99 = M(9, 9);
  if (!(m99 > 0)) return false;
  const Eigen::Matrix<double, 9, 9> Mr = M.topLeftCorner<9, 9>() - M.topRightCorner<9, 1>() * M.bottomLeftCorner<1, 9>() / m99;
  Eigen::Matrix<double, 9, 9> Nr = N.topLeftCorner<9, 9>();
  Nr += 1e-12 * Nr.trace() * Eigen::Matrix<double, 9, 9>::Identity();
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> es(Mr, Nr);
  if (es.info() != Eigen::Success) return false;
  const Eigen::Matrix<double, 9, 1> t = es.eigenvectors().col(0);
  theta->head<9>() = t;
  (*theta)(9) = -(M.bottomLeftCorner<1, 9>() * t)(0) / m99;
  theta->normalize();
  return theta->allFinite();
}

/** Robust (Tukey IRLS on geometric distances) fit of an implicit quadric to the points where `use` is set. */
bool fitQuadric(const cv::Mat& xyz, const cv::Mat& use, int max_points, double max_scale, ReferenceSurface* ref) {
  int total = 0;
  const std::vector<Eigen::Vector3d> pts = subsample(xyz, use, max_points, &total);
  if (pts.size() < 200) return false;
  ReferenceSurface cur = *ref;
  cur.model = "quadric";
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : pts) c += p;
  c /= static_cast<double>(pts.size());
  double sc = 0;
  for (const auto& p : pts) sc += (p - c).squaredNorm();
  sc = std::sqrt(sc / pts.size());
  if (!(sc > 0)) return false;
  cur.q_centre = c;
  cur.q_scale = sc;
  std::vector<Eigen::Vector3d> ys(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) ys[i] = (pts[i] - c) / sc;
  // start: the current reference's residuals (the RANSAC plane's, or the previous quadric's) with a wide cut-off
  std::vector<double> w(pts.size()), r(pts.size());
  forEachIndex(pts.size(), [&](std::size_t i) { r[i] = ref->height(pts[i]); });
  for (int it = 0; it < 10; ++it) {
    std::vector<double> a(r.size());
    for (std::size_t i = 0; i < r.size(); ++i) a[i] = std::fabs(r[i]);
    std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
    // first an unweighted fit (the start's residuals say nothing about a curved surface), then Tukey weights
    // with a cut-off that narrows to the plane's (a few hundred um) as the fit settles
    const double cap = it <= 2 ? 10 * max_scale : max_scale / 3.0;
    const double scale = std::min(std::max(1.4826 * a[a.size() / 2], 1e-7), cap);
    for (std::size_t i = 0; i < pts.size(); ++i) w[i] = it == 0 ? 1.0 : tukey(r[i], 4.685 * scale);
    Vec10 theta;
    if (!taubinQuadric(ys, w, &theta)) return false;
    cur.coefficients = theta;
    cur.q_sign = 1.0;
    // orient: positive towards the camera (the origin) at the weighted median point
    double vote = 0;
    for (std::size_t i = 0; i < pts.size(); i += std::max<std::size_t>(1, pts.size() / 2000)) {
      const Eigen::Vector3d g = quadricGradient(theta, ys[i]);
      vote += w[i] * (g.dot(-pts[i]) > 0 ? 1 : -1);
    }
    cur.q_sign = vote >= 0 ? 1.0 : -1.0;
    forEachIndex(pts.size(), [&](std::size_t i) { r[i] = cur.height(pts[i]); });
  }
  double s2 = 0;
  int k = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (w[i] <= 0) continue;
    s2 += r[i] * r[i];
    ++k;
  }
  cur.rms = k > 0 ? std::sqrt(s2 / k) : 0;
  cur.points = total;
  // a tangent plane for messages and footprints: at the weighted mean point
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double ws = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    mean += w[i] * pts[i];
    ws += w[i];
  }
  if (ws > 0) mean /= ws;
  const Eigen::Vector4d tp = cur.tangentPlane(mean);
  cur.normal = tp.head<3>();
  cur.d = tp(3);
  cur.origin = mean;
  *ref = cur;
  return true;
}

/** Robust (Tukey IRLS) fit of the reference to the points where `use` is set, starting from `ref`. */
bool fitReference(const cv::Mat& xyz, const cv::Mat& use, const std::string& model, int max_points, double max_scale,
                  ReferenceSurface* ref) {
  int total = 0;
  const std::vector<Eigen::Vector3d> pts = subsample(xyz, use, max_points, &total);
  if (pts.size() < 50) return false;
  std::vector<double> w(pts.size(), 1.0), r(pts.size());
  ReferenceSurface cur = *ref;
  for (int it = 0; it < 8; ++it) {
    forEachIndex(pts.size(), [&](std::size_t i) { r[i] = cur.height(pts[i]); });
    std::vector<double> a(r.size());
    for (std::size_t i = 0; i < r.size(); ++i) a[i] = std::fabs(r[i]);
    std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
    // robust scale, at most a third of the RANSAC inlier distance (Tukey's cut-off then ~1.5 x that distance)
    const double scale = std::min(std::max(1.4826 * a[a.size() / 2], 1e-7), max_scale / 3.0);
    const double c = 4.685 * scale;
    for (std::size_t i = 0; i < pts.size(); ++i) w[i] = tukey(r[i], c);
    // weighted plane (PCA)
    double ws = 0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < pts.size(); ++i) {
      ws += w[i];
      mean += w[i] * pts[i];
    }
    if (ws <= 0) return false;
    mean /= ws;
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (std::size_t i = 0; i < pts.size(); ++i) C += w[i] * (pts[i] - mean) * (pts[i] - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
    Eigen::Vector3d n = es.eigenvectors().col(0);
    if (n.dot(mean) > 0) n = -n;  // towards the camera (origin)
    ReferenceSurface next;
    next.model = model;
    next.normal = n;
    next.d = -n.dot(mean);
    next.origin = mean;
    next.e1 = (es.eigenvectors().col(2) - n * n.dot(es.eigenvectors().col(2))).normalized();
    next.e2 = n.cross(next.e1);
    if (model == "quadratic") {
      // heights above the plane as a quadric of (u, v), weighted least squares
      Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
      Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
      for (std::size_t i = 0; i < pts.size(); ++i) {
        if (w[i] <= 0) continue;
        const Eigen::Vector3d q = pts[i] - mean;
        const double u = q.dot(next.e1), v = q.dot(next.e2), h = q.dot(n);
        Eigen::Matrix<double, 6, 1> f;
        f << 1, u, v, u * u, u * v, v * v;
        A += w[i] * f * f.transpose();
        b += w[i] * f * h;
      }
      next.quadric = A.ldlt().solve(b);
      if (!next.quadric.allFinite()) next.quadric.setZero();
    }
    cur = next;
  }
  // final RMS of the (weighted-in) healthy points
  double s2 = 0;
  int k = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (w[i] <= 0) continue;
    const double h = cur.height(pts[i]);
    s2 += h * h;
    ++k;
  }
  cur.rms = k > 0 ? std::sqrt(s2 / k) : 0;
  cur.points = total;
  *ref = cur;
  return true;
}

/** Footprint on the reference plane of every pixel in `rect` (m^2), from the viewing rays. */
cv::Mat footprint(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Rect& rect) {
  cv::Mat P(rect.height + 1, rect.width + 1, CV_64FC3);
  for (int y = 0; y <= rect.height; ++y)
    for (int x = 0; x <= rect.width; ++x) {
      const int yy = std::min(rect.y + y, ray.rows - 1), xx = std::min(rect.x + x, ray.cols - 1);
      const cv::Vec3f& r = ray.at<cv::Vec3f>(yy, xx);
      const Eigen::Vector3d d(r[0], r[1], r[2]);
      const double den = ref.normal.dot(d);
      const Eigen::Vector3d X = std::fabs(den) > 1e-9 ? Eigen::Vector3d(d * (-ref.d / den)) : Eigen::Vector3d::Zero();
      P.at<cv::Vec3d>(y, x) = cv::Vec3d(X.x(), X.y(), X.z());
    }
  cv::Mat A(rect.size(), CV_64F);
  for (int y = 0; y < rect.height; ++y)
    for (int x = 0; x < rect.width; ++x) {
      // a pixel at the image's last row/column reuses its neighbour's edge vectors
      const int x0 = std::min(x, rect.width - 1), y0 = std::min(y, rect.height - 1);
      const cv::Vec3d du = P.at<cv::Vec3d>(y0, x0 + 1) - P.at<cv::Vec3d>(y0, x0);
      const cv::Vec3d dv = P.at<cv::Vec3d>(y0 + 1, x0) - P.at<cv::Vec3d>(y0, x0);
      const cv::Vec3d c = du.cross(dv);
      A.at<double>(y, x) = std::fabs(ref.normal.x() * c[0] + ref.normal.y() * c[1] + ref.normal.z() * c[2]);
    }
  return A;
}

double detectionThreshold(const cv::Mat& hs, const cv::Mat& use, double min_height, double band);

/**
 * Segmentation smoothing that suits the data: from `start` px, widened by sqrt(2) steps until three robust sigma
 * of the smoothed healthy heights (the detection threshold the noise asks for) fall below 1.5 min_height, at most
 * `limit` px: the threshold then stays below the 0.1 mm a plaque must have to count (2 min_height by default) with
 * margin, and a plaque is not cut into pieces by noise crossing it; no wider than that, since a wide Gaussian
 * merges neighbouring plaques and rounds their outlines. On a speckle plate the start holds;
 * on weakly textured, noisy skin the matcher's noise is several times larger and the smoothing grows with it.
 * `smoothed`: the map smoothed by the sigma returned.
 */
double adaptiveSmoothing(const cv::Mat& h, const cv::Mat& use, double start, double limit, double min_height, double band,
                         cv::Mat* smoothed) {
  NanSmoother smooth(h);
  std::vector<double> s{std::max(start, 0.5)}, t;
  while (true) {
    *smoothed = smooth(s.back());
    t.push_back(detectionThreshold(*smoothed, use, 0.0, band));
    const size_t i = t.size() - 1;
    if (t[i] <= 1.5 * min_height) return s[i];
    if (s[i] >= limit) {
      if (s[i] != limit) *smoothed = smooth(limit);  // a limit below the 0.5 px start
      return limit;
    }
    s.push_back(std::min(limit, s[i] * std::sqrt(2.0)));
  }
}

/**
 * Where the ray of a pixel (unit `r`, from the left camera at the origin) first meets the reference: the
 * distance along it, NaN if it misses. Along a ray every model is a quadratic in the distance (the plane and the
 * quadratic height field in their heights, the implicit quadric in F), so three samples give it exactly.
 */
double rayHit(const ReferenceSurface& ref, const Eigen::Vector3d& r) {
  const bool quadric = ref.model == "quadric";
  const double T = std::max(1e-3, quadric ? ref.q_centre.norm() : ref.origin.norm() + std::fabs(ref.d));
  auto g = [&](double t) {
    const Eigen::Vector3d x = t * T * r;
    return quadric ? quadricValue(ref.coefficients, (x - ref.q_centre) / ref.q_scale) : ref.height(x);
  };
  const double f0 = g(0), f1 = g(1), f2 = g(2);
  const double a = 0.5 * (f2 - 2 * f1 + f0), b = f1 - f0 - a, c = f0;
  double u = std::numeric_limits<double>::quiet_NaN();
  if (std::fabs(a) < 1e-12 * (std::fabs(b) + std::fabs(c))) {
    if (b != 0 && -c / b > 0) u = -c / b;
  } else {
    const double disc = b * b - 4 * a * c;
    if (disc < 0) return std::numeric_limits<double>::quiet_NaN();
    const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
    const double u1 = q / a, u2 = q != 0 ? c / q : std::numeric_limits<double>::quiet_NaN();
    for (double v : {u1, u2})
      if (v > 0 && !(v >= u)) u = v;  // the nearest root in front of the camera
  }
  return u * T;
}

/**
 * The height of a plaque's top (m): the level its height profile reaches at the centre. The heights are binned by
 * their distance from the outline (px, distance transform of `mask`); from twice `margin` px in (clear of the
 * ramp and of the matcher's blur of it, which reaches 8-12 px in at full resolution: a profile of 0.5-1.4 mm
 * plaques reads 10-60 um low 8 px in, right from 12 px in), or from half way to the centre on a small plaque
 * (but at least `margin` px in), the bins' medians are fitted, weighted
 * by the bins' counts, with a + b (d_max - d)^2: a paraboloid, a domed top, read at the deepest point (a). The
 * dome is kept only if the centre is higher and the curvature significant (-b over its standard error, from the
 * fit's own residuals, above 3); otherwise the top is flat (or dished: its highest level is not at the centre)
 * and its height is the weighted mean of the bins (less noisy than extrapolating).
 * NaN if fewer than 30 heights are that deep.
 */
double topHeight(const cv::Mat& mask, const cv::Mat& h, int margin) {
  cv::Mat dist;
  cv::distanceTransform(mask, dist, cv::DIST_L2, cv::DIST_MASK_5);
  double dmax = 0;
  cv::minMaxLoc(dist, nullptr, &dmax);
  const double d0 = std::max(static_cast<double>(margin), std::min(2.0 * margin, 0.5 * dmax));
  std::vector<std::vector<float>> bins(static_cast<std::size_t>(dmax) + 1);
  int n = 0;
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x) {
      const float d = dist.at<float>(y, x), v = h.at<float>(y, x);
      if (mask.at<uchar>(y, x) && d >= d0 && !std::isnan(v)) {
        bins[static_cast<std::size_t>(d)].push_back(v);
        ++n;
      }
    }
  if (n < 30) return std::numeric_limits<double>::quiet_NaN();
  std::vector<Eigen::Vector3d> pts;  // (x, median, weight)
  Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  double sw = 0, swm = 0;
  for (std::size_t k = 0; k < bins.size(); ++k) {
    auto& b = bins[k];
    if (b.size() < 3) continue;
    std::nth_element(b.begin(), b.begin() + b.size() / 2, b.end());
    const double x = (dmax - (k + 0.5)) * (dmax - (k + 0.5)), w = static_cast<double>(b.size()), m = b[b.size() / 2];
    pts.emplace_back(x, m, w);
    const Eigen::Vector2d row(1.0, x);
    A += w * row * row.transpose();
    rhs += w * row * m;
    sw += w;
    swm += w * m;
  }
  if (!(sw > 0)) return std::numeric_limits<double>::quiet_NaN();
  const double flat = swm / sw;
  if (pts.size() < 5 || !(std::fabs(A.determinant()) > 1e-12 * A.squaredNorm())) return flat;
  const Eigen::Vector2d ab = A.ldlt().solve(rhs);
  double ssr = 0;
  for (const auto& p : pts) ssr += p(2) * std::pow(p(1) - ab(0) - ab(1) * p(0), 2);
  const double var_b = ssr / (pts.size() - 2) * A.inverse()(1, 1);
  return var_b > 0 && ab(1) < -3 * std::sqrt(var_b) ? ab(0) : flat;
}

/**
 * Incidence of the reference surface (deg, CV_32F): for every pixel whose ray meets the reference, the larger of
 * the angles its normal makes with the rays to the two cameras (the left at the origin, the right at
 * `right_centre`; only the left if that is unknown); 180 where it faces away from the right camera, NaN where the
 * ray misses. It is the reference's geometry, not the measured points': a mismatched point beyond a limb's
 * silhouette has none, and a pixel the matcher left unknown has one if the skin there faces the rig.
 * Evaluated every 4 px (the reference is smooth) and spread to the pixels between.
 */
cv::Mat incidenceMap(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Vec3d& right_centre) {
  constexpr int kStep = 4;
  const bool have_right = std::isfinite(right_centre[0]);
  const Eigen::Vector3d rc(right_centre[0], right_centre[1], right_centre[2]);
  const cv::Size small((ray.cols + kStep - 1) / kStep, (ray.rows + kStep - 1) / kStep);
  cv::Mat inc(small, CV_32F, cv::Scalar(kNaN));
  cv::parallel_for_(cv::Range(0, small.height), [&](const cv::Range& rows) {
    for (int sy = rows.start; sy < rows.end; ++sy)
      for (int sx = 0; sx < small.width; ++sx) {
        const cv::Vec3f& rv = ray.at<cv::Vec3f>(std::min(ray.rows - 1, sy * kStep + kStep / 2), std::min(ray.cols - 1, sx * kStep + kStep / 2));
        const Eigen::Vector3d r = Eigen::Vector3d(rv[0], rv[1], rv[2]).normalized();
        const double t = rayHit(ref, r);
        if (!(t > 0)) continue;
        const Eigen::Vector3d X = t * r;
        Eigen::Vector3d n;
        if (ref.model == "quadric") {
          n = quadricGradient(ref.coefficients, (X - ref.q_centre) / ref.q_scale);
          if (!(n.norm() > 0)) continue;
          n.normalize();
        } else {
          n = ref.tangentPlane(X).head<3>();
        }
        if (n.dot(r) > 0) n = -n;  // towards the left camera, which sees the first hit
        const double cl = n.dot(-r);
        const double cr = have_right ? n.dot((rc - X).normalized()) : 1.0;
        inc.at<float>(sy, sx) = cr <= 0 ? 180.0f : static_cast<float>(std::acos(std::min(1.0, std::min(cl, cr))) * 180.0 / M_PI);
      }
  });
  cv::Mat out;
  cv::resize(inc, out, ray.size(), 0, 0, cv::INTER_NEAREST);
  return out;
}

/** The working band: pixels whose reference incidence (incidenceMap) is at most `max_deg`. */
cv::Mat workingBand(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Vec3d& right_centre, double max_deg) {
  if (max_deg >= 90) return cv::Mat(ray.size(), CV_8U, cv::Scalar(255));
  return incidenceMap(ray, ref, right_centre) <= max_deg;  // NaN compares false
}

/** Detection threshold: min_height, or 3 robust sigma of the smoothed healthy heights if that is larger
 *  (healthy: `use` and within `band` of the reference, so that unmasked plaques do not inflate it). */
double detectionThreshold(const cv::Mat& hs, const cv::Mat& use, double min_height, double band) {
  std::vector<float> v;
  const int total = cv::countNonZero(use);
  const int step = std::max(1, static_cast<int>(std::sqrt(total / 50000.0)));
  for (int y = 0; y < hs.rows; y += step)
    for (int x = 0; x < hs.cols; x += step)
      if (use.at<uchar>(y, x) && std::fabs(hs.at<float>(y, x)) < band) v.push_back(hs.at<float>(y, x));
  if (v.size() < 20) return min_height;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  const float med = v[v.size() / 2];
  for (auto& x : v) x = std::fabs(x - med);
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return std::max(min_height, 3.0 * 1.4826 * v[v.size() / 2]);
}


/** Pixels of `mask`'s holes: zero pixels not reachable from the border through zero pixels (8-bit masks). */
cv::Mat holesOf(const cv::Mat& mask) {
  cv::Mat flood;
  cv::copyMakeBorder(mask, flood, 1, 1, 1, 1, cv::BORDER_CONSTANT, 0);
  cv::floodFill(flood, cv::Point(0, 0), 128);
  return flood(cv::Rect(1, 1, mask.cols, mask.rows)) == 0;
}

/**
 * The footprint of a plaque's region (`mask`, in `box` of the image): the pixels that belong to the plaque by
 * what was measured. The region is drawn on the height map as filled across the matcher's gaps, so part of it
 * may lie in a gap. Such a pixel counts
 * - inside the plaque: between its measured pixels (closing over up to `max_gap` px, and holes), e.g. a strip
 *   the matcher could not match across it;
 * - at a step edge: within a gap at most `max_gap` px across between the plaque's measured pixels and measured
 *   skin below `edge` (the half-height boundary then lies in the gap, as the region has it);
 * but not where the gap opens onto unmeasured skin (the band's edge, beyond a silhouette): there the filled
 * heights only continue the plaque's edge, and the plaque's extent is unknown.
 * `known`: measured pixels of the image; `h`: heights (image; m).
 */
struct Footprint {
  cv::Mat pixels;       //!< CV_8U in the region's box
  double open = 0;      //!< share of the pixels just outside it that are unmeasured and not a step edge's gap
};

Footprint measuredFootprint(const cv::Mat& mask, const cv::Rect& box, const cv::Mat& known, const cv::Mat& h, double edge, int max_gap) {
  const cv::Rect win = cv::Rect(box.x - max_gap, box.y - max_gap, box.width + 2 * max_gap, box.height + 2 * max_gap) &
                       cv::Rect(0, 0, known.cols, known.rows);
  const cv::Rect inner = box - win.tl();
  cv::Mat m = cv::Mat::zeros(win.size(), CV_8U);
  mask.copyTo(m(inner));
  const cv::Mat plaque = m & known(win);
  const cv::Mat healthy = known(win) & ~m & (h(win) < edge);
  cv::Mat closed, dp, dh;
  const int r = std::max(1, max_gap / 2);
  // (default border: the closing's erosion does not eat a plaque touching the image's border)
  cv::morphologyEx(plaque, closed, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  closed |= plaque;
  closed |= holesOf(closed);
  // distance to the nearest measured plaque / healthy pixel, and which pixel that is
  cv::Mat lp, lh;
  cv::distanceTransform(~plaque, dp, lp, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  cv::distanceTransform(~healthy, dh, lh, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  auto where = [](const cv::Mat& src, const cv::Mat& labels) {  // label -> its pixel (each source pixel has its own)
    std::vector<cv::Point> at(1);
    for (int y = 0; y < src.rows; ++y)
      for (int x = 0; x < src.cols; ++x)
        if (src.at<uchar>(y, x)) {
          const int l = labels.at<int>(y, x);
          if (l >= static_cast<int>(at.size())) at.resize(static_cast<std::size_t>(l) + 1);
          at[static_cast<std::size_t>(l)] = cv::Point(x, y);
        }
    return at;
  };
  const std::vector<cv::Point> at_p = where(plaque, lp), at_h = where(healthy, lh);
  // in a step edge's gap: the plaque on one side, healthy skin on the other (not round a corner of the plaque)
  auto across = [&](int x, int y) {
    if (dp.at<float>(y, x) + dh.at<float>(y, x) > max_gap) return false;
    const int a = lp.at<int>(y, x), b = lh.at<int>(y, x);
    if (a <= 0 || b <= 0 || a >= static_cast<int>(at_p.size()) || b >= static_cast<int>(at_h.size())) return false;
    const cv::Point2d u = at_p[static_cast<std::size_t>(a)] - cv::Point(x, y), v = at_h[static_cast<std::size_t>(b)] - cv::Point(x, y);
    return u.dot(v) <= 0;  // at least a right angle apart (the gap's sides are ragged)
  };
  cv::Mat fp = m & closed;
  for (int y = 0; y < fp.rows; ++y)
    for (int x = 0; x < fp.cols; ++x)
      if (m.at<uchar>(y, x) && !fp.at<uchar>(y, x) && across(x, y)) fp.at<uchar>(y, x) = 255;
  fp |= holesOf(fp);  // pockets it encloses (a few gap pixels whose nearest measured pixels are not across)
  fp &= m;            // (not a neighbour's pixels, taken out of the region before)
  // the pixels just outside: measured, in a step edge's gap, next to measured healthy skin, or open (the plaque
  // may continue there)
  cv::Mat ring;
  cv::dilate(fp, ring, cv::Mat(), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, 0);
  ring &= ~fp;
  int all = 0, open = 0;
  const cv::Mat kw = known(win);
  for (int y = 0; y < ring.rows; ++y)
    for (int x = 0; x < ring.cols; ++x)
      if (ring.at<uchar>(y, x)) {
        ++all;
        // (measured healthy skin a matching window or so away closes it too: the end of a strip the matcher
        // could not match across the plaque)
        open += !kw.at<uchar>(y, x) && !across(x, y) && dh.at<float>(y, x) > max_gap / 4;
      }
  Footprint out;
  out.pixels = fp(inner).clone();
  out.open = all > 0 ? open / static_cast<double>(all) : 0.0;
  return out;
}

/** The connected regions (8-connected) of `mask` whose footprint on the reference is at least min_area / 4. */
cv::Mat largeRegions(const cv::Mat& mask, const cv::Mat& ray, const ReferenceSurface& ref, double min_area) {
  cv::Mat lab, stats, cents;
  const int n = cv::connectedComponentsWithStats(mask, lab, stats, cents, 8, CV_32S);
  std::vector<char> keep(n, 0);
  for (int k = 1; k < n; ++k) {
    // footprint of one pixel at the region's centre, times its pixel count
    const int cx = std::min(ray.cols - 2, std::max(0, static_cast<int>(cents.at<double>(k, 0))));
    const int cy = std::min(ray.rows - 2, std::max(0, static_cast<int>(cents.at<double>(k, 1))));
    const double a = footprint(ray, ref, cv::Rect(cx, cy, 1, 1)).at<double>(0, 0);
    keep[k] = stats.at<int>(k, cv::CC_STAT_AREA) * a >= 0.25 * min_area;
  }
  cv::Mat out = cv::Mat::zeros(mask.size(), CV_8U);
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x)
      if (keep[lab.at<int>(y, x)]) out.at<uchar>(y, x) = 255;
  return out;
}

}  // namespace

Eigen::Vector4d ReferenceSurface::tangentPlane(const Eigen::Vector3d& x) const {
  if (model != "quadric") return plane();
  // foot point of x, then the gradient there
  Eigen::Vector3d y = (x - q_centre) / q_scale;
  for (int i = 0; i < 6; ++i) {
    const double F = quadricValue(coefficients, y);
    const Eigen::Vector3d g = quadricGradient(coefficients, y);
    const double g2 = g.squaredNorm();
    if (!(g2 > 1e-30)) break;
    y -= F * g / g2;
  }
  Eigen::Vector3d n = quadricGradient(coefficients, y) * q_sign;
  if (!(n.norm() > 0)) return plane();
  n.normalize();
  const Eigen::Vector3d foot = q_centre + q_scale * y;
  return Eigen::Vector4d(n.x(), n.y(), n.z(), -n.dot(foot));
}

double ReferenceSurface::height(const Eigen::Vector3d& x) const {
  if (model == "quadric") {
    // signed distance: Newton steps along the gradient to the foot point
    const Eigen::Vector3d y0 = (x - q_centre) / q_scale;
    Eigen::Vector3d y = y0;
    double F0 = 0;
    for (int i = 0; i < 4; ++i) {
      const double F = quadricValue(coefficients, y);
      if (i == 0) F0 = F;
      const Eigen::Vector3d g = quadricGradient(coefficients, y);
      const double g2 = g.squaredNorm();
      if (!(g2 > 1e-30)) break;
      y -= F * g / g2;
    }
    const double dist = (y - y0).norm() * q_scale;
    return (F0 * q_sign >= 0 ? dist : -dist);
  }
  double h = normal.dot(x) + d;
  if (model == "quadratic") {
    const Eigen::Vector3d q = x - origin;
    const double u = q.dot(e1), v = q.dot(e2);
    h -= quadric(0) + quadric(1) * u + quadric(2) * v + quadric(3) * u * u + quadric(4) * u * v + quadric(5) * v * v;
  }
  return h;
}

namespace {

/** What the measurement works on: the cloud with its outliers removed, and where it is known. */
struct Surface {
  const stereo::DenseCloud& cloud;
  const IndurationOptions& o;
  cv::Mat xyz;
  cv::Mat known_mask;
  int known_points = 0;
};

/** The reference fitted to one model by alternation, with its plaque mask and healthy-skin scale. */
struct Alternation {
  ReferenceSurface ref;
  cv::Mat plaque_mask;
  double healthy_fraction = 1.0, scale = std::numeric_limits<double>::infinity();
  double smoothing = 0;  // px: segmentation smoothing chosen for this model's heights
  cv::Mat band;          // the working band under this model's first fit
  bool ok = false;
};

/** The starting plane: RANSAC on a subsample of about 20000 points (normal towards the camera side). */
bool ransacStart(const Surface& s, ReferenceSurface* ref) {
  std::vector<Eigen::Vector3f> sample;
  const int step = std::max(1, static_cast<int>(std::sqrt(s.known_points / 20000.0)));
  for (int y = 0; y < s.xyz.rows; y += step)
    for (int x = 0; x < s.xyz.cols; x += step) {
      const cv::Vec3f& p = s.xyz.at<cv::Vec3f>(y, x);
      if (known(p)) sample.emplace_back(p[0], p[1], p[2]);
    }
  Eigen::Vector4d plane;
  int inliers = 0;
  if (!ransacPlane(sample, s.o.ransac_threshold, &plane, &inliers)) return false;
  ref->normal = plane.head<3>();
  ref->d = plane(3);
  if (ref->d < 0) {
    ref->normal = -ref->normal;
    ref->d = -ref->d;
  }
  ref->model = "plane";
  return true;
}

/** Robust scale (1.4826 MAD) of the healthy skin's residuals to the alternation's reference. */
double healthyScale(const Surface& s, const Alternation& a) {
  const cv::Mat use = a.band & ~a.plaque_mask;
  std::vector<double> r;
  const int step = std::max(1, static_cast<int>(std::sqrt(cv::countNonZero(use) / 50000.0)));
  for (int y = 0; y < s.xyz.rows; y += step)
    for (int x = 0; x < s.xyz.cols; x += step)
      if (use.at<uchar>(y, x)) {
        const cv::Vec3f& p = s.xyz.at<cv::Vec3f>(y, x);
        r.push_back(std::fabs(a.ref.height(Eigen::Vector3d(p[0], p[1], p[2]))));
      }
  if (r.size() < 20) return std::numeric_limits<double>::infinity();
  std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
  return 1.4826 * r[r.size() / 2];
}

/** Alternates a robust reference fit of `model` on the healthy points with the plaque mask from the heights. */
Alternation alternate(const Surface& s, const ReferenceSurface& start, const std::string& model) {
  const IndurationOptions& o = s.o;
  const cv::Mat dil = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * o.exclusion_margin_px + 1, 2 * o.exclusion_margin_px + 1));
  Alternation a;
  a.ref = start;
  a.plaque_mask = cv::Mat::zeros(s.xyz.size(), CV_8U);
  const bool curved = model == "quadratic" || model == "quadric";
  auto fit = [&](const cv::Mat& use, double scale) {
    return model == "quadric" ? fitQuadric(s.xyz, use, o.fit_points, scale, &a.ref)
                              : fitReference(s.xyz, use, model, o.fit_points, scale, &a.ref);
  };
  a.band = s.known_mask.clone();  // its own data: assigning an expression to a.band below writes into it
  for (int it = 0; it < o.max_iterations; ++it) {
    // from the second pass on, the reference is fitted within the working band of the first fit: the sides
    // of a limb, seen very obliquely by one camera, are measured worst and would pull it
    if (it == 1) a.band = workingBand(s.cloud.ray, a.ref, s.cloud.right_centre, o.max_incidence_deg) & s.known_mask;
    cv::Mat use = a.band & ~a.plaque_mask;
    a.healthy_fraction = cv::countNonZero(use) / static_cast<double>(s.known_points);
    if (a.healthy_fraction < o.min_reference_fraction) return a;
    // the first pass measures against the RANSAC plane itself: a fit to every point would be pulled towards
    // large plaques; later passes fit the healthy skin only (a curved model first fits all points robustly
    // with a wider cut-off: a curved surface leaves a plane's band)
    if (it == 0 && curved && !fit(use, 3 * o.ransac_threshold)) return a;
    if (it > 0 && !fit(use, o.ransac_threshold)) return a;
    const cv::Mat h = heights(s.xyz, a.ref);
    // the smoothing is chosen on the healthy skin: from the second pass on, once the plaques are masked
    cv::Mat hs;
    if (it == 0) {
      a.smoothing = o.smoothing_px;
      hs = smoothNaN(h, a.smoothing);
    } else {
      a.smoothing = adaptiveSmoothing(h, use, o.smoothing_px, o.max_smoothing_px, o.min_height, o.ransac_threshold, &hs);
    }
    const double threshold = detectionThreshold(hs, use, o.min_height, o.ransac_threshold);
    // only regions of plaque size are excluded: excluding every pixel of the noise's upper tail would
    // bias the next fit downwards, which raises more pixels above the threshold, and so on
    cv::Mat next;
    cv::dilate(largeRegions(hs > threshold, s.cloud.ray, a.ref, o.min_area), next, dil);
    const double changed = cv::countNonZero(next != a.plaque_mask) / static_cast<double>(s.known_points);
    a.plaque_mask = next;
    if (it > 0 && changed < 1e-4) break;
  }
  a.ok = true;
  a.scale = healthyScale(s, a);
  return a;
}

/** The reference: "auto" alternates the plane and the quadric and keeps the quadric only if it fits the healthy
 *  skin clearly better; otherwise the model asked for. `candidates`: each model tried with its scale. */
Alternation chooseReference(const Surface& s, const ReferenceSurface& start,
                            std::vector<std::pair<std::string, double>>* candidates) {
  if (s.o.reference_model != "auto") {
    Alternation best = alternate(s, start, s.o.reference_model);
    if (best.ok) candidates->emplace_back(s.o.reference_model, best.scale);
    return best;
  }
  const Alternation pl = alternate(s, start, "plane");
  const Alternation qu = alternate(s, start, "quadric");
  if (pl.ok) candidates->emplace_back("plane", pl.scale);
  if (qu.ok) candidates->emplace_back("quadric", qu.scale);
  // The quadric must halve the healthy skin's scatter: on a limb it reduces it by one or two orders of
  // magnitude, while on flat skin a near-degenerate quadric (two sheets close to the plane) can shave a
  // quarter off the noise's scale without describing anything.
  return (qu.ok && (!pl.ok || qu.scale < 0.5 * pl.scale)) ? qu : pl;
}

/** Sums over one plaque's region (footprint, heights of its interior, sigma along the local normal). */
struct PlaqueSums {
  double area = 0, sh = 0, sh2 = 0, ssig2 = 0, vol = 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  std::vector<float> hk;  // interior heights
  int px = 0, nc = 0;     // footprint pixels, pixels with a height
};

/** "N px at pixel (x, y)": where a region was, for the warnings. */
std::string atPixel(const cv::Rect& box) {
  return "pixel (" + std::to_string(box.x + box.width / 2) + ", " + std::to_string(box.y + box.height / 2) + ")";
}

/**
 * The plaques: regions above the detection threshold in the working band, each re-drawn from its core at
 * edge_fraction of its median height, measured, and checked (surroundings known, not too high, enough heights).
 */
class PlaqueSearch {
 public:
  PlaqueSearch(const Surface& s, const cv::Mat& hs, const cv::Mat& band, const cv::Mat& reach, double threshold,
               double smoothing, IndurationResult& res)
      : s_(s), o_(s.o), hs_(hs), reach_(reach), threshold_(threshold), smoothing_(smoothing), res_(res) {
    // A plaque cut by a narrow unknown or low strip (a step edge the matcher could not follow, a line of noise)
    // is one plaque: regions closer than about one interior margin are joined (closing) before labelling.
    const int jr = (o_.interior_margin_px + 1) / 2;
    join_ = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * jr + 1, 2 * jr + 1));
    off_band_ = s.known_mask & ~band;  // measured, but seen too obliquely
    cv::Mat above = (hs > threshold) & band, cents;
    if (o_.interior_margin_px > 0) {
      cv::morphologyEx(above, above, cv::MORPH_CLOSE, join_);
      above.setTo(0, off_band_);
    }
    n_ = cv::connectedComponentsWithStats(above, lab_, stats_, cents, 8, CV_32S);
    final_labels_ = cv::Mat(s.xyz.size(), CV_32S, cv::Scalar(0));
  }

  /** Draws every core, largest first: a plaque whose core the matcher cut in two (an occlusion shadow across it)
   *  is drawn from its larger piece, and the smaller piece, already inside it, is skipped. Then the ids by
   *  decreasing area, the labels, and the warnings of the regions ignored. */
  void run() {
    std::vector<int> cores(std::max(0, n_ - 1));
    std::iota(cores.begin(), cores.end(), 1);
    std::stable_sort(cores.begin(), cores.end(),
                     [&](int a, int b) { return stats_.at<int>(a, cv::CC_STAT_AREA) > stats_.at<int>(b, cv::CC_STAT_AREA); });
    for (const int k : cores) drawCore(k);
    renumberByArea();
    warnIgnored();
  }

 private:
  /** Core k's plaque, if it is one. */
  void drawCore(int k) {
    const cv::Rect bb(stats_.at<int>(k, cv::CC_STAT_LEFT), stats_.at<int>(k, cv::CC_STAT_TOP),
                      stats_.at<int>(k, cv::CC_STAT_WIDTH), stats_.at<int>(k, cv::CC_STAT_HEIGHT));
    if (takenAlready(k, bb)) return;  // part of a plaque drawn already
    double edge = 0, ceiling = 0;
    if (!coreLevels(k, bb, &edge, &ceiling)) return;
    cv::Rect box;
    cv::Mat mask;
    growRegion(k, bb, edge, ceiling, &box, &mask);
    if (isShoulder(k, bb, edge, box)) return;
    // statistics: area and centroid over the whole plaque; heights over its interior (the plaque eroded by
    // interior_margin_px: the matching window blurs the edge into a ramp, which would pull the mean down)
    // footprints on the reference's tangent plane at the region (the plane itself for the plane model)
    const ReferenceSurface local = localPlane(box, mask);
    const cv::Mat A = footprint(s_.cloud.ray, local, box);
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (final_labels_.at<int>(y + box.y, x + box.x) != 0) mask.at<uchar>(y, x) = 0;  // a few pixels of a neighbour
    // area, share measured, volume, label and the top's profile over the footprint the measurements support
    // (mean, max, std: the region's interior, as before)
    const Footprint foot =
        measuredFootprint(mask, box, s_.known_mask, res_.height_map, edge, 4 * std::max(1, o_.interior_margin_px));
    PlaqueSums sums = accumulate(box, mask, foot.pixels, A, local);
    if (sums.area < o_.min_area || sums.hk.size() < 10) return;
    if (atEdgeOrTooHigh(box, mask, sums)) return;
    if (sums.nc < o_.min_measured_share * sums.px) {
      sparse_.emplace_back(sums.px, std::to_string(sums.px) + " px at " + atPixel(box) + ", " +
                                        num(std::round(100.0 * sums.nc / std::max(1, sums.px))) + " % measured");
      return;
    }
    addPlaque(box, foot, sums);
  }

  /** True when at least half of core k lies in a plaque drawn already. */
  bool takenAlready(int k, const cv::Rect& bb) const {
    int in_core = 0, taken = 0;
    for (int y = bb.y; y < bb.y + bb.height; ++y)
      for (int x = bb.x; x < bb.x + bb.width; ++x)
        if (lab_.at<int>(y, x) == k) {
          ++in_core;
          taken += final_labels_.at<int>(y, x) != 0;
        }
    return 2 * taken >= in_core;
  }

  /** The core's edge level (edge_fraction of its median height, at least the threshold) and its ceiling; false
   *  when the core has under 10 heights. */
  bool coreLevels(int k, const cv::Rect& bb, double* edge, double* ceiling) const {
    std::vector<float> hv;
    for (int y = bb.y; y < bb.y + bb.height; ++y)
      for (int x = bb.x; x < bb.x + bb.width; ++x)
        if (lab_.at<int>(y, x) == k && !std::isnan(res_.height_map.at<float>(y, x))) hv.push_back(res_.height_map.at<float>(y, x));
    if (hv.size() < 10) return false;
    std::nth_element(hv.begin(), hv.begin() + hv.size() / 2, hv.end());
    const double median = hv[hv.size() / 2];
    *edge = std::max(threshold_, o_.edge_fraction * median);
    // The core holds the plaque's top: a pixel of its region far above the core's highest is another bump (a
    // stripe of mismatches along the measured surface's edge, a neighbouring higher plaque), not this plaque.
    std::nth_element(hv.begin(), hv.begin() + static_cast<std::ptrdiff_t>(0.99 * (hv.size() - 1)), hv.end());
    *ceiling = 2.0 * hv[static_cast<std::size_t>(0.99 * (hv.size() - 1))] + threshold_;
    return true;
  }

  /** The region above `edge` (and below `upper`) connected to core k, in the box. */
  cv::Mat connected(int k, const cv::Rect& bb, double edge, const cv::Rect& box, double upper) const {
    cv::Mat region = (hs_(box) > edge) & (hs_(box) < upper);
    if (o_.interior_margin_px > 0) {
      cv::morphologyEx(region, region, cv::MORPH_CLOSE, join_);
      region.setTo(0, off_band_(box));
    }
    cv::Mat rl;
    const int rn = cv::connectedComponents(region, rl, 8, CV_32S);
    std::vector<char> keep(rn, 0);
    for (int y = bb.y; y < bb.y + bb.height; ++y)
      for (int x = bb.x; x < bb.x + bb.width; ++x)
        if (lab_.at<int>(y, x) == k) keep[rl.at<int>(y - box.y, x - box.x)] = 1;
    keep[0] = 0;
    cv::Mat out = cv::Mat::zeros(box.size(), CV_8U);
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (keep[rl.at<int>(y, x)]) out.at<uchar>(y, x) = 255;
    return out;
  }

  /** The region at the edge level connected to the core, within a margin around the core's box; the margin
   *  doubles (up to 3 times) while the region reaches the box's border inside the image: the part of a plaque
   *  beyond its core's box (past a gap the core could not cross) must not be cut off along a straight line.
   *  Holes (background not reachable from the box border) are filled. */
  void growRegion(int k, const cv::Rect& bb, double edge, double ceiling, cv::Rect* box, cv::Mat* mask) const {
    const cv::Mat& xyz = s_.xyz;
    int m = 4 * std::max(1, static_cast<int>(std::ceil(smoothing_))) + 2 * o_.exclusion_margin_px + 2;
    for (int grow = 0;; ++grow, m *= 2) {
      *box = cv::Rect(bb.x - m, bb.y - m, bb.width + 2 * m, bb.height + 2 * m) & cv::Rect(0, 0, xyz.cols, xyz.rows);
      *mask = connected(k, bb, edge, *box, ceiling);
      const cv::Rect& b = *box;
      const bool touches = (b.x > 0 && cv::countNonZero(mask->col(0)) > 0) || (b.y > 0 && cv::countNonZero(mask->row(0)) > 0) ||
                           (b.x + b.width < xyz.cols && cv::countNonZero(mask->col(b.width - 1)) > 0) ||
                           (b.y + b.height < xyz.rows && cv::countNonZero(mask->row(b.height - 1)) > 0);
      if (!touches || grow == 3) break;
    }
    *mask |= holesOf(*mask);
  }

  /** A core whose half-height region reaches a plaque drawn already (from a larger core) is that plaque's
   *  shoulder (its ramp, a step the matcher blurred, a piece past a gap): no valley below its half height
   *  separates them, so it is not a plaque of its own. (Without the ceiling: the way up to a higher plaque is
   *  above the core's own top.) */
  bool isShoulder(int k, const cv::Rect& bb, double edge, const cv::Rect& box) const {
    const cv::Mat loose = connected(k, bb, edge, box, std::numeric_limits<double>::infinity());
    int overlap = 0;
    for (int y = 0; y < box.height && overlap < 10; ++y)
      for (int x = 0; x < box.width; ++x)
        if (loose.at<uchar>(y, x) && final_labels_.at<int>(y + box.y, x + box.x) != 0) ++overlap;
    return overlap >= 10;
  }

  /** The reference's tangent plane at the region's mean point (the reference itself unless it is a quadric). */
  ReferenceSurface localPlane(const cv::Rect& box, const cv::Mat& mask) const {
    const ReferenceSurface& ref = res_.reference;
    ReferenceSurface local = ref;
    if (ref.model != "quadric") return local;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    int mk = 0;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (mask.at<uchar>(y, x) && known(s_.xyz.at<cv::Vec3f>(y + box.y, x + box.x))) {
          const cv::Vec3f& q = s_.xyz.at<cv::Vec3f>(y + box.y, x + box.x);
          m += Eigen::Vector3d(q[0], q[1], q[2]);
          ++mk;
        }
    if (mk > 0) {
      const Eigen::Vector4d tp = ref.tangentPlane(m / mk);
      local.model = "plane";
      local.normal = tp.head<3>();
      local.d = tp(3);
    }
    return local;
  }

  /** Area over the footprint `fp`, volume and centroid over the known pixels, heights over the interior. */
  PlaqueSums accumulate(const cv::Rect& box, const cv::Mat& mask, const cv::Mat& fp, const cv::Mat& A,
                        const ReferenceSurface& local) const {
    cv::Mat interior;
    if (o_.interior_margin_px > 0) {
      cv::erode(mask, interior,
                cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * o_.interior_margin_px + 1, 2 * o_.interior_margin_px + 1)),
                cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, 0);
      if (cv::countNonZero(interior) < 10) interior = mask;  // too small to have an interior
    } else {
      interior = mask;
    }
    PlaqueSums t;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x) {
        if (!mask.at<uchar>(y, x)) continue;
        const float h = res_.height_map.at<float>(y + box.y, x + box.x);
        if (fp.at<uchar>(y, x)) {
          ++t.px;
          t.area += A.at<double>(y, x);
        }
        if (std::isnan(h)) continue;
        t.vol += std::max(0.0f, h) * A.at<double>(y, x);
        const cv::Vec3f& q = s_.xyz.at<cv::Vec3f>(y + box.y, x + box.x);
        t.c += Eigen::Vector3d(q[0], q[1], q[2]);
        ++t.nc;
        if (!interior.at<uchar>(y, x)) continue;
        t.hk.push_back(h);
        t.sh += h;
        t.sh2 += static_cast<double>(h) * h;
        if (!s_.cloud.sigma.empty()) {
          const float sg = s_.cloud.sigma.at<float>(y + box.y, x + box.x);
          const cv::Vec3f& r = s_.cloud.ray.at<cv::Vec3f>(y + box.y, x + box.x);
          const double cosi = std::fabs(local.normal.x() * r[0] + local.normal.y() * r[1] + local.normal.z() * r[2]);
          if (std::isfinite(sg)) t.ssig2 += (sg * cosi) * (sg * cosi);
        }
      }
    return t;
  }

  /** A region whose surroundings are mostly unknown lies at the edge of the measured surface (or is an island of
   *  mismatches): its height above the reference means nothing (listed in at_edge_); one higher than max_height
   *  is not skin (a warning). True when the region is ignored for either reason. */
  bool atEdgeOrTooHigh(const cv::Rect& box, const cv::Mat& mask, const PlaqueSums& t) {
    const int r1 = 2 * o_.interior_margin_px, r2 = 4 * o_.interior_margin_px;
    // Only the surroundings in the working band count (where the reference says the skin faces both
    // cameras): a plaque next to the band's edge keeps its measurable side; an island beyond a silhouette,
    // where no ray meets the reference in the band, has none. Computed in a window of the box grown by r2
    // (the ring cannot reach further); beyond the image border counts as in the band and unknown.
    const cv::Rect win(box.x - r2, box.y - r2, box.width + 2 * r2, box.height + 2 * r2);
    const cv::Rect in = win & cv::Rect(0, 0, s_.xyz.cols, s_.xyz.rows);
    cv::Mat full = cv::Mat::zeros(win.size(), CV_8U), d1, d2;
    cv::Mat known_pad = cv::Mat::zeros(win.size(), CV_8U), reach_pad(win.size(), CV_8U, cv::Scalar(255));
    full(cv::Rect(r2, r2, box.width, box.height)).setTo(255, mask);
    s_.known_mask(in).copyTo(known_pad(in - win.tl()));
    reach_(in).copyTo(reach_pad(in - win.tl()));
    cv::dilate(full, d1, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r1 + 1, 2 * r1 + 1)));
    cv::dilate(full, d2, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r2 + 1, 2 * r2 + 1)));
    const cv::Mat ring = d2 & ~d1 & reach_pad;
    const int ring_all = cv::countNonZero(d2 & ~d1);
    const int ring_n = cv::countNonZero(ring), ring_known = cv::countNonZero(ring & known_pad);
    const double mean_h = t.sh / static_cast<double>(t.hk.size());
    if (ring_n < 0.25 * ring_all || ring_known < 0.8 * ring_n) {
      // (in pixels: beyond a silhouette the reference's tangent plane is edge-on and an area means nothing)
      at_edge_.emplace_back(t.px, std::to_string(t.px) + " px at " + atPixel(box) + ", " +
                                      num(std::round(100.0 * ring_known / std::max(1, ring_n))) + " % of its surroundings known");
      return true;
    }
    if (mean_h > o_.max_height) {
      res_.warnings.push_back("a region " + num(std::round(mean_h * 1e5) / 100) + " mm above the reference at " +
                              atPixel(box) + " was ignored: higher than max_height " + num(o_.max_height * 1e3) +
                              " mm (not skin)");
      return true;
    }
    return false;
  }

  /** The plaque's figures, its warnings (partly measured, open outline) and its label. */
  void addPlaque(const cv::Rect& box, const Footprint& foot, PlaqueSums& t) {
    Plaque p;
    const double nk = static_cast<double>(t.hk.size());
    p.area = t.area;
    p.centroid = t.c / std::max(1, t.nc);
    p.mean_height = t.sh / nk;
    p.std_height = std::sqrt(std::max(0.0, t.sh2 / nk - p.mean_height * p.mean_height));
    std::nth_element(t.hk.begin(), t.hk.begin() + static_cast<long>(0.99 * (nk - 1)), t.hk.end());
    p.max_height = t.hk[static_cast<std::size_t>(0.99 * (nk - 1))];
    p.mean_height_sigma = std::sqrt(t.ssig2) / nk;
    // the top: from the height profile; a plaque too small to have 30 heights clear of its ramp takes the 99th
    // percentile of its interior (the mean would read its blurred ramp). The profile's distances are from the
    // footprint's outline: where a plaque runs into unmeasured skin, the region's part in the gap would move
    // its deepest point off the measured top (partly measured plaques of seeds 5, 8, 11: +28.5, -6.8, +10.1 um
    // -> +21.7, -2.9, +6.4 um; seeds 9 and 10, not looked at for this: within 2 um)
    p.top_height = topHeight(foot.pixels, res_.height_map(box), o_.interior_margin_px);
    if (!std::isfinite(p.top_height)) p.top_height = p.max_height;
    p.pasi_class = pasiClass(p.top_height, o_.pasi_boundaries);
    p.pixels = t.px;
    p.measured_fraction = t.px > 0 ? t.nc / static_cast<double>(t.px) : 0.0;
    p.volume = p.measured_fraction > 0 ? t.vol / p.measured_fraction : 0.0;
    p.outline_unmeasured = foot.open;
    const std::string what = "a plaque of " + num(std::round(t.area * 1e7) / 10) + " mm^2 at " + atPixel(box);
    if (p.measured_fraction < 0.9)
      res_.warnings.push_back(what + " is only partly measured: " + num(std::round(100 * p.measured_fraction)) +
                              " % of its footprint has a height (its mean and volume rest on that part)");
    if (p.outline_unmeasured > kOpenOutline)
      res_.warnings.push_back(what + " borders unmeasured skin along " + num(std::round(100 * p.outline_unmeasured)) +
                              " % of its outline: it may extend there (its area is what was measured; turn the skin "
                              "towards the rig to measure all of it)");
    p.bbox = box;
    p.id = static_cast<int>(plaques_.size()) + 1;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (foot.pixels.at<uchar>(y, x)) final_labels_.at<int>(y + box.y, x + box.x) = p.id;
    plaques_.push_back(p);
  }

  /** ids in order of decreasing area, in the result and in its label image. */
  void renumberByArea() {
    std::vector<int> order(plaques_.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return plaques_[a].area > plaques_[b].area; });
    std::vector<int> new_id(plaques_.size() + 1, 0);
    for (std::size_t i = 0; i < order.size(); ++i) {
      new_id[plaques_[order[i]].id] = static_cast<int>(i) + 1;
      res_.plaques.push_back(plaques_[order[i]]);
      res_.plaques.back().id = static_cast<int>(i) + 1;
    }
    for (int y = 0; y < final_labels_.rows; ++y)
      for (int x = 0; x < final_labels_.cols; ++x) {
        int& l = final_labels_.at<int>(y, x);
        if (l) l = new_id[l];
      }
    res_.labels = final_labels_;
  }

  /** One warning per kind of ignored region (a limb's silhouette can leave dozens), the three largest named. */
  void warnIgnored() {
    auto largest = [](std::vector<std::pair<double, std::string>>& v) {
      std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
      std::string list;
      for (size_t i = 0; i < std::min<size_t>(3, v.size()); ++i) list += (i ? "; " : "") + v[i].second;
      return list;
    };
    if (!at_edge_.empty()) {
      const std::string list = largest(at_edge_);
      res_.warnings.push_back(at_edge_.size() == 1
                                  ? "a raised region of " + list + " was ignored: it lies at the edge of the measured surface"
                                  : std::to_string(at_edge_.size()) + " raised regions were ignored: they lie at the edge of the "
                                    "measured surface (their height above the reference means nothing); the largest: " + list);
    }
    if (!sparse_.empty()) {
      const std::string list = largest(sparse_);
      res_.warnings.push_back(std::to_string(sparse_.size()) + " raised region" + (sparse_.size() == 1 ? " was" : "s were") +
                              " ignored: under " + num(std::round(100 * o_.min_measured_share)) +
                              " % of the footprint has a height (scattered matches, mostly where the skin turns away from "
                              "the rig, are not a plaque); the largest: " + list);
    }
  }

  const Surface& s_;
  const IndurationOptions& o_;
  const cv::Mat hs_, reach_;
  const double threshold_, smoothing_;
  IndurationResult& res_;
  cv::Mat join_, off_band_, lab_, stats_, final_labels_;
  int n_ = 0;
  std::vector<Plaque> plaques_;
  std::vector<std::pair<double, std::string>> at_edge_;  // ignored regions at the edge: area, description
  std::vector<std::pair<double, std::string>> sparse_;   // ignored regions with too few heights: area, description
};

}  // namespace

IndurationResult measureInduration(const stereo::DenseCloud& cloud, const IndurationOptions& o) {
  o.validate();
  IndurationResult res;
  if (cloud.xyz.empty() || cloud.xyz.type() != CV_32FC3) {
    res.warnings.push_back("empty point cloud: nothing to measure");
    return res;
  }
  if (cloud.ray.size() != cloud.xyz.size() || cloud.ray.type() != CV_32FC3)
    throw IndurationError("the cloud has no viewing ray per pixel (DenseCloud::ray): triangulate it with triangulateDisparity");
  Surface s{cloud, o, cloud.xyz.clone(), cv::Mat(), 0};
  res.labels = cv::Mat(s.xyz.size(), CV_32S, cv::Scalar(0));
  res.height_map = cv::Mat(s.xyz.size(), CV_32F, cv::Scalar(kNaN));
  res.outliers_removed = removeOutliers(s.xyz, o.sor_std_ratio);
  s.known_mask.create(s.xyz.size(), CV_8U);
  for (int y = 0; y < s.xyz.rows; ++y)
    for (int x = 0; x < s.xyz.cols; ++x) s.known_mask.at<uchar>(y, x) = known(s.xyz.at<cv::Vec3f>(y, x)) ? 255 : 0;
  res.known_points = s.known_points = cv::countNonZero(s.known_mask);
  if (res.known_points < 1000) {
    res.warnings.push_back("too few surface points (" + std::to_string(res.known_points) +
                           ") to fit a reference: check the dense matching (texture, overlap, working range)");
    return res;
  }

  // ---- the reference: a RANSAC plane to start, then alternation (robust fit on the healthy points, plaque
  // mask from the heights) for the plane and the quadric
  ReferenceSurface start;
  if (!ransacStart(s, &start)) {
    res.warnings.push_back("no plane found in the surface points (RANSAC): no reference");
    return res;
  }
  std::vector<std::pair<std::string, double>> candidates;
  const Alternation best = chooseReference(s, start, &candidates);
  if (!best.ok && best.healthy_fraction >= o.min_reference_fraction) {
    res.warnings.push_back("the reference surface could not be fitted to the surface points");
    return res;
  }
  if (best.healthy_fraction < o.min_reference_fraction) {
    res.warnings.push_back("no healthy skin left to fit the reference: only " +
                           num(std::round(1000 * best.healthy_fraction) / 10) + " % of the points are not raised (minimum " +
                           num(100 * o.min_reference_fraction) + " %); widen the region of interest to include skin around the plaques");
    return res;
  }
  res.reference = best.ref;
  res.reference.candidates = candidates;
  res.reference_ok = true;
  res.height_map = heights(s.xyz, res.reference);
  res.smoothing_px = best.smoothing;
  const cv::Mat hs = smoothFilled(res.height_map, best.smoothing, o.interior_margin_px);

  // ---- the working band: where the reference faces both cameras within max_incidence_deg
  const cv::Mat inc = incidenceMap(cloud.ray, res.reference, cloud.right_centre);
  const cv::Mat reach = o.max_incidence_deg >= 90 ? cv::Mat(inc.size(), CV_8U, cv::Scalar(255)) : (inc <= o.max_incidence_deg);
  const cv::Mat band = reach & s.known_mask;
  res.band_fraction = res.known_points > 0 ? cv::countNonZero(band) / static_cast<double>(res.known_points) : 1.0;
  if (res.band_fraction < 0.995)
    res.warnings.push_back(num(std::round(1000 * (1 - res.band_fraction)) / 10) + " % of the measured surface faces a camera at more than " +
                           num(o.max_incidence_deg) + " deg (the sides of a limb): not searched for plaques; turn the skin "
                           "towards the rig to measure there");

  // ---- plaques: regions above the detection threshold, re-drawn at edge_fraction of their median height
  res.detection_threshold = detectionThreshold(hs, s.known_mask & ~best.plaque_mask & band, o.min_height, o.ransac_threshold);
  PlaqueSearch(s, hs, band, reach, res.detection_threshold, best.smoothing, res).run();
  if (res.plaques.empty()) res.warnings.push_back("no plaque stands more than " + num(o.min_height * 1e3) + " mm above the reference");
  return res;
}

}  // namespace induration
}  // namespace skin3d
