// SPDX-License-Identifier: BSD-3-Clause
// Private helpers of the stereo calibration (calibration.cpp: corners and calibration; calibration_io.cpp:
// text parsing, preview, camera_info YAML and the report). Not installed.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "../common/text.h"
#include "skin3d/stereo/calibration.h"
#include "skin3d/stereo/rectification.h"

namespace skin3d {
namespace stereo {
namespace calib_detail {

inline constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

[[noreturn]] inline void fail(const std::string& field, const std::string& why) {
  throw CalibrationError(field, why);
}

inline std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

/** Shortest text that reads back as exactly the same double. */
inline std::string exact(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

using common::fixed;

inline std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out + "\"";
}

inline cv::Mat toGray8(const cv::Mat& image) {
  cv::Mat gray;
  if (image.channels() == 3)
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 4)
    cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  else
    gray = image;
  if (gray.depth() == CV_16U) {
    cv::Mat g8;
    gray.convertTo(g8, CV_8U, 1.0 / 256.0);
    return g8;
  }
  if (gray.depth() != CV_8U) {
    cv::Mat g8;
    cv::normalize(gray, g8, 0, 255, cv::NORM_MINMAX, CV_8U);
    return g8;
  }
  return gray;
}

inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  double med = v[m];
  if (v.size() % 2 == 0) med = 0.5 * (med + *std::max_element(v.begin(), v.begin() + m));
  return med;
}

inline cv::Mat infoK(const geometry::CameraInfo& info) {
  cv::Mat K;
  cv::eigen2cv(info.K, K);
  return K;
}

inline bool insideBoth(const RectifiedPair& p, const Eigen::Vector3d& X) {
  for (bool right : {false, true}) {
    const Eigen::Vector2d uv = projectRectified(p, X, right);
    const auto& info = right ? p.right : p.left;
    if (!uv.allFinite() || uv.x() < -0.5 || uv.y() < -0.5 || uv.x() > info.width - 0.5 || uv.y() > info.height - 0.5)
      return false;
  }
  return true;
}


}  // namespace calib_detail
}  // namespace stereo
}  // namespace skin3d
