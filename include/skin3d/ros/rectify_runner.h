// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file rectify_runner.h
 * @brief skin3d_ros: the runner of the stereo_rectify nodelet (see runner.h): the rectified pair for viewing and
 * recording (stereo/{left,right}/image_rect, mono8), with the input checks every door shares
 * (ros_conv::checkStereoPair). The measuring pipelines rectify by themselves (stereo::PairRectifier).
 * Subscribes stereo/{left,right}/image_raw + camera_info only while an output has a subscriber.
 */
#pragma once

#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <memory>
#include <mutex>
#include <string>

#include "skin3d/ros/runner.h"
#include "skin3d/ros/stereo_sync.h"
#include "skin3d/stereo/front_end.h"

namespace skin3d {
namespace ros_run {

class RectifyRunner {
 public:
  /** @brief Parameters from `pnh` (~max_stamp_diff 0.005 s, ~queue_size 5, ~approximate_sync false), topics.
   *  @throws std::invalid_argument naming a bad parameter. */
  RectifyRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, RunLog log);
  ~RectifyRunner();
  void onStereo(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                const sensor_msgs::Image& right, const sensor_msgs::CameraInfo& right_info);

 private:
  void connectionChanged();
  std::mutex mutex_, connect_mutex_;
  RunLog log_;
  InputLedger ledger_;
  stereo::PairRectifier rectify_;
  ros::NodeHandle nh_;
  double max_stamp_diff_ = 0.005;
  int queue_size_ = 5;
  bool approximate_ = false;
  std::string transport_ = "raw";  // ~image_transport
  std::unique_ptr<ros_conv::StereoSync> sync_;
  ros::Publisher pub_left_, pub_right_;
};

}  // namespace ros_run
}  // namespace skin3d
