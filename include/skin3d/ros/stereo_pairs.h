// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the bag stereo-pair reader of the offline tools and benchmarks (process_bag's SLAM and induration
// modes, bench_dense, bench_frontend): pairs the left and right images of a bag by stamp (a bag may store either
// first, and the camera_info after the images) and keeps the rectifiers of the first camera_info of each side.
#pragma once

#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "skin3d/ros/conversions.h"
#include "skin3d/ros/input_checks.h"
#include "skin3d/stereo/rectification.h"

namespace skin3d {
namespace ros_run {
class InputLedger;
}
namespace ros_io {

/**
 * @brief Pairs the left and right images of a stream by stamp and keeps the rectifiers of the first usable
 * camera_info of each side; every message it cannot use is handed to the drop handler (the runner's InputLedger)
 * with its topic, stamp and fault (input_checks.h), never dropped silently:
 *  - a camera_info that fails checkCameraInfo, or that cannot build a rectifier (later good ones are not compared);
 *  - an image with a zero, duplicate or backwards stamp (per topic) or that fails checkImage (encoding, size, data);
 *  - at pairing, an image whose size differs from its camera_info's, and then its partner ("no usable left image
 *    with this stamp" / "... right ...");
 *  - an image whose partner never came: the older head of one queue once the other side has a later image
 *    ("no right image with this stamp" on the left topic, "no left image with this stamp" on the right one);
 *  - at flush() (the end of the input), every image still waiting: unpaired, or "no usable camera_info" when
 *    its side never got one.
 * Images are checked before they are converted, so rectifyLeft/Right of a pair from next() do not throw for
 * input reasons.
 */
class StereoPairs {
 public:
  /** @brief Same arguments as ros_run::InputLedger::drop (topic, stamp in s, fault, detail). */
  using DropHandler = std::function<void(const std::string& topic, double stamp, const std::string& fault,
                                         const std::string& detail)>;
  /** @param left_image,right_image,left_info,right_info the relative topic names used in drops (and by add()) */
  explicit StereoPairs(std::string left_image = "stereo/left/image_raw", std::string right_image = "stereo/right/image_raw",
                       std::string left_info = "stereo/left/camera_info", std::string right_info = "stereo/right/camera_info");

  /** @brief Where drops go (default: only counted here). */
  void setDropHandler(DropHandler h) { on_drop_ = std::move(h); }
  /** @brief Drops go to `ledger` (must outlive this object; nullptr: only counted here). */
  void setLedger(ros_run::InputLedger* ledger);

  /** @brief Takes a message of one of the four topics (instantiated here); false for any other topic.
   *  @param topic the message's relative topic name (ros_io::BagTopics::relative of its stored name) */
  bool add(const std::string& topic, const rosbag::MessageInstance& mi);
  /** @brief One camera_info of the left (or right) camera: checked; the first usable one of each side is kept. */
  void addCameraInfo(bool left, const sensor_msgs::CameraInfo& m);
  /** @brief One raw image of the left (or right) camera: stamp and image checked, then queued for pairing. */
  void addImage(bool left, const sensor_msgs::Image::ConstPtr& img);

  /** @brief The next complete pair in stamp order once both camera_infos are known (images without a partner and
   *  images that do not fit their camera_info are dropped on the way). False when no pair is complete yet. */
  bool next(sensor_msgs::Image::ConstPtr* left, sensor_msgs::Image::ConstPtr* right);
  /** @brief The end of the input: drops every image still waiting (call it when the whole input was read, not
   *  when a --frames limit stopped the reading: the images after the limit are not faults). */
  void flush();

  bool calibrated() const { return rect_l_ && rect_r_; }
  /** @brief The latest camera_info message of each side (what a live subscriber pairs with the images). */
  /** @brief The latest camera_info message of each side as received (checked or not: what a live subscriber pairs
   *  with the images; the runners check it again, as they do live). Null before the first one. */
  const sensor_msgs::CameraInfo::ConstPtr& leftInfoMsg() const { return latest_info_l_; }
  const sensor_msgs::CameraInfo::ConstPtr& rightInfoMsg() const { return latest_info_r_; }
  bool haveLeftInfo() const { return static_cast<bool>(rect_l_); }
  const geometry::CameraInfo& leftInfo() const { return info_l_; }
  const geometry::CameraInfo& rightInfo() const { return info_r_; }
  /** @brief Rectified mono8 images of a pair (calibrated() must hold). */
  cv::Mat rectifyLeft(const sensor_msgs::Image& m) const { return (*rect_l_)(ros_conv::toMono8(m)); }
  cv::Mat rectifyRight(const sensor_msgs::Image& m) const { return (*rect_r_)(ros_conv::toMono8(m)); }

  /** @brief Left images dropped because no right image with their stamp came (and vice versa). */
  int unpairedLeft() const { return unpaired_l_; }
  int unpairedRight() const { return unpaired_r_; }
  /** @brief Every message dropped here (unpaired ones included). */
  int dropped() const { return dropped_; }
  /** @brief The last fault of each kind, for an error when nothing could be paired ("" when none). */
  const std::string& lastFault() const { return last_fault_; }

 private:
  void drop(const std::string& topic, const ros::Time& stamp, const std::string& fault, const std::string& detail = "");
  using Queue = std::map<ros::Time, sensor_msgs::Image::ConstPtr>;
  std::string topic_l_, topic_r_, info_topic_l_, info_topic_r_;
  DropHandler on_drop_;
  geometry::CameraInfo info_l_, info_r_;
  sensor_msgs::CameraInfo info_msg_l_, info_msg_r_;
  sensor_msgs::CameraInfo::ConstPtr latest_info_l_, latest_info_r_;
  std::unique_ptr<stereo::Rectifier> rect_l_, rect_r_;
  Queue pending_l_, pending_r_;
  ros_conv::StampOrder order_l_, order_r_;
  int unpaired_l_ = 0, unpaired_r_ = 0, dropped_ = 0;
  std::string last_fault_;
};

class BagTopics;

/** @brief The relative names a bag's stereo pairs may be stored under: stereo/{left,right}/image_raw, their
 *  image_transport "compressed" topics (image_raw/compressed: JPEG or PNG CompressedImage) and the camera_infos. */
std::vector<std::string> stereoTopicsWanted();
/** @brief The image topic of one camera in a bag: image_raw when stored, else image_raw/compressed, else "". */
std::string stereoImageTopic(const BagTopics& topics, bool left);
/** @brief The stored names to read for the stereo pairs (each camera's image topic as stereoImageTopic chooses it,
 *  the camera_infos) and for the `others` relative names: a bag with both transports is read raw. */
std::vector<std::string> stereoTopicsRead(const BagTopics& topics, const std::vector<std::string>& others = {});

/** The raw stereo pairs of a bag, read into memory (benchmarks time them without the bag's I/O). */
struct RawStereoPairs {
  std::vector<std::pair<cv::Mat, cv::Mat>> pairs;  //!< left, right, mono8, in stamp order
  geometry::CameraInfo left, right;                //!< the first camera_info of each side
};

/**
 * @brief The first `max_pairs` (<= 0: all) stereo/{left,right}/image_raw (or image_raw/compressed) pairs with equal stamps of the bag
 * (topics under `ns` as ros_io::BagTopics chooses them) as mono8 images, and the first camera_info of each side.
 * @throws std::runtime_error naming the bag and the problem: unreadable, no pair, no camera_info, or a
 * camera_info whose size differs from the images'.
 */
RawStereoPairs readRawStereoPairs(const std::string& bag_path, const std::string& ns, long max_pairs);

}  // namespace ros_io
}  // namespace skin3d
