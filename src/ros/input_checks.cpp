// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the checks of every input message (see include/skin3d/ros/input_checks.h).
#include "skin3d/ros/input_checks.h"

#include <sensor_msgs/image_encodings.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace skin3d {
namespace ros_conv {

namespace {
std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.9g", v);
  return b;
}

template <class Array>
void nonFinite(const char* name, const Array& a, std::vector<std::string>* out) {
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!std::isfinite(a[i])) out->push_back(std::string(name) + "[" + std::to_string(i) + "] = " + num(a[i]));
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

/** Bytes per pixel of an accepted encoding, 0 for the others. */
int bytesPerPixel(const std::string& e) {
  namespace enc = sensor_msgs::image_encodings;
  if (e == enc::MONO8 || e == enc::TYPE_8UC1) return 1;
  if (e == enc::MONO16 || e == enc::TYPE_16UC1) return 2;
  if (e == enc::BGR8 || e == enc::RGB8) return 3;
  if (e == enc::BGRA8 || e == enc::RGBA8) return 4;
  return 0;
}
}  // namespace

InputFault checkCameraInfo(const sensor_msgs::CameraInfo& m) {
  std::vector<std::string> bad;
  nonFinite("K", m.K, &bad);
  nonFinite("D", m.D, &bad);
  nonFinite("R", m.R, &bad);
  nonFinite("P", m.P, &bad);
  if (!bad.empty()) return {"non-finite camera_info entries", join(bad)};
  if (m.width == 0 || m.height == 0)
    return {"camera_info has no image size", std::to_string(m.width) + "x" + std::to_string(m.height)};
  if (m.K[0] == 0.0 && m.K[4] == 0.0) return {"uncalibrated camera_info", "K[0] = K[4] = 0"};
  if (!(m.K[0] > 0.0) || !(m.K[4] > 0.0))
    return {"camera_info focal length not positive", "K[0] = " + num(m.K[0]) + ", K[4] = " + num(m.K[4])};
  if (m.K[3] != 0.0 || m.K[6] != 0.0 || m.K[7] != 0.0 || std::abs(m.K[8] - 1.0) > 1e-9)
    return {"camera_info K is not an intrinsic matrix",
            "K[3], K[6], K[7], K[8] = " + num(m.K[3]) + ", " + num(m.K[6]) + ", " + num(m.K[7]) + ", " + num(m.K[8]) +
                " (0, 0, 0, 1 expected)"};
  if (m.P[0] == 0.0 && m.P[5] == 0.0) return {"camera_info has no projection matrix", "P[0] = P[5] = 0"};
  if (!(m.P[0] > 0.0) || !(m.P[5] > 0.0))
    return {"camera_info projection focal length not positive", "P[0] = " + num(m.P[0]) + ", P[5] = " + num(m.P[5])};
  if (m.P[4] != 0.0 || m.P[8] != 0.0 || m.P[9] != 0.0 || std::abs(m.P[10] - 1.0) > 1e-9)
    return {"camera_info P is not a projection matrix",
            "P[4], P[8], P[9], P[10] = " + num(m.P[4]) + ", " + num(m.P[8]) + ", " + num(m.P[9]) + ", " + num(m.P[10]) +
                " (0, 0, 0, 1 expected)"};
  Eigen::Matrix3d R;
  for (int i = 0; i < 9; ++i) R(i / 3, i % 3) = m.R[i];
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), det = R.determinant();
  if (orth > 1e-6 || std::abs(det - 1.0) > 1e-6)
    return {"camera_info R is not a rotation", "max |R^T R - I| = " + num(orth) + ", det R = " + num(det)};
  const std::string& dm = m.distortion_model;
  const std::size_t n = m.D.size();
  if (dm == "plumb_bob") {
    if (n != 0 && n != 4 && n != 5)
      return {"camera_info D does not fit its distortion_model", "plumb_bob with " + std::to_string(n) + " coefficients (5 expected)"};
  } else if (dm == "rational_polynomial") {
    if (n != 8)
      return {"camera_info D does not fit its distortion_model",
              "rational_polynomial with " + std::to_string(n) + " coefficients (8 expected)"};
  } else if (!(dm.empty() && n == 0)) {
    return {"unsupported distortion_model", "'" + dm + "' (plumb_bob or rational_polynomial expected)"};
  }
  return {};
}

InputFault checkImu(const sensor_msgs::Imu& m) {
  const auto& w = m.angular_velocity;
  std::vector<std::string> bad;
  if (!std::isfinite(w.x)) bad.push_back("x = " + num(w.x));
  if (!std::isfinite(w.y)) bad.push_back("y = " + num(w.y));
  if (!std::isfinite(w.z)) bad.push_back("z = " + num(w.z));
  if (!bad.empty()) return {"non-finite angular velocity", join(bad)};
  nonFinite("angular_velocity_covariance", m.angular_velocity_covariance, &bad);
  if (!bad.empty()) return {"non-finite angular velocity covariance", join(bad)};
  const Eigen::Matrix3d C = gyroCovariance(m);
  if (C.isZero(0.0)) return {};  // unknown: the configured gyro_noise
  const double asym = (C - C.transpose()).cwiseAbs().maxCoeff();
  if (asym > 1e-9 * C.cwiseAbs().maxCoeff())
    return {"angular velocity covariance not symmetric", "max |C - C^T| = " + num(asym)};
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(C, Eigen::EigenvaluesOnly).eigenvalues();
  Eigen::LLT<Eigen::Matrix3d> llt(C);  // what the filter needs (slam::SlamSystem::addGyro)
  if (!(ev.minCoeff() > 0.0) || llt.info() != Eigen::Success)
    return {"angular velocity covariance not positive definite",
            "eigenvalues " + num(ev[0]) + ", " + num(ev[1]) + ", " + num(ev[2]) + " (rad/s)^2"};
  return {};
}

Eigen::Matrix3d gyroCovariance(const sensor_msgs::Imu& m) {
  Eigen::Matrix3d C;
  for (int i = 0; i < 9; ++i) C(i / 3, i % 3) = m.angular_velocity_covariance[i];
  if (C(0, 0) == -1.0) C.setZero();  // REP 145: -1 = not known
  return C;
}

const std::vector<std::string>& acceptedImageEncodings() {
  static const std::vector<std::string> e = {"mono8", "8UC1", "mono16", "16UC1", "bgr8", "rgb8", "bgra8", "rgba8"};
  return e;
}

InputFault checkImage(const sensor_msgs::Image& img, const sensor_msgs::CameraInfo* info, FrameIdCheck frame_id) {
  if (img.width == 0 || img.height == 0 || img.data.empty())
    return {"empty image", std::to_string(img.width) + "x" + std::to_string(img.height) + ", " +
                               std::to_string(img.data.size()) + " bytes"};
  const int bpp = bytesPerPixel(img.encoding);
  if (bpp == 0) {
    std::string list;
    for (const auto& e : acceptedImageEncodings()) list += (list.empty() ? "" : ", ") + e;
    return {"unsupported encoding", "'" + img.encoding + "'; accepted: " + list};
  }
  if (static_cast<std::size_t>(img.step) < static_cast<std::size_t>(img.width) * bpp)
    return {"image step smaller than a row",
            "step " + std::to_string(img.step) + " < " + std::to_string(img.width) + " x " + std::to_string(bpp) + " bytes"};
  if (static_cast<std::size_t>(img.step) * img.height > img.data.size())
    return {"image data shorter than step x height",
            std::to_string(img.data.size()) + " bytes < " + std::to_string(img.step) + " x " + std::to_string(img.height)};
  if (info && (img.width != info->width || img.height != info->height))
    return {"image size differs from its camera_info's",
            "image " + std::to_string(img.width) + "x" + std::to_string(img.height) + ", camera_info " +
                std::to_string(info->width) + "x" + std::to_string(info->height)};
  if (info && frame_id == FrameIdCheck::kCompare && !info->header.frame_id.empty() && !img.header.frame_id.empty() &&
      img.header.frame_id != info->header.frame_id)
    return {"image frame_id differs from its camera_info's",
            "'" + img.header.frame_id + "' vs '" + info->header.frame_id + "'"};
  return {};
}

InputFault checkStamp(const ros::Time& t, const ros::Time& previous) {
  if (t.isZero()) return {"zero stamp"};
  if (previous.isZero()) return {};
  if (t == previous) return {"duplicate stamp", "same as the previous message's"};
  if (t < previous) {
    char b[96];
    std::snprintf(b, sizeof b, "%.9f s before the previous message's %.9f", (previous - t).toSec(), previous.toSec());
    return {"stamp goes backwards", b};
  }
  return {};
}

}  // namespace ros_conv
}  // namespace skin3d
