// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map TRUTH.yaml]
 *             [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--quiet]
 *
 * Runs a recorded or simulated session through the same core code as the nodelets, without a ROS master,
 * as fast as the CPU allows: landmark bags (stereo/landmarks) go straight into the ES-EKF SLAM, image bags
 * (stereo/{left,right}/image_raw + camera_info) through the front end (rectify, features, MMSE
 * triangulation) first; imu/data feeds the gyroscope with --gyro. Writes the results directory of
 * DESIGN.md: trajectory.tum, map.ply, sphere_fit.yaml (robust sphere fit of the map), state.csv (per-frame
 * filter state), summary.yaml (with the absolute trajectory error when the bag has ground_truth/pose), and
 * ground_truth.tum.
 *
 * --known-map TRUTH.yaml: thesis experiment 1, the landmark positions are known (the dataset's
 * landmarks_world_m; descriptors are not in the truth file, so association is by position + Mahalanobis gate).
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
#include <sys/stat.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>

#include "conversions.h"  // src/nodelets
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
    "usage: process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map TRUTH.yaml]\n"
    "                   [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--quiet]\n"
    "  --bag        dataset or recorded session (stereo/landmarks, or stereo/*/image_raw + camera_info)\n"
    "  --out        results directory (created)\n"
    "  --config     SLAM parameters (default: the package's config/slam.yaml keys and defaults)\n"
    "  --gyro       fuse imu/data (thesis experiment 3); same as --set use_gyro=true\n"
    "  --known-map  truth YAML with landmarks_world_m: localisation with known landmarks (experiment 1)\n"
    "  --features   front end for image bags (default kaze)\n"
    "  --frames     process at most N frames\n"
    "  --set        override one SLAM parameter (repeatable)\n";

struct Args {
  std::string bag, out, config, known_map, features = "kaze";
  std::vector<std::pair<std::string, std::string>> sets;
  bool gyro = false, quiet = false;
  int frames = -1;
};

double secs(const ros::Time& t) { return t.toSec(); }

slam::StampedPose fromPoseMsg(const geometry_msgs::PoseStamped& m) {
  slam::StampedPose p;
  p.t = secs(m.header.stamp);
  p.p = Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z);
  p.q = Eigen::Quaterniond(m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z);
  return p;
}

std::vector<slam::Measurement> fromLandmarkMsg(const skin3d::LandmarkArray& a) {
  std::vector<slam::Measurement> out;
  out.reserve(a.landmarks.size());
  for (const auto& l : a.landmarks) {
    slam::Measurement m;
    m.z = Eigen::Vector3d(l.position.x, l.position.y, l.position.z);
    for (int i = 0; i < 9; ++i) m.C(i / 3, i % 3) = l.covariance[i];
    m.descriptor = l.descriptor;
    m.strength = l.strength;
    out.push_back(std::move(m));
  }
  return out;
}

class Progress {
 public:
  Progress(bool quiet) : quiet_(quiet), t0_(std::chrono::steady_clock::now()) {}
  void tick(int k, const slam::FrameStats& s, int pool) {
    if (quiet_) return;
    const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    if (el - last_ < 2.0) return;
    last_ = el;
    std::fprintf(stderr, "  frame %d (t = %.1f s): %d measured, %d associated, %d used, %d new, pool %d; %.1f frames/s\n",
                 k, s.time, s.measurements, s.associated, s.used, s.initialised, pool, k / el);
  }

 private:
  bool quiet_;
  std::chrono::steady_clock::time_point t0_;
  double last_ = 0.0;
};

int run(const Args& a) {
  slam::SlamOptions opt = a.config.empty() ? slam::SlamOptions() : slam::loadSlamOptions(a.config);
  if (a.gyro) opt.use_gyro = true;
  for (const auto& kv : a.sets) slam::setSlamOption(&opt, kv.first, kv.second);
  opt.validate();
  slam::SlamSystem slam(opt);

  if (!a.known_map.empty()) {
    const YAML::Node t = YAML::LoadFile(a.known_map);
    if (!t["landmarks_world_m"])
      throw std::invalid_argument("'" + a.known_map + "' has no landmarks_world_m (a globe-landmarks truth file?)");
    std::vector<Eigen::Vector3d> pos;
    for (const auto& p : t["landmarks_world_m"]) pos.emplace_back(p[0].as<double>(), p[1].as<double>(), p[2].as<double>());
    slam.setKnownMap(pos, std::vector<std::vector<float>>(pos.size()));
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
  std::unique_ptr<stereo::Rectifier> rect_l, rect_r;
  geometry::CameraInfo info_l, info_r;
  bool have_l = false, have_r = false;
  sensor_msgs::Image::ConstPtr img_l;
  stereo::FeatureOptions fo;
  fo.type = stereo::parseFeatureType(a.features);
  const stereo::TriangulateOptions to;
  int frames = 0, bad_frames = 0;
  Progress progress(a.quiet);
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
    progress.tick(frames, s, slam.pool().used());
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
      frame(secs(l->header.stamp), fromLandmarkMsg(*l));
    } else if (topic == "stereo/left/camera_info" && !have_l) {
      info_l = ros_conv::fromMsg(*mi.instantiate<sensor_msgs::CameraInfo>());
      rect_l = std::make_unique<stereo::Rectifier>(info_l);
      have_l = true;
    } else if (topic == "stereo/right/camera_info" && !have_r) {
      info_r = ros_conv::fromMsg(*mi.instantiate<sensor_msgs::CameraInfo>());
      rect_r = std::make_unique<stereo::Rectifier>(info_r);
      have_r = true;
    } else if (topic == "stereo/left/image_raw") {
      img_l = mi.instantiate<sensor_msgs::Image>();
    } else if (topic == "stereo/right/image_raw") {
      const auto img_r = mi.instantiate<sensor_msgs::Image>();
      if (!img_l || img_l->header.stamp != img_r->header.stamp || !have_l || !have_r) continue;
      if (!matcher) {
        fo.disparity_offset = info_l.P(0, 2) - info_r.P(0, 2);
        matcher = std::make_unique<stereo::StereoFeatureMatcher>(fo);
      }
      const cv::Mat L = (*rect_l)(ros_conv::toMono8(*img_l));
      const cv::Mat R = (*rect_r)(ros_conv::toMono8(*img_r));
      const auto lms = stereo::triangulateMatches(info_l, info_r, matcher->process(L, R), to);
      std::vector<slam::Measurement> m;
      for (const auto& l : lms) m.push_back({l.position, l.covariance, l.descriptor, l.strength});
      frame(secs(img_r->header.stamp), m);
      img_l.reset();
    }
  }
  if (frames == 0) throw std::invalid_argument("no frames in '" + a.bag + "' (no stereo/landmarks or image pairs)");

  // ---- results
  mkdir(a.out.c_str(), 0755);
  struct stat st;
  if (stat(a.out.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) throw std::runtime_error("cannot create '" + a.out + "'");
  slam::writeTum(a.out + "/trajectory.tum", trajectory);
  const auto map = slam.map();
  slam::writePly(a.out + "/map.ply", map);
  slam::writeStateCsv(a.out + "/state.csv", rows);
  if (!truth.empty()) slam::writeTum(a.out + "/ground_truth.tum", truth);
  YAML::Emitter y;
  y << YAML::BeginMap;
  y << YAML::Key << "bag" << YAML::Value << a.bag << YAML::Key << "frames" << YAML::Value << frames;
  y << YAML::Key << "frames_dropped" << YAML::Value << bad_frames;
  y << YAML::Key << "gyro" << YAML::Value << opt.use_gyro << YAML::Key << "known_map" << YAML::Value
    << !a.known_map.empty();
  y << YAML::Key << "landmarks_in_map" << YAML::Value << map.size();
  y << YAML::Key << "landmarks_ever_seen" << YAML::Value << static_cast<long>(slam.pool().everSeen());
  y << YAML::Key << "slam_ms_per_frame" << YAML::Value << 1e3 * frame_seconds / frames;
  y << YAML::Key << "wall_time_s" << YAML::Value
    << std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  y << YAML::Key << "final_covariance_trace" << YAML::Value << YAML::BeginMap << YAML::Key << "rig" << YAML::Value
    << rows.back().trace_rig << YAML::Key << "landmarks_m2" << YAML::Value << rows.back().trace_landmarks
    << YAML::Key << "all" << YAML::Value << rows.back().trace_all << YAML::EndMap;
  y << YAML::Key << "corr_vx_wy_final" << YAML::Value << rows.back().corr_vx_wy;
  if (!truth.empty()) {
    const slam::TrajectoryError e = slam::trajectoryError(trajectory, truth);
    y << YAML::Key << "ate" << YAML::Value << YAML::BeginMap << YAML::Key << "pairs" << YAML::Value << e.pairs
      << YAML::Key << "rmse_mm" << YAML::Value << 1e3 * e.rmse << YAML::Key << "mean_mm" << YAML::Value
      << 1e3 * e.mean << YAML::Key << "max_mm" << YAML::Value << 1e3 * e.max << YAML::Key << "final_mm"
      << YAML::Value << 1e3 * e.final << YAML::Key << "rotation_rmse_mrad" << YAML::Value << 1e3 * e.rotation_rmse
      << YAML::Key << "alignment" << YAML::Value << "none (both worlds are the first camera frame)" << YAML::EndMap;
  }
  if (map.size() >= 4 && a.known_map.empty()) {
    std::vector<Eigen::Vector3d> pts;
    for (const auto& m : map) pts.push_back(m.position);
    try {
      const geometry::SphereFit fit = geometry::fitSphere(pts);
      slam::writeSphereFit(a.out + "/sphere_fit.yaml", fit);
      y << YAML::Key << "sphere_fit" << YAML::Value << YAML::BeginMap << YAML::Key << "radius_mm" << YAML::Value
        << 1e3 * fit.radius << YAML::Key << "rms_residual_mm" << YAML::Value << 1e3 * fit.rms_inliers << YAML::Key
        << "inliers" << YAML::Value << fit.inliers << YAML::EndMap;
    } catch (const std::invalid_argument& e) {
      std::fprintf(stderr, "process_bag: no sphere fit: %s\n", e.what());
    }
  }
  y << YAML::EndMap;
  std::ofstream s(a.out + "/summary.yaml");
  s << "# skin3d process_bag summary (mm where the key says so)\n" << y.c_str() << '\n';
  if (!s) throw std::runtime_error("cannot write '" + a.out + "/summary.yaml'");
  if (!a.quiet) std::cout << y.c_str() << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
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
    else if (k == "--config") a.config = value();
    else if (k == "--known-map") a.known_map = value();
    else if (k == "--features") a.features = value();
    else if (k == "--frames") a.frames = std::atoi(value().c_str());
    else if (k == "--gyro") a.gyro = true;
    else if (k == "--quiet") a.quiet = true;
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
    return run(a);
  } catch (const std::runtime_error& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 1;
  }
}
