// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag --induration: every stereo pair of an image bag through rectification, dense matching and the
 * induration measurement (the same core calls as the dense_stereo and induration nodelets). Writes
 * induration.yaml (every frame + the repeatability over frames), height_map.png and surface.ply of the
 * last frame (and, for checking the matcher, its disparity.tiff / disparity_sigma.tiff in px, height_map.tiff
 * in m and left_rect.png), and prints a per-plaque table in mm.
 */
#include "process_bag_induration.h"
#include "skin3d/common/run_info.h"

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <opencv2/imgcodecs.hpp>

#include "skin3d/ros/conversions.h"
#include "skin3d/induration/induration.h"
#include "skin3d/induration/induration_config.h"
#include "skin3d/induration/induration_io.h"
#include "skin3d/stereo/dense_stereo.h"
#include "skin3d/ros/bag_topics.h"
#include "skin3d/stereo/rectification.h"
#include "skin3d/ros/stereo_pairs.h"

namespace skin3d {
namespace tools {

int runInduration(const IndurationRun& a) {
  induration::PipelineOptions opt;
  for (const auto& c : a.configs) induration::applyPipelineOptions(&opt, c);
  for (const auto& kv : a.sets) induration::setPipelineOption(&opt, kv.first, kv.second);
  opt.validate();

  rosbag::Bag bag;
  ros_io::openForReading(&bag, a.bag);
  const ros_io::BagTopics topics(bag, a.bag,
                                 {"stereo/left/image_raw", "stereo/right/image_raw", "stereo/left/camera_info",
                                  "stereo/right/camera_info"},
                                 a.ns);
  for (const char* t : {"stereo/left/image_raw", "stereo/right/image_raw", "stereo/left/camera_info",
                        "stereo/right/camera_info"})
    if (!topics.has(t))
      throw std::invalid_argument("'" + a.bag + "' has no " + t + " (" + topics.summary() + "). Its topics:\n" +
                                  ros_io::describeTopics(topics.all()));
  if (!a.quiet) std::fprintf(stderr, "process_bag: %s\n", topics.summary().c_str());
  rosbag::View view(bag, rosbag::TopicQuery(topics.stored()));
  int expected = static_cast<int>(topics.count("stereo/left/image_raw"));
  if (a.frames >= 0 && a.frames < expected) expected = a.frames;
  ros_io::StereoPairs pairs_in;
  std::vector<induration::FrameRecord> records;
  stereo::DenseCloud last_cloud;
  cv::Mat last_left, last_disparity, last_sigma, last_unknown;
  int bad = 0;
  std::filesystem::create_directories(a.out);

  auto process = [&](const sensor_msgs::Image& left, const sensor_msgs::Image& right) {
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    auto since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
    const cv::Mat L = pairs_in.rectifyLeft(left);
    const cv::Mat R = pairs_in.rectifyRight(right);
    const double t_rectify = since(t0);
    const geometry::CameraInfo& info_l = pairs_in.leftInfo();
    const geometry::CameraInfo& info_r = pairs_in.rightInfo();
    stereo::DenseStereoOptions d = opt.dense;
    const auto range = stereo::disparityRangeForDepth(info_l, info_r, opt.z_min, opt.z_max);
    d.min_disparity = range.first;
    d.max_disparity = range.second;
    auto t1 = Clock::now();
    const stereo::DisparityMap map = stereo::computeDisparity(L, R, d);
    const double t_match = since(t1);
    t1 = Clock::now();
    const stereo::DenseCloud cloud = stereo::triangulateDisparity(map, info_l, info_r);
    const double t_triangulate = since(t1);
    induration::FrameRecord rec;
    rec.stamp = left.header.stamp.toSec();
    t1 = Clock::now();
    rec.result = induration::measureInduration(cloud, opt.induration);
    const double t_measure = since(t1);
    for (const auto& w : map.warnings) rec.result.warnings.insert(rec.result.warnings.begin(), "dense stereo: " + w);
    rec.valid_fraction = map.valid_fraction;
    rec.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!a.quiet) {
      std::printf("frame %zu/%d (t = %.3f s): %.1f %% matched, reference RMS %.4f mm, %zu plaques, %.1f s "
                  "(rectification %.1f s, matching %.1f s of which sgbm %.1f s and refinement %.1f s, triangulation %.1f s, "
                  "measurement %.1f s)\n",
                  records.size() + 1, expected, rec.stamp, 100 * map.valid_fraction, rec.result.reference.rms * 1e3,
                  rec.result.plaques.size(), rec.seconds, t_rectify, t_match, map.timing.sgbm, map.timing.refine, t_triangulate,
                  t_measure);
      std::printf("  %s\n", stereo::describeUnknown(map).c_str());
      for (const auto& w : rec.result.warnings) std::printf("  warning: %s\n", w.c_str());
      std::fflush(stdout);
    }
    records.push_back(rec);
    last_cloud = cloud;
    last_left = L;
    last_disparity = map.disparity;
    last_sigma = map.sigma;
    last_unknown = stereo::unknownReasonImage(map, L);
  };

  int pairs = 0;
  for (const rosbag::MessageInstance& mi : view) {
    pairs_in.add(topics.relative(mi.getTopic()), mi);
    sensor_msgs::Image::ConstPtr left, right;
    while (!(a.frames >= 0 && pairs >= a.frames) && pairs_in.next(&left, &right)) {
      ++pairs;
      try {
        process(*left, *right);
      } catch (const std::exception& e) {
        ++bad;
        std::fprintf(stderr, "process_bag: image pair at t = %.6f s dropped: %s\n", left->header.stamp.toSec(), e.what());
      }
    }
  }
  if (records.empty())
    throw std::invalid_argument("no stereo pair of '" + a.bag + "' could be measured (" + std::to_string(pairs) +
                                " pairs, " + std::to_string(bad) + " dropped; the bag needs stereo/{left,right}/image_raw and camera_info)");

  // ---- results (also when only some frames worked)
  const std::string yaml = a.out + "/induration.yaml";
  common::writeParameters(a.out + "/parameters.yaml", "induration, keys of config/induration.yaml", a.command_line,
                  induration::pipelineOptionKeys(),
                  [&](const std::string& k) { return induration::getPipelineOption(opt, k); });
  induration::writeInduration(yaml, records, opt.induration, "stereo_left_optical_frame", a.bag);
  const auto& last = records.back().result;
  if (!last.height_map.empty()) {
    const cv::Mat img = induration::heightMapImage(last.height_map, last.labels, last.plaques);
    if (!cv::imwrite(a.out + "/height_map.png", img)) throw std::runtime_error("cannot write " + a.out + "/height_map.png");
  }
  induration::writeSurfacePly(a.out + "/surface.ply", last_cloud, last_left, a.ply_step);
  // the last frame's matching, for checking the matcher: disparity and its sigma (px, NaN unknown), left image
  if (!cv::imwrite(a.out + "/disparity.tiff", last_disparity) || !cv::imwrite(a.out + "/disparity_sigma.tiff", last_sigma) ||
      !cv::imwrite(a.out + "/left_rect.png", last_left))
    throw std::runtime_error("cannot write the disparity images to " + a.out);
  if (!last_unknown.empty() && !cv::imwrite(a.out + "/unknown_reason.png", last_unknown))
    throw std::runtime_error("cannot write " + a.out + "/unknown_reason.png");
  if (!last.height_map.empty() && !cv::imwrite(a.out + "/height_map.tiff", last.height_map))
    throw std::runtime_error("cannot write " + a.out + "/height_map.tiff");
  if (!a.quiet) {
    std::printf("\n%zu frame(s), %d dropped. Last frame, heights above the healthy-skin reference (mm):\n",
                records.size(), bad);
    std::printf("| plaque | centroid x y z (mm, left optical) | area (mm²) | top | mean | max (p99) | std | PASI |\n"
                "|---|---|---|---|---|---|---|---|\n");
    for (const auto& p : last.plaques)
      std::printf("| %d | %.1f %.1f %.1f | %.1f | %.3f | %.3f | %.3f | %.3f | %d |\n", p.id, 1e3 * p.centroid.x(),
                  1e3 * p.centroid.y(), 1e3 * p.centroid.z(), 1e6 * p.area, 1e3 * p.top_height, 1e3 * p.mean_height, 1e3 * p.max_height,
                  1e3 * p.std_height, p.pasi_class);
    std::printf("results: %s (induration.yaml, height_map.png, surface.ply)\n", a.out.c_str());
  }
  return 0;
}

}  // namespace tools
}  // namespace skin3d
