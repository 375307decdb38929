// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map MAP.csv]
 *             [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--ns NAMESPACE]
 *             [--input auto|images|landmarks] [--ate-align auto|none|first_pose|se3] [--ate-max-dt S] [--serial]
 *             [--quiet]
 *
 * Runs a recorded or simulated session through the same core code as the nodelets, without a ROS master,
 * as fast as the CPU allows: landmark bags (stereo/landmarks) go straight into the ES-EKF SLAM, image bags
 * (stereo/{left,right}/image_raw + camera_info) through the front end (rectify, features, MMSE
 * triangulation) first; imu/data feeds the gyroscope with --gyro. Writes the results directory of
 * DESIGN.md: trajectory.tum, map.ply, sphere_fit.yaml (robust sphere fit of the map), state.csv (per-frame
 * filter state), rig_covariance.csv (per-frame rig covariance), map_covariance.csv (each landmark's covariance),
 * summary.yaml (with the absolute trajectory error when the bag has ground_truth/pose), ground_truth.tum, and
 * parameters.yaml (the command line and every
 * parameter's effective value). Progress on stderr (every 2 s on a terminal, every 10 % in a log).
 *
 * --known-map MAP.csv: thesis experiment 1, the landmarks are known (make_dataset globe-landmarks writes
 * FILE.map.csv beside the bag: positions and descriptors); association by descriptor + Mahalanobis gate.
 *
 * --induration: the induration measurement instead of SLAM (issue 6): every stereo pair is rectified, densely
 * matched and measured (process_bag_induration.cpp); --config / --set then take the keys of
 * config/induration.yaml. Writes induration.yaml, height_map.png and surface.ply.
 *
 * Bags recorded by others: topics are found under their relative names (stereo/landmarks), absolute names
 * (/stereo/landmarks, as `rosbag record -a` writes them) or a namespace (/rig1/stereo/landmarks; --ns rig1, or
 * found when it is the only one); when nothing matches, the error lists the bag's topics. A bag with both the
 * raw images and the front end's stereo/landmarks (record -a of a running rig) is processed from the images
 * (--input landmarks replays the recorded landmarks instead).
 *
 * Image bags run as a two-stage pipeline on two threads: the front end (features, matching, triangulation) of
 * pair k runs while the SLAM processes pair k-1. The SLAM sees the same frames and gyro samples in the same
 * order, so the results are the same as with --serial (one stage after the other), which only serves to measure
 * the gain. summary.yaml gives both stages' ms per frame (front_end_ms_per_frame, slam_ms_per_frame).
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

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <future>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include "skin3d/ros/conversions.h"
#include "process_bag_induration.h"
#include "skin3d/ros/bag_topics.h"
#include "skin3d/common/run_info.h"
#include "skin3d/ros/stereo_pairs.h"
#include "skin3d/common/large_buffers.h"
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
    "                   [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--ns NAMESPACE]\n"
    "                   [--input auto|images|landmarks] [--ate-align auto|none|first_pose|se3] [--quiet]\n"
    "  --bag        dataset or recorded session (stereo/landmarks, or stereo/*/image_raw + camera_info)\n"
    "  --out        results directory (created)\n"
    "  --config     SLAM parameters over the defaults of config/slam.yaml (repeatable: later files win); image\n"
    "               input first applies config/slam_frontend.yaml's (the front end's measurement model)\n"
    "  --gyro       fuse imu/data (thesis experiment 3); same as --set use_gyro=true\n"
    "  --known-map  make_dataset's FILE.map.csv (landmarks + descriptors): localisation with a known map (exp. 1)\n"
    "  --features   front end for image bags: akaze (default, as the rig's launch files), kaze or orb; akaze and orb\n"
    "               also set max_descriptor_distance 5.5 (binary descriptors; a --config or --set still wins)\n"
    "  --frames     process at most N frames\n"
    "  --set        override one SLAM parameter (repeatable)\n"
    "  --ns         the bag's topics are under this namespace (e.g. rig1 for /rig1/stereo/...; '/' = the root);\n"
    "               default: the root, or the one namespace that holds skin3d's topics\n"
    "  --input      auto (default: the images when the bag has them, else stereo/landmarks) | images | landmarks\n"
    "  --ate-align  how the ground truth is aligned for summary.yaml's ate: auto (default: none when its world is\n"
    "               the SLAM's, i.e. its first pose is the first estimate's, else se3) | none | first_pose | se3;\n"
    "               ate_se3 (SE(3)-aligned, as evo_ape --align) is always written too\n"
    "  --ate-max-dt time association tolerance of the ATE, s (default 0.01, as evo)\n"
    "  --serial     image bags: run the front end and the SLAM one after the other instead of overlapping them on\n"
    "               two threads (same results; for timing comparisons)\n"
    "  --induration measure plaque heights instead (dense stereo + induration; --config/--set take the keys of\n"
    "               config/induration.yaml; writes induration.yaml, height_map.png, surface.ply)\n";

struct Args {
  std::string bag, out, known_map, features = "akaze", ns, input = "auto", ate_align = "auto";
  double ate_max_dt = 0.01;
  std::vector<std::string> configs;
  std::vector<std::pair<std::string, std::string>> sets;
  bool gyro = false, quiet = false, induration = false, serial = false;
  int frames = -1;
  std::vector<std::string> command_line;
};

double secs(const ros::Time& t) { return t.toSec(); }
std::int64_t nsecs(const ros::Time& t) { return static_cast<std::int64_t>(t.toNSec()); }

slam::StampedPose fromPoseMsg(const geometry_msgs::PoseStamped& m) {
  slam::StampedPose p;
  p.t = secs(m.header.stamp);
  p.stamp_ns = nsecs(m.header.stamp);
  p.p = Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z);
  p.q = Eigen::Quaterniond(m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z);
  return p;
}

/** The SLAM options of a run: config/slam.yaml's defaults, then for image input the front end's measurement model
 *  and association distance (slam::imageInputOptions, = config/slam_frontend.yaml; a landmark bag's measurements
 *  and descriptors are the recorded ones), --config files, --gyro, --set (the user's wins), validated. */
slam::SlamOptions slamOptionsOf(const Args& a, bool use_images) {
  slam::SlamOptions opt;
  if (use_images)
    for (const auto& kv : slam::imageInputOptions(a.features)) slam::setSlamOption(&opt, kv.first, kv.second);
  for (const auto& c : a.configs) slam::applySlamOptions(&opt, c);
  if (a.gyro) opt.use_gyro = true;
  for (const auto& kv : a.sets) slam::setSlamOption(&opt, kv.first, kv.second);
  opt.validate();
  return opt;
}

/** Whether the run takes the bag's stereo images through the front end (else its stereo/landmarks), from what
 *  the bag holds and --input; throws std::invalid_argument naming what is missing. */
bool useImages(const Args& a, const ros_io::BagTopics& topics) {
  const bool have_images = topics.has("stereo/left/image_raw") && topics.has("stereo/right/image_raw");
  const bool have_landmarks = topics.has("stereo/landmarks");
  bool use_images = have_images;
  if (a.input == "landmarks") use_images = false;
  if (a.input == "images" && !have_images)
    throw std::invalid_argument("--input images: '" + a.bag + "' has no stereo/{left,right}/image_raw (" +
                                topics.summary() + ")");
  if (a.input == "landmarks" && !have_landmarks)
    throw std::invalid_argument("--input landmarks: '" + a.bag + "' has no stereo/landmarks (" + topics.summary() + ")");
  if (!use_images && !have_landmarks)
    throw std::invalid_argument("'" + a.bag + "' has neither stereo/landmarks nor both stereo/{left,right}/image_raw (" +
                                topics.summary() + "). Its topics:\n" + ros_io::describeTopics(topics.all()));
  if (!a.quiet) {
    std::fprintf(stderr, "process_bag: %s; input: %s%s\n", topics.summary().c_str(),
                 use_images ? "stereo images through the front end" : "stereo/landmarks",
                 use_images && have_landmarks ? " (the recorded stereo/landmarks are not used: --input landmarks)" : "");
  }
  return use_images;
}

/** Image pairs through the front end (features, matching, triangulation), overlapped with the SLAM: submit()
 *  starts pair k's front end on a second thread, then hands pair k-1's measurements to the sink (the SLAM) on the
 *  calling thread. One front end runs at a time (it owns the matcher), so the sink sees the pairs in order. With
 *  serial, each pair's front end and its sink run one after the other on the calling thread. */
class FrontEndPipeline {
 public:
  using Sink = std::function<void(const ros::Time&, const std::vector<slam::Measurement>&)>;
  FrontEndPipeline(const stereo::FeatureOptions& options, bool serial, Sink sink)
      : fo_(options), serial_(serial), sink_(std::move(sink)) {}
  ~FrontEndPipeline() {
    if (pending_ && pending_->result.valid()) pending_->result.wait();  // never leave a front end running
  }

  bool started() const { return matcher_ != nullptr; }
  int inFlight() const { return pending_ ? 1 : 0; }  //!< pairs submitted and not yet handed to the sink
  int dropped() const { return dropped_; }           //!< pairs whose front end failed
  double secondsPerPair() const { return pairs_ > 0 ? seconds_ / pairs_ : 0.0; }

  void submit(const ros::Time& stamp, const cv::Mat& L, const cv::Mat& R, const geometry::CameraInfo& li,
              const geometry::CameraInfo& ri) {
    if (!matcher_) {
      fo_.disparity_offset = li.P(0, 2) - ri.P(0, 2);
      matcher_ = std::make_unique<stereo::StereoFeatureMatcher>(fo_);
    }
    std::optional<Pending> previous = std::move(pending_);
    pending_.reset();
    std::optional<std::vector<slam::Measurement>> previous_m;
    if (previous) previous_m = take(&*previous);  // before the next front end starts: one at a time
    stereo::StereoFeatureMatcher* matcher = matcher_.get();
    auto work = [matcher, L, R, li, ri]() {
      const auto t0 = std::chrono::steady_clock::now();
      const stereo::TriangulateOptions to;
      const auto lms = stereo::triangulateMatches(li, ri, matcher->process(L, R), to);
      Result r;
      for (const auto& l : lms) r.measurements.push_back({l.position, l.covariance, l.descriptor, l.strength});
      r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      return r;
    };
    pending_ = Pending{stamp, std::async(serial_ ? std::launch::deferred : std::launch::async, work)};
    if (previous_m) sink_(previous->stamp, *previous_m);
    if (serial_) finish();  // the deferred front end runs now, then its frame
  }

  /** Hands the pair still in the front end (if any) to the sink. */
  void finish() {
    if (!pending_) return;
    Pending p = std::move(*pending_);
    pending_.reset();
    const auto m = take(&p);
    if (m) sink_(p.stamp, *m);
  }

 private:
  struct Result {
    std::vector<slam::Measurement> measurements;
    double seconds = 0.0;
  };
  struct Pending {
    ros::Time stamp;
    std::future<Result> result;
  };
  // The measurements of a pending pair, or nothing (the pair is counted as dropped) when its front end failed.
  std::optional<std::vector<slam::Measurement>> take(Pending* p) {
    try {
      Result r = p->result.get();
      seconds_ += r.seconds;
      ++pairs_;
      return std::move(r.measurements);
    } catch (const std::exception& e) {
      ++dropped_;
      std::fprintf(stderr, "process_bag: image pair at t = %.6f s dropped: %s\n", p->stamp.toSec(), e.what());
      return std::nullopt;
    }
  }

  stereo::FeatureOptions fo_;
  bool serial_;
  Sink sink_;
  std::unique_ptr<stereo::StereoFeatureMatcher> matcher_;
  std::optional<Pending> pending_;
  int pairs_ = 0, dropped_ = 0;
  double seconds_ = 0.0;
};

int run(const Args& a) {
  rosbag::Bag bag;
  ros_io::openForReading(&bag, a.bag);
  const ros_io::BagTopics topics(bag, a.bag,
                                 {"stereo/landmarks", "stereo/left/image_raw", "stereo/right/image_raw",
                                  "stereo/left/camera_info", "stereo/right/camera_info", "imu/data",
                                  "ground_truth/pose"},
                                 a.ns);
  const bool use_images = useImages(a, topics);
  const slam::SlamOptions opt = slamOptionsOf(a, use_images);
  slam::SlamSystem slam(opt);
  if (!a.known_map.empty()) {
    const auto known = slam::readLandmarkMap(a.known_map);
    slam.setKnownMap(known.first, known.second);
  }
  std::vector<std::string> read = topics.stored();
  read.erase(std::remove_if(read.begin(), read.end(),
                            [&](const std::string& t) {
                              const std::string r = topics.relative(t);
                              return use_images ? r == "stereo/landmarks" : r.rfind("stereo/", 0) == 0 && r != "stereo/landmarks";
                            }),
             read.end());
  if (opt.use_gyro && !topics.has("imu/data"))
    std::fprintf(stderr, "process_bag: warning: use_gyro is set but the bag has no imu/data\n");
  rosbag::View view(bag, rosbag::TopicQuery(read));

  std::vector<slam::StampedPose> trajectory, truth;
  std::vector<slam::StateRow> rows;
  ros_io::StereoPairs pairs_in;
  stereo::FeatureOptions fo;
  fo.type = stereo::parseFeatureType(a.features);
  int frames = 0, bad_frames = 0;
  // frames to expect, for the progress line: landmark messages, or else left images
  int expected = static_cast<int>(use_images ? topics.count("stereo/left/image_raw") : topics.count("stereo/landmarks"));
  if (a.frames >= 0 && a.frames < expected) expected = a.frames;
  common::Progress progress(expected, a.quiet);
  const auto t_start = std::chrono::steady_clock::now();
  double frame_seconds = 0.0;

  auto frame = [&](const ros::Time& stamp, const std::vector<slam::Measurement>& m) {
    const double t = secs(stamp);
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
    trajectory.push_back({t, nsecs(stamp), x.p, x.q});
    rows.push_back(slam::stateRow(slam, s));
    ++frames;
    char detail[160];
    std::snprintf(detail, sizeof detail, "t = %.1f s: %d measured, %d associated, %d used, %d new, %d in the pool",
                  s.time, s.measurements, s.associated, s.used, s.initialised, slam.pool().used());
    progress.tick(frames, detail);
  };

  FrontEndPipeline front_end(fo, a.serial, frame);

  for (const rosbag::MessageInstance& mi : view) {
    if (a.frames >= 0 && frames + front_end.inFlight() >= a.frames) break;
    const std::string topic = topics.relative(mi.getTopic());
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
      frame(l->header.stamp, ros_conv::fromMsg(*l));
    } else {
      pairs_in.add(topic, mi);
    }
    // Process the complete pairs in stamp order once both camera_infos are known.
    sensor_msgs::Image::ConstPtr left, right;
    while (!(a.frames >= 0 && frames + front_end.inFlight() >= a.frames) && pairs_in.next(&left, &right)) {
      cv::Mat L, R;
      try {
        L = pairs_in.rectifyLeft(*left);
        R = pairs_in.rectifyRight(*right);
      } catch (const std::exception& e) {
        ++bad_frames;
        std::fprintf(stderr, "process_bag: image pair at t = %.6f s dropped: %s\n", secs(left->header.stamp), e.what());
        continue;
      }
      front_end.submit(left->header.stamp, L, R, pairs_in.leftInfo(), pairs_in.rightInfo());
    }
  }
  front_end.finish();  // the last pair
  bad_frames += front_end.dropped();
  progress.done();
  if (frames == 0)
    throw std::invalid_argument("no frame of '" + a.bag + "' could be processed (" + topics.summary() + "; " +
                                std::to_string(bad_frames) + " dropped" +
                                (use_images && !pairs_in.calibrated() ? "; no camera_info for both cameras" : "") + ")");

  // ---- results
  slam::RunRecord rec;
  rec.trajectory = trajectory;
  rec.rows = rows;
  rec.map = slam.map();
  rec.ground_truth = truth;
  rec.fit_sphere = a.known_map.empty();
  rec.ate_alignment = slam::parseAteAlignment(a.ate_align);
  rec.ate_max_dt = a.ate_max_dt;
  rec.info = {{"bag", a.bag},
              {"frames_dropped", std::to_string(bad_frames)},
              {"gyro", opt.use_gyro ? "true" : "false"},
              {"known_map", a.known_map.empty() ? "false" : "true"},
              {"front_end", front_end.started() ? a.features : "none (landmark bag)"},
              {"topics", topics.summary()},
              {"slam_ms_per_frame", std::to_string(1e3 * frame_seconds / frames)},
              {"front_end_ms_per_frame",
               front_end.started() ? std::to_string(1e3 * front_end.secondsPerPair()) : "none"},
              {"pipeline", !front_end.started() ? "none (landmark bag)" : a.serial ? "serial (--serial)" : "front end || SLAM, 2 threads"},
              {"wall_time_s", std::to_string(std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count())}};
  const std::string text = slam::writeResults(a.out, rec);
  common::writeParameters(a.out + "/parameters.yaml", "ES-EKF SLAM, keys of config/slam.yaml", a.command_line,
                         slam::slamOptionKeys(), [&](const std::string& k) { return slam::getSlamOption(opt, k); });
  if (!a.quiet) std::cout << text << std::flush;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  skin3d::keepLargeBuffers();  // 13-megapixel buffers from the heap, not fresh mmap()s
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
    else if (k == "--ns") a.ns = value();
    else if (k == "--input") a.input = value();
    else if (k == "--ate-align") a.ate_align = value();
    else if (k == "--ate-max-dt") a.ate_max_dt = std::atof(value().c_str());
    else if (k == "--frames") a.frames = std::atoi(value().c_str());
    else if (k == "--gyro") a.gyro = true;
    else if (k == "--quiet") a.quiet = true;
    else if (k == "--serial") a.serial = true;
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
  if (a.input != "auto" && a.input != "images" && a.input != "landmarks") {
    std::cerr << "process_bag: --input must be auto, images or landmarks (got '" << a.input << "')\n";
    return 2;
  }
  try {
    slam::parseAteAlignment(a.ate_align);
  } catch (const std::invalid_argument& e) {
    std::cerr << "process_bag: --ate-align: " << e.what() << "\n";
    return 2;
  }
  if (!(a.ate_max_dt > 0.0)) {
    std::cerr << "process_bag: --ate-max-dt must be a positive number of seconds\n";
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
      r.ns = a.ns;
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
