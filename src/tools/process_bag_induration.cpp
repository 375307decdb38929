// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag --induration: every stereo pair of an image bag, in the bag's order, into the same runner the
 * induration nodelet is (ros_run::IndurationRunner: rectification, dense matching, the induration measurement),
 * as open_vins' serial runner feeds its live callbacks. Writes the runner's results directory (induration.yaml of
 * every frame with the repeatability over frames; the last frame's height_map.png, surface.ply and, for checking the
 * matcher, disparity.tiff / disparity_sigma.tiff in px, height_map.tiff in m, left_rect.png, unknown_reason.png)
 * and prints a per-plaque table in mm.
 */
#include "process_bag_induration.h"

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <cmath>
#include <cstdio>

#include "skin3d/induration/induration_config.h"
#include "skin3d/ros/bag_topics.h"
#include "skin3d/ros/induration_runner.h"
#include "skin3d/ros/stereo_pairs.h"

namespace skin3d {
namespace tools {

namespace {

void printFrame(const induration::FrameMeasurement& m, int k, int expected) {
  const auto& r = m.record.result;
  std::printf("frame %d/%d (t = %.3f s): %.1f %% matched, reference RMS %.4f mm, %zu plaques, %.1f s "
              "(rectification %.1f s, matching %.1f s of which sgbm %.1f s and refinement %.1f s, triangulation %.1f s, "
              "measurement %.1f s)\n",
              k, expected, m.record.stamp, 100 * m.record.valid_fraction, r.reference.rms * 1e3, r.plaques.size(),
              m.record.seconds, m.seconds_rectify, m.seconds_match, m.disparity.timing.sgbm, m.disparity.timing.refine,
              m.seconds_triangulate, m.seconds_measure);
  const auto& f = m.record;
  std::printf("  depth %.3f ... %.3f m (%s; disparity %.0f ... %.0f px)", f.z_near, f.z_far,
              f.range_searched ? "searched" : "set", f.min_disparity, f.max_disparity);
  if (std::isfinite(f.vertical_median))
    std::printf(", vertical disparity on the skin %.2f px (spread %.2f px)", f.vertical_median, f.vertical_spread);
  std::printf("\n  %s\n", stereo::describeUnknown(m.disparity).c_str());
  for (const auto& w : r.warnings) std::printf("  warning: %s\n", w.c_str());
  std::fflush(stdout);
}

void printTable(const induration::FrameMeasurement& last, int frames, int dropped, const std::string& out) {
  std::printf("\n%d frame(s), %d dropped. Last frame, heights above the healthy-skin reference (mm):\n", frames, dropped);
  std::printf("| plaque | centroid x y z (mm, left optical) | area (mm²) | top | mean | max (p99) | std | PASI |\n"
              "|---|---|---|---|---|---|---|---|\n");
  for (const auto& p : last.record.result.plaques)
    std::printf("| %d | %.1f %.1f %.1f | %.1f | %.3f | %.3f | %.3f | %.3f | %d |\n", p.id, 1e3 * p.centroid.x(),
                1e3 * p.centroid.y(), 1e3 * p.centroid.z(), 1e6 * p.area, 1e3 * p.top_height, 1e3 * p.mean_height,
                1e3 * p.max_height, 1e3 * p.std_height, p.pasi_class);
  std::printf("results: %s (induration.yaml, height_map.png, surface.ply)\n", out.c_str());
}

}  // namespace

int runInduration(const IndurationRun& a) {
  induration::PipelineOptions opt;
  for (const auto& c : a.configs) induration::applyPipelineOptions(&opt, c);
  for (const auto& kv : a.sets) induration::setPipelineOption(&opt, kv.first, kv.second);
  opt.validate();  // a bad configuration is refused before the bag is read
  ros_run::IndurationRunner runner(opt, "", ros_run::RunLog::stderrLog("process_bag", a.quiet));
  if (a.every_frame_maps) runner.keepEveryFrameMaps(a.out);

  rosbag::Bag bag;
  ros_io::openForReading(&bag, a.bag);
  const ros_io::BagTopics topics(bag, a.bag, ros_io::stereoTopicsWanted(), a.ns);
  for (const char* t : {"stereo/left/image_raw", "stereo/right/image_raw", "stereo/left/camera_info",
                        "stereo/right/camera_info"}) {
    const bool image = std::string(t).find("image_raw") != std::string::npos;
    if (image ? ros_io::stereoImageTopic(topics, std::string(t).find("left") != std::string::npos).empty() : !topics.has(t))
      throw std::invalid_argument("'" + a.bag + "' has no " + t + (image ? " (nor " + std::string(t) + "/compressed)" : "") +
                                  " (" + topics.summary() + "). Its topics:\n" + ros_io::describeTopics(topics.all()));
  }
  if (!a.quiet) std::fprintf(stderr, "process_bag: %s\n", topics.summary().c_str());
  rosbag::View view(bag, rosbag::TopicQuery(ros_io::stereoTopicsRead(topics)));
  int expected = static_cast<int>(topics.count(ros_io::stereoImageTopic(topics, true)));
  if (a.frames >= 0 && a.frames < expected) expected = a.frames;
  ros_run::RunLog pairs_log = ros_run::RunLog::stderrLog("process_bag", a.quiet);
  ros_run::InputLedger pairs_ledger(&pairs_log);  // images that cannot be paired, bad stamps, encodings, sizes
  ros_io::StereoPairs pairs;
  pairs.setLedger(&pairs_ledger);
  int fed = 0;
  auto feed = [&](const sensor_msgs::Image::ConstPtr& l, const sensor_msgs::Image::ConstPtr& r) {
    ++fed;
    if (runner.onStereo(*l, *pairs.leftInfoMsg(), *r, *pairs.rightInfoMsg()) && !a.quiet)
      printFrame(*runner.last(), runner.frames(), expected);
  };
  const auto full = [&]() { return a.frames >= 0 && fed >= a.frames; };
  for (const rosbag::MessageInstance& mi : view) {
    if (full()) break;
    pairs.add(topics.relative(mi.getTopic()), mi);
    sensor_msgs::Image::ConstPtr left, right;
    while (!full() && pairs.next(&left, &right)) feed(left, right);
  }
  if (!full()) pairs.flush();  // the whole bag was read: what still waits for a partner is dropped (and counted)
  ros_run::InputLedger dropped = runner.ledger();
  dropped.absorb(pairs_ledger);
  if (runner.frames() == 0)
    throw std::invalid_argument("no stereo pair of '" + a.bag + "' could be measured (" + std::to_string(fed) +
                                " pairs, " + std::to_string(dropped.dropped()) + " dropped: " + dropped.summary() +
                                "; the bag needs stereo/{left,right}/image_raw and camera_info)");

  // ---- results (also when only some frames worked)
  std::string message;
  if (!runner.save(a.out, &message, a.command_line, a.bag, &pairs_ledger)) throw std::runtime_error(message);
  if (!a.quiet) printTable(*runner.last(), runner.frames(), dropped.dropped(), a.out);
  if (const int n = runner.framesNotFollowed()) {
    std::fprintf(stderr,
                 "process_bag: in %d of %d frames the healthy-skin reference did not follow the skin: plaques there "
                 "could not be measured (the warnings and the hatched height map say where); exit status 4\n",
                 n, runner.frames());
    return 4;
  }
  return 0;
}

}  // namespace tools
}  // namespace skin3d
