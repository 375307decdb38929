// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_triangulate: MMSE triangulation (core: stereo/stereo_landmarks.h) of every match.
 *
 * Subscribes: stereo/matches (skin3d/StereoMatchArray), stereo/{left,right}/camera_info (raw calibration:
 *             R and P say how the rectified pixels relate to the left optical frame).
 * Publishes:  stereo/landmarks (skin3d/LandmarkArray: position and 3x3 covariance in the left optical
 *             frame, descriptor, strength, rectified pixels), stereo/points (sensor_msgs/PointCloud2,
 *             fields x y z strength, for rviz).
 * Parameters: ~sigma_px (px, 0 = estimated per frame from the matches' row residuals) pixel localisation
 *             error of a matched feature; ~min_depth (m, 0.05),
 *             ~max_depth (m, 5.0); ~max_landmarks (0 = all; else the strongest N); ~queue_size (5);
 *             ~row_gate (3.0, in sqrt(2) sigma of the row residual; 0 = off); ~disparity_gate (4.0, in robust
 *             spreads of the disparity residuals of a plane through the ~neighbours (12) nearest matches; 0 = off);
 *             ~slant_noise (true: horizontal localisation error grown with the surface slant, see stereo_landmarks.h);
 *             ~size_noise (true: localisation error grown with the keypoint size, fitted per frame; sigma_px 0 only).
 * Bad input (uncalibrated camera_info, frame mismatch) drops the frame with a throttled warning.
 */
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <skin3d/LandmarkArray.h>
#include <skin3d/StereoMatchArray.h>

#include <algorithm>
#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/conversions.h"
#include "skin3d/stereo/stereo_landmarks.h"

namespace skin3d {

using sensor_msgs::CameraInfo;

class StereoTriangulateNodelet : public nodelet::Nodelet {
  using Exact = message_filters::sync_policies::ExactTime<skin3d::StereoMatchArray, CameraInfo, CameraInfo>;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param("sigma_px", options_.sigma_px, options_.sigma_px);
    pnh.param("min_depth", options_.min_depth, options_.min_depth);
    pnh.param("max_depth", options_.max_depth, options_.max_depth);
    pnh.param("row_gate", options_.row_gate, options_.row_gate);
    pnh.param("disparity_gate", options_.disparity_gate, options_.disparity_gate);
    pnh.param("neighbours", options_.neighbours, options_.neighbours);
    pnh.param("slant_noise", options_.slant_noise, options_.slant_noise);
    pnh.param("size_noise", options_.size_noise, options_.size_noise);
    pnh.param("max_landmarks", max_landmarks_, 0);
    int queue = 5;
    pnh.param("queue_size", queue, 5);
    if (!(options_.sigma_px >= 0.0)) {
      NODELET_ERROR("stereo_triangulate: ~sigma_px = %g must be >= 0 (0: estimated per frame); using 0",
                    options_.sigma_px);
      options_.sigma_px = 0.0;
    }
    if (!(options_.max_depth > options_.min_depth) || options_.min_depth < 0.0) {
      NODELET_ERROR("stereo_triangulate: need 0 <= ~min_depth (%g) < ~max_depth (%g); using 0.05 and 5",
                    options_.min_depth, options_.max_depth);
      options_.min_depth = 0.05;
      options_.max_depth = 5.0;
    }
    pub_landmarks_ = nh.advertise<skin3d::LandmarkArray>("stereo/landmarks", 5);
    pub_points_ = nh.advertise<sensor_msgs::PointCloud2>("stereo/points", 2);
    sub_m_.subscribe(nh, "stereo/matches", queue);
    sub_lc_.subscribe(nh, "stereo/left/camera_info", queue);
    sub_rc_.subscribe(nh, "stereo/right/camera_info", queue);
    sync_ = std::make_unique<message_filters::Synchronizer<Exact>>(Exact(std::max(1, queue)), sub_m_, sub_lc_, sub_rc_);
    sync_->registerCallback(&StereoTriangulateNodelet::callback, this);
  }

  void callback(const skin3d::StereoMatchArray::ConstPtr& matches, const CameraInfo::ConstPtr& lc,
                const CameraInfo::ConstPtr& rc) {
    std::string problem = ros_conv::checkCameraInfo(*lc, "stereo/left/camera_info");
    if (problem.empty()) problem = ros_conv::checkCameraInfo(*rc, "stereo/right/camera_info");
    if (problem.empty() && matches->header.frame_id != lc->header.frame_id)
      problem = "stereo/matches frame_id '" + matches->header.frame_id + "' is not the left camera's '" +
                lc->header.frame_id + "'";
    if (!problem.empty()) {
      NODELET_WARN_THROTTLE(2.0, "stereo_triangulate: dropping frame: %s", problem.c_str());
      return;
    }
    std::vector<stereo::StereoMatch> in;
    in.reserve(matches->matches.size());
    for (const auto& m : matches->matches) {
      stereo::StereoMatch s;
      s.left = Eigen::Vector2d(m.u_left, m.v_left);
      s.right = Eigen::Vector2d(m.u_right, m.v_right);
      s.descriptor = m.descriptor;
      s.strength = m.strength;
      s.size = m.size;
      in.push_back(std::move(s));
    }
    if (max_landmarks_ > 0 && static_cast<int>(in.size()) > max_landmarks_) {
      std::partial_sort(in.begin(), in.begin() + max_landmarks_, in.end(),
                        [](const stereo::StereoMatch& a, const stereo::StereoMatch& b) { return a.strength > b.strength; });
      in.resize(max_landmarks_);
    }
    std::vector<stereo::StereoLandmark> lms;
    int dropped = 0;
    try {
      lms = stereo::triangulateMatches(ros_conv::fromMsg(*lc), ros_conv::fromMsg(*rc), in, options_, &dropped);
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(2.0, "stereo_triangulate: dropping frame: %s", e.what());
      return;
    }
    if (dropped > 0)
      NODELET_DEBUG("stereo_triangulate: %d of %zu matches outside [%g, %g] m or behind the rig", dropped, in.size(),
                    options_.min_depth, options_.max_depth);
    skin3d::LandmarkArray out;
    out.header = matches->header;
    out.landmarks.reserve(lms.size());
    for (const auto& l : lms)  // pixels: rectified
      out.landmarks.push_back(
          ros_conv::toLandmarkMsg(l.position, l.covariance, l.descriptor, l.strength, l.uv_left, l.uv_right));
    pub_landmarks_.publish(out);
    if (pub_points_.getNumSubscribers() > 0) pub_points_.publish(cloud(out));
  }

  static sensor_msgs::PointCloud2 cloud(const skin3d::LandmarkArray& lms) {
    sensor_msgs::PointCloud2 pc;
    pc.header = lms.header;
    sensor_msgs::PointCloud2Modifier mod(pc);
    mod.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32,
                             "z", 1, sensor_msgs::PointField::FLOAT32, "strength", 1, sensor_msgs::PointField::FLOAT32);
    mod.resize(lms.landmarks.size());
    sensor_msgs::PointCloud2Iterator<float> x(pc, "x"), y(pc, "y"), z(pc, "z"), s(pc, "strength");
    for (const auto& l : lms.landmarks) {
      *x = l.position.x;
      *y = l.position.y;
      *z = l.position.z;
      *s = l.strength;
      ++x, ++y, ++z, ++s;
    }
    return pc;
  }

  stereo::TriangulateOptions options_;
  int max_landmarks_ = 0;
  ros::Publisher pub_landmarks_, pub_points_;
  message_filters::Subscriber<skin3d::StereoMatchArray> sub_m_;
  message_filters::Subscriber<CameraInfo> sub_lc_, sub_rc_;
  std::unique_ptr<message_filters::Synchronizer<Exact>> sync_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoTriangulateNodelet, nodelet::Nodelet)
