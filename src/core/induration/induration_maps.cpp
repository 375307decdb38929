// SPDX-License-Identifier: BSD-3-Clause
// Induration measurement: the height map, its smoothing and detection threshold, the reference's incidence,
// footprints and regions. See include/skin3d/induration/induration.h.
#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "../common/parallel.h"
#include "induration_detail.h"

namespace skin3d {
namespace induration {
namespace induration_detail {

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

namespace {

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

}  // namespace

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

namespace {

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

}  // namespace

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
 * NaN if fewer than 30 heights are that deep. `sigma`: the top's standard deviation from the height noise
 * (`noise_density`: its per-pixel variance times its correlation area, m^2 px^2; see heightNoise), NaN with it.
 */
double topHeight(const cv::Mat& mask, const cv::Mat& h, int margin, double noise_density, double* sigma) {
  *sigma = std::numeric_limits<double>::quiet_NaN();
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
  // The noise of a bin's median of w heights is about (pi/2) noise_density / w (noise_density: the per-pixel
  // variance times the noise's correlation area, so w correlated heights count as w / area independent ones);
  // with the bins weighted by w, the weighted fit's covariance is then (pi/2) noise_density A^-1, and the flat
  // top's variance (pi/2) noise_density / sum w.
  const double c = 0.5 * 3.14159265358979323846 * noise_density;
  const double flat = swm / sw;
  *sigma = std::sqrt(c / sw);
  if (pts.size() < 5 || !(std::fabs(A.determinant()) > 1e-12 * A.squaredNorm())) return flat;
  const Eigen::Vector2d ab = A.ldlt().solve(rhs);
  double ssr = 0;
  for (const auto& p : pts) ssr += p(2) * std::pow(p(1) - ab(0) - ab(1) * p(0), 2);
  const Eigen::Matrix2d Ai = A.inverse();
  const double var_b = ssr / (pts.size() - 2) * Ai(1, 1);
  if (!(var_b > 0 && ab(1) < -3 * std::sqrt(var_b))) return flat;
  *sigma = std::sqrt(c * Ai(0, 0));
  return ab(0);
}

std::pair<double, double> medianAndScale(std::vector<float>& v) {
  auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  const float med = *mid;
  for (float& x : v) x = std::fabs(x - med);
  std::nth_element(v.begin(), mid, v.end());
  return {med, 1.4826 * *mid};
}

HeightNoise heightNoise(const cv::Mat& h, const cv::Mat& use, int block) {
  HeightNoise out;
  cv::Mat hu(h.size(), CV_32F, cv::Scalar(kNaN));
  h.copyTo(hu, use & (h == h));
  // residuals about the heights' own slow trend (a reference that bends away from the skin over centimetres is
  // not noise: it would inflate the block means' scatter)
  const cv::Mat trend = smoothNaN(hu, 2.0 * block);
  cv::Mat r = hu - trend;  // NaN where hu is
  std::vector<float> px, means;
  for (int y = 0; y < r.rows; y += 2) {
    const float* p = r.ptr<float>(y);
    for (int x = 0; x < r.cols; x += 2)
      if (std::isfinite(p[x])) px.push_back(p[x]);
  }
  for (int by = 0; by + block <= r.rows; by += block)
    for (int bx = 0; bx + block <= r.cols; bx += block) {
      double sum = 0;
      int n = 0;
      for (int y = by; y < by + block; ++y) {
        const float* p = r.ptr<float>(y);
        for (int x = bx; x < bx + block; ++x)
          if (std::isfinite(p[x])) {
            sum += p[x];
            ++n;
          }
      }
      if (n >= 0.9 * block * block) means.push_back(static_cast<float>(sum / n));
    }
  if (px.size() < 100) return out;
  out.sigma = medianAndScale(px).second;
  out.blocks = static_cast<int>(means.size());
  if (means.size() < 20 || !(out.sigma > 0)) return out;
  const double sb = medianAndScale(means).second;
  out.correlation_area = std::min(static_cast<double>(block) * block,
                                  std::max(1.0, static_cast<double>(block) * block * sb * sb / (out.sigma * out.sigma)));
  return out;
}

double pixelSize(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Mat& use) {
  std::vector<float> v;
  const int step = std::max(8, static_cast<int>(std::sqrt(cv::countNonZero(use) / 400.0)));
  for (int y = step / 2; y + 1 < use.rows; y += step)
    for (int x = step / 2; x + 1 < use.cols; x += step)
      if (use.at<uchar>(y, x)) {
        const double a = footprint(ray, ref, cv::Rect(x, y, 1, 1)).at<double>(0, 0);
        if (a > 0 && std::isfinite(a)) v.push_back(static_cast<float>(std::sqrt(a)));
      }
  if (v.empty()) return 0;
  return medianAndScale(v).first;
}

/**
 * The surface's per-pixel noise before any reference is fitted (m): the robust sigma of the depths about their
 * own smoothing over kBlur px, along the rays (the depth's scatter is the matcher's, in every rig). The smoothing
 * is wide against the matcher's correlation (a few px) and narrow against the body's curvature (a limb bends its
 * depths by ~1/(2R) x (kBlur px)^2: 0.02 mm for R = 40 mm at 0.2 mm per px), so neither the shape nor the
 * correlated part of the noise hides in it; the residual's scatter is within ~10 % of the noise's.
 */
double pixelNoise(const cv::Mat& xyz, const cv::Mat& known) {
  constexpr double kBlur = 8.0;
  cv::Mat depth, z(xyz.size(), CV_32F, cv::Scalar(kNaN));
  cv::extractChannel(xyz, depth, 2);
  depth.copyTo(z, known);
  const cv::Mat r = z - smoothNaN(z, kBlur);
  std::vector<float> v;
  const int step = std::max(1, static_cast<int>(std::sqrt(cv::countNonZero(known) / 100000.0)));
  for (int y = 0; y < r.rows; y += step) {
    const float* p = r.ptr<float>(y);
    for (int x = 0; x < r.cols; x += step)
      if (std::isfinite(p[x])) v.push_back(p[x]);
  }
  if (v.size() < 100) return 0;
  return medianAndScale(v).second;
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

double aspectOf(const Eigen::Vector3d& sum, const Eigen::Matrix3d& sq, int points) {
  if (points < 10) return 1;
  const Eigen::Vector3d mean = sum / points;
  const Eigen::Matrix3d cov = sq / points - mean * mean.transpose();
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues();  // ascending
  return std::sqrt(std::max(ev(2), 0.0) / std::max(ev(1), 1e-18));
}

cv::Mat plaqueLikeRegions(const cv::Mat& regions, const cv::Mat& hs, const cv::Mat& xyz, const cv::Mat& known,
                          double smoothing, double threshold, double max_height) {
  cv::Mat lab, stats, cents;
  const int n = cv::connectedComponentsWithStats(regions, lab, stats, cents, 8, CV_32S);
  const int gap = static_cast<int>(std::ceil(2 * smoothing)), width = std::max(gap, 8);
  const int reach = gap + width;
  const cv::Mat k_in = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * gap + 1, 2 * gap + 1));
  const cv::Mat k_out = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * reach + 1, 2 * reach + 1));
  cv::Mat out = cv::Mat::zeros(regions.size(), CV_8U);
  for (int k = 1; k < n; ++k) {
    const cv::Rect r(stats.at<int>(k, 0), stats.at<int>(k, 1), stats.at<int>(k, 2), stats.at<int>(k, 3));
    const cv::Rect box = (r + cv::Size(2 * reach, 2 * reach) - cv::Point(reach, reach)) & cv::Rect(0, 0, regions.cols, regions.rows);
    const cv::Mat mine = lab(box) == k;
    cv::Mat near, far;
    cv::dilate(mine, near, k_in);
    cv::dilate(mine, far, k_out);
    const cv::Mat ring = far & ~near & known(box) & ~regions(box);
    std::vector<float> in, around;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d sq = Eigen::Matrix3d::Zero();
    int points = 0;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x) {
        if (mine.at<uchar>(y, x) && known.at<uchar>(box.y + y, box.x + x)) {
          const cv::Vec3f& p = xyz.at<cv::Vec3f>(box.y + y, box.x + x);
          const Eigen::Vector3d q(p[0], p[1], p[2]);
          sum += q;
          sq += q * q.transpose();
          ++points;
        }
        const float v = hs.at<float>(box.y + y, box.x + x);
        if (!std::isfinite(v)) continue;
        if (mine.at<uchar>(y, x)) in.push_back(v);
        else if (ring.at<uchar>(y, x)) around.push_back(v);
      }
    bool rise = true;
    double c = 0;
    if (!in.empty() && around.size() >= 20) {
      c = medianAndScale(in).first - medianAndScale(around).first;
      rise = c >= 0.5 * threshold;
    }
    const double aspect = aspectOf(sum, sq, points);
    const bool compact = aspect <= kMaxPlaqueAspect || c > max_height;
    if (rise && compact) out(box).setTo(255, mine);
  }
  return out;
}

double ellipseFill(const cv::Mat& m) {
  const cv::Moments mo = cv::moments(m, true);
  if (mo.m00 < 3) return 0;
  const double a = mo.mu20 / mo.m00, b = mo.mu02 / mo.m00, c = mo.mu11 / mo.m00;
  const double det = a * b - c * c;
  return det > 0 ? mo.m00 / (4 * M_PI * std::sqrt(det)) : 0;
}

cv::Mat largeEnough(const cv::Mat& mask, double pixels) {
  cv::Mat lab, stats, cents;
  const int n = cv::connectedComponentsWithStats(mask, lab, stats, cents, 8, CV_32S);
  std::vector<uchar> keep(n, 0);
  for (int k = 1; k < n; ++k) keep[k] = stats.at<int>(k, cv::CC_STAT_AREA) >= pixels ? 255 : 0;
  cv::Mat out(mask.size(), CV_8U);
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x) out.at<uchar>(y, x) = keep[lab.at<int>(y, x)];
  return out;
}

double interiorNoise(const cv::Mat& h_box, const cv::Mat& fp, int margin) {
  cv::Mat interior = fp.clone();
  if (margin > 0)
    cv::erode(fp, interior,
              cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * margin + 1, 2 * margin + 1)),
              cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, 0);
  std::vector<Eigen::Vector3d> pts;  // (x, y, h), x and y about the box centre in units of its half size
  const double cx = 0.5 * fp.cols, cy = 0.5 * fp.rows, sc = std::max(1.0, 0.5 * std::max(fp.cols, fp.rows));
  for (int y = 0; y < fp.rows; ++y)
    for (int x = 0; x < fp.cols; ++x) {
      const float h = h_box.at<float>(y, x);
      if (interior.at<uchar>(y, x) && std::isfinite(h)) pts.emplace_back((x - cx) / sc, (y - cy) / sc, h);
    }
  if (pts.size() < 100) return kNaN;
  auto basis = [](const Eigen::Vector3d& q) {
    Eigen::Matrix<double, 6, 1> f;
    f << 1, q.x(), q.y(), q.x() * q.x(), q.x() * q.y(), q.y() * q.y();
    return f;
  };
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  for (const auto& q : pts) {
    const Eigen::Matrix<double, 6, 1> f = basis(q);
    A += f * f.transpose();
    b += f * q.z();
  }
  const Eigen::Matrix<double, 6, 1> c = A.ldlt().solve(b);
  if (!c.allFinite()) return kNaN;
  std::vector<float> r;
  r.reserve(pts.size());
  for (const auto& q : pts) r.push_back(static_cast<float>(q.z() - basis(q).dot(c)));
  return medianAndScale(r).second;
}

}  // namespace induration_detail
}  // namespace induration
}  // namespace skin3d
