// SPDX-License-Identifier: BSD-3-Clause
// The induration measurement of one stereo pair as one object (see include/skin3d/induration/frame_measurer.h).
#include "skin3d/induration/frame_measurer.h"

#include <chrono>
#include <filesystem>
#include <fstream>
#include <yaml-cpp/yaml.h>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

#include "skin3d/common/run_info.h"
#include "skin3d/induration/induration.h"

namespace skin3d {
namespace induration {

FrameMeasurer::FrameMeasurer(const PipelineOptions& options) : options_(options) { options_.validate(); }

FrameMeasurement FrameMeasurer::measure(const cv::Mat& left_raw, const cv::Mat& right_raw,
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
  const auto range = stereo::disparityRangeForDepth(left, right, options_.z_min, options_.z_max);
  d.min_disparity = range.first;
  d.max_disparity = range.second;
  auto t1 = Clock::now();
  m.disparity = stereo::computeDisparity(rect.first, rect.second, d);
  m.seconds_match = since(t1);
  t1 = Clock::now();
  m.cloud = stereo::triangulateDisparity(m.disparity, left, right);
  m.seconds_triangulate = since(t1);
  t1 = Clock::now();
  m.record.stamp = stamp;
  m.record.result = measureInduration(m.cloud, options_.induration);
  m.seconds_measure = since(t1);
  for (const auto& w : m.disparity.warnings)
    m.record.result.warnings.insert(m.record.result.warnings.begin(), "dense stereo: " + w);
  m.record.valid_fraction = m.disparity.valid_fraction;  // known disparity / the matched region
  m.record.seconds = since(t0);
  return m;
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
  const IndurationResult& r = last.record.result;
  auto write = [&](const std::string& name, const cv::Mat& img) {
    if (img.empty()) return;
    if (!cv::imwrite(dir + "/" + name, img)) throw std::runtime_error("cannot write " + dir + "/" + name);
  };
  if (!r.height_map.empty()) write("height_map.png", heightMapImage(r.height_map, r.labels, r.plaques));
  writeSurfacePly(dir + "/surface.ply", last.cloud, last.left_rect, ply_step);
  // the last frame's matching, for checking the matcher: disparity and its sigma (px, NaN unknown), left image
  write("disparity.tiff", last.disparity.disparity);
  write("disparity_sigma.tiff", last.disparity.sigma);
  write("left_rect.png", last.left_rect);
  if (!last.left_rect.empty()) write("unknown_reason.png", stereo::unknownReasonImage(last.disparity, last.left_rect));
  write("height_map.tiff", r.height_map);
}

}  // namespace induration
}  // namespace skin3d
