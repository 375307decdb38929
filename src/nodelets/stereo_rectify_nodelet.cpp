// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_rectify: synchronised rectification of a stereo pair from its camera_info (K, D, R, P).
 *
 * Subscribes: stereo/{left,right}/image_raw, stereo/{left,right}/camera_info.
 * Publishes:  stereo/{left,right}/image_rect (mono8, rectified), stereo/{left,right}/camera_info_rect
 *             (K = P[0:3,0:3], D = 0, R = I, P unchanged).
 * Parameters: ~approximate_sync (bool, false): ApproximateTime instead of ExactTime;
 *             ~queue_size (int, 5); ~max_stamp_diff (double s, 0.005): with approximate sync, pairs
 *             further apart are dropped. Interpolation is bilinear (stereo::Rectifier, the same maps as
 *             process_bag and the benchmarks).
 * Note: image_geometry's PinholeCameraModel::rectifyImage copies the raw image unchanged when all distortion
 * coefficients are zero, ignoring R; a converged rig (or any perturbed calibration) has R != I, so the
 * core's Rectifier is used (maps rebuilt only when a camera_info changes).
 * Bad input (sizes, encodings, uncalibrated camera_info, frame_id or stamp mismatch) drops that frame
 * with a throttled warning naming the topic; the nodelet keeps running.
 */
#include <cv_bridge/cv_bridge.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>

#include <memory>
#include <mutex>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/conversions.h"
#include "skin3d/ros/stereo_sync.h"
#include "skin3d/stereo/rectification.h"

namespace skin3d {

using sensor_msgs::CameraInfo;
using sensor_msgs::Image;

class StereoRectifyNodelet : public nodelet::Nodelet {
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param("max_stamp_diff", max_stamp_diff_, 0.005);
    if (pnh.hasParam("interpolation")) NODELET_WARN("stereo_rectify: ~interpolation is no longer used (always bilinear)");
    if (nh.getNamespace() == "/")
      NODELET_WARN("stereo_rectify: started in the global namespace; topics are stereo/...; usually it runs in a rig namespace");
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    pub_left_ = it_->advertise("stereo/left/image_rect", 1);
    pub_right_ = it_->advertise("stereo/right/image_rect", 1);
    pub_left_info_ = nh.advertise<CameraInfo>("stereo/left/camera_info_rect", 1);
    pub_right_info_ = nh.advertise<CameraInfo>("stereo/right/camera_info_rect", 1);
    const auto on_pair = [this](const Image::ConstPtr& li, const CameraInfo::ConstPtr& lc, const Image::ConstPtr& ri,
                                const CameraInfo::ConstPtr& rc) { callback(li, lc, ri, rc); };
    const std::string sync_problem = sync_.subscribe(nh, pnh, "image_raw", on_pair);
    if (!sync_problem.empty()) NODELET_WARN("stereo_rectify: %s", sync_problem.c_str());
  }

  void callback(const Image::ConstPtr& li, const CameraInfo::ConstPtr& lc, const Image::ConstPtr& ri,
                const CameraInfo::ConstPtr& rc) {
    std::string problem = ros_conv::checkCameraInfo(*lc, "stereo/left/camera_info");
    if (problem.empty()) problem = ros_conv::checkCameraInfo(*rc, "stereo/right/camera_info");
    if (problem.empty()) problem = ros_conv::checkImage(*li, lc.get(), "stereo/left/image_raw");
    if (problem.empty()) problem = ros_conv::checkImage(*ri, rc.get(), "stereo/right/image_raw");
    if (problem.empty() && (li->width != ri->width || li->height != ri->height))
      problem = "left and right images differ in size (" + std::to_string(li->width) + "x" + std::to_string(li->height) +
                " vs " + std::to_string(ri->width) + "x" + std::to_string(ri->height) + ")";
    if (problem.empty() && li->header.frame_id == ri->header.frame_id)
      problem = "left and right images have the same frame_id '" + li->header.frame_id + "'";
    if (problem.empty() && std::abs((li->header.stamp - ri->header.stamp).toSec()) > max_stamp_diff_)
      problem = "left/right stamps differ by " + std::to_string((li->header.stamp - ri->header.stamp).toSec()) +
                " s (> ~max_stamp_diff)";
    if (!problem.empty()) {
      NODELET_WARN_THROTTLE(2.0, "stereo_rectify: dropping frame: %s", problem.c_str());
      return;
    }
    try {
      std::lock_guard<std::mutex> lock(mutex_);
      update(*lc, &left_info_, &left_rect_);  // maps rebuilt only when the camera_info changes
      update(*rc, &right_info_, &right_rect_);
      publish(*li, *left_rect_, pub_left_, pub_left_info_, *lc);
      publish(*ri, *right_rect_, pub_right_, pub_right_info_, *rc);
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(2.0, "stereo_rectify: dropping frame: %s", e.what());
    }
  }

  static void update(const CameraInfo& info, CameraInfo* cached, std::unique_ptr<stereo::Rectifier>* rect) {
    if (*rect && info.K == cached->K && info.D == cached->D && info.R == cached->R && info.P == cached->P &&
        info.width == cached->width && info.height == cached->height)
      return;
    *rect = std::make_unique<stereo::Rectifier>(ros_conv::fromMsg(info));
    *cached = info;
  }

  void publish(const Image& raw, const stereo::Rectifier& rectifier, image_transport::Publisher& pub,
               ros::Publisher& pub_info, const CameraInfo& info) {
    const cv::Mat gray = ros_conv::toMono8(raw);
    cv_bridge::CvImage out;
    out.header = raw.header;
    out.encoding = sensor_msgs::image_encodings::MONO8;
    out.image = rectifier(gray);
    pub.publish(out.toImageMsg());
    CameraInfo rect = info;
    for (int i = 0; i < 9; ++i) rect.K[i] = info.P[(i / 3) * 4 + i % 3];
    rect.D.assign(info.D.size(), 0.0);
    rect.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    pub_info.publish(rect);
  }

  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Publisher pub_left_, pub_right_;
  ros::Publisher pub_left_info_, pub_right_info_;
  ros_conv::StereoSync sync_;
  CameraInfo left_info_, right_info_;
  std::unique_ptr<stereo::Rectifier> left_rect_, right_rect_;
  std::mutex mutex_;
  double max_stamp_diff_ = 0.005;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoRectifyNodelet, nodelet::Nodelet)
