// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the four stereo topics synchronised (see include/skin3d/ros/stereo_sync.h).
#include "skin3d/ros/stereo_sync.h"

namespace skin3d {
namespace ros_conv {

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
  return problem;
}

void StereoSync::onPair(const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                        const sensor_msgs::Image::ConstPtr& ri, const sensor_msgs::CameraInfo::ConstPtr& rc) {
  callback_(li, lc, ri, rc);
}

}  // namespace ros_conv
}  // namespace skin3d
