// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_front_end: the stereo front end (rectify -> features -> MMSE triangulation) of each raw stereo
 * pair: stereo/landmarks with their covariance. All of it is ros_run::FrontEndRunner
 * (include/skin3d/ros/front_end_runner.h), which process_bag runs too; topics and parameters: docs/nodes.md.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/front_end_runner.h"

namespace skin3d {

class StereoFrontEndNodelet : public nodelet::Nodelet {
  void onInit() override {
    try {
      runner_ = ros_run::startFrontEndRunner(getNodeHandle(), getPrivateNodeHandle(), getName(),
                                             ros_run::rosLog("stereo_front_end"));
    } catch (const std::exception& e) {
      NODELET_FATAL("stereo_front_end: refusing to start, bad configuration: %s", e.what());
    }
  }
  std::unique_ptr<ros_run::FrontEndRunner> runner_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoFrontEndNodelet, nodelet::Nodelet)
