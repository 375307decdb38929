// SPDX-License-Identifier: BSD-3-Clause
// ROS <-> core conversions and input checks shared by the skin3d nodelets (ROS side only).
#pragma once

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <skin3d/Landmark.h>
#include <skin3d/LandmarkArray.h>

#include <Eigen/Core>
#include <vector>

#include <string>

#include "skin3d/geometry/camera.h"
#include "skin3d/slam/slam_system.h"

namespace skin3d {
namespace ros_conv {

inline geometry::CameraInfo fromMsg(const sensor_msgs::CameraInfo& m) {
  geometry::CameraInfo c;
  c.width = static_cast<int>(m.width);
  c.height = static_cast<int>(m.height);
  c.distortion_model = m.distortion_model;
  c.D = m.D;
  for (int i = 0; i < 9; ++i) c.K(i / 3, i % 3) = m.K[i];
  for (int i = 0; i < 9; ++i) c.R(i / 3, i % 3) = m.R[i];
  for (int i = 0; i < 12; ++i) c.P(i / 4, i % 4) = m.P[i];
  return c;
}

/** @brief The SLAM's measurements of one LandmarkArray (no checks: the SLAM drops bad ones and counts them). */
inline std::vector<slam::Measurement> fromMsg(const skin3d::LandmarkArray& a) {
  std::vector<slam::Measurement> out;
  out.reserve(a.landmarks.size());
  for (const auto& l : a.landmarks) {
    slam::Measurement m;
    m.z = Eigen::Vector3d(l.position.x, l.position.y, l.position.z);
    for (int i = 0; i < 9; ++i) m.C(i / 3, i % 3) = l.covariance[i];
    m.descriptor = l.descriptor;
    m.strength = l.strength;
    out.push_back(std::move(m));
  }
  return out;
}

/** @brief One landmark message: position (m), row-major 3x3 covariance (m^2), descriptor, strength, pixels. */
inline skin3d::Landmark toLandmarkMsg(const Eigen::Vector3d& position, const Eigen::Matrix3d& covariance,
                                      const std::vector<float>& descriptor, float strength,
                                      const Eigen::Vector2d& uv_left, const Eigen::Vector2d& uv_right) {
  skin3d::Landmark m;
  m.position.x = position.x();
  m.position.y = position.y();
  m.position.z = position.z();
  for (int i = 0; i < 9; ++i) m.covariance[i] = covariance(i / 3, i % 3);
  m.descriptor = descriptor;
  m.strength = strength;
  m.u_left = uv_left.x();
  m.v_left = uv_left.y();
  m.u_right = uv_right.x();
  m.v_right = uv_right.y();
  return m;
}

/** @brief Empty when the camera_info is usable for rectification, else what is wrong with it. */
inline std::string checkCameraInfo(const sensor_msgs::CameraInfo& m, const std::string& topic) {
  if (m.K[0] == 0.0) return topic + ": uncalibrated camera_info (K[0] = 0)";
  if (m.P[0] == 0.0) return topic + ": camera_info has no projection matrix (P[0] = 0)";
  if (m.width == 0 || m.height == 0) return topic + ": camera_info has no image size";
  if (!m.D.empty() && m.distortion_model != "plumb_bob" && m.distortion_model != "rational_polynomial")
    return topic + ": unsupported distortion_model '" + m.distortion_model + "' (plumb_bob expected)";
  return "";
}

/** @brief Empty when the image can be used, else what is wrong with it (names the topic). */
inline std::string checkImage(const sensor_msgs::Image& img, const sensor_msgs::CameraInfo* info, const std::string& topic) {
  namespace enc = sensor_msgs::image_encodings;
  if (img.width == 0 || img.height == 0 || img.data.empty()) return topic + ": empty image";
  if (img.encoding != enc::MONO8 && img.encoding != enc::BGR8 && img.encoding != enc::RGB8 &&
      img.encoding != enc::MONO16 && img.encoding != enc::BGRA8 && img.encoding != enc::RGBA8)
    return topic + ": unsupported encoding '" + img.encoding + "' (mono8, mono16, bgr8, rgb8, bgra8, rgba8)";
  if (img.step * img.height > img.data.size()) return topic + ": image data shorter than step x height";
  if (info && (img.width != info->width || img.height != info->height))
    return topic + ": image is " + std::to_string(img.width) + "x" + std::to_string(img.height) +
           " but its camera_info says " + std::to_string(info->width) + "x" + std::to_string(info->height);
  if (info && !info->header.frame_id.empty() && img.header.frame_id != info->header.frame_id)
    return topic + ": image frame_id '" + img.header.frame_id + "' differs from its camera_info's '" +
           info->header.frame_id + "'";
  return "";
}

/** @brief 8-bit grayscale view of a checked image (throws cv_bridge::Exception on conversion failure). */
inline cv::Mat toMono8(const sensor_msgs::Image& img) {
  namespace enc = sensor_msgs::image_encodings;
  if (img.encoding == enc::MONO16) {
    cv::Mat m16 = cv_bridge::toCvCopy(img, enc::MONO16)->image, m8;
    m16.convertTo(m8, CV_8U, 1.0 / 256.0);
    return m8;
  }
  return cv_bridge::toCvCopy(img, enc::MONO8)->image;
}

}  // namespace ros_conv
}  // namespace skin3d
