// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag's SLAM mode: the bag's messages, in the bag's order, into the same runners the live nodelets are
 * (ros_run::FrontEndRunner for image bags, ros_run::SlamRunner), as open_vins' serial runner feeds its live
 * callbacks. Image pairs overlap with the SLAM on two threads: the front end of pair k runs while the SLAM takes
 * pair k-1; the SLAM sees the same frames and gyro samples in the same order (it waits for the gyro samples up
 * to each frame's stamp), so --serial gives the same results and only serves to measure the gain.
 */
#include "process_bag.h"

#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <future>
#include <iostream>
#include <optional>

#include "skin3d/common/run_info.h"
#include "skin3d/ros/bag_topics.h"
#include "skin3d/ros/front_end_runner.h"
#include "skin3d/ros/slam_runner.h"
#include "skin3d/ros/stereo_pairs.h"

namespace skin3d {
namespace tools {

namespace {

/** Whether the run takes the bag's stereo images through the front end (else its stereo/landmarks). */
bool useImages(const SlamRun& a, const ros_io::BagTopics& topics) {
  const bool have_images = !ros_io::stereoImageTopic(topics, true).empty() && !ros_io::stereoImageTopic(topics, false).empty();
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

/** Pairs through the front-end runner, overlapped with the SLAM: submit() starts pair k's front end on a second
 *  thread, then hands pair k-1's landmarks to the sink (the SLAM runner) on the calling thread. One front end runs
 *  at a time, so the sink sees the pairs in order. With serial, each pair's front end and its sink run one after
 *  the other on the calling thread. */
class OverlappedFrontEnd {
 public:
  using Sink = std::function<void(const skin3d::LandmarkArray&)>;
  OverlappedFrontEnd(ros_run::FrontEndRunner* runner, bool serial, Sink sink)
      : runner_(runner), serial_(serial), sink_(std::move(sink)) {}
  ~OverlappedFrontEnd() {
    if (pending_.valid()) pending_.wait();  // never leave a front end running
  }
  int inFlight() const { return pending_.valid() ? 1 : 0; }

  void submit(const sensor_msgs::Image::ConstPtr& l, const sensor_msgs::CameraInfo::ConstPtr& lc,
              const sensor_msgs::Image::ConstPtr& r, const sensor_msgs::CameraInfo::ConstPtr& rc) {
    std::optional<skin3d::LandmarkArray> previous;
    if (pending_.valid()) previous = pending_.get();  // before the next front end starts: one at a time
    ros_run::FrontEndRunner* runner = runner_;
    pending_ = std::async(serial_ ? std::launch::deferred : std::launch::async,
                          [runner, l, lc, r, rc]() { return runner->onStereo(*l, *lc, *r, *rc); });
    if (previous) sink_(*previous);
    if (serial_) finish();
  }
  /** Hands the pair still in the front end (if any) to the sink. */
  void finish() {
    if (!pending_.valid()) return;
    const auto last = pending_.get();
    if (last) sink_(*last);
  }

 private:
  ros_run::FrontEndRunner* runner_;
  bool serial_;
  Sink sink_;
  std::future<std::optional<skin3d::LandmarkArray>> pending_;
};

ros_run::SlamRunnerParams slamParams(const SlamRun& a, bool use_images) {
  ros_run::SlamRunnerParams par;
  par.known_map = a.known_map;
  par.front_end = use_images ? a.features : "";
  par.ate_alignment = slam::parseAteAlignment(a.ate_align);
  par.ate_max_dt = a.ate_max_dt;
  return par;
}

stereo::FrontEndOptions frontEndOptions(const SlamRun& a) {
  stereo::FrontEndOptions fo;
  stereo::setFrontEndOption(&fo, "feature_type", a.features);
  for (const auto& c : a.front_end_configs) stereo::applyFrontEndOptions(&fo, c);
  for (const auto& kv : a.front_end_sets) stereo::setFrontEndOption(&fo, kv.first, kv.second);
  fo.validate();
  return fo;
}

}  // namespace

int runSlam(const SlamRun& a) {
  const auto t_start = std::chrono::steady_clock::now();
  rosbag::Bag bag;
  ros_io::openForReading(&bag, a.bag);
  const ros_io::BagTopics topics(bag, a.bag,
                                 {"stereo/landmarks", "stereo/left/image_raw", "stereo/right/image_raw",
                                  "stereo/left/image_raw/compressed", "stereo/right/image_raw/compressed",
                                  "stereo/left/camera_info", "stereo/right/camera_info", "imu/data",
                                  "ground_truth/pose"},
                                 a.ns);
  const bool use_images = useImages(a, topics);
  // The configuration is checked before the first message: a bad one is refused by name.
  std::vector<std::pair<std::string, std::string>> sets;
  if (a.gyro) sets.emplace_back("use_gyro", "true");
  sets.insert(sets.end(), a.sets.begin(), a.sets.end());
  const slam::SlamOptions opt = ros_run::slamOptionsFor(use_images ? a.features : "", a.configs, sets);
  ros_run::SlamRunner slam(opt, slamParams(a, use_images), ros_run::RunLog::stderrLog("process_bag", a.quiet));
  std::unique_ptr<ros_run::FrontEndRunner> front_end;
  if (use_images)
    front_end = std::make_unique<ros_run::FrontEndRunner>(frontEndOptions(a),
                                                          ros_run::RunLog::stderrLog("process_bag", a.quiet));
  if (opt.use_gyro && !topics.has("imu/data"))
    std::fprintf(stderr, "process_bag: warning: use_gyro is set but the bag has no imu/data\n");

  // the images (each camera's raw topic, else its compressed one) or the landmarks, and the rest
  std::vector<std::string> read =
      use_images ? ros_io::stereoTopicsRead(topics, {"imu/data", "ground_truth/pose"}) : std::vector<std::string>();
  if (!use_images)
    for (const char* r : {"stereo/landmarks", "imu/data", "ground_truth/pose"})
      for (const auto& s : topics.stored(r)) read.push_back(s);
  rosbag::View view(bag, rosbag::TopicQuery(read));
  int expected = static_cast<int>(use_images ? topics.count(ros_io::stereoImageTopic(topics, true)) : topics.count("stereo/landmarks"));
  if (a.frames >= 0 && a.frames < expected) expected = a.frames;
  common::Progress progress(expected, a.quiet);
  int fed = 0;  // frames handed to the SLAM
  auto to_slam = [&](const skin3d::LandmarkArray& m) {
    ++fed;
    slam.onLandmarks(m);
    char detail[120];
    std::snprintf(detail, sizeof detail, "t = %.1f s: %zu measured, %d in the pool", m.header.stamp.toSec(),
                  m.landmarks.size(), slam.slam().pool().used());
    progress.tick(slam.frames(), detail);
  };
  OverlappedFrontEnd overlap(front_end.get(), a.serial, to_slam);
  ros_run::RunLog pairs_log = ros_run::RunLog::stderrLog("process_bag", a.quiet);
  ros_run::InputLedger pairs_ledger(&pairs_log);  // images that cannot be paired, bad stamps, encodings, sizes
  ros_io::StereoPairs pairs;
  pairs.setLedger(&pairs_ledger);
  auto full = [&]() { return a.frames >= 0 && fed + overlap.inFlight() >= a.frames; };
  for (const rosbag::MessageInstance& mi : view) {
    if (full()) break;
    const std::string topic = topics.relative(mi.getTopic());
    if (topic == "ground_truth/pose") {
      if (const auto g = mi.instantiate<geometry_msgs::PoseStamped>()) slam.onGroundTruth(*g);
    } else if (topic == "imu/data") {
      if (const auto imu = mi.instantiate<sensor_msgs::Imu>()) slam.onImu(*imu);
    } else if (topic == "stereo/landmarks") {
      if (const auto l = mi.instantiate<skin3d::LandmarkArray>()) to_slam(*l);
    } else {
      pairs.add(topic, mi);
    }
    sensor_msgs::Image::ConstPtr left, right;
    while (!full() && pairs.next(&left, &right))
      overlap.submit(left, pairs.leftInfoMsg(), right, pairs.rightInfoMsg());
  }
  if (!full()) {  // the whole bag was read: what still waits for a partner is dropped (and counted)
    pairs.flush();
    sensor_msgs::Image::ConstPtr left, right;
    while (pairs.next(&left, &right)) overlap.submit(left, pairs.leftInfoMsg(), right, pairs.rightInfoMsg());
  }
  overlap.finish();  // the last pair
  slam.flush();      // the frames still waiting for the gyro
  progress.done();
  ros_run::InputLedger upstream = front_end ? front_end->ledger() : ros_run::InputLedger();
  upstream.absorb(pairs_ledger);
  upstream.setLog(nullptr);
  const int dropped = slam.ledger().dropped() + upstream.dropped();
  if (slam.frames() == 0)
    throw std::invalid_argument("no frame of '" + a.bag + "' could be processed (" + topics.summary() + "; " +
                                std::to_string(dropped) + " dropped: " + upstream.summary() + "; " +
                                slam.ledger().summary() +
                                (use_images && !pairs.calibrated() ? "; no camera_info for both cameras" : "") + ")");

  // ---- results: those of the SLAM runner, with the bag's figures
  std::vector<std::pair<std::string, std::string>> extra = {
      {"bag", a.bag},
      {"topics", topics.summary()},
      {"front_end_ms_per_frame", front_end ? std::to_string(1e3 * front_end->secondsPerFrame()) : "none"},
      {"pipeline", !front_end ? "none (landmark bag)" : a.serial ? "serial (--serial)" : "front end || SLAM, 2 threads"},
      {"wall_time_s", std::to_string(std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count())}};
  std::string message;
  if (!slam.save(a.out, &message, extra, a.command_line, &upstream)) throw std::runtime_error(message);
  if (!a.quiet) std::cout << message << std::flush;
  return 0;
}

}  // namespace tools
}  // namespace skin3d
