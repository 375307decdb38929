// SPDX-License-Identifier: BSD-3-Clause
// The induration measurement of one stereo pair as one object (see include/skin3d/induration/frame_measurer.h).
#include "skin3d/induration/frame_measurer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <yaml-cpp/yaml.h>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

#include "skin3d/common/run_info.h"
#include "skin3d/induration/induration.h"

namespace skin3d {
namespace induration {

namespace {

/** The fitted vertical disparity over the known pixels (every 4th row and column): median and 1.4826 MAD, px; a
 *  warning when the rows of the pair do not meet (more than 0.5 px off, or spread over more than 0.5 px). */
void verticalDisparity(const stereo::DisparityMap& map, FrameRecord* r) {
  if (map.vertical.empty()) return;
  std::vector<float> v;
  for (int y = 0; y < map.vertical.rows; y += 4) {
    const float* p = map.vertical.ptr<float>(y);
    for (int x = 0; x < map.vertical.cols; x += 4)
      if (std::isfinite(p[x])) v.push_back(p[x]);
  }
  if (v.size() < 20) return;
  const auto median = [](std::vector<float>& a) {
    auto k = a.begin() + static_cast<std::ptrdiff_t>(a.size() / 2);
    std::nth_element(a.begin(), k, a.end());
    return static_cast<double>(*k);
  };
  r->vertical_median = median(v);
  for (float& x : v) x = std::fabs(x - static_cast<float>(r->vertical_median));
  r->vertical_spread = 1.4826 * median(v);
  if (std::fabs(r->vertical_median) > 0.5 || r->vertical_spread > 0.5) {
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "the rows of the rectified pair do not meet on the skin: vertical disparity %.2f px (median), "
                  "spread %.2f px (a stale calibration, unsynchronised or rolling-shutter frames?)",
                  r->vertical_median, r->vertical_spread);
    r->result.warnings.push_back(buf);
  }
}

/** The points the measurement found too oblique (IndurationResult::oblique) leave the disparity map and the cloud:
 *  unknown for the reason kOblique, so that disparity.tiff, surface.ply and a site's fusion do not hold them. */
void dropOblique(FrameMeasurement* m) {
  const cv::Mat& ob = m->record.result.oblique;
  stereo::DisparityMap& d = m->disparity;
  if (ob.empty() || ob.size() != d.disparity.size() || ob.size() != m->cloud.xyz.size()) return;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  long n = 0;
  for (int y = 0; y < ob.rows; ++y) {
    const uchar* o = ob.ptr<uchar>(y);
    for (int x = 0; x < ob.cols; ++x) {
      if (!o[x] || !std::isfinite(d.disparity.at<float>(y, x))) continue;
      d.disparity.at<float>(y, x) = nan;
      if (!d.sigma.empty()) d.sigma.at<float>(y, x) = nan;
      if (!d.vertical.empty()) d.vertical.at<float>(y, x) = nan;
      if (!d.unknown_reason.empty()) d.unknown_reason.at<uchar>(y, x) = static_cast<uchar>(stereo::UnknownReason::kOblique);
      m->cloud.xyz.at<cv::Vec3f>(y, x) = cv::Vec3f(nan, nan, nan);
      if (!m->cloud.sigma.empty()) m->cloud.sigma.at<float>(y, x) = nan;
      ++n;
    }
  }
  const double area = std::max(1, d.roi.area());
  d.valid_fraction = std::max(0.0, d.valid_fraction - n / area);
  if (d.unknown_share.size() == static_cast<size_t>(stereo::UnknownReason::kCount)) {
    d.unknown_share[static_cast<size_t>(stereo::UnknownReason::kOblique)] += n / area;
    d.unknown_share[0] = d.valid_fraction;
  }
}

}  // namespace

FrameMeasurer::FrameMeasurer(const PipelineOptions& options) : options_(options) { options_.validate(); }

FrameMeasurement FrameMeasurer::measure(const cv::Mat& left_raw, const cv::Mat& right_raw,
                                        const geometry::CameraInfo& left, const geometry::CameraInfo& right,
                                        double stamp) {
  FrameMeasurement m = match(left_raw, right_raw, left, right, stamp);
  finish(&m);
  return m;
}

FrameMeasurement FrameMeasurer::match(const cv::Mat& left_raw, const cv::Mat& right_raw,
                                      const geometry::CameraInfo& left, const geometry::CameraInfo& right,
                                      double stamp) {
  using Clock = std::chrono::steady_clock;
  const auto since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
  const auto t0 = Clock::now();
  FrameMeasurement m;
  const auto rect = rectify_(left_raw, right_raw, left, right);
  m.left_rect = rect.first;
  m.seconds_rectify = since(t0);
  stereo::DenseStereoOptions d = options_.dense;
  auto t1 = Clock::now();
  std::string range_note;
  if (options_.autoDepthRange()) {  // from the images and the calibration: any rig
    const stereo::DisparitySearch s = stereo::searchDisparityRange(rect.first, rect.second, left, right, d);
    d.min_disparity = s.min_disparity;
    d.max_disparity = s.max_disparity;
    m.record.z_near = s.z_near;
    m.record.z_far = s.z_far;
    m.record.range_searched = true;
    if (!s.found) range_note = s.note;
  } else {
    const auto range = stereo::disparityRangeForDepth(left, right, options_.z_min, options_.z_max);
    d.min_disparity = range.first;
    d.max_disparity = range.second;
    m.record.z_near = options_.z_min;
    m.record.z_far = options_.z_max;
  }
  m.record.min_disparity = d.min_disparity;
  m.record.max_disparity = d.max_disparity;
  m.seconds_range = since(t1);
  t1 = Clock::now();
  m.disparity = stereo::computeDisparity(rect.first, rect.second, d);
  m.seconds_match = since(t1);
  t1 = Clock::now();
  m.cloud = stereo::triangulateDisparity(m.disparity, left, right);
  m.seconds_triangulate = since(t1);
  m.record.stamp = stamp;
  m.range_note = range_note;
  m.record.seconds = since(t0);
  return m;
}

void FrameMeasurer::finish(FrameMeasurement* m) const {
  using Clock = std::chrono::steady_clock;
  const auto t1 = Clock::now();
  m->record.result = measureInduration(m->cloud, options_.induration);
  m->seconds_measure = std::chrono::duration<double>(Clock::now() - t1).count();
  dropOblique(m);
  for (const auto& w : m->disparity.warnings)
    m->record.result.warnings.insert(m->record.result.warnings.begin(), "dense stereo: " + w);
  if (!m->range_note.empty())
    m->record.result.warnings.insert(m->record.result.warnings.begin(), "dense stereo: " + m->range_note);
  m->record.valid_fraction = m->disparity.valid_fraction;  // known disparity / the matched region
  verticalDisparity(m->disparity, &m->record);
  m->record.seconds += m->seconds_measure;
}

void writeMeasurementResults(const std::string& dir, const std::vector<FrameRecord>& frames,
                             const FrameMeasurement& last, const PipelineOptions& opt, const std::string& frame_id,
                             const std::string& source, const std::vector<std::string>& command_line,
                             int frames_dropped, const std::string& dropped_input, int ply_step) {
  if (frames.empty()) throw std::runtime_error("nothing measured: no results written to " + dir);
  std::filesystem::create_directories(dir);
  common::writeParameters(dir + "/parameters.yaml", "induration, keys of config/induration.yaml", command_line,
                          pipelineOptionKeys(), [&](const std::string& k) { return getPipelineOption(opt, k); });
  writeInduration(dir + "/induration.yaml", frames, opt.induration, frame_id, source);
  {
    YAML::Emitter y;  // what was dropped before measuring, by fault
    y << YAML::BeginMap << YAML::Key << "frames_dropped" << YAML::Value << frames_dropped << YAML::Key
      << "dropped_input" << YAML::Value << dropped_input << YAML::EndMap;
    std::ofstream f(dir + "/induration.yaml", std::ios::app);
    f << y.c_str() << "\n";
    if (!f) throw std::runtime_error("cannot write " + dir + "/induration.yaml");
  }
  writeSurfacePly(dir + "/surface.ply", last.cloud, last.left_rect, ply_step);
  writeFrameMaps(dir, last);
}

void writeFrameMaps(const std::string& dir, const FrameMeasurement& m) {
  std::filesystem::create_directories(dir);
  const IndurationResult& r = m.record.result;
  auto write = [&](const std::string& name, const cv::Mat& img) {
    if (img.empty()) return;
    if (!cv::imwrite(dir + "/" + name, img)) throw std::runtime_error("cannot write " + dir + "/" + name);
  };
  if (!r.height_map.empty())
    write("height_map.png", heightMapImage(r.height_map, r.labels, r.plaques, 0.0, 1600, r.unfollowed));
  // the matching, for checking the matcher: disparity and its sigma (px, NaN unknown), left image
  write("disparity.tiff", m.disparity.disparity);
  write("disparity_sigma.tiff", m.disparity.sigma);
  write("left_rect.png", m.left_rect);
  if (!m.left_rect.empty()) write("unknown_reason.png", stereo::unknownReasonImage(m.disparity, m.left_rect));
  write("height_map.tiff", r.height_map);
  // where the reference does not follow the skin (255; all 0 when it does): the hatching of height_map.png
  if (!r.height_map.empty())
    write("reference_unfollowed.png", r.unfollowed.empty() ? cv::Mat(r.height_map.size(), CV_8U, cv::Scalar(0)) : r.unfollowed);
}

std::string frameMapsDirectory(const std::string& results, int index) {
  char name[32];
  std::snprintf(name, sizeof name, "frames/%04d", index);
  return results + "/" + name;
}

}  // namespace induration
}  // namespace skin3d
