// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the stereo_capture nodelet's node (see include/skin3d/ros/capture_node.h).
#include <camera_info_manager/camera_info_manager.h>
#include <cv_bridge/cv_bridge.h>
#include <image_transport/image_transport.h>
#include <ros/ros.h>

#include <memory>
#include <opencv2/videoio.hpp>

#include "skin3d/ros/capture_node.h"

namespace skin3d {
namespace ros_run {
namespace {

class StereoCaptureNode {
 public:
  StereoCaptureNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    pnh.param<std::string>("left_source", left_source_, "");
    pnh.param<std::string>("right_source", right_source_, "");
    pnh.param<std::string>("side_by_side_source", sbs_source_, "");
    pnh.param("width", width_, 0);
    pnh.param("height", height_, 0);
    pnh.param("fps", fps_, 10.0);
    pnh.param("exposure", exposure_, -1.0);
    pnh.param("loop", loop_, false);
    pnh.param<std::string>("left_frame_id", left_frame_, "stereo_left_optical_frame");
    pnh.param<std::string>("right_frame_id", right_frame_, "stereo_right_optical_frame");
    std::string lurl, rurl, lname, rname;
    pnh.param<std::string>("left_camera_info_url", lurl, "");
    pnh.param<std::string>("right_camera_info_url", rurl, "");
    pnh.param<std::string>("left_camera_name", lname, "left");
    pnh.param<std::string>("right_camera_name", rname, "right");
    if (sbs_source_.empty() && (left_source_.empty() || right_source_.empty())) {
      ROS_ERROR("stereo_capture: set ~left_source and ~right_source (or ~side_by_side_source); nothing is captured");
      return;
    }
    if (!(fps_ > 0.0) || fps_ > 1000.0) {
      ROS_WARN("stereo_capture: ~fps = %g must be in (0, 1000]; using 10", fps_);
      fps_ = 10.0;
    }
    left_nh_ = ros::NodeHandle(nh, "stereo/left");
    right_nh_ = ros::NodeHandle(nh, "stereo/right");
    left_info_ = std::make_unique<camera_info_manager::CameraInfoManager>(left_nh_, lname, lurl);
    right_info_ = std::make_unique<camera_info_manager::CameraInfoManager>(right_nh_, rname, rurl);
    for (const auto& cam : {std::make_pair(left_info_.get(), lname), std::make_pair(right_info_.get(), rname)})
      if (!cam.first->isCalibrated())
        ROS_WARN("stereo_capture: camera '%s' is not calibrated (no or unreadable camera_info URL): camera_info "
                     "will have K = 0 and the rest of the chain drops the frames; run calibrate_stereo",
                     cam.second.c_str());
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    pub_left_ = it_->advertiseCamera("stereo/left/image_raw", 2);
    pub_right_ = it_->advertiseCamera("stereo/right/image_raw", 2);
    timer_ = nh.createWallTimer(ros::WallDuration(1.0 / fps_), &StereoCaptureNode::tick, this);
  }

  bool open(cv::VideoCapture& cap, const std::string& source) {
    if (cap.isOpened()) return true;
    char* end = nullptr;
    const long index = std::strtol(source.c_str(), &end, 10);
    const bool is_index = !source.empty() && *end == '\0';
    const bool ok = is_index ? cap.open(static_cast<int>(index)) : cap.open(source);
    if (!ok) {
      ROS_ERROR_THROTTLE(5.0, "stereo_capture: cannot open source '%s'", source.c_str());
      return false;
    }
    if (width_ > 0) cap.set(cv::CAP_PROP_FRAME_WIDTH, width_);
    if (height_ > 0) cap.set(cv::CAP_PROP_FRAME_HEIGHT, height_);
    if (is_index) cap.set(cv::CAP_PROP_FPS, fps_);
    if (exposure_ >= 0.0) cap.set(cv::CAP_PROP_EXPOSURE, exposure_);
    return true;
  }

  /** Grabs the next frame; at the end of a file with ~loop, starts it again. */
  bool grab(cv::VideoCapture& cap, const std::string& source) {
    if (cap.grab()) return true;
    if (!loop_) return false;
    cap.release();
    return open(cap, source) && cap.grab();
  }

  static bool read(cv::VideoCapture& cap, cv::Mat* img) { return cap.retrieve(*img) && !img->empty(); }

  void tick(const ros::WallTimerEvent&) {
    cv::Mat left, right;
    if (!sbs_source_.empty()) {
      if (!open(left_cap_, sbs_source_)) return;
      cv::Mat both;
      if (!grab(left_cap_, sbs_source_) || !read(left_cap_, &both)) return endOfStream(sbs_source_);
      if (both.cols < 2) return;
      left = both.colRange(0, both.cols / 2).clone();
      right = both.colRange(both.cols / 2, both.cols).clone();
    } else {
      if (!open(left_cap_, left_source_) || !open(right_cap_, right_source_)) return;
      // Grab both first, then decode: the two exposures are as close in time as the devices allow.
      const bool gl = grab(left_cap_, left_source_), gr = grab(right_cap_, right_source_);
      if (!gl || !read(left_cap_, &left)) return endOfStream(left_source_);
      if (!gr || !read(right_cap_, &right)) return endOfStream(right_source_);
    }
    const ros::Time stamp = ros::Time::now();
    publish(left, left_frame_, *left_info_, pub_left_, stamp);
    publish(right, right_frame_, *right_info_, pub_right_, stamp);
  }

  void endOfStream(const std::string& source) {
    ROS_WARN_THROTTLE(10.0, "stereo_capture: no frame from '%s' (end of file, or device error)%s",
                          source.c_str(), loop_ ? "" : "; set ~loop to restart files");
  }

  void publish(const cv::Mat& img, const std::string& frame, camera_info_manager::CameraInfoManager& info,
               image_transport::CameraPublisher& pub, const ros::Time& stamp) {
    cv_bridge::CvImage out;
    out.header.stamp = stamp;
    out.header.frame_id = frame;
    out.encoding = img.channels() == 1 ? "mono8" : "bgr8";
    out.image = img;
    sensor_msgs::CameraInfoPtr ci(new sensor_msgs::CameraInfo(info.getCameraInfo()));
    ci->header = out.header;
    if (ci->width == 0) {
      ci->width = img.cols;
      ci->height = img.rows;
    }
    pub.publish(out.toImageMsg(), ci);
  }

  std::string left_source_, right_source_, sbs_source_, left_frame_, right_frame_;
  int width_ = 0, height_ = 0;
  double fps_ = 10.0, exposure_ = -1.0;
  bool loop_ = false;
  cv::VideoCapture left_cap_, right_cap_;
  ros::NodeHandle left_nh_, right_nh_;
  std::unique_ptr<camera_info_manager::CameraInfoManager> left_info_, right_info_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::CameraPublisher pub_left_, pub_right_;
  ros::WallTimer timer_;
};

}  // namespace

std::shared_ptr<void> startStereoCapture(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
  return std::make_shared<StereoCaptureNode>(nh, pnh);
}

}  // namespace ros_run
}  // namespace skin3d

