// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map MAP.csv]
 *             [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--quiet]
 *
 * Runs a recorded or simulated session through the same core code as the nodelets, without a ROS master,
 * as fast as the CPU allows: landmark bags (stereo/landmarks) go straight into the ES-EKF SLAM, image bags
 * (stereo/{left,right}/image_raw + camera_info) through the front end (rectify, features, MMSE
 * triangulation) first; imu/data feeds the gyroscope with --gyro. Writes the results directory of
 * DESIGN.md: trajectory.tum, map.ply, sphere_fit.yaml (robust sphere fit of the map), state.csv (per-frame
 * filter state), rig_covariance.csv (per-frame rig covariance), summary.yaml (with the absolute trajectory
 * error when the bag has ground_truth/pose), ground_truth.tum, and parameters.yaml (the command line and every
 * parameter's effective value). Progress on stderr (every 2 s on a terminal, every 10 % in a log).
 *
 * --known-map MAP.csv: thesis experiment 1, the landmarks are known (make_dataset globe-landmarks writes
 * FILE.map.csv beside the bag: positions and descriptors); association by descriptor + Mahalanobis gate.
 *
 * --induration: the induration measurement instead of SLAM (issue 6): every stereo pair is rectified, densely
 * matched and measured (process_bag_induration.cpp); --config / --set then take the keys of
 * config/induration.yaml. Writes induration.yaml, height_map.png and surface.ply.
 *
 * Exit codes: 0 ok, 1 bad configuration or data, 2 bad command line, 3 cannot write the output.
 */
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>

#include "conversions.h"  // src/nodelets
#include "process_bag_induration.h"
#include "run_info.h"
#include "stereo_pairs.h"
#include "skin3d/geometry/sphere_fit.h"
#include "skin3d/slam/results.h"
#include "skin3d/slam/slam_config.h"
#include "skin3d/slam/slam_system.h"
#include "skin3d/stereo/features.h"
#include "skin3d/stereo/rectification.h"
#include "skin3d/stereo/stereo_landmarks.h"

namespace {

using namespace skin3d;

const char* kUsage =
    "usage: process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map MAP.csv]\n"
    "                   [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--quiet]\n"
    "  --bag        dataset or recorded session (stereo/landmarks, or stereo/*/image_raw + camera_info)\n"
    "  --out        results directory (created)\n"
    "  --config     SLAM parameters over the defaults of config/slam.yaml (repeatable: later files win)\n"
    "  --gyro       fuse imu/data (thesis experiment 3); same as --set use_gyro=true\n"
    "  --known-map  make_dataset's FILE.map.csv (landmarks + descriptors): localisation with a known map (exp. 1)\n"
    "  --features   front end for image bags (default kaze; akaze/orb also set max_descriptor_distance 5.5)\n"
    "  --frames     process at most N frames\n"
    "  --set        override one SLAM parameter (repeatable)\n"
    "  --induration measure plaque heights instead (dense stereo + induration; --config/--set take the keys of\n"
    "               config/induration.yaml; writes induration.yaml, height_map.png, surface.ply)\n";

struct Args {
  std::string bag, out, known_map, features = "kaze";
  std::vector<std::string> configs;
  std::vector<std::pair<std::string, std::string>> sets;
  bool gyro = false, quiet = false, induration = false;
  int frames = -1;
  std::vector<std::string> command_line;
};

double secs(const ros::Time& t) { return t.toSec(); }

slam::StampedPose fromPoseMsg(const geometry_msgs::PoseStamped& m) {
  slam::StampedPose p;
  p.t = secs(m.header.stamp);
  p.p = Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z);
  p.q = Eigen::Quaterniond(m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z);
  return p;
}

int run(const Args& a) {
  slam::SlamOptions opt;
  // Binary descriptors (AKAZE, ORB: one float 0/1 per bit, L2 = sqrt(Hamming)) need a wider association
  // distance than KAZE's unit-norm floats (config/slam.yaml's 0.3 accepts only identical bit strings):
  // Hamming <= 30, as launch/rig.launch and replay_globe.launch set it; a config file or --set still wins.
  if (a.features != "kaze") slam::setSlamOption(&opt, "max_descriptor_distance", "5.5");
  for (const auto& c : a.configs) slam::applySlamOptions(&opt, c);
  if (a.gyro) opt.use_gyro = true;
  for (const auto& kv : a.sets) slam::setSlamOption(&opt, kv.first, kv.second);
  opt.validate();
  slam::SlamSystem slam(opt);

  if (!a.known_map.empty()) {
    const auto known = slam::readLandmarkMap(a.known_map);
    slam.setKnownMap(known.first, known.second);
  }

  rosbag::Bag bag;
  try {
    bag.open(a.bag, rosbag::bagmode::Read);
  } catch (const std::exception& e) {
    throw std::invalid_argument("cannot open bag '" + a.bag + "': " + e.what());
  }
  const std::vector<std::string> topics = {"stereo/landmarks", "stereo/left/image_raw", "stereo/right/image_raw",
                                           "stereo/left/camera_info", "stereo/right/camera_info", "imu/data",
                                           "ground_truth/pose"};
  rosbag::View view(bag, rosbag::TopicQuery(topics));

  std::vector<slam::StampedPose> trajectory, truth;
  std::vector<slam::StateRow> rows;
  std::unique_ptr<stereo::StereoFeatureMatcher> matcher;
  tools::StereoPairs pairs_in;
  stereo::FeatureOptions fo;
  fo.type = stereo::parseFeatureType(a.features);
  const stereo::TriangulateOptions to;
  int frames = 0, bad_frames = 0;
  // frames to expect, for the progress line: landmark messages, or else left images
  int expected = static_cast<int>(rosbag::View(bag, rosbag::TopicQuery("stereo/landmarks")).size());
  if (expected == 0) expected = static_cast<int>(rosbag::View(bag, rosbag::TopicQuery("stereo/left/image_raw")).size());
  if (a.frames >= 0 && a.frames < expected) expected = a.frames;
  tools::Progress progress(expected, a.quiet);
  const auto t_start = std::chrono::steady_clock::now();
  double frame_seconds = 0.0;

  auto frame = [&](double t, const std::vector<slam::Measurement>& m) {
    const auto t0 = std::chrono::steady_clock::now();
    slam::FrameStats s;
    try {
      s = slam.processFrame(t, m);
    } catch (const std::invalid_argument& e) {
      ++bad_frames;
      std::fprintf(stderr, "process_bag: frame at t = %.6f s dropped: %s\n", t, e.what());
      return;
    }
    frame_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const auto& x = slam.filter().state();
    trajectory.push_back({t, x.p, x.q});
    rows.push_back(slam::stateRow(slam, s));
    ++frames;
    char detail[160];
    std::snprintf(detail, sizeof detail, "t = %.1f s: %d measured, %d associated, %d used, %d new, %d in the pool",
                  s.time, s.measurements, s.associated, s.used, s.initialised, slam.pool().used());
    progress.tick(frames, detail);
  };

  for (const rosbag::MessageInstance& mi : view) {
    if (a.frames >= 0 && frames >= a.frames) break;
    const std::string& topic = mi.getTopic();
    if (topic == "ground_truth/pose") {
      truth.push_back(fromPoseMsg(*mi.instantiate<geometry_msgs::PoseStamped>()));
    } else if (topic == "imu/data") {
      const auto imu = mi.instantiate<sensor_msgs::Imu>();
      Eigen::Matrix3d C;
      for (int i = 0; i < 9; ++i) C(i / 3, i % 3) = imu->angular_velocity_covariance[i];
      if (C(0, 0) < 0.0) C.setZero();  // -1: unknown -> the configured gyro_noise
      slam.addGyro(secs(imu->header.stamp),
                   Eigen::Vector3d(imu->angular_velocity.x, imu->angular_velocity.y, imu->angular_velocity.z), C);
    } else if (topic == "stereo/landmarks") {
      const auto l = mi.instantiate<skin3d::LandmarkArray>();
      frame(secs(l->header.stamp), ros_conv::fromMsg(*l));
    } else {
      pairs_in.add(mi);
    }
    // Process the complete pairs in stamp order once both camera_infos are known.
    sensor_msgs::Image::ConstPtr left, right;
    while (!(a.frames >= 0 && frames >= a.frames) && pairs_in.next(&left, &right)) {
      if (!matcher) {
        fo.disparity_offset = pairs_in.leftInfo().P(0, 2) - pairs_in.rightInfo().P(0, 2);
        matcher = std::make_unique<stereo::StereoFeatureMatcher>(fo);
      }
      try {
        const cv::Mat L = pairs_in.rectifyLeft(*left);
        const cv::Mat R = pairs_in.rectifyRight(*right);
        const auto lms = stereo::triangulateMatches(pairs_in.leftInfo(), pairs_in.rightInfo(), matcher->process(L, R), to);
        std::vector<slam::Measurement> m;
        for (const auto& l : lms) m.push_back({l.position, l.covariance, l.descriptor, l.strength});
        frame(secs(left->header.stamp), m);
      } catch (const std::exception& e) {
        ++bad_frames;
        std::fprintf(stderr, "process_bag: image pair at t = %.6f s dropped: %s\n", secs(left->header.stamp), e.what());
      }
    }
  }
  progress.done();
  if (frames == 0) throw std::invalid_argument("no frames in '" + a.bag + "' (no stereo/landmarks or image pairs)");

  // ---- results
  slam::RunRecord rec;
  rec.trajectory = trajectory;
  rec.rows = rows;
  rec.map = slam.map();
  rec.ground_truth = truth;
  rec.fit_sphere = a.known_map.empty();
  rec.info = {{"bag", a.bag},
              {"frames_dropped", std::to_string(bad_frames)},
              {"gyro", opt.use_gyro ? "true" : "false"},
              {"known_map", a.known_map.empty() ? "false" : "true"},
              {"front_end", matcher ? a.features : "none (landmark bag)"},
              {"slam_ms_per_frame", std::to_string(1e3 * frame_seconds / frames)},
              {"wall_time_s", std::to_string(std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count())}};
  const std::string text = slam::writeResults(a.out, rec);
  tools::writeParameters(a.out + "/parameters.yaml", "ES-EKF SLAM, keys of config/slam.yaml", a.command_line,
                         slam::slamOptionKeys(), [&](const std::string& k) { return slam::getSlamOption(opt, k); });
  if (!a.quiet) std::cout << text << std::flush;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  a.command_line.assign(argv, argv + argc);
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "process_bag: " << k << " needs a value\n" << kUsage;
        std::exit(2);
      }
      return argv[++i];
    };
    if (k == "--bag") a.bag = value();
    else if (k == "--out") a.out = value();
    else if (k == "--config") a.configs.push_back(value());
    else if (k == "--known-map") a.known_map = value();
    else if (k == "--features") a.features = value();
    else if (k == "--frames") a.frames = std::atoi(value().c_str());
    else if (k == "--gyro") a.gyro = true;
    else if (k == "--quiet") a.quiet = true;
    else if (k == "--induration") a.induration = true;
    else if (k == "--set") {
      const std::string kv = value();
      const auto eq = kv.find('=');
      if (eq == std::string::npos) {
        std::cerr << "process_bag: --set needs key=value (got '" << kv << "')\n";
        return 2;
      }
      a.sets.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    } else if (k == "-h" || k == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (k.rfind("__", 0) == 0) {
      // roslaunch remapping arguments: ignore.
    } else {
      std::cerr << "process_bag: unknown argument '" << k << "'\n" << kUsage;
      return 2;
    }
  }
  if (a.bag.empty() || a.out.empty()) {
    std::cerr << "process_bag: --bag and --out are required\n" << kUsage;
    return 2;
  }
  try {
    if (a.induration) {
      tools::IndurationRun r;
      r.bag = a.bag;
      r.out = a.out;
      r.configs = a.configs;
      r.sets = a.sets;
      r.frames = a.frames;
      r.quiet = a.quiet;
      r.command_line = a.command_line;
      return tools::runInduration(r);
    }
    return run(a);
  } catch (const std::runtime_error& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 1;
  }
}
