// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: a bag's raw stereo pairs read into memory (see include/skin3d/ros/stereo_pairs.h).
#include "skin3d/ros/stereo_pairs.h"

#include <rosbag/bag.h>

#include <stdexcept>

#include "skin3d/ros/bag_topics.h"

namespace skin3d {
namespace ros_io {

RawStereoPairs readRawStereoPairs(const std::string& bag_path, const std::string& ns, long max_pairs) {
  RawStereoPairs out;
  StereoPairs in;
  try {
    rosbag::Bag bag;
    openForReading(&bag, bag_path);
    const BagTopics topics(bag, bag_path,
                           {"stereo/left/image_raw", "stereo/right/image_raw", "stereo/left/camera_info",
                            "stereo/right/camera_info"},
                           ns);
    rosbag::View view(bag, rosbag::TopicQuery(topics.stored()));
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
                             "stereo/{left,right}/camera_info");
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
