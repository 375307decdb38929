// SPDX-License-Identifier: BSD-3-Clause
// Whether the healthy-skin reference follows the skin (see checkReferenceFollows in induration_detail.h).
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "../common/text.h"
#include "induration_detail.h"

namespace skin3d {
namespace induration {
namespace induration_detail {

using common::num;

namespace {

/** Robust scale (1.4826 MAD about the median) of the finite values of `v` where `use` is set, every `step`-th. */
double robustScale(const cv::Mat& v, const cv::Mat& use, int step) {
  std::vector<float> a;
  for (int y = 0; y < v.rows; y += step) {
    const float* p = v.ptr<float>(y);
    const uchar* u = use.ptr<uchar>(y);
    for (int x = 0; x < v.cols; x += step)
      if (u[x] && std::isfinite(p[x])) a.push_back(p[x]);
  }
  if (a.size() < 20) return std::numeric_limits<double>::quiet_NaN();
  return medianAndScale(a).second;
}

}  // namespace

void checkReferenceFollows(const Surface& s, const cv::Mat& hs, const cv::Mat& band, IndurationResult& res) {
  const IndurationOptions& o = s.o;
  // healthy skin: the band outside the plaques and their flanks (the outer half of a plaque's edge ramp, widened
  // by the segmentation smoothing, the exclusion margin and the matching window's ramp)
  cv::Mat near_plaque = res.labels != 0;
  {
    const int r = o.exclusion_margin_px + o.interior_margin_px + static_cast<int>(std::ceil(2 * res.smoothing_px));
    cv::dilate(near_plaque, near_plaque, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  }
  cv::Mat healthy = band & ~near_plaque;
  const int n_healthy = cv::countNonZero(healthy);
  if (n_healthy == 0) return;
  // the reference's own figure of merit: its healthy-skin scatter against the matcher's stated noise
  const double scatter = robustScale(res.height_map, healthy, 2);
  const double noise = [&] {
    std::vector<float> sg;
    for (int y = 0; y < s.cloud.sigma.rows; y += 4) {
      const float* p = s.cloud.sigma.ptr<float>(y);
      const uchar* u = healthy.ptr<uchar>(y);
      for (int x = 0; x < s.cloud.sigma.cols; x += 4)
        if (u[x] && std::isfinite(p[x])) sg.push_back(p[x]);
    }
    if (sg.empty()) return std::numeric_limits<double>::quiet_NaN();
    auto mid = sg.begin() + static_cast<std::ptrdiff_t>(sg.size() / 2);
    std::nth_element(sg.begin(), mid, sg.end());
    return static_cast<double>(*mid);
  }();
  res.reference_noise_ratio = noise > 0 ? scatter / noise : std::numeric_limits<double>::quiet_NaN();
  // where it departs from the skin: healthy skin of the working band whose smoothed height lies beyond the detection
  // threshold (above or below), in regions of at least min_area (the noise alone crosses 3 sigma in specks)
  cv::Mat off(hs.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < hs.rows; ++y) {
    const float* h = hs.ptr<float>(y);
    const uchar* u = healthy.ptr<uchar>(y);
    uchar* q = off.ptr<uchar>(y);
    for (int x = 0; x < hs.cols; ++x) q[x] = u[x] && std::isfinite(h[x]) && std::fabs(h[x]) > res.detection_threshold ? 255 : 0;
  }
  // Counted only inside the measured body: its bodies are the connected parts of the known surface that hold at
  // least 10 % of it (islands beyond gaps of the matching are mostly mismatches near the image borders, and the
  // plaque search already sets them aside), eroded by the matching window's ramp at their edges (2 x
  // interior_margin_px). What lies outside is not a surface the reference was asked to follow.
  cv::Mat bodies(s.known_mask.size(), CV_8U, cv::Scalar(0));
  {
    cv::Mat lab, stats, cents;
    const int n = cv::connectedComponentsWithStats(s.known_mask, lab, stats, cents, 8, CV_32S);
    for (int k = 1; k < n; ++k)
      if (stats.at<int>(k, cv::CC_STAT_AREA) >= 0.1 * s.known_points) bodies.setTo(255, lab == k);
    bodies |= holesOf(bodies);  // the matcher's gaps inside a body are not its edge
    const int r = 2 * o.interior_margin_px;
    if (r > 0) cv::erode(bodies, bodies, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  }
  res.unfollowed = largeRegions(off & bodies, s.cloud.ray, res.reference, 4 * o.min_area);
  if (!res.relief.empty()) res.unfollowed |= res.relief;  // raised regions shaped like relief (findPlaques)
  const int n_off = cv::countNonZero(res.unfollowed);
  res.unfollowed_share = n_off / static_cast<double>(std::max(1, cv::countNonZero(band & bodies)));
  res.reference_follows = res.unfollowed_share <= kMaxUnfollowedShare;
  if (res.reference_follows) {
    if (n_off == 0) res.unfollowed.release();
    return;
  }
  // the largest regions, named
  cv::Mat lab, stats, cents;
  const int n = cv::connectedComponentsWithStats(res.unfollowed, lab, stats, cents, 8, CV_32S);
  std::vector<std::pair<int, int>> by_size;
  for (int k = 1; k < n; ++k) by_size.emplace_back(stats.at<int>(k, cv::CC_STAT_AREA), k);
  std::sort(by_size.rbegin(), by_size.rend());
  std::string where;
  for (size_t i = 0; i < std::min<size_t>(3, by_size.size()); ++i) {
    const int k = by_size[i].second;
    double lo = 0, hi = 0;
    cv::minMaxLoc(hs, &lo, &hi, nullptr, nullptr, lab == k);
    const double extreme = std::fabs(lo) > std::fabs(hi) ? lo : hi;
    where += (i ? "; " : "") + std::to_string(by_size[i].first) + " px at pixel (" +
             std::to_string(static_cast<int>(cents.at<double>(k, 0))) + ", " +
             std::to_string(static_cast<int>(cents.at<double>(k, 1))) + "), up to " +
             num(std::round(extreme * 1e5) / 100) + " mm";
  }
  res.warnings.push_back("the reference surface (" + res.reference.model + ") does not follow the skin: " +
                         num(std::round(1000 * res.unfollowed_share) / 10) + " % of the working band lies more than " +
                         num(std::round(res.detection_threshold * 1e5) / 100) + " mm above or below it in " +
                         std::to_string(by_size.size()) + " region(s) (" + where +
                         "); plaques cannot be measured there (hatched in the height map): a face, a fold or two "
                         "bodies in view? Narrow the roi to one gently curved skin area");
}

}  // namespace induration_detail
}  // namespace induration
}  // namespace skin3d
