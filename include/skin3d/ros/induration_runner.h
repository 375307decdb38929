// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file induration_runner.h
 * @brief skin3d_ros: the induration measurement's runner (see runner.h): induration::FrameMeasurer (rectify ->
 * dense disparity with sigma -> cloud -> reference and plaques) with its parameters, input checks, topics,
 * diagnostics and results. The induration nodelet constructs it and calls attach(); `process_bag --induration`
 * constructs it and calls onStereo() with a bag's pairs, so both write the same induration.yaml.
 *
 * Live topics: subscribes stereo/{left,right}/image_raw + camera_info (exact or approximate sync); publishes
 * induration/report and induration/height_map, and only while subscribed induration/points (the organised cloud
 * for rviz: x y z rgb sigma ray_x ray_y ray_z) and stereo/left/image_rect.
 */
#pragma once

#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "skin3d/induration/frame_measurer.h"
#include "skin3d/ros/runner.h"
#include "skin3d/ros/stereo_sync.h"

namespace diagnostic_updater {
class Updater;
class DiagnosticStatusWrapper;
}  // namespace diagnostic_updater

namespace skin3d {
namespace ros_run {

class IndurationRunner {
 public:
  /** @param results directory written on save_results and when the runner goes (empty: none)
   *  @throws std::invalid_argument for bad options. */
  IndurationRunner(const induration::PipelineOptions& options, const std::string& results, RunLog log);
  /** Writes the results (when ~results is set and something was measured since the last save). */
  ~IndurationRunner();

  /** @brief Live: subscriptions (queue `queue_size`), outputs, ~save_results, diagnostics. */
  void attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name, int queue_size,
              bool approximate_sync);

  /** @brief One raw stereo pair (both doors): checked (a bad one is dropped through the ledger: topic, stamp,
   *  fault), measured, published (live) and kept for the results. @return whether it was measured. */
  bool onStereo(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                const sensor_msgs::Image& right, const sensor_msgs::CameraInfo& right_info);

  /** @brief onStereo() in two halves, for a pipeline that matches one pair while it measures the one before:
   *  match() checks the pair (a bad one is dropped through the ledger: nullptr) and matches it (one thread at a time);
   *  complete() measures it and keeps it as onStereo() does (thread-safe; in the order the pairs came). */
  std::unique_ptr<induration::FrameMeasurement> match(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                                                      const sensor_msgs::Image& right, const sensor_msgs::CameraInfo& right_info);
  bool complete(std::unique_ptr<induration::FrameMeasurement> m, const std_msgs::Header& left_header);

  /** @brief Writes the results directory (induration/frame_measurer.h); induration.yaml ends with
   *  frames_dropped and dropped_input (by fault), with `upstream`'s drops (process_bag's pairing) counted too.
   *  @return false with the reason in `message`. */
  bool save(const std::string& dir, std::string* message, const std::vector<std::string>& command_line = {},
            const std::string& source = "", const InputLedger* upstream = nullptr);

  /** @brief Also writes each frame's maps, as it is measured, to frameMapsDirectory(dir, index) (empty: only the
   *  last frame's, with the results). A frame whose maps cannot be written is still measured (the log says why). */
  void keepEveryFrameMaps(const std::string& dir);

  int frames() const;
  /** @brief Frames whose healthy-skin reference did not follow the skin (IndurationResult::reference_follows). */
  int framesNotFollowed() const;
  InputLedger ledger() const;
  /** @brief The last frame's measurement (for process_bag's table), or nullptr. */
  const induration::FrameMeasurement* last() const { return last_ ? &*last_ : nullptr; }

 private:
  std::string live_source_ = "stereo/{left,right}/image_raw";  // the topics it subscribed (~image_transport)
  bool saveLocked(const std::string& dir, std::string* message, const std::vector<std::string>& command_line,
                  const std::string& source, const InputLedger* upstream);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  std::mutex serial_mutex_;  // onStereo(): one pair after the other, in order
  mutable std::mutex mutex_;
  std::mutex match_mutex_;  // match(): the measurer's rectification, one pair at a time
  RunLog log_;
  InputLedger ledger_;
  RunnerStatus status_;
  induration::FrameMeasurer measurer_;
  std::string results_, frame_id_ = "stereo_left_optical_frame", node_name_ = "induration";
  std::vector<induration::FrameRecord> frames_;  // every frame; maps only in the last (last_)
  std::unique_ptr<induration::FrameMeasurement> last_;
  bool unsaved_ = false;
  std::string every_frame_maps_;  // results directory of every frame's maps (empty: the last frame's only)

  // live only
  bool attached_ = false;
  std::unique_ptr<ros_conv::StereoSync> sync_;
  ros::Publisher pub_report_, pub_height_, pub_points_, pub_rect_;
  ros::ServiceServer srv_save_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::Timer diag_timer_;
};

/**
 * @brief The live runner of the induration nodelet: the options from `pnh` (~config: a YAML file of the keys of
 * config/induration.yaml, applied first; then every key set as a private parameter), ~results, ~queue_size (2),
 * ~approximate_sync (false), then attach().
 * @throws std::invalid_argument naming every bad parameter.
 */
std::unique_ptr<IndurationRunner> startIndurationRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh,
                                                        const std::string& name, RunLog log);

}  // namespace ros_run
}  // namespace skin3d
