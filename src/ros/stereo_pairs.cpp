// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: a bag's raw stereo pairs read into memory (see include/skin3d/ros/stereo_pairs.h).
#include "skin3d/ros/stereo_pairs.h"

#include <rosbag/bag.h>

#include <stdexcept>

#include "skin3d/ros/runner.h"

#include "skin3d/ros/bag_topics.h"

namespace skin3d {
namespace ros_io {

StereoPairs::StereoPairs(std::string left_image, std::string right_image, std::string left_info, std::string right_info)
    : topic_l_(std::move(left_image)),
      topic_r_(std::move(right_image)),
      info_topic_l_(std::move(left_info)),
      info_topic_r_(std::move(right_info)) {}

void StereoPairs::setLedger(ros_run::InputLedger* ledger) {
  if (!ledger) {
    on_drop_ = nullptr;
    return;
  }
  on_drop_ = [ledger](const std::string& topic, double stamp, const std::string& fault, const std::string& detail) {
    ledger->drop(topic, stamp, fault, detail);
  };
}

void StereoPairs::drop(const std::string& topic, const ros::Time& stamp, const std::string& fault,
                       const std::string& detail) {
  ++dropped_;
  last_fault_ = topic + ": " + fault + (detail.empty() ? "" : " (" + detail + ")");
  if (on_drop_) on_drop_(topic, stamp.toSec(), fault, detail);
}

bool StereoPairs::add(const std::string& topic, const rosbag::MessageInstance& mi) {
  const bool left_info = topic == info_topic_l_, right_info = topic == info_topic_r_;
  if (left_info || right_info) {
    const auto m = mi.instantiate<sensor_msgs::CameraInfo>();
    if (!m) {
      drop(topic, mi.getTime(), "not a sensor_msgs/CameraInfo", mi.getDataType());
      return true;
    }
    (left_info ? latest_info_l_ : latest_info_r_) = m;
    addCameraInfo(left_info, *m);
    return true;
  }
  const bool left_image = topic == topic_l_ || topic == topic_l_ + "/compressed";
  const bool right_image = topic == topic_r_ || topic == topic_r_ + "/compressed";
  if (left_image || right_image) {
    if (const auto m = mi.instantiate<sensor_msgs::Image>()) {
      addImage(left_image, m);
      return true;
    }
    // image_transport's compressed transport (JPEG, PNG): decoded here, then checked as a raw image
    const auto c = mi.instantiate<sensor_msgs::CompressedImage>();
    if (!c) {
      drop(topic, mi.getTime(), "not a sensor_msgs/Image or CompressedImage", mi.getDataType());
      return true;
    }
    try {
      addImage(left_image, ros_conv::fromCompressed(*c));
    } catch (const std::exception& e) {
      drop(topic, c->header.stamp, "compressed image not decodable", e.what());
    }
    return true;
  }
  return false;
}

void StereoPairs::addCameraInfo(bool left, const sensor_msgs::CameraInfo& m) {
  const std::string& topic = left ? info_topic_l_ : info_topic_r_;
  if (const ros_conv::InputFault f = ros_conv::checkCameraInfo(m)) {
    drop(topic, m.header.stamp, f.fault, f.detail);
    return;
  }
  std::unique_ptr<stereo::Rectifier>& rect = left ? rect_l_ : rect_r_;
  if (rect) return;  // the first usable one is kept
  try {
    geometry::CameraInfo c = ros_conv::fromMsg(m);
    rect = std::make_unique<stereo::Rectifier>(c);
    (left ? info_l_ : info_r_) = std::move(c);
    (left ? info_msg_l_ : info_msg_r_) = m;
  } catch (const std::exception& e) {
    rect.reset();
    drop(topic, m.header.stamp, "camera_info unusable for rectification", e.what());
  }
}

void StereoPairs::addImage(bool left, const sensor_msgs::Image::ConstPtr& img) {
  const std::string& topic = left ? topic_l_ : topic_r_;
  if (const ros_conv::InputFault f = (left ? order_l_ : order_r_).admit(img->header.stamp)) {
    drop(topic, img->header.stamp, f.fault, f.detail);
    return;
  }
  if (const ros_conv::InputFault f = ros_conv::checkImage(*img)) {
    drop(topic, img->header.stamp, f.fault, f.detail);
    return;
  }
  (left ? pending_l_ : pending_r_)[img->header.stamp] = img;
}

bool StereoPairs::next(sensor_msgs::Image::ConstPtr* left, sensor_msgs::Image::ConstPtr* right) {
  while (calibrated() && !pending_l_.empty() && !pending_r_.empty()) {
    const auto li = pending_l_.begin(), ri = pending_r_.begin();
    if (li->first < ri->first) {  // the right image of this stamp never came (the right stream is past it)
      ++unpaired_l_;
      drop(topic_l_, li->first, "no right image with this stamp");
      pending_l_.erase(li);
      continue;
    }
    if (ri->first < li->first) {
      ++unpaired_r_;
      drop(topic_r_, ri->first, "no left image with this stamp");
      pending_r_.erase(ri);
      continue;
    }
    const auto fl = ros_conv::checkImage(*li->second, &info_msg_l_, ros_conv::FrameIdCheck::kIgnore);
    const auto fr = ros_conv::checkImage(*ri->second, &info_msg_r_, ros_conv::FrameIdCheck::kIgnore);
    if (fl || fr) {
      if (fl) drop(topic_l_, li->first, fl.fault, fl.detail);
      else drop(topic_l_, li->first, "no usable right image with this stamp");
      if (fr) drop(topic_r_, ri->first, fr.fault, fr.detail);
      else drop(topic_r_, ri->first, "no usable left image with this stamp");
      pending_l_.erase(li);
      pending_r_.erase(ri);
      continue;
    }
    *left = li->second;
    *right = ri->second;
    pending_l_.erase(li);
    pending_r_.erase(ri);
    return true;
  }
  return false;
}

void StereoPairs::flush() {
  const bool cal = calibrated();
  for (int side = 0; side < 2; ++side) {
    Queue& q = side == 0 ? pending_l_ : pending_r_;
    const bool has_info = side == 0 ? static_cast<bool>(rect_l_) : static_cast<bool>(rect_r_);
    for (const auto& kv : q) {
      if (!has_info)
        drop(side == 0 ? topic_l_ : topic_r_, kv.first, "no usable camera_info for this camera");
      else if (!cal)
        drop(side == 0 ? topic_l_ : topic_r_, kv.first, "no usable camera_info for the other camera");
      else {
        ++(side == 0 ? unpaired_l_ : unpaired_r_);
        drop(side == 0 ? topic_l_ : topic_r_, kv.first, side == 0 ? "no right image with this stamp" : "no left image with this stamp");
      }
    }
    q.clear();
  }
}

std::vector<std::string> stereoTopicsWanted() {
  return {"stereo/left/image_raw", "stereo/right/image_raw", "stereo/left/image_raw/compressed",
          "stereo/right/image_raw/compressed", "stereo/left/camera_info", "stereo/right/camera_info"};
}

std::string stereoImageTopic(const BagTopics& topics, bool left) {
  const std::string raw = left ? "stereo/left/image_raw" : "stereo/right/image_raw";
  if (topics.has(raw)) return raw;
  return topics.has(raw + "/compressed") ? raw + "/compressed" : std::string();
}

std::vector<std::string> stereoTopicsRead(const BagTopics& topics, const std::vector<std::string>& others) {
  std::vector<std::string> relative = {"stereo/left/camera_info", "stereo/right/camera_info"};
  for (const bool left : {true, false})
    if (!stereoImageTopic(topics, left).empty()) relative.push_back(stereoImageTopic(topics, left));
  relative.insert(relative.end(), others.begin(), others.end());
  std::vector<std::string> stored;
  for (const auto& r : relative)
    for (const auto& s : topics.stored(r)) stored.push_back(s);
  return stored;
}

RawStereoPairs readRawStereoPairs(const std::string& bag_path, const std::string& ns, long max_pairs) {
  RawStereoPairs out;
  StereoPairs in;
  try {
    rosbag::Bag bag;
    openForReading(&bag, bag_path);
    const BagTopics topics(bag, bag_path,
                           stereoTopicsWanted(), ns);
    rosbag::View view(bag, rosbag::TopicQuery(stereoTopicsRead(topics)));
    auto full = [&] { return max_pairs > 0 && static_cast<long>(out.pairs.size()) >= max_pairs; };
    for (const rosbag::MessageInstance& m : view) {
      if (full()) break;
      in.add(topics.relative(m.getTopic()), m);
      sensor_msgs::Image::ConstPtr l, r;
      while (!full() && in.next(&l, &r)) out.pairs.emplace_back(ros_conv::toMono8(*l), ros_conv::toMono8(*r));
    }
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot read " + bag_path + ": " + e.what());
  }
  if (out.pairs.empty() || !in.calibrated())
    throw std::runtime_error(bag_path + " has no stereo/{left,right}/image_raw pairs with equal stamps or no "
                             "usable stereo/{left,right}/camera_info" +
                             (in.lastFault().empty() ? std::string() : " (last dropped: " + in.lastFault() + ")"));
  out.left = in.leftInfo();
  out.right = in.rightInfo();
  const cv::Size size = out.pairs.front().first.size();
  if (out.left.width != size.width || out.left.height != size.height)
    throw std::runtime_error("camera_info size " + std::to_string(out.left.width) + "x" + std::to_string(out.left.height) +
                             " differs from the images' " + std::to_string(size.width) + "x" + std::to_string(size.height));
  return out;
}

}  // namespace ros_io
}  // namespace skin3d
