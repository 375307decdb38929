// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_rectify: the rectified stereo pair (stereo/{left,right}/image_rect, mono8) for viewing and
 * recording. All of it is ros_run::RectifyRunner (include/skin3d/ros/rectify_runner.h); topics and parameters:
 * docs/nodes.md.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/rectify_runner.h"

namespace skin3d {

class StereoRectifyNodelet : public nodelet::Nodelet {
  void onInit() override {
    try {
      runner_ = std::make_unique<ros_run::RectifyRunner>(getNodeHandle(), getPrivateNodeHandle(),
                                                         ros_run::rosLog("stereo_rectify"));
    } catch (const std::exception& e) {
      NODELET_FATAL("stereo_rectify: refusing to start, bad configuration: %s", e.what());
    }
  }
  std::unique_ptr<ros_run::RectifyRunner> runner_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoRectifyNodelet, nodelet::Nodelet)
