// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file stereo_sync.h
 * @brief skin3d_ros: the four stereo topics (left image, left camera_info, right image, right camera_info)
 * synchronised, exactly or approximately, for the nodelets that take a stereo pair.
 */
#pragma once

#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <ros/node_handle.h>
#include <message_filters/simple_filter.h>
#include <ros/subscriber.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>

#include <functional>
#include <memory>
#include <string>

namespace skin3d {
namespace ros_conv {

/** @brief A fault of a stereo pair's four messages and the topic it is on. */
struct PairFault {
  std::string topic;  //!< empty: no fault
  std::string fault;
  explicit operator bool() const { return !topic.empty(); }
};

/**
 * @brief The checks every door applies to a raw stereo pair (stereo/{left,right}/image_raw + camera_info): each
 * camera_info (ros_conv::checkCameraInfo), each image against its camera_info (ros_conv::checkImage), left and
 * right sizes, distinct frame_ids, stamps at most `max_stamp_diff` s apart. @return the first fault found.
 */
PairFault checkStereoPair(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                          const sensor_msgs::Image& right, const sensor_msgs::CameraInfo& right_info,
                          double max_stamp_diff = 0.005);

/**
 * @brief ~image_transport of `pnh`: "raw" (default: sensor_msgs/Image on stereo/SIDE/image_raw) or "compressed"
 * (image_transport's compressed transport: sensor_msgs/CompressedImage, JPEG or PNG, on image_raw/compressed,
 * decoded by the node). @throws std::invalid_argument naming any other value.
 */
std::string imageTransportParam(const ros::NodeHandle& pnh);

/** @brief A message_filters source of decoded images: subscribes TOPIC/compressed and passes each CompressedImage on
 *  as a sensor_msgs/Image (ros_conv::fromCompressed); an undecodable one is logged (throttled) and skipped. */
class DecodedImages : public message_filters::SimpleFilter<sensor_msgs::Image> {
 public:
  void subscribe(ros::NodeHandle& nh, const std::string& topic, uint32_t queue_size);
  int undecodable() const { return undecodable_; }

 private:
  void onCompressed(const sensor_msgs::CompressedImage::ConstPtr& m);
  ros::Subscriber sub_;
  int undecodable_ = 0;
};

class StereoSync {
 public:
  using Callback = std::function<void(const sensor_msgs::Image::ConstPtr&, const sensor_msgs::CameraInfo::ConstPtr&,
                                      const sensor_msgs::Image::ConstPtr&, const sensor_msgs::CameraInfo::ConstPtr&)>;
  /**
   * @brief Subscribes stereo/left/`image`, stereo/left/camera_info, stereo/right/`image` and
   * stereo/right/camera_info of `nh` (or the images' compressed topics), synchronised as the private parameters
   * ~approximate_sync (false: equal stamps), ~queue_size (5) and ~image_transport (raw) of `pnh` say, and calls
   * `callback` with each set.
   * @return empty, or the problem with a parameter to log (a ~queue_size below 1 is replaced by 5, an unknown
   * ~image_transport by raw).
   */
  std::string subscribe(ros::NodeHandle& nh, const ros::NodeHandle& pnh, const std::string& image, Callback callback);
  /** @brief As above with the queue (>= 1), the policy and the transport ("raw" or "compressed", see
   *  imageTransportParam) given. Destroying the StereoSync unsubscribes. */
  void subscribe(ros::NodeHandle& nh, const std::string& image, int queue_size, bool approximate, Callback callback,
                 const std::string& transport = "raw");

 private:
  // message_filters binds a member function to the four messages (a std::function would be bound to nine)
  void onPair(const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
              const sensor_msgs::Image::ConstPtr& ri, const sensor_msgs::CameraInfo::ConstPtr& rc);
  using Exact = message_filters::sync_policies::ExactTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                          sensor_msgs::Image, sensor_msgs::CameraInfo>;
  using Approx = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                                 sensor_msgs::Image, sensor_msgs::CameraInfo>;
  message_filters::Subscriber<sensor_msgs::Image> li_, ri_;
  DecodedImages lz_, rz_;  // the compressed transport's
  message_filters::Subscriber<sensor_msgs::CameraInfo> lc_, rc_;
  std::unique_ptr<message_filters::Synchronizer<Exact>> exact_;
  std::unique_ptr<message_filters::Synchronizer<Approx>> approx_;
  Callback callback_;
};

}  // namespace ros_conv
}  // namespace skin3d
