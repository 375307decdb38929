// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/eskf_slam: the ES-EKF SLAM on the stereo landmarks of each frame, optionally fused with the gyroscope.
 * All of it is ros_run::SlamRunner (include/skin3d/ros/slam_runner.h), which process_bag runs too; topics,
 * services and parameters: docs/nodes.md.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/slam_runner.h"

namespace skin3d {

class EskfSlamNodelet : public nodelet::Nodelet {
  void onInit() override {
    try {
      runner_ = ros_run::startSlamRunner(getNodeHandle(), getPrivateNodeHandle(), getName(), ros_run::rosLog("eskf_slam"));
    } catch (const std::exception& e) {
      NODELET_FATAL("eskf_slam: refusing to start, bad configuration: %s", e.what());
    }
  }
  std::unique_ptr<ros_run::SlamRunner> runner_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::EskfSlamNodelet, nodelet::Nodelet)
