// SPDX-License-Identifier: BSD-3-Clause
// Induration measurement: the reference surface (robust plane, quadratic and quadric fits) and its alternation
// with the plaque mask. See include/skin3d/induration/induration.h.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "../common/parallel.h"
#include "induration_detail.h"
#include "reference_ransac.h"

namespace skin3d {
namespace induration {
namespace induration_detail {
namespace {

/** Tukey biweight of r with scale c. */
inline double tukey(double r, double c) {
  const double u = r / c;
  return std::fabs(u) >= 1 ? 0.0 : (1 - u * u) * (1 - u * u);
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

/**
 * The known points of the largest connected surface. Neighbours (on a grid of at most about 250000 points, across
 * gaps of up to 3 unknown ones) are connected when they are closer in 3-D than 10 times the median distance of
 * neighbouring points (times the points spanned): a surface stays connected up to about 84 deg of incidence, while
 * the background and mismatches at other depths are cut off. A curved model's first fit, unweighted, starts on it:
 * a tenth of the points on another body or on the background could pull that fit into a saddle between them, which
 * the robust passes after it do not leave.
 */
cv::Mat largestSurface(const cv::Mat& xyz, const cv::Mat& known) {
  const int total = cv::countNonZero(known);
  const int step = std::max(1, static_cast<int>(std::ceil(std::sqrt(total / 250000.0))));
  const int gw = (xyz.cols + step - 1) / step, gh = (xyz.rows + step - 1) / step;
  std::vector<Eigen::Vector3f> p(static_cast<size_t>(gw) * gh);
  std::vector<char> ok(p.size(), 0);
  for (int gy = 0; gy < gh; ++gy)
    for (int gx = 0; gx < gw; ++gx) {
      const int x = gx * step, y = gy * step;
      const cv::Vec3f& q = xyz.at<cv::Vec3f>(y, x);
      if (known.at<uchar>(y, x) && std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2])) {
        p[gy * gw + gx] = Eigen::Vector3f(q[0], q[1], q[2]);
        ok[gy * gw + gx] = 1;
      }
    }
  std::vector<float> spacing;
  for (int i = 0; i < static_cast<int>(p.size()); ++i) {
    if (!ok[i]) continue;
    if ((i % gw) + 1 < gw && ok[i + 1]) spacing.push_back((p[i + 1] - p[i]).norm());
    if (i + gw < static_cast<int>(p.size()) && ok[i + gw]) spacing.push_back((p[i + gw] - p[i]).norm());
  }
  if (spacing.size() < 100) return known.clone();
  std::nth_element(spacing.begin(), spacing.begin() + spacing.size() / 2, spacing.end());
  const float tol = 10.f * spacing[spacing.size() / 2];
  std::vector<int> parent(p.size());
  for (int i = 0; i < static_cast<int>(parent.size()); ++i) parent[i] = i;
  auto root = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // each point is joined to the next known one to its right and below, across gaps of up to kGap unknown points
  // (a matcher's gap or outliers removed along a step), the tolerance growing with the distance spanned
  constexpr int kGap = 3;
  const int n_points = static_cast<int>(p.size());
  for (int i = 0; i < n_points; ++i) {
    if (!ok[i]) continue;
    for (int k = 1; k <= kGap + 1 && (i % gw) + k < gw; ++k)
      if (ok[i + k]) {
        if ((p[i + k] - p[i]).norm() < tol * k) parent[root(i)] = root(i + k);
        break;
      }
    for (int k = 1; k <= kGap + 1 && i + k * gw < n_points; ++k)
      if (ok[i + k * gw]) {
        if ((p[i + k * gw] - p[i]).norm() < tol * k) parent[root(i)] = root(i + k * gw);
        break;
      }
  }
  std::vector<int> size(p.size(), 0);
  int best = -1;
  for (int i = 0; i < static_cast<int>(p.size()); ++i)
    if (ok[i] && ++size[root(i)] > (best < 0 ? 0 : size[best])) best = root(i);
  cv::Mat grid(gh, gw, CV_8U, cv::Scalar(0));
  for (int i = 0; i < static_cast<int>(p.size()); ++i)
    if (ok[i] && root(i) == best) grid.at<uchar>(i / gw, i % gw) = 255;
  cv::Mat full;
  cv::resize(grid, full, xyz.size(), 0, 0, cv::INTER_NEAREST);
  return full & known;
}

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
bool fitQuadric(const cv::Mat& xyz, const cv::Mat& use, int max_points, double max_scale, ReferenceSurface* ref,
                bool warm) {
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
    // (a warm start, from a quadric fitted to this surface before, has meaningful residuals: Tukey weights with
    // the narrow cut-off from the first step, so that points far off it, a silhouette's mismatches or an object
    // beside the skin, never pull the fit)
    const double cap = it <= 2 && !warm ? 10 * max_scale : max_scale / 3.0;
    const double scale = std::min(std::max(1.4826 * a[a.size() / 2], 1e-7), cap);
    for (std::size_t i = 0; i < pts.size(); ++i) w[i] = it == 0 && !warm ? 1.0 : tukey(r[i], 4.685 * scale);
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

}  // namespace

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
  if (!ransacPlane(sample, s.band, &plane, &inliers)) return false;
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
    return model == "quadric" ? fitQuadric(s.xyz, use, o.fit_points, scale, &a.ref, a.ref.model == "quadric")
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
    if (it == 0 && curved && !fit(use & largestSurface(s.xyz, s.known_mask), 3 * s.band)) return a;
    if (it > 0 && !fit(use, s.band)) return a;
    const cv::Mat h = heights(s.xyz, a.ref);
    // the smoothing is chosen on the healthy skin: from the second pass on, once the plaques are masked
    cv::Mat hs;
    if (it == 0) {
      a.smoothing = o.smoothing_px;
      hs = smoothNaN(h, a.smoothing);
    } else {
      // at most what keeps 3/4 of the smallest plaque's height (maxSmoothing), in px on this skin
      const double pixel_m = pixelSize(s.cloud.ray, a.ref, use);
      const double cap_px = pixel_m > 0 ? maxSmoothing(o.min_area) / pixel_m : o.max_smoothing_px;
      const double limit = std::max(o.smoothing_px, std::min(o.max_smoothing_px, cap_px));
      a.smoothing = adaptiveSmoothing(h, use, o.smoothing_px, limit, o.min_height, s.band, &hs);
    }
    const double threshold = detectionThreshold(hs, use, o.min_height, s.band);
    // only regions of plaque size are excluded: excluding every pixel of the noise's upper tail would
    // bias the next fit downwards, which raises more pixels above the threshold, and so on
    cv::Mat next;
    // (and only plaque-like ones: a long strip is the reference bending away from the body, and leaving it out
    // takes away the skin that holds the fit)
    const cv::Mat raised = largeRegions((hs > threshold) & a.band, s.cloud.ray, a.ref, o.min_area);
    cv::dilate(plaqueLikeRegions(raised, hs, s.xyz, s.known_mask, a.smoothing, threshold, o.max_height), next, dil);
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

}  // namespace induration_detail

using namespace induration_detail;  // NOLINT(build/namespaces): the private helpers of the induration files

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

}  // namespace induration
}  // namespace skin3d
