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

#include <geometry_msgs/PoseStamped.h>
#include <nav_msgs/Odometry.h>

#include <map>
#include <memory>
#include <condition_variable>
#include <exception>
#include <functional>
#include <optional>
#include <thread>

#include "skin3d/common/cli.h"
#include "skin3d/induration/induration_config.h"
#include "skin3d/site/site_fusion.h"
#include "skin3d/ros/bag_topics.h"
#include "skin3d/ros/induration_runner.h"
#include "skin3d/ros/site_runner.h"
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

/** The site options: config/site.yaml's defaults, then the site_* keys of --set. */
site::SiteOptions siteOptions(const std::vector<std::pair<std::string, std::string>>& sets) {
  site::SiteOptions o;
  for (const auto& [k, v] : sets) site::setSiteOption(&o, k, v);
  o.validate();
  return o;
}

/** Every pose of `topic` (PoseStamped or Odometry), by stamp. */
std::map<double, Eigen::Isometry3d> readPoses(const rosbag::Bag& bag, const std::string& path, const std::string& topic,
                                              const std::string& ns) {
  const ros_io::BagTopics t(bag, path, {topic}, ns);
  std::map<double, Eigen::Isometry3d> out;
  rosbag::View view(bag, rosbag::TopicQuery(t.stored(topic)));
  for (const rosbag::MessageInstance& m : view) {
    geometry_msgs::Pose p;
    double stamp;
    if (auto ps = m.instantiate<geometry_msgs::PoseStamped>()) {
      p = ps->pose;
      stamp = ps->header.stamp.toSec();
    } else if (auto od = m.instantiate<nav_msgs::Odometry>()) {
      p = od->pose.pose;
      stamp = od->header.stamp.toSec();
    } else {
      throw std::invalid_argument("'" + topic + "' in '" + path + "' is " + m.getDataType() +
                                  ", not geometry_msgs/PoseStamped or nav_msgs/Odometry");
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z).normalized().toRotationMatrix();
    T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
    out[stamp] = T;
  }
  return out;
}

/** The site's second half on its own thread: complete() each prepared pair in order (a queue of one), `done` after
 *  each; finish() waits for the last and throws what the thread threw. */
class SitePipeline {
 public:
  SitePipeline(ros_run::SiteRunner* site, std::function<void(bool)> done) : site_(site), done_(std::move(done)) {
    if (site_) thread_ = std::thread([this] { run(); });
  }
  ~SitePipeline() {
    try {
      finish();
    } catch (...) {  // finish() was not called: an exception is already on its way
    }
  }
  void push(ros_run::SiteRunner::Prepared p) {
    std::unique_lock<std::mutex> l(m_);
    cv_.wait(l, [this] { return !slot_ || failed_; });
    if (failed_) return;
    slot_ = std::make_unique<ros_run::SiteRunner::Prepared>(std::move(p));
    cv_.notify_all();
  }
  void finish() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard<std::mutex> l(m_);
      closed_ = true;
      cv_.notify_all();
    }
    thread_.join();
    if (error_) std::rethrow_exception(error_);
  }

 private:
  void run() {
    for (;;) {
      std::unique_ptr<ros_run::SiteRunner::Prepared> p;
      {
        std::unique_lock<std::mutex> l(m_);
        cv_.wait(l, [this] { return slot_ || closed_; });
        if (!slot_) return;
        p = std::move(slot_);
        cv_.notify_all();
      }
      try {
        done_(site_->complete(std::move(*p)));
      } catch (...) {
        std::lock_guard<std::mutex> l(m_);
        error_ = std::current_exception();
        failed_ = true;
        cv_.notify_all();
        return;
      }
    }
  }
  ros_run::SiteRunner* site_;
  std::function<void(bool)> done_;
  std::thread thread_;
  std::mutex m_;
  std::condition_variable cv_;
  std::unique_ptr<ros_run::SiteRunner::Prepared> slot_;
  bool closed_ = false, failed_ = false;
  std::exception_ptr error_;
};

void printSiteFrame(const site::SiteFrame& f) {
  if (f.fused)
    std::printf("  site: frame %d fused, %ld samples (overlap %.0f %%; seams over %d blocks %.1f um RMS, %.1f um beyond the "
                "noise, rigid part %.1f um; registration moved it %.3f mm in %d iterations; %.1f s registration, %.1f s "
                "fusion)\n",
                f.index, f.samples, 100 * f.overlap, f.seam_blocks, f.seam_rms * 1e6, f.seam_excess * 1e6,
                f.seam_rigid * 1e6, f.correction_rms * 1e3, f.registration_iterations, f.seconds_register, f.seconds_fuse);
  else
    std::printf("  site: frame %d left out: %s\n", f.index, f.reason.c_str());
  std::fflush(stdout);
}

void printSite(const site::SiteResult& r, const std::string& out) {
  std::printf("\nsite: %d frame(s) fused, %d left out; surface %s (cell %.0f um, %.0f mm^2 fused), seams %.1f um RMS "
              "(%.1f um beyond the noise, rigid part %.1f um); measured in %.1f s\n",
              r.frames_fused, r.frames_left_out, r.surface.model.c_str(), r.cell * 1e6, r.fused_area * 1e6, r.seam_rms * 1e6,
              r.seam_excess * 1e6, r.seam_rigid * 1e6, r.seconds_measure);
  std::printf("| plaque | centroid x y z (mm, world) | area (mm²) | volume (mm³) | top | mean | PASI | views | spread (um) | best incidence (deg) | measured |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& p : r.plaques)
    std::printf("| %d | %.1f %.1f %.1f | %.1f | %.2f | %.3f | %.3f | %d | %d | %.0f | %.0f | %.0f %% |\n", p.id, 1e3 * p.centroid.x(),
                1e3 * p.centroid.y(), 1e3 * p.centroid.z(), 1e6 * p.area, 1e9 * p.volume, 1e3 * p.top_height,
                1e3 * p.mean_height, p.pasi_class, p.views, 1e6 * p.spread, p.best_incidence_deg, 100 * p.measured_share);
  for (const auto& p : r.grazing)
    std::printf("| (never seen within 45 deg: best %.0f deg) | %.1f %.1f %.1f | %.1f | %.2f | %.3f | %.3f | %d | %d | - | %.0f | %.0f %% |\n",
                p.best_incidence_deg, 1e3 * p.centroid.x(), 1e3 * p.centroid.y(), 1e3 * p.centroid.z(), 1e6 * p.area,
                1e9 * p.volume, 1e3 * p.top_height, 1e3 * p.mean_height, p.pasi_class, p.views, p.best_incidence_deg,
                100 * p.measured_share);
  for (const auto& w : r.warnings) std::printf("  warning: %s\n", w.c_str());
  std::printf("site results: %s (site.yaml, site_height_map.png, site_coverage.png, site_surface.ply)\n", out.c_str());
}

}  // namespace

int runInduration(const IndurationRun& a) {
  induration::PipelineOptions opt;
  for (const auto& c : a.configs) induration::applyPipelineOptions(&opt, c);
  for (const auto& kv : a.sets) induration::setPipelineOption(&opt, kv.first, kv.second);
  opt.validate();  // a bad configuration is refused before the bag is read
  // --site: the same runner as the site_fusion nodelet's, its per-pair measurement as --induration's
  std::unique_ptr<ros_run::SiteRunner> site;
  std::optional<ros_run::IndurationRunner> alone;
  const std::string pose_topic = a.site_poses.empty() ? "slam/odometry" : a.site_poses;
  if (a.site) {
    ros_run::SiteRunOptions ro;
    ro.poses = pose_topic;
    ro.pose_wait = 0;  // every pose of the bag is known before the first pair
    site = std::make_unique<ros_run::SiteRunner>(opt, siteOptions(a.site_sets), ro, "",
                                                 ros_run::RunLog::stderrLog("process_bag", a.quiet));
  } else {
    alone.emplace(opt, "", ros_run::RunLog::stderrLog("process_bag", a.quiet));
  }
  ros_run::IndurationRunner& runner = site ? site->measurer() : *alone;
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
  std::vector<site::SiteFrame> site_lines;  // printed after the pair's own line
  auto printSiteLines = [&site_lines]() {
    for (const auto& f : site_lines) printSiteFrame(f);
    site_lines.clear();
  };
  if (site && pose_topic == "images") {
    if (!a.quiet) std::fprintf(stderr, "process_bag: site: poses from the pairs' own stereo features\n");
    if (!a.quiet) site->onFrame([&site_lines](const site::SiteFrame& f) { site_lines.push_back(f); });
  } else if (site) {
    std::map<double, Eigen::Isometry3d> poses;
    try {
      poses = readPoses(bag, a.bag, pose_topic, a.ns);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string("--site needs the rig's pose for every pair: ") + e.what() +
                                  (a.site_poses.empty() ? " (record slam/odometry with the SLAM running, or name a pose topic with "
                                                          "--site-poses TOPIC, e.g. ground_truth/pose of a simulated sweep)" : ""));
    }
    if (poses.empty()) throw std::invalid_argument("--site: '" + pose_topic + "' in '" + a.bag + "' holds no pose");
    if (!a.quiet) std::fprintf(stderr, "process_bag: site: %zu poses on %s\n", poses.size(), pose_topic.c_str());
    for (const auto& [t, T] : poses) site->onPose(t, T);
    if (!a.quiet) site->onFrame([&site_lines](const site::SiteFrame& f) { site_lines.push_back(f); });
  }
  rosbag::View view(bag, rosbag::TopicQuery(ros_io::stereoTopicsRead(topics)));
  int expected = static_cast<int>(topics.count(ros_io::stereoImageTopic(topics, true)));
  if (a.frames >= 0 && a.frames < expected) expected = a.frames;
  ros_run::RunLog pairs_log = ros_run::RunLog::stderrLog("process_bag", a.quiet);
  ros_run::InputLedger pairs_ledger(&pairs_log);  // images that cannot be paired, bad stamps, encodings, sizes
  ros_io::StereoPairs pairs;
  pairs.setLedger(&pairs_ledger);
  int fed = 0;
  // --site: two threads, pair k+1 matched while pair k is measured and fused (in order: the same site)
  SitePipeline pipeline(site.get(), [&](bool ok) {
    if (ok && !a.quiet) printFrame(*runner.last(), runner.frames(), expected);
    printSiteLines();
  });
  auto feed = [&](const sensor_msgs::Image::ConstPtr& l, const sensor_msgs::Image::ConstPtr& r) {
    ++fed;
    if (site) {
      pipeline.push(site->prepare(*l, *pairs.leftInfoMsg(), *r, *pairs.rightInfoMsg()));
      return;
    }
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
  pipeline.finish();
  ros_run::InputLedger dropped = runner.ledger();
  dropped.absorb(pairs_ledger);
  if (runner.frames() == 0)
    throw std::invalid_argument("no stereo pair of '" + a.bag + "' could be measured (" + std::to_string(fed) +
                                " pairs, " + std::to_string(dropped.dropped()) + " dropped: " + dropped.summary() +
                                "; the bag needs stereo/{left,right}/image_raw and camera_info)");

  // ---- results (also when only some frames worked)
  std::string message;
  site::SiteResult sr;
  if (site) site->finish();
  printSiteLines();
  if (!(site ? site->save(a.out, &message, a.command_line, a.bag, &pairs_ledger, &sr)
             : runner.save(a.out, &message, a.command_line, a.bag, &pairs_ledger)))
    throw std::runtime_error(message);
  if (!a.quiet) printTable(*runner.last(), runner.frames(), dropped.dropped(), a.out);
  if (site) {
    if (!a.quiet) printSite(sr, a.out);
    if (runner.frames() > 1 && sr.frames_fused < 2) {
      std::fprintf(stderr, "process_bag: site: %d of %d frames could be fused: the sweep's frames do not overlap (site.yaml "
                           "names why each was left out); exit status 5\n", sr.frames_fused, runner.frames());
      return 5;
    }
  }
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
