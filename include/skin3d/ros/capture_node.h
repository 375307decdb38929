// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file capture_node.h
 * @brief skin3d_ros: the stereo_capture nodelet's node: its parameters, topics and work (the nodelet only constructs it).
 * Topics and parameters: docs/nodes.md, skin3d/stereo_capture.
 */
#pragma once

#include <ros/ros.h>

#include <memory>

namespace skin3d {
namespace ros_run {

/** @brief Starts the node on `nh` / `pnh`; it runs as long as the returned handle lives. */
std::shared_ptr<void> startStereoCapture(ros::NodeHandle& nh, ros::NodeHandle& pnh);

}  // namespace ros_run
}  // namespace skin3d
