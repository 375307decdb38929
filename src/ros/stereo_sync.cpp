// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the four stereo topics synchronised (see include/skin3d/ros/stereo_sync.h).
#include "skin3d/ros/stereo_sync.h"

#include <cmath>

#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_conv {

PairFault checkStereoPair(const sensor_msgs::Image& li, const sensor_msgs::CameraInfo& lc,
                          const sensor_msgs::Image& ri, const sensor_msgs::CameraInfo& rc, double max_stamp_diff) {
  const char* kLi = "stereo/left/camera_info";
  const char* kRi = "stereo/right/camera_info";
  const char* kL = "stereo/left/image_raw";
  const char* kR = "stereo/right/image_raw";
  std::string p = checkCameraInfo(lc, kLi);
  if (!p.empty()) return {kLi, p};
  if (!(p = checkCameraInfo(rc, kRi)).empty()) return {kRi, p};
  if (!(p = checkImage(li, &lc, kL)).empty()) return {kL, p};
  if (!(p = checkImage(ri, &rc, kR)).empty()) return {kR, p};
  if (li.width != ri.width || li.height != ri.height)
    return {kR, "left and right images differ in size (" + std::to_string(li.width) + "x" + std::to_string(li.height) +
                    " vs " + std::to_string(ri.width) + "x" + std::to_string(ri.height) + ")"};
  if (li.header.frame_id == ri.header.frame_id)
    return {kR, "left and right images have the same frame_id '" + li.header.frame_id + "'"};
  if (li.header.frame_id != lc.header.frame_id)
    return {kL, "frame_id '" + li.header.frame_id + "' is not its camera_info's '" + lc.header.frame_id + "'"};
  const double dt = (li.header.stamp - ri.header.stamp).toSec();
  if (std::abs(dt) > max_stamp_diff)
    return {kR, "left/right stamps differ by " + std::to_string(dt) + " s (more than " + std::to_string(max_stamp_diff) + " s)"};
  return {};
}

std::string StereoSync::subscribe(ros::NodeHandle& nh, const ros::NodeHandle& pnh, const std::string& image,
                                  Callback callback) {
  bool approximate = false;
  int queue = 5;
  pnh.param("approximate_sync", approximate, false);
  pnh.param("queue_size", queue, 5);
  std::string problem;
  if (queue < 1) {
    problem = "~queue_size = " + std::to_string(queue) + " must be >= 1; using 5";
    queue = 5;
  }
  subscribe(nh, image, queue, approximate, std::move(callback));
  return problem;
}

void StereoSync::subscribe(ros::NodeHandle& nh, const std::string& image, int queue, bool approximate,
                           Callback callback) {
  li_.subscribe(nh, "stereo/left/" + image, queue);
  lc_.subscribe(nh, "stereo/left/camera_info", queue);
  ri_.subscribe(nh, "stereo/right/" + image, queue);
  rc_.subscribe(nh, "stereo/right/camera_info", queue);
  callback_ = std::move(callback);
  if (approximate) {
    approx_ = std::make_unique<message_filters::Synchronizer<Approx>>(Approx(queue), li_, lc_, ri_, rc_);
    approx_->registerCallback(&StereoSync::onPair, this);
  } else {
    exact_ = std::make_unique<message_filters::Synchronizer<Exact>>(Exact(queue), li_, lc_, ri_, rc_);
    exact_->registerCallback(&StereoSync::onPair, this);
  }
}

void StereoSync::onPair(const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                        const sensor_msgs::Image::ConstPtr& ri, const sensor_msgs::CameraInfo::ConstPtr& rc) {
  callback_(li, lc, ri, rc);
}

}  // namespace ros_conv
}  // namespace skin3d
