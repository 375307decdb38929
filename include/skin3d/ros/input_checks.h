// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file input_checks.h
 * @brief skin3d_ros: the checks of every input message, the same for every door (nodelets live, process_bag and
 * the benchmarks offline).
 *
 * Rule of every door: a bad message is dropped through the runner's ros_run::InputLedger (which logs it,
 * throttled, with the topic and the stamp, and counts it for the results), a bad configuration is refused at
 * start by name, and the good frames' results are always written. These functions only say what is wrong with one
 * message; they do not log, throw or count. Their fault names neither the topic nor the stamp: the ledger adds
 * both. A runner drops a faulty message with
 *
 *     if (const auto f = ros_conv::checkImu(*msg)) ledger.drop("imu/data", msg->header.stamp.toSec(), f.fault, f.detail);
 *
 * What is accepted:
 *  - camera_info: width and height > 0; every entry of K, D, R, P finite; K = [fx s cx; 0 fy cy; 0 0 1] with
 *    fx, fy > 0; R a rotation (orthonormal within 1e-6, det +1); P = [fx' s' cx' Tx; 0 fy' cy' Ty; 0 0 1 Tz] with
 *    fx', fy' > 0; distortion_model plumb_bob (D of 0, 4 or 5), rational_polynomial (D of 8) or, without D, empty;
 *  - images: encodings mono8, 8UC1 (taken as mono8), mono16, 16UC1 (taken as mono16; both scaled by 1/256 to
 *    8 bits), bgr8, rgb8, bgra8, rgba8; non-empty; step >= width x bytes per pixel; data >= step x height; the
 *    size of the camera_info of the same camera (when given) and its frame_id (when both are set);
 *  - imu/data: only what the SLAM reads, the angular velocity and its covariance (orientation and linear
 *    acceleration are not used and not checked): angular velocity finite; covariance unknown
 *    (angular_velocity_covariance[0] = -1, or all zero: the configured gyro_noise is used), else finite,
 *    symmetric and positive definite (a singular covariance would give the filter an infinite weight);
 *  - stamps (StampOrder, per topic): not zero, and strictly after the previous admitted stamp of that topic.
 */
#pragma once

#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace ros_conv {

/**
 * @brief What is wrong with one message: `fault` is a short, stable name (the InputLedger's count key, e.g.
 * "non-finite angular velocity"); `detail` names the entries and values ("x = nan"). No fault = the message is
 * usable (the object is false).
 */
struct InputFault {
  std::string fault;
  std::string detail;
  InputFault() = default;
  InputFault(std::string f, std::string d = "") : fault(std::move(f)), detail(std::move(d)) {}
  explicit operator bool() const { return !fault.empty(); }
  /** @brief "fault (detail)", "fault", or "" when there is none. */
  std::string text() const { return detail.empty() ? fault : fault + " (" + detail + ")"; }
};

/**
 * @brief Whether a camera_info can rectify and triangulate (see the file comment). The non-finite entries are
 * named one by one with their row-major index ("non-finite camera_info entries": "K[2] = nan, P[3] = inf"), so a
 * NaN in P is never reported as a zero focal length nor blamed on a derived value (the disparity offset).
 */
InputFault checkCameraInfo(const sensor_msgs::CameraInfo& m);

/**
 * @brief Whether an imu/data sample can go to the SLAM (slam::SlamSystem::addGyro never throws after this
 * passes). Faults: "non-finite angular velocity", "non-finite angular velocity covariance", "angular velocity
 * covariance not symmetric", "angular velocity covariance not positive definite" (detail: its eigenvalues).
 * The stamp is checked with StampOrder, the frame by the caller.
 */
InputFault checkImu(const sensor_msgs::Imu& m);

/** @brief The covariance to hand to addGyro with a sample that passed checkImu: zero (= the configured gyro_noise)
 *  when unknown, else the message's (row-major, (rad/s)^2). */
Eigen::Matrix3d gyroCovariance(const sensor_msgs::Imu& m);

/**
 * @brief Whether an image can be converted by toMono8 (see the file comment for the encodings), and, with
 * `info`, whether it fits the camera_info of its camera (its size; its frame_id too unless FrameIdCheck::kIgnore:
 * offline readers pair by topic and do not need equal frame_ids). (An enum, not a bool, so that the older
 * checkImage(img, info, "topic") of conversions.h is never taken for this one.) Faults: "empty image", "unsupported encoding",
 * "image step smaller than a row", "image data shorter than step x height", "image size differs from its
 * camera_info's", "image frame_id differs from its camera_info's".
 */
enum class FrameIdCheck { kCompare, kIgnore };
InputFault checkImage(const sensor_msgs::Image& img, const sensor_msgs::CameraInfo* info = nullptr,
                      FrameIdCheck frame_id = FrameIdCheck::kCompare);

/** @brief The image encodings toMono8 converts (as written in messages). */
const std::vector<std::string>& acceptedImageEncodings();

/**
 * @brief What is wrong with a stamp given the previous admitted one of the same topic (zero: none yet):
 * "zero stamp", "duplicate stamp" (equal to the previous), "stamp goes backwards" (detail: by how much).
 */
InputFault checkStamp(const ros::Time& t, const ros::Time& previous);

/** @brief The stamp order of one topic: admit() each message's stamp; a faulty stamp is not remembered, so one
 *  bad message does not make the good ones after it look out of order. */
class StampOrder {
 public:
  /** @brief No fault (and `t` becomes the previous stamp) when `t` is non-zero and after the previous admitted one. */
  InputFault admit(const ros::Time& t) {
    InputFault f = checkStamp(t, last_);
    if (!f) last_ = t;
    return f;
  }
  const ros::Time& last() const { return last_; }
  void reset() { last_ = ros::Time(); }

 private:
  ros::Time last_;
};

}  // namespace ros_conv
}  // namespace skin3d
