// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the four stereo topics synchronised (see include/skin3d/ros/stereo_sync.h).
#include "skin3d/ros/stereo_sync.h"
#include <stdexcept>
#include <ros/console.h>

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

std::string imageTransportParam(const ros::NodeHandle& pnh) {
  std::string t = "raw";
  pnh.param<std::string>("image_transport", t, t);
  if (t != "raw" && t != "compressed")
    throw std::invalid_argument("~image_transport = '" + t + "' must be raw or compressed (JPEG / PNG on image_raw/compressed)");
  return t;
}

void DecodedImages::subscribe(ros::NodeHandle& nh, const std::string& topic, uint32_t queue_size) {
  sub_ = nh.subscribe(topic + "/compressed", queue_size, &DecodedImages::onCompressed, this);
}

void DecodedImages::onCompressed(const sensor_msgs::CompressedImage::ConstPtr& m) {
  sensor_msgs::ImageConstPtr img;
  try {
    img = fromCompressed(*m);
  } catch (const std::exception& e) {
    ++undecodable_;
    ROS_ERROR_THROTTLE(5.0, "%s: %s (%d undecodable so far; skipped)", sub_.getTopic().c_str(), e.what(), undecodable_);
    return;
  }
  signalMessage(img);
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
  std::string transport = "raw";
  try {
    transport = imageTransportParam(pnh);
  } catch (const std::exception& e) {
    problem += (problem.empty() ? "" : "; ") + std::string(e.what()) + "; using raw";
  }
  subscribe(nh, image, queue, approximate, std::move(callback), transport);
  return problem;
}

void StereoSync::subscribe(ros::NodeHandle& nh, const std::string& image, int queue, bool approximate,
                           Callback callback, const std::string& transport) {
  const bool compressed = transport == "compressed";
  if (!compressed && transport != "raw")
    throw std::invalid_argument("image transport '" + transport + "' must be raw or compressed");
  if (compressed) {
    lz_.subscribe(nh, "stereo/left/" + image, queue);
    rz_.subscribe(nh, "stereo/right/" + image, queue);
  } else {
    li_.subscribe(nh, "stereo/left/" + image, queue);
    ri_.subscribe(nh, "stereo/right/" + image, queue);
  }
  lc_.subscribe(nh, "stereo/left/camera_info", queue);
  rc_.subscribe(nh, "stereo/right/camera_info", queue);
  callback_ = std::move(callback);
  if (approximate) {
    approx_ = compressed ? std::make_unique<message_filters::Synchronizer<Approx>>(Approx(queue), lz_, lc_, rz_, rc_)
                         : std::make_unique<message_filters::Synchronizer<Approx>>(Approx(queue), li_, lc_, ri_, rc_);
    approx_->registerCallback(&StereoSync::onPair, this);
  } else {
    exact_ = compressed ? std::make_unique<message_filters::Synchronizer<Exact>>(Exact(queue), lz_, lc_, rz_, rc_)
                        : std::make_unique<message_filters::Synchronizer<Exact>>(Exact(queue), li_, lc_, ri_, rc_);
    exact_->registerCallback(&StereoSync::onPair, this);
  }
}

void StereoSync::onPair(const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                        const sensor_msgs::Image::ConstPtr& ri, const sensor_msgs::CameraInfo::ConstPtr& rc) {
  callback_(li, lc, ri, rc);
}

}  // namespace ros_conv
}  // namespace skin3d
