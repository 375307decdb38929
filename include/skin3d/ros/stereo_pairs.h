// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the bag stereo-pair reader of the offline tools and benchmarks (process_bag's SLAM and induration
// modes, bench_dense, bench_frontend): pairs the left and right images of a bag by stamp (a bag may store either
// first, and the camera_info after the images) and keeps the rectifiers of the first camera_info of each side.
#pragma once

#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "skin3d/ros/conversions.h"
#include "skin3d/stereo/rectification.h"

namespace skin3d {
namespace ros_io {

class StereoPairs {
 public:
  /** @brief Takes a stereo/{left,right}/{image_raw,camera_info} message; false for any other topic.
   *  @param topic the message's relative topic name (ros_io::BagTopics::relative of its stored name) */
  bool add(const std::string& topic, const rosbag::MessageInstance& mi) {
    if (topic == "stereo/left/camera_info" || topic == "stereo/right/camera_info") {
      const bool left = topic == "stereo/left/camera_info";
      (left ? info_msg_l_ : info_msg_r_) = mi.instantiate<sensor_msgs::CameraInfo>();  // the latest, as received
      if (!(left ? rect_l_ : rect_r_)) {
        (left ? info_l_ : info_r_) = ros_conv::fromMsg(*mi.instantiate<sensor_msgs::CameraInfo>());
        (left ? rect_l_ : rect_r_) = std::make_unique<stereo::Rectifier>(left ? info_l_ : info_r_);
      }
      return true;
    }
    if (topic == "stereo/left/image_raw" || topic == "stereo/right/image_raw") {
      const auto img = mi.instantiate<sensor_msgs::Image>();
      (topic == "stereo/left/image_raw" ? pending_l_ : pending_r_)[img->header.stamp] = img;
      return true;
    }
    return false;
  }

  /** @brief The next complete pair in stamp order once both camera_infos are known; an older image without a
   *  partner is dropped. False when no pair is complete yet. */
  bool next(sensor_msgs::Image::ConstPtr* left, sensor_msgs::Image::ConstPtr* right) {
    while (calibrated() && !pending_l_.empty() && !pending_r_.empty()) {
      const ros::Time t = std::max(pending_l_.begin()->first, pending_r_.begin()->first);
      const auto li = pending_l_.find(t), ri = pending_r_.find(t);
      if (li == pending_l_.end() || ri == pending_r_.end()) {
        auto& older = pending_l_.begin()->first < t ? pending_l_ : pending_r_;
        older.erase(older.begin());
        continue;
      }
      *left = li->second;
      *right = ri->second;
      pending_l_.erase(pending_l_.begin(), std::next(li));
      pending_r_.erase(pending_r_.begin(), std::next(ri));
      return true;
    }
    return false;
  }

  bool calibrated() const { return rect_l_ && rect_r_; }
  /** @brief The latest camera_info message of each side (what a live subscriber pairs with the images). */
  const sensor_msgs::CameraInfo::ConstPtr& leftInfoMsg() const { return info_msg_l_; }
  const sensor_msgs::CameraInfo::ConstPtr& rightInfoMsg() const { return info_msg_r_; }
  bool haveLeftInfo() const { return static_cast<bool>(rect_l_); }
  const geometry::CameraInfo& leftInfo() const { return info_l_; }
  const geometry::CameraInfo& rightInfo() const { return info_r_; }
  /** @brief Rectified mono8 images of a pair (calibrated() must hold). */
  cv::Mat rectifyLeft(const sensor_msgs::Image& m) const { return (*rect_l_)(ros_conv::toMono8(m)); }
  cv::Mat rectifyRight(const sensor_msgs::Image& m) const { return (*rect_r_)(ros_conv::toMono8(m)); }

 private:
  geometry::CameraInfo info_l_, info_r_;
  std::unique_ptr<stereo::Rectifier> rect_l_, rect_r_;
  sensor_msgs::CameraInfo::ConstPtr info_msg_l_, info_msg_r_;
  std::map<ros::Time, sensor_msgs::Image::ConstPtr> pending_l_, pending_r_;
};

/** The raw stereo pairs of a bag, read into memory (benchmarks time them without the bag's I/O). */
struct RawStereoPairs {
  std::vector<std::pair<cv::Mat, cv::Mat>> pairs;  //!< left, right, mono8, in stamp order
  geometry::CameraInfo left, right;                //!< the first camera_info of each side
};

/**
 * @brief The first `max_pairs` (<= 0: all) stereo/{left,right}/image_raw pairs with equal stamps of the bag
 * (topics under `ns` as ros_io::BagTopics chooses them) as mono8 images, and the first camera_info of each side.
 * @throws std::runtime_error naming the bag and the problem: unreadable, no pair, no camera_info, or a
 * camera_info whose size differs from the images'.
 */
RawStereoPairs readRawStereoPairs(const std::string& bag_path, const std::string& ns, long max_pairs);

}  // namespace ros_io
}  // namespace skin3d
