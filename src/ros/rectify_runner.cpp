// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the stereo_rectify nodelet's runner (see include/skin3d/ros/rectify_runner.h).
#include "skin3d/ros/rectify_runner.h"

#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_run {

RectifyRunner::RectifyRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, RunLog log)
    : log_(std::move(log)), ledger_(&log_), nh_(nh) {
  pnh.param("max_stamp_diff", max_stamp_diff_, max_stamp_diff_);
  pnh.param("queue_size", queue_size_, queue_size_);
  pnh.param("approximate_sync", approximate_, approximate_);
  transport_ = ros_conv::imageTransportParam(pnh);
  if (!(max_stamp_diff_ >= 0.0)) throw std::invalid_argument("~max_stamp_diff must be >= 0 s");
  if (queue_size_ < 1) throw std::invalid_argument("~queue_size = " + std::to_string(queue_size_) + " must be >= 1");
  const ros::SubscriberStatusCallback changed = [this](const ros::SingleSubscriberPublisher&) { connectionChanged(); };
  {
    std::lock_guard<std::mutex> l(connect_mutex_);
    pub_left_ = nh.advertise<sensor_msgs::Image>("stereo/left/image_rect", 1, changed, changed);
    pub_right_ = nh.advertise<sensor_msgs::Image>("stereo/right/image_rect", 1, changed, changed);
  }
  connectionChanged();
}

RectifyRunner::~RectifyRunner() {
  std::lock_guard<std::mutex> l(connect_mutex_);
  sync_.reset();
}

void RectifyRunner::connectionChanged() {
  std::lock_guard<std::mutex> l(connect_mutex_);
  const bool wanted = pub_left_.getNumSubscribers() + pub_right_.getNumSubscribers() > 0;
  if (wanted && !sync_) {
    sync_ = std::make_unique<ros_conv::StereoSync>();
    sync_->subscribe(nh_, "image_raw", queue_size_, approximate_,
                     [this](const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                            const sensor_msgs::Image::ConstPtr& ri,
                            const sensor_msgs::CameraInfo::ConstPtr& rc) { onStereo(*li, *lc, *ri, *rc); },
                     transport_);
  } else if (!wanted && sync_) {
    sync_.reset();
  }
}

void RectifyRunner::onStereo(const sensor_msgs::Image& li, const sensor_msgs::CameraInfo& lc,
                             const sensor_msgs::Image& ri, const sensor_msgs::CameraInfo& rc) {
  std::lock_guard<std::mutex> lock(mutex_);
  const double t = li.header.stamp.toSec();
  const ros_conv::PairFault bad = ros_conv::checkStereoPair(li, lc, ri, rc, max_stamp_diff_);
  if (bad) {
    ledger_.drop(bad.topic, t, bad.fault);
    return;
  }
  try {
    const auto rect = rectify_(ros_conv::toMono8(li), ros_conv::toMono8(ri), ros_conv::fromMsg(lc), ros_conv::fromMsg(rc));
    pub_left_.publish(ros_conv::toMono8Msg(rect.first, li.header.frame_id, li.header.stamp));
    pub_right_.publish(ros_conv::toMono8Msg(rect.second, ri.header.frame_id, ri.header.stamp));
  } catch (const std::exception& e) {
    ledger_.drop("stereo/left/image_raw", t, e.what(), "the pair could not be rectified");
  }
}

}  // namespace ros_run
}  // namespace skin3d
