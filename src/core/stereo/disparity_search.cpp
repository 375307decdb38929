// SPDX-License-Identifier: BSD-3-Clause
// The working disparity range of a rectified pair found from the images: a semi-global search over every
// disparity both images can share, at a coarse level. See searchDisparityRange in include/skin3d/stereo/dense_stereo.h.
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "../common/text.h"
#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {
namespace stereo {

namespace {

using common::num;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/** The rectified pair's fx B (px m) and the disparity of depth infinity, cx_left - cx_right (px). */
std::pair<double, double> rectifiedBaseline(const geometry::CameraInfo& left, const geometry::CameraInfo& right) {
  const auto r = disparityRangeForDepth(left, right, 1.0, 2.0);  // checks the pair: d = fB / z + dc
  const double fb = 2.0 * (r.second - r.first);                   // fB (1/1 - 1/2) = d(1) - d(2)
  return {fb, r.second - fb};
}

/** Grey float image. */
cv::Mat greyFloat(const cv::Mat& img) {
  cv::Mat g = img, f;
  if (img.channels() == 3) cv::cvtColor(img, g, cv::COLOR_BGR2GRAY);
  else if (img.channels() == 4) cv::cvtColor(img, g, cv::COLOR_BGRA2GRAY);
  g.convertTo(f, CV_32F);
  return f;
}

/** Normalised cross-correlation of the (2h+1)^2 windows of l at (x, y) and r at (xr, y); -1 when a window leaves
 *  its image or has no contrast. */
double windowCorrelation(const cv::Mat& l, const cv::Mat& r, int x, int xr, int y, int h) {
  if (x < h || xr < h || y < h || x + h >= l.cols || xr + h >= r.cols || y + h >= l.rows) return -1;
  double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
  for (int dy = -h; dy <= h; ++dy) {
    const float* a = l.ptr<float>(y + dy);
    const float* b = r.ptr<float>(y + dy);
    for (int dx = -h; dx <= h; ++dx) {
      const double va = a[x + dx], vb = b[xr + dx];
      sa += va;
      sb += vb;
      saa += va * va;
      sbb += vb * vb;
      sab += va * vb;
    }
  }
  const double n = (2 * h + 1) * (2 * h + 1);
  const double caa = saa - sa * sa / n, cbb = sbb - sb * sb / n, cab = sab - sa * sb / n;
  return caa > 1e-9 && cbb > 1e-9 ? cab / std::sqrt(caa * cbb) : -1;
}

}  // namespace

DisparitySearch searchDisparityRange(const cv::Mat& left, const cv::Mat& right, const geometry::CameraInfo& left_info,
                                     const geometry::CameraInfo& right_info, const DenseStereoOptions& base,
                                     const DisparitySearchOptions& so) {
  if (left.empty() || right.empty() || left.size() != right.size())
    throw DenseStereoError("disparity range search: the rectified images are empty or differ in size");
  if (!(so.width >= 64) || !(so.percentile > 0 && so.percentile < 25) || !(so.depth_margin >= 0) ||
      !(so.min_matched > 0 && so.min_matched < 1) || !(so.min_correlation < 1))
    throw DenseStereoError("disparity range search: bad options (width >= 64, percentile in (0, 25), depth_margin >= 0, "
                           "min_matched in (0, 1))");
  const auto [fb, dc] = rectifiedBaseline(left_info, right_info);
  DisparitySearch out;
  const int w = left.cols;
  // every disparity both images can share: a point seen by both has x_left and x_right in [0, w), so
  // |d| < w; and it lies in front of the rig: d > dc (depth infinity)
  out.searched_min = std::max(dc, -0.9 * w);
  out.searched_max = 0.9 * w;
  if (!(out.searched_max > out.searched_min + 16))
    throw DenseStereoError("disparity range search: the rectified images cannot overlap (depth infinity lies at " +
                           num(dc) + " px, beyond 90 % of the " + std::to_string(w) + " px width)");
  // the coarse level: halve until at most so.width wide
  int levels = 0;
  while ((w >> levels) > so.width && levels < 8) ++levels;
  out.scale = 1 << levels;
  cv::Mat l = left, r = right;
  if (levels > 0) {
    const cv::Size small(std::max(16, left.cols >> levels), std::max(16, left.rows >> levels));
    cv::resize(left, l, small, 0, 0, cv::INTER_AREA);
    cv::resize(right, r, small, 0, 0, cv::INTER_AREA);
  }
  const double s = static_cast<double>(left.cols) / l.cols;
  DenseStereoOptions o = base;  // the matcher's own judgement (uniqueness, left-right check, weak texture)
  o.min_disparity = out.searched_min / s;
  o.max_disparity = out.searched_max / s;
  o.subpixel = "sgbm";
  o.slant_passes = 0;
  o.coarse_max_width = std::max(64, l.cols);
  o.coarse_min_levels = 0;  // the reduced pair is already averaged
  if (base.roi.area() > 0) {
    const cv::Rect roi(cvFloor(base.roi.x / s), cvFloor(base.roi.y / s), std::max(16, cvCeil(base.roi.width / s)),
                       std::max(16, cvCeil(base.roi.height / s)));
    o.roi = roi & cv::Rect(0, 0, l.cols, l.rows);
  } else {
    o.roi = cv::Rect();
  }
  const DisparityMap m = computeDisparity(l, r, o);
  // A wide search pairs up what only one camera sees (the strips at opposite edges of a converged pair) into
  // smooth, left-right consistent, wrong matches: they pass the semi-global matcher's checks but their windows do
  // not look alike. Kept: matches whose 11 x 11 windows correlate at least so.min_correlation (true matches at
  // the reduced scale, where the sensor noise is averaged, reach 0.8-0.99; the best of hundreds of wrong
  // candidates stays near 0.3-0.4 for 121 independent pixels).
  const cv::Mat lf = greyFloat(l), rf = greyFloat(r);
  std::vector<float> d;
  d.reserve(static_cast<size_t>(m.roi.area()));
  for (int y = m.roi.y; y < m.roi.br().y; ++y) {
    const float* p = m.disparity.ptr<float>(y);
    for (int x = m.roi.x; x < m.roi.br().x; ++x)
      if (std::isfinite(p[x]) &&
          windowCorrelation(lf, rf, x, static_cast<int>(std::lround(x - p[x])), y, 5) >= so.min_correlation)
        d.push_back(p[x]);
  }
  out.matched_fraction = d.size() / static_cast<double>(std::max(1, m.roi.area()));
  if (out.matched_fraction < so.min_matched || d.size() < 50) {
    out.found = false;
    out.min_disparity = out.searched_min;
    out.max_disparity = out.searched_max;
    out.z_near = fb / (out.max_disparity - dc);
    out.z_far = out.min_disparity > dc ? fb / (out.min_disparity - dc) : std::numeric_limits<double>::infinity();
    out.note = "the depth range search matched " + num(std::round(1000 * out.matched_fraction) / 10) +
               " % of the image (under " + num(100 * so.min_matched) +
               " %): every disparity the images can share is searched (slow, coarse)";
    return out;
  }
  // the bulk of what both cameras see: the shortest interval that holds all but 2 x `percentile` % of the matches
  // (mismatches over the wide search spread thinly and fall outside it; two bodies at different depths that are
  // both in view both stay in), widened by the depth margin and 2 coarse pixels
  std::sort(d.begin(), d.end());
  const size_t keep = std::max<size_t>(1, static_cast<size_t>(std::ceil((1.0 - 2.0 * so.percentile / 100.0) * d.size())));
  size_t best = 0;
  for (size_t i = 0; i + keep <= d.size(); ++i)
    if (d[i + keep - 1] - d[i] < d[best + keep - 1] - d[best]) best = i;
  const double lo = s * d[best], hi = s * d[best + keep - 1];
  const double z_far = lo > dc ? fb / (lo - dc) : std::numeric_limits<double>::infinity();
  const double z_near = fb / std::max(hi - dc, 1e-9);
  out.z_near = z_near / (1.0 + so.depth_margin);
  out.z_far = z_far * (1.0 + so.depth_margin);
  out.min_disparity = std::max(out.searched_min, (std::isfinite(out.z_far) ? fb / out.z_far + dc : dc) - 2 * s);
  out.max_disparity = std::min(out.searched_max, fb / out.z_near + dc + 2 * s);
  if (!(out.max_disparity > out.min_disparity + 1)) out.max_disparity = out.min_disparity + 1;
  out.found = true;
  out.note = "depth " + num(std::round(1000 * out.z_near) / 1000) + " ... " +
             (std::isfinite(out.z_far) ? num(std::round(1000 * out.z_far) / 1000) : std::string("inf")) + " m (" +
             num(std::round(1000 * out.matched_fraction) / 10) + " % of the image matched at 1/" + num(s) + " scale)";
  return out;
}

}  // namespace stereo
}  // namespace skin3d
