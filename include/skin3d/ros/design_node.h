// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file design_node.h
 * @brief skin3d_ros: the stereo_design nodelet's node: its parameters, topics and work (the nodelet only constructs it).
 * Topics and parameters: docs/nodes.md, skin3d/stereo_design.
 */
#pragma once

#include <ros/ros.h>

#include <memory>

namespace skin3d {
namespace ros_run {

/** @brief Starts the node on `nh` / `pnh`; it runs as long as the returned handle lives. */
std::shared_ptr<void> startStereoDesign(ros::NodeHandle& nh, ros::NodeHandle& pnh);

}  // namespace ros_run
}  // namespace skin3d
