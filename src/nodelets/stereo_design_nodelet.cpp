// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_design: shows a stereo design in rviz.
 *
 * Parameters (private):
 *   ~config (string, required)   design YAML (config/part1_rig_design.yaml)
 *   ~rig_frame (string, "stereo_rig")  frame at the midpoint of the optical centres (see design.h)
 *   ~left_frame (string, "stereo_left_optical_frame"), ~right_frame ("stereo_right_optical_frame")
 *   ~ellipsoid_scale (double, 100)  exaggeration of the 1-sigma uncertainty ellipsoids for display
 * Publishes (latched): stereo_design/markers (visualization_msgs/MarkerArray, metres),
 *   static TF rig_frame -> left_frame, rig_frame -> right_frame.
 * A bad config logs an error naming the field and publishes nothing; the nodelet keeps running.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/design_node.h"

namespace skin3d {

class StereoDesignNodelet : public nodelet::Nodelet {
  void onInit() override { node_ = ros_run::startStereoDesign(getNodeHandle(), getPrivateNodeHandle()); }
  std::shared_ptr<void> node_;  // ros_run::StereoDesignNode
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoDesignNodelet, nodelet::Nodelet)
