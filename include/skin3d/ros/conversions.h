// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file conversions.h
 * @brief skin3d_ros: ROS message <-> core struct conversions, input checks and the option loader shared by the
 * nodelets and the tools (the ROS side only; the core never includes this).
 */
#pragma once

#include <geometry_msgs/Pose.h>
#include <ros/node_handle.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <skin3d/IndurationReport.h>
#include <skin3d/Landmark.h>
#include <skin3d/LandmarkArray.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "skin3d/geometry/camera.h"
#include "skin3d/induration/induration.h"
#include "skin3d/induration/induration_config.h"
#include "skin3d/ros/input_checks.h"
#include "skin3d/slam/slam_system.h"
#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {
namespace ros_conv {

/** @brief A position and a rotation as a geometry_msgs/Pose. */
geometry_msgs::Pose toPoseMsg(const Eigen::Vector3d& p, const Eigen::Quaterniond& q);

/** @brief A camera_info message as the core's CameraInfo (the inverse of toMsg). */
geometry::CameraInfo fromMsg(const sensor_msgs::CameraInfo& m);

/** @brief The core's CameraInfo as a plumb_bob camera_info message (D padded to 5) in `frame`, stamped `t`. */
sensor_msgs::CameraInfo toMsg(const geometry::CameraInfo& c, const std::string& frame, const ros::Time& t);

/** @brief The SLAM's measurements of one LandmarkArray (no checks: the SLAM drops bad ones and counts them). */
std::vector<slam::Measurement> fromMsg(const skin3d::LandmarkArray& a);

/** @brief One landmark message: position (m), row-major 3x3 covariance (m^2), descriptor, strength, pixels. */
skin3d::Landmark toLandmarkMsg(const Eigen::Vector3d& position, const Eigen::Matrix3d& covariance,
                               const std::vector<float>& descriptor, float strength,
                               const Eigen::Vector2d& uv_left, const Eigen::Vector2d& uv_right);

/** @brief Empty when the camera_info is usable for rectification, else "TOPIC: fault (detail)" of
 *  checkCameraInfo(m) (input_checks.h; a runner drops through its InputLedger with that one instead). */
std::string checkCameraInfo(const sensor_msgs::CameraInfo& m, const std::string& topic);

/** @brief Empty when the image can be used, else "TOPIC: fault (detail)" of checkImage(img, info) (input_checks.h). */
std::string checkImage(const sensor_msgs::Image& img, const sensor_msgs::CameraInfo* info, const std::string& topic);

/** @brief 8-bit grayscale copy of an image that passed checkImage: mono8 and 8UC1 as they are, mono16 and 16UC1
 *  scaled by 1/256 (either byte order), colour encodings through cv_bridge.
 *  @throws std::invalid_argument (single-channel encodings) or cv_bridge::Exception when the image is not usable. */
cv::Mat toMono8(const sensor_msgs::Image& img);

/**
 * @brief A sensor_msgs/CompressedImage (image_transport's "compressed": JPEG or PNG) decoded into an Image with the
 * same header: mono8, bgr8, bgra8 or mono16 as the data holds (the format string is not needed; compressed_image_
 * transport's "rgb8; jpeg compressed bgr8" and plain "jpeg" / "png" both decode).
 * @throws std::invalid_argument naming the format and size when the data is empty or cannot be decoded.
 */
sensor_msgs::ImagePtr fromCompressed(const sensor_msgs::CompressedImage& m);

/** @brief The image as a CompressedImage: "jpeg" with `jpeg_quality` 1 ... 100, or "png" when it is 0. */
sensor_msgs::CompressedImage toCompressed(const sensor_msgs::Image& img, int jpeg_quality);

/** @brief An 8-bit single-channel image as a mono8 message (copied row by row) in `frame`, stamped `t`. */
sensor_msgs::Image toMono8Msg(const cv::Mat& mono8, const std::string& frame, const ros::Time& t);

// ------------------------------------------------------------------ dense stereo and induration

/** @brief A ROS parameter as the text the core's option tables parse (numbers in full precision, booleans
 *  true/false, lists space-separated); false for maps and other types. */
bool xmlRpcToText(XmlRpc::XmlRpcValue& v, std::string* text);

/**
 * @brief Every key of `keys` that is set as a private parameter, as text through `set` (a core option table's
 * setter). A key that is not a value or a list of values, or that `set` rejects, keeps its value (`get`) and is
 * reported in `errors`, one line naming the key. The one loader of every nodelet's option table.
 */
void loadOptionParams(const ros::NodeHandle& pnh, const std::vector<std::string>& keys,
                      const std::function<void(const std::string&, const std::string&)>& set,
                      const std::function<std::string(const std::string&)>& get, std::vector<std::string>* errors);

/**
 * @brief The dense stereo / induration options (induration/induration_config.h) from private parameters:
 * first the YAML file named by ~config (if set), then every key of pipelineOptionKeys() that is set as a
 * parameter, then validation. Problems go to `errors` (one line each, naming the key); a bad key keeps the
 * value it had, options that do not validate are reset to the defaults (the last error says so).
 */
induration::PipelineOptions loadPipelineOptions(const ros::NodeHandle& pnh, std::vector<std::string>* errors);

/** @brief Byte layout of the clouds that toCloudMsg writes (all float32). */
enum DenseCloudField { kX = 0, kY, kZ, kRgb, kSigma, kRayX, kRayY, kRayZ, kDenseCloudFields };

/**
 * @brief An organised PointCloud2 of a dense cloud (size of the image): fields x y z (m; NaN unknown,
 * is_dense false), rgb (packed float, from `colour`: grey or BGR 8-bit of the same size, white when empty),
 * sigma (m, 1 sigma along the ray; NaN unknown) and ray_x ray_y ray_z (unit viewing ray of every pixel, known
 * or not: what the induration needs to measure areas over holes).
 */
sensor_msgs::PointCloud2Ptr toCloudMsg(const stereo::DenseCloud& cloud, const cv::Mat& colour,
                                       const std_msgs::Header& header);

/**
 * @brief The dense cloud of an organised PointCloud2 (fields x y z float32 required; sigma, ray_x/y/z and rgb
 * used when present). Without `sigma`, sigma is 0 (unknown) at every known point; without rays, the ray of
 * a known point is its unit direction from the origin (the left camera centre), NaN elsewhere. `colour`
 * (optional) gets the rgb field as 8-bit BGR (empty without one).
 * @return empty on success, else what is wrong with the message (names the topic).
 */
std::string fromCloudMsg(const sensor_msgs::PointCloud2& pc, const std::string& topic,
                         stereo::DenseCloud* cloud, cv::Mat* colour);

/** @brief The report message of one measurement (SI units, frame of `header`). */
skin3d::IndurationReport toReportMsg(const induration::IndurationResult& r, const std_msgs::Header& header);

}  // namespace ros_conv
}  // namespace skin3d
