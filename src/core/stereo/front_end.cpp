// SPDX-License-Identifier: BSD-3-Clause
// The stereo front end as one object (see include/skin3d/stereo/front_end.h).
#include "skin3d/stereo/front_end.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace skin3d {
namespace stereo {

namespace {

bool sameCalibration(const geometry::CameraInfo& a, const geometry::CameraInfo& b) {
  return a.width == b.width && a.height == b.height && a.distortion_model == b.distortion_model && a.D == b.D &&
         a.K == b.K && a.R == b.R && a.P == b.P;
}

void checkSize(const cv::Mat& img, const geometry::CameraInfo& info, const char* side) {
  if (img.empty()) throw std::invalid_argument(std::string("the ") + side + " image is empty");
  if (img.cols != info.width || img.rows != info.height)
    throw std::invalid_argument(std::string("the ") + side + " image is " + std::to_string(img.cols) + "x" +
                                std::to_string(img.rows) + " but its camera_info says " + std::to_string(info.width) +
                                "x" + std::to_string(info.height));
}

}  // namespace

void FrontEndOptions::validate() const {
  features.validate();
  const TriangulateOptions& t = triangulate;
  auto bad = [](const std::string& key, double v, const std::string& why) {
    throw std::invalid_argument("front end parameter '" + key + "' = " + std::to_string(v) + ": " + why);
  };
  if (!(t.sigma_px >= 0.0) || !std::isfinite(t.sigma_px)) bad("sigma_px", t.sigma_px, "must be >= 0 (0: estimated per frame)");
  if (!(t.min_depth >= 0.0) || !std::isfinite(t.min_depth)) bad("min_depth", t.min_depth, "must be >= 0 (m)");
  if (!(t.max_depth > t.min_depth)) bad("max_depth", t.max_depth, "must be > min_depth (m)");
  if (!(t.row_gate >= 0.0)) bad("row_gate", t.row_gate, "must be >= 0 (0: off)");
  if (!(t.disparity_gate >= 0.0)) bad("disparity_gate", t.disparity_gate, "must be >= 0 (0: off)");
  if (t.neighbours < 0) bad("neighbours", t.neighbours, "must be >= 0");
  if (max_landmarks < 0) bad("max_landmarks", max_landmarks, "must be >= 0 (0: all)");
}

std::pair<cv::Mat, cv::Mat> PairRectifier::operator()(const cv::Mat& left_raw, const cv::Mat& right_raw,
                                                      const geometry::CameraInfo& left,
                                                      const geometry::CameraInfo& right) {
  checkSize(left_raw, left, "left");
  checkSize(right_raw, right, "right");
  if (!rect_l_ || !sameCalibration(left, left_)) {
    rect_l_ = std::make_unique<Rectifier>(left);
    left_ = left;
  }
  if (!rect_r_ || !sameCalibration(right, right_)) {
    rect_r_ = std::make_unique<Rectifier>(right);
    right_ = right;
  }
  return {(*rect_l_)(left_raw), (*rect_r_)(right_raw)};
}

FrontEnd::FrontEnd(const FrontEndOptions& options) : options_(options) { options_.validate(); }

FrontEndFrame FrontEnd::process(const cv::Mat& left_raw, const cv::Mat& right_raw, const geometry::CameraInfo& left,
                                const geometry::CameraInfo& right) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto rect = rectify_(left_raw, right_raw, left, right);
  FrontEndFrame f = processRectified(rect.first, rect.second, left, right);
  f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return f;
}

FrontEndFrame FrontEnd::processRectified(const cv::Mat& left_rect, const cv::Mat& right_rect,
                                         const geometry::CameraInfo& left, const geometry::CameraInfo& right) {
  const auto t0 = std::chrono::steady_clock::now();
  if (left_rect.size() != right_rect.size())
    throw std::invalid_argument("the rectified left and right images differ in size");
  // cx_l - cx_r of the rectified projections: the disparity of a point at infinity
  const double offset = left.P(0, 2) - right.P(0, 2);
  if (!std::isfinite(offset)) throw std::invalid_argument("the rectified projections P have a non-finite cx");
  if (!matcher_ || matcher_->options().disparity_offset != offset) {
    FeatureOptions fo = options_.features;
    fo.disparity_offset = offset;
    matcher_ = std::make_unique<StereoFeatureMatcher>(fo);
  }
  FrontEndFrame f;
  f.left_rect = left_rect;
  f.right_rect = right_rect;
  f.matches = matcher_->process(left_rect, right_rect, &f.stats);
  const int keep = options_.max_landmarks;
  if (keep > 0 && static_cast<int>(f.matches.size()) > keep) {
    std::partial_sort(f.matches.begin(), f.matches.begin() + keep, f.matches.end(),
                      [](const StereoMatch& a, const StereoMatch& b) { return a.strength > b.strength; });
    f.matches.resize(keep);
  }
  f.landmarks = triangulateMatches(left, right, f.matches, options_.triangulate, &f.dropped, &f.sigma_px);
  f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return f;
}

}  // namespace stereo
}  // namespace skin3d
