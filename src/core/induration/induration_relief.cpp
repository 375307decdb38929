// SPDX-License-Identifier: BSD-3-Clause
// Induration measurement: the shape of a raised region's border, a plaque's or healthy relief's (borderShape in
// induration_detail.h, used by the plaque search).
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "induration_detail.h"

namespace skin3d {
namespace induration {
namespace induration_detail {

Eigen::Matrix2d pixelOnPlane(const cv::Mat& ray, const cv::Rect& box, const ReferenceSurface& local, int step) {
  auto onPlane = [&](double u, double v) {
    const int ui = std::clamp(static_cast<int>(std::lround(u)), 0, ray.cols - 1);
    const int vi = std::clamp(static_cast<int>(std::lround(v)), 0, ray.rows - 1);
    const cv::Vec3f& q = ray.at<cv::Vec3f>(vi, ui);
    const Eigen::Vector3d r(q[0], q[1], q[2]);
    return Eigen::Vector3d(-local.d / local.normal.dot(r) * r);
  };
  const double cu = box.x + 0.5 * box.width, cv0 = box.y + 0.5 * box.height;
  const Eigen::Vector3d X0 = onPlane(cu, cv0), du = (onPlane(cu + step, cv0) - X0) / step,
                        dv = (onPlane(cu, cv0 + step) - X0) / step;
  const Eigen::Vector3d b1 = du.normalized(), b2 = local.normal.cross(b1).normalized();
  Eigen::Matrix2d J;
  J << b1.dot(du), b1.dot(dv), b2.dot(du), b2.dot(dv);
  return J;
}

namespace {

/** The grid's cells by their signed distance to the outline (the region and the skin around it that may be used,
 *  known or not; `cls_g` 1 inside, 2 around, 0 neither): out->cells in bins of a quarter of a profile bin (`w` grid
 *  px, `n_out` of them outside), for the area within a level's crossing (areaRatioAt); returns each outside bin's
 *  ring. */
std::vector<double> countCells(const cv::Mat& cls_g, const cv::Mat& din, const cv::Mat& dout, double w, int n_out,
                               BorderShape* out) {
  std::vector<double> ring(n_out, 0.0);
  out->cell_bin = 0.25 * w;
  out->cells_reach = n_out * w;
  out->cells.assign(static_cast<std::size_t>(std::ceil(2 * out->cells_reach / out->cell_bin)) + 1, 0.0);
  for (int y = 0; y < cls_g.rows; ++y)
    for (int x = 0; x < cls_g.cols; ++x) {
      const uchar c = cls_g.at<uchar>(y, x);
      if (c == 0) continue;
      const bool in = c == 1;
      const double d = in ? din.at<float>(y, x) - 0.5 : 0.5 - dout.at<float>(y, x);
      const int i = static_cast<int>(std::floor(d / w)) + n_out;
      if (!in && i >= 0 && i < n_out) ring[i] += 1;
      const long k = static_cast<long>(std::floor((d + out->cells_reach) / out->cell_bin));
      out->cells[static_cast<std::size_t>(std::clamp(k, 0L, static_cast<long>(out->cells.size()) - 1))] += 1;
    }
  return ring;
}

}  // namespace

BorderShape borderShape(const cv::Mat& cls, const cv::Mat& hw, const Eigen::Matrix2d& J, const HeightNoise& noise,
                        double threshold) {
  BorderShape out;
  const Eigen::JacobiSVD<Eigen::Matrix2d> svd(J);
  const double g_min = svd.singularValues()(1), g_max = svd.singularValues()(0);
  if (!J.allFinite() || !(g_min > 0)) return out;
  out.pixel = g_min;
  // the grid: the finest pixel's size; the window's corners give its extent
  const Eigen::Matrix2d M = J / g_min;
  Eigen::Vector2d lo(1e30, 1e30), hi(-1e30, -1e30);
  for (const Eigen::Vector2d& c : {Eigen::Vector2d(0, 0), Eigen::Vector2d(cls.cols, 0), Eigen::Vector2d(0, cls.rows),
                                  Eigen::Vector2d(cls.cols, cls.rows)}) {
    lo = lo.cwiseMin(M * c);
    hi = hi.cwiseMax(M * c);
  }
  const cv::Size gs(static_cast<int>(std::ceil(hi.x() - lo.x())) + 1, static_cast<int>(std::ceil(hi.y() - lo.y())) + 1);
  if (gs.area() > 16.0 * static_cast<double>(cls.total()) + 1e6) return out;
  const cv::Matx23d A(M(0, 0), M(0, 1), -lo.x(), M(1, 0), M(1, 1), -lo.y());
  cv::Mat cls_g, h_g;
  cv::warpAffine(cls, cls_g, A, gs, cv::INTER_NEAREST, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::warpAffine(hw, h_g, A, gs, cv::INTER_NEAREST, cv::BORDER_CONSTANT, cv::Scalar(kNaN));
  const cv::Mat inside = cls_g == 1;
  cv::Mat din, dout;
  double dmax = 0;
  cv::distanceTransform(inside, din, cv::DIST_L2, cv::DIST_MASK_5);
  cv::distanceTransform(~inside, dout, cv::DIST_L2, cv::DIST_MASK_5);
  cv::minMaxLoc(din, nullptr, &dmax);
  if (dmax < 3) return out;
  const double w = std::max(1.0, dmax / 32);  // grid px per bin
  const int n_out = static_cast<int>(std::ceil(dmax / w)), n_in = n_out;
  std::vector<std::vector<float>> bins(n_out + n_in);  // bin i: distance (i - n_out) w ... (i - n_out + 1) w
  for (int y = 0; y < gs.height; ++y)
    for (int x = 0; x < gs.width; ++x) {
      const uchar c = cls_g.at<uchar>(y, x);
      const float h = h_g.at<float>(y, x);
      if (c == 0 || !std::isfinite(h)) continue;
      const double d = c == 1 ? din.at<float>(y, x) - 0.5 : 0.5 - dout.at<float>(y, x);
      const int i = static_cast<int>(std::floor(d / w)) + n_out;
      if (i >= 0 && i < n_out + n_in) bins[i].push_back(h);
    }
  const double pixel_m = g_min;
  // the noise of a bin's median: a grid pixel is (g_min^2 / det J) of an image pixel
  const double grid_per_image = std::fabs(J.determinant()) / (g_min * g_min);
  // bin medians and their standard errors (the noise's correlation counted, as for the top)
  const double density = noise.sigma * noise.sigma * noise.correlation_area * grid_per_image;
  std::vector<double> med(bins.size(), kNaN), err(bins.size(), kNaN);
  for (std::size_t i = 0; i < bins.size(); ++i) {
    auto& b = bins[i];
    if (b.size() < 10) continue;
    std::nth_element(b.begin(), b.begin() + b.size() / 2, b.end());
    med[i] = b[b.size() / 2];
    err[i] = std::sqrt(0.5 * M_PI * density / b.size());
  }
  std::vector<double> run(bins.size(), kNaN), run_err(bins.size(), kNaN);  // 3-bin running means
  for (std::size_t i = 0; i < bins.size(); ++i) {
    double sm = 0, se = 0;
    int c = 0;
    for (std::size_t j = i > 0 ? i - 1 : 0; j <= std::min(bins.size() - 1, i + 1); ++j)
      if (std::isfinite(med[j])) {
        sm += med[j];
        se += err[j] * err[j];
        ++c;
      }
    if (c >= 2) {
      run[i] = sm / c;
      run_err[i] = std::sqrt(se) / c;
    }
  }
  std::vector<double> skin;
  for (int i = 0; i < n_out / 2; ++i)
    if (std::isfinite(med[i])) skin.push_back(med[i]);
  if (skin.size() < 2) return out;
  std::nth_element(skin.begin(), skin.begin() + skin.size() / 2, skin.end());
  const double base = skin[skin.size() / 2];
  int top_i = -1;
  for (int i = n_out; i < n_out + n_in; ++i)
    if (std::isfinite(run[i]) && (top_i < 0 || run[i] > run[top_i])) top_i = i;
  if (top_i < 0) return out;
  out.rise = run[top_i] - base;
  std::vector<double> errs;
  for (double e : run_err)
    if (std::isfinite(e)) errs.push_back(e);
  if (errs.empty()) return out;
  std::nth_element(errs.begin(), errs.begin() + errs.size() / 2, errs.end());
  out.rise_error = errs[errs.size() / 2];
  out.clear = out.rise > kBorderClear * out.rise_error && std::isfinite(noise.sigma);
  // the crossings, scanning inward (interpolated between bin centres)
  auto crossing = [&](double f) -> double {
    const double level = base + f * out.rise;
    double prev_d = kNaN, prev_v = kNaN;
    for (int i = 0; i <= top_i; ++i) {
      if (!std::isfinite(run[i])) continue;
      const double d = (i - n_out + 0.5) * w;
      if (run[i] >= level)
        return std::isfinite(prev_v) ? prev_d + (d - prev_d) * (level - prev_v) / (run[i] - prev_v) : d;
      prev_d = d;
      prev_v = run[i];
    }
    return kNaN;
  };
  const double d20 = crossing(0.2), d50 = crossing(0.5);
  const std::vector<double> ring = countCells(cls_g, din, dout, w, n_out, &out);
  out.base = base;
  for (int i = 0; i <= top_i; ++i)
    if (std::isfinite(run[i])) out.profile.emplace_back((i - n_out + 0.5) * w, run[i]);
  // the skirt: outward from the outline while the rise stands 2 errors above the skin around (a bin's own median
  // where it has one), and no further than three times the border's width (20 -> 50 % of the rise) beyond its half
  // height: a ramp blurred by the matcher has 0.1 % of its rise left there, a linear ramp none (the skin around
  // the plaque standing off the reference, relief or the band's edge would otherwise add ring after ring)
  const double skirt_end = std::isfinite(d20) && std::isfinite(d50) ? d50 - 3 * (d50 - d20) : 0.0;
  for (int i = n_out - 1; i >= 0; --i) {
    if ((i - n_out + 0.5) * w < skirt_end) break;
    if (!std::isfinite(run[i]) || run[i] - base <= 2 * run_err[i]) break;
    const double v = std::isfinite(med[i]) ? med[i] : run[i];
    out.skirt_volume += std::max(0.0, v - base) * ring[i] * pixel_m * pixel_m;
  }
  // how far out the region's skirt stands above the detection threshold (all the profile's outside if it does)
  const double d_thr = out.rise > threshold ? crossing(threshold / out.rise) : 0.0;
  out.reach = (std::isfinite(d_thr) ? std::max(0.0, -d_thr) : dmax) * pixel_m;
  out.width = (d50 - d20) * pixel_m;
  const double blur_px = std::sqrt(std::max(1.0, noise.correlation_area) / (4 * M_PI));
  // (and the profile's own resolution: 3-bin means over bins of w px, a box of 3 w + 1 px, spans 0.3 of it)
  const double resolution = 0.3 * (3 * w + 1) * pixel_m;
  out.limit = kMaxBorderFactor * std::sqrt(std::pow(0.21 * 2 * kHalfRamp, 2) + std::pow(0.84 * blur_px * g_max, 2) +
                                           resolution * resolution);
  // inward of the first crest: the lowest level before the deepest bins
  double low = run[top_i];
  for (int i = top_i + 1; i < n_out + n_in; ++i)
    if (std::isfinite(run[i])) low = std::min(low, run[i]);
  // (a significant fall only: the deepest bins hold the fewest heights)
  double low_err = 0;
  for (int i = top_i + 1; i < n_out + n_in; ++i)
    if (std::isfinite(run[i]) && run[i] == low) low_err = run_err[i];
  const bool significant = run[top_i] - low > 3 * std::hypot(low_err, run_err[top_i]);
  out.dip = out.rise > 0 && significant ? (run[top_i] - low) / out.rise : 0;
  return out;
}

double BorderShape::areaRatioAt(double level) const {
  // the first crossing scanning inward, interpolated between bin centres
  double d = kNaN;
  for (std::size_t i = 0; i < profile.size(); ++i)
    if (profile[i].second >= level) {
      d = i == 0 ? profile[i].first
                 : profile[i - 1].first + (profile[i].first - profile[i - 1].first) * (level - profile[i - 1].second) /
                                              (profile[i].second - profile[i - 1].second);
      break;
    }
  if (!std::isfinite(d) || cells.empty()) return kNaN;
  // cells at or beyond d (the bin holding d by its share) over those inside the outline (d >= 0)
  auto within = [&](double from) {
    const double x = (from + cells_reach) / cell_bin;
    const long c = static_cast<long>(std::floor(x));
    double n = 0;
    for (long k = std::max(0L, c + 1); k < static_cast<long>(cells.size()); ++k) n += cells[static_cast<std::size_t>(k)];
    if (c >= 0 && c < static_cast<long>(cells.size())) n += (c + 1 - x) * cells[static_cast<std::size_t>(c)];
    return n;
  };
  const double at_outline = within(0.0);
  return at_outline > 0 ? within(d) / at_outline : kNaN;
}

}  // namespace induration_detail
}  // namespace induration
}  // namespace skin3d
