// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file front_end_runner.h
 * @brief skin3d_ros: the stereo front end's runner (see runner.h): stereo::FrontEnd (rectify -> features ->
 * triangulate) with its parameters, input checks, topics and diagnostics. The stereo_front_end nodelet
 * constructs it and calls attach(); process_bag constructs it and calls onStereo() with a bag's pairs.
 *
 * Live topics: subscribes stereo/{left,right}/image_raw + camera_info (exact or approximate sync) while someone
 * listens to an output (lazy, as image_pipeline does); publishes stereo/landmarks, and only while subscribed:
 * stereo/points (PointCloud2 x y z strength), stereo/matches (skin3d/StereoMatchArray), stereo/matches_image
 * (bgr8 picture of the matches), stereo/{left,right}/image_rect (mono8).
 */
#pragma once

#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <skin3d/LandmarkArray.h>

#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "skin3d/ros/runner.h"
#include "skin3d/ros/stereo_sync.h"
#include "skin3d/stereo/front_end.h"

namespace diagnostic_updater {
class Updater;
class DiagnosticStatusWrapper;
}  // namespace diagnostic_updater

namespace skin3d {
namespace ros_run {

class FrontEndRunner {
 public:
  /** @throws std::invalid_argument for bad options (a bad configuration is refused at start). */
  FrontEndRunner(const stereo::FrontEndOptions& options, RunLog log);
  ~FrontEndRunner();

  /** @brief Live: the lazy subscriptions (queue `queue_size` per topic, ~approximate_sync), the outputs and the
   *  diagnostics. */
  void attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name, int queue_size,
              bool approximate_sync);

  /**
   * @brief One raw stereo pair (both doors). Checks the four messages (a bad one drops the pair through the
   * ledger: topic, stamp, fault), runs the front end, publishes (live) and returns the landmarks in the left
   * optical frame, stamped as the left image; nothing when the pair was dropped.
   */
  std::optional<skin3d::LandmarkArray> onStereo(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                                                const sensor_msgs::Image& right,
                                                const sensor_msgs::CameraInfo& right_info);

  const stereo::FrontEndOptions& options() const { return front_end_.options(); }
  /** @brief Pairs dropped, by fault (thread-safe copy). */
  InputLedger ledger() const;
  int frames() const { return status_.frames(); }
  double secondsPerFrame() const;

 private:
  void connectionChanged();
  void publishExtras(const std_msgs::Header& header, const stereo::FrontEndFrame& f, const skin3d::LandmarkArray& out);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  mutable std::mutex mutex_;
  RunLog log_;
  InputLedger ledger_;
  RunnerStatus status_;
  stereo::FrontEnd front_end_;
  double seconds_ = 0.0;

  // live only
  bool attached_ = false;
  std::unique_ptr<ros::NodeHandle> nh_;  // live only (a NodeHandle needs ros::init)
  int queue_size_ = 5;
  bool approximate_ = false;
  std::string transport_ = "raw";  // ~image_transport
  std::mutex connect_mutex_;
  std::unique_ptr<ros_conv::StereoSync> sync_;
  ros::Publisher pub_landmarks_, pub_points_, pub_matches_, pub_matches_image_, pub_rect_l_, pub_rect_r_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::Timer diag_timer_;
};

/**
 * @brief The live runner of the stereo_front_end nodelet: the front end's options from `pnh` (every key of
 * config/frontend.yaml over the code's defaults; ~config names a YAML file of them applied first), ~queue_size,
 * ~approximate_sync, then attach().
 * @throws std::invalid_argument naming every bad parameter.
 */
std::unique_ptr<FrontEndRunner> startFrontEndRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh,
                                                    const std::string& name, RunLog log);

}  // namespace ros_run
}  // namespace skin3d
