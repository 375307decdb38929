// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: ground truth drawn beside a live SLAM run (see include/skin3d/ros/ground_truth_path.h).
#include "skin3d/ros/ground_truth_path.h"

#include <cmath>

#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_conv {

void GroundTruthPath::advertise(ros::NodeHandle& nh, const std::string& topic, const std::string& world_frame) {
  world_frame_ = world_frame;
  pub_ = nh.advertise<nav_msgs::Path>(topic, 2, true);
}

std::string GroundTruthPath::add(const geometry_msgs::PoseStamped& msg, double jump_back,
                                 const slam::StampedPose* slam_first) {
  const auto& p = msg.pose.position;
  const auto& o = msg.pose.orientation;
  const Eigen::Quaterniond q(o.w, o.x, o.y, o.z);
  if (!std::isfinite(p.x + p.y + p.z) || !(q.norm() > 1e-6))  // NaN-safe: !(NaN > x)
    return "dropping a ground-truth pose with NaN or a zero quaternion";
  slam::StampedPose s;
  s.t = msg.header.stamp.toSec();
  s.stamp_ns = static_cast<std::int64_t>(msg.header.stamp.toNSec());
  s.p = Eigen::Vector3d(p.x, p.y, p.z);
  s.q = q.normalized();
  if (aligner_.add(s, jump_back)) clear();  // a restarted bag: the old run is forgotten
  if (!slam_first) return "";
  if (!aligner_.anchored()) {
    anchor(*slam_first);
  } else if (aligner_.inRun(s.t, slam_first->t)) {
    append(aligner_.align(s));
    pub_.publish(path_);
  }
  return "";
}

void GroundTruthPath::anchor(const slam::StampedPose& slam_first) {
  if (!pub_ || !aligner_.anchor(slam_first)) return;
  path_.poses.clear();
  aligned_.clear();
  for (const auto& g : aligner_.alignedSince(slam_first.t)) append(g);
  pub_.publish(path_);
}

void GroundTruthPath::append(const slam::StampedPose& g) {
  geometry_msgs::PoseStamped ps;
  if (g.stamp_ns >= 0) ps.header.stamp.fromNSec(static_cast<std::uint64_t>(g.stamp_ns));
  else ps.header.stamp.fromSec(g.t);
  ps.header.frame_id = world_frame_;
  ps.pose = toPoseMsg(g.p, g.q);
  path_.header = ps.header;
  path_.poses.push_back(ps);
  aligned_.push_back(g);
}

void GroundTruthPath::clear() {
  aligner_.dropAnchor();
  aligned_.clear();
  if (!pub_ || path_.poses.empty()) return;
  path_.poses.clear();
  path_.header.frame_id = world_frame_;
  pub_.publish(path_);
}

}  // namespace ros_conv
}  // namespace skin3d
