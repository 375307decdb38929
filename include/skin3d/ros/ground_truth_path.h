// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file ground_truth_path.h
 * @brief skin3d_ros: a dataset's ground-truth poses drawn beside a live SLAM run (slam/ground_truth_path), moved
 * onto the SLAM's first pose by the core's slam::GroundTruthAligner; the aligned poses go into the results.
 */
#pragma once

#include <geometry_msgs/PoseStamped.h>
#include <nav_msgs/Path.h>
#include <ros/node_handle.h>
#include <ros/publisher.h>

#include <string>
#include <vector>

#include "skin3d/slam/ground_truth.h"
#include "skin3d/slam/results.h"

namespace skin3d {
namespace ros_conv {

class GroundTruthPath {
 public:
  /** @brief Advertises `topic` (nav_msgs/Path, latched) in `world_frame`. */
  void advertise(ros::NodeHandle& nh, const std::string& topic, const std::string& world_frame);
  /**
   * @brief One ground-truth pose (world_truth <- camera). `slam_first`: the SLAM's first pose (nullptr before
   * its first frame). A pose older than the last by more than `jump_back` s is a restarted bag: the old path is
   * cleared. @return empty, or why the pose was dropped (NaN, zero quaternion).
   */
  std::string add(const geometry_msgs::PoseStamped& msg, double jump_back, const slam::StampedPose* slam_first);
  /** @brief The SLAM's first frame is known: aligns the buffered poses on it (once) and draws them. */
  void anchor(const slam::StampedPose& slam_first);
  /** @brief A SLAM reset: the path is cleared (and published empty); the next first frame aligns again. */
  void clear();
  /** @brief The aligned poses drawn so far (for ground_truth.tum and the ATE of the results). */
  const std::vector<slam::StampedPose>& aligned() const { return aligned_; }

 private:
  void append(const slam::StampedPose& g);
  ros::Publisher pub_;
  std::string world_frame_;
  slam::GroundTruthAligner aligner_{0.05, 5000};  // matched within 0.05 s; the last 5000 poses kept
  nav_msgs::Path path_;
  std::vector<slam::StampedPose> aligned_;
};

}  // namespace ros_conv
}  // namespace skin3d
