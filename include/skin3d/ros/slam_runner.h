// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file slam_runner.h
 * @brief skin3d_ros: the SLAM pipeline's runner (see runner.h): the ES-EKF SLAM (slam::SlamSystem) with its
 * parameters, input checks, topics, services, diagnostics and results. The eskf_slam nodelet constructs it and
 * calls attach(); process_bag constructs it and calls the same callbacks with a bag's messages in the bag's order.
 *
 * Frames and gyro samples: with use_gyro, a frame is processed only once a gyro sample at or after its stamp has
 * arrived (the samples up to a frame are then all there, whichever arrived first: the gyro comes straight from
 * the driver or bag, the landmarks later through the front end), or when the gyro lags by more than ~gyro_wait
 * (stamp time, or wall time since the frame came; then with a throttled warning), or at the end of the input. So the live path and process_bag integrate the same samples for every frame.
 */
#pragma once

#include <geometry_msgs/PoseStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>

#include <chrono>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "skin3d/ros/input_checks.h"
#include "skin3d/ros/runner.h"
#include "skin3d/ros/slam_messages.h"
#include "skin3d/slam/results.h"
#include "skin3d/slam/slam_system.h"
#include "skin3d/slam/smoother.h"

namespace diagnostic_updater {
class Updater;
class DiagnosticStatusWrapper;
}  // namespace diagnostic_updater

namespace skin3d {
namespace ros_conv {
class GroundTruthPath;
}
namespace ros_run {

/** @brief The SLAM options of a run, in the order every door applies them: the code's defaults (documented in
 *  config/slam.yaml); for landmarks measured by skin3d's image front end with `features`, the front end's
 *  measurement model and descriptor distance (slam::imageInputOptions); then the user's files and keys. */
slam::SlamOptions slamOptionsFor(const std::string& front_end_features, const std::vector<std::string>& config_files,
                                 const std::vector<std::pair<std::string, std::string>>& sets);

/** @brief The runner's own parameters besides the SLAM's options (see docs/nodes.md, skin3d/eskf_slam). */
struct SlamRunnerParams : ros_conv::SlamNodeParams {
  /** The front end whose landmarks come in ("kaze", "akaze", "orb": its measurement model is applied; empty: the
   *  landmarks carry their own model, e.g. a landmark dataset). */
  std::string front_end;
  double gyro_wait = 0.5;  //!< s: how long a frame waits for the gyro samples up to its stamp
  slam::AteAlignment ate_alignment = slam::AteAlignment::Auto;
  double ate_max_dt = 0.01;  //!< s
  /** @throws std::invalid_argument naming the parameter. */
  void validate() const;
};

class SlamRunner {
 public:
  /** @throws std::invalid_argument for bad options or parameters (a bad configuration is refused at start). */
  SlamRunner(const slam::SlamOptions& options, const SlamRunnerParams& params, RunLog log);
  /** Writes the results (params.results) when something was processed since the last save: no data is lost. */
  ~SlamRunner();
  SlamRunner(const SlamRunner&) = delete;
  SlamRunner& operator=(const SlamRunner&) = delete;

  /** @brief Live: subscribes stereo/landmarks, imu/data (with use_gyro), the ground truth; advertises the
   *  outputs, the services ~reset and ~save_results and the diagnostics. */
  void attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name);

  // ---- the callbacks both doors call
  void onLandmarks(const skin3d::LandmarkArray& msg);
  void onImu(const sensor_msgs::Imu& msg);
  void onGroundTruth(const geometry_msgs::PoseStamped& msg);
  /** @brief End of input: processes the frames still waiting for the gyro. */
  void flush();

  /** @brief Writes the results directory. `extra`: more summary.yaml lines (process_bag: the bag, timings);
   *  `upstream`: what the stages before the SLAM dropped, counted in frames_dropped too.
   *  @return false with the reason in `message` when it cannot be written; else the summary's text. */
  bool save(const std::string& dir, std::string* message,
            const std::vector<std::pair<std::string, std::string>>& extra = {},
            const std::vector<std::string>& command_line = {}, const InputLedger* upstream = nullptr);
  /** @brief Forgets everything (the results so far are written first when ~results is set). */
  void reset();

  int frames() const;
  const InputLedger& ledger() const { return ledger_; }
  const slam::SlamSystem& slam() const { return *slam_; }
  double slamSecondsPerFrame() const;

 private:
  void processLocked(const skin3d::LandmarkArray& msg);
  void drainLocked(bool all);
  void resetLocked();
  bool saveLocked(const std::string& dir, std::string* message,
                  const std::vector<std::pair<std::string, std::string>>& extra,
                  const std::vector<std::string>& command_line, const InputLedger* upstream);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  /** With options.smoother: the smoother's trajectory into `run` (its summary lines too). */
  void smoothInto(slam::RunRecord* run);

  mutable std::mutex mutex_;
  RunLog log_;
  InputLedger ledger_;
  RunnerStatus status_;
  SlamRunnerParams par_;
  std::unique_ptr<slam::SlamSystem> slam_;
  slam::RunRecord run_;
  std::vector<slam::StampedPose> truth_;                 // as the input gave it
  struct Waiting {
    skin3d::LandmarkArray msg;
    std::chrono::steady_clock::time_point arrived;
  };
  std::deque<Waiting> waiting_;                          // frames waiting for the gyro
  double last_gyro_ = -1e300;                            // stamp of the newest gyro sample
  ros_conv::StampOrder imu_order_;                       // imu/data stamps must increase
  double last_frame_ = -1e300;                           // stamp of the newest frame taken
  bool unsaved_ = false;
  std::vector<slam::SmootherFrame> smoother_frames_;     // what the smoother needs (options.smoother only)
  std::vector<slam::GyroSample> smoother_gyro_;
  bool smoothed_ = false;
  double slam_seconds_ = 0.0;
  std::string node_name_ = "eskf_slam";

  // live only (attach)
  std::unique_ptr<ros_conv::SlamPublisher> pub_;
  std::unique_ptr<ros_conv::GroundTruthPath> truth_path_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::Subscriber sub_landmarks_, sub_imu_, sub_truth_;
  ros::ServiceServer srv_reset_, srv_save_;
  ros::Timer diag_timer_;
  ros::WallTimer wait_timer_;  // frames whose gyro samples do not come are processed after ~gyro_wait
};

/**
 * @brief The live runner of the eskf_slam nodelet: its parameters from `pnh` (the SLAM keys of config/slam.yaml
 * over the code's defaults and, with ~front_end, the front end's measurement model; the node's own keys of
 * docs/nodes.md), then attach().
 * @throws std::invalid_argument naming every bad parameter (the node refuses to start on a bad configuration).
 */
std::unique_ptr<SlamRunner> startSlamRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name,
                                            RunLog log);

}  // namespace ros_run
}  // namespace skin3d
