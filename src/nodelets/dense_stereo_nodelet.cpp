// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/dense_stereo: dense sub-pixel disparity of the rectified pair and its organised point cloud (core:
 * stereo/dense_stereo.h), the input of skin3d/induration.
 *
 * Subscribes: stereo/{left,right}/image_rect (mono8 from skin3d/stereo_rectify; mono16, bgr8, rgb8 also taken),
 *             stereo/{left,right}/camera_info (the calibration: P gives the rectified projections and the left R
 *             turns the rectified frame back into the left optical frame. camera_info_rect carries R = I, so a
 *             cloud from it would be in the rectified frame, not in ~frame_id, on a converged rig 27 deg apart).
 * Publishes:  induration/points (sensor_msgs/PointCloud2, organised like the left image, in ~frame_id: x y z
 *             (m, NaN unknown), rgb (left image), sigma (m, 1 sigma along the ray), ray_x ray_y ray_z (unit ray
 *             of every pixel)); dense_stereo/disparity (sensor_msgs/Image 32FC1, px, x_left - x_right, NaN
 *             unknown; only while subscribed).
 * Parameters: ~config (YAML file of the keys below, applied first; the launch files pass
 *             config/induration.yaml), then every key of config/induration.yaml that is set as a private
 *             parameter (z_min, z_max, roi, the matcher's keys; the induration keys are read but unused here);
 *             ~frame_id (stereo_left_optical_frame: the frame of the cloud); ~approximate_sync (false);
 *             ~queue_size (5).
 * Bad input (uncalibrated camera_info, encodings, left/right size mismatch, a pair the matcher rejects) drops
 * that frame with a throttled error naming the problem; the nodelet keeps running. The matcher's warnings
 * (no texture, little overlap) are throttled warnings.
 */
#include <cv_bridge/cv_bridge.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/conversions.h"
#include "skin3d/ros/stereo_sync.h"
#include "skin3d/common/large_buffers.h"
#include "skin3d/induration/induration_config.h"
#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {

using sensor_msgs::CameraInfo;
using sensor_msgs::Image;

class DenseStereoNodelet : public nodelet::Nodelet {
  void onInit() override {
    keepLargeBuffers();  // process-wide: full-resolution buffers from the heap, not fresh mmap()s
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::vector<std::string> errors;
    options_ = ros_conv::loadPipelineOptions(pnh, &errors);
    for (const auto& e : errors) NODELET_ERROR("dense_stereo: %s", e.c_str());
    pnh.param<std::string>("frame_id", frame_id_, "stereo_left_optical_frame");
    if (nh.getNamespace() == "/")
      NODELET_WARN("dense_stereo: started in the global namespace; topics are stereo/...; usually it runs in a rig namespace");
    pub_points_ = nh.advertise<sensor_msgs::PointCloud2>("induration/points", 2);
    pub_disparity_ = nh.advertise<Image>("dense_stereo/disparity", 2);
    const auto on_pair = [this](const Image::ConstPtr& li, const CameraInfo::ConstPtr& lc, const Image::ConstPtr& ri,
                                const CameraInfo::ConstPtr& rc) { callback(li, lc, ri, rc); };
    const std::string sync_problem = sync_.subscribe(nh, pnh, "image_rect", on_pair);
    if (!sync_problem.empty()) NODELET_ERROR("dense_stereo: %s", sync_problem.c_str());
    NODELET_INFO("dense_stereo: depths %.3f ... %.3f m, semi-global '%s' (block %d), sub-pixel '%s'; cloud in '%s'",
                 options_.z_min, options_.z_max, options_.dense.sgbm_mode.c_str(), options_.dense.block_size,
                 options_.dense.subpixel.c_str(), frame_id_.c_str());
  }

  void callback(const Image::ConstPtr& li, const CameraInfo::ConstPtr& lc, const Image::ConstPtr& ri,
                const CameraInfo::ConstPtr& rc) {
    std::string problem = ros_conv::checkCameraInfo(*lc, "stereo/left/camera_info");
    if (problem.empty()) problem = ros_conv::checkCameraInfo(*rc, "stereo/right/camera_info");
    if (problem.empty()) problem = ros_conv::checkImage(*li, lc.get(), "stereo/left/image_rect");
    if (problem.empty()) problem = ros_conv::checkImage(*ri, rc.get(), "stereo/right/image_rect");
    if (problem.empty() && (li->width != ri->width || li->height != ri->height))
      problem = "left and right images differ in size (" + std::to_string(li->width) + "x" + std::to_string(li->height) +
                " vs " + std::to_string(ri->width) + "x" + std::to_string(ri->height) + ")";
    if (!problem.empty()) {
      NODELET_ERROR_THROTTLE(2.0, "dense_stereo: dropping frame: %s", problem.c_str());
      return;
    }
    if (li->header.frame_id != frame_id_)
      NODELET_WARN_ONCE("dense_stereo: the left image is in '%s' but the cloud is published in ~frame_id '%s'",
                        li->header.frame_id.c_str(), frame_id_.c_str());
    cv::Mat left, right;
    stereo::DisparityMap map;
    stereo::DenseCloud cloud;
    try {
      left = image(li);
      right = image(ri);
      const geometry::CameraInfo lci = ros_conv::fromMsg(*lc), rci = ros_conv::fromMsg(*rc);
      stereo::DenseStereoOptions o = options_.dense;
      std::tie(o.min_disparity, o.max_disparity) =
          stereo::disparityRangeForDepth(lci, rci, options_.z_min, options_.z_max);
      map = stereo::computeDisparity(left, right, o);
      cloud = stereo::triangulateDisparity(map, lci, rci);
    } catch (const std::exception& e) {  // DenseStereoError, cv_bridge::Exception, cv::Exception
      NODELET_ERROR_THROTTLE(2.0, "dense_stereo: dropping frame: %s", e.what());
      return;
    }
    for (const auto& w : map.warnings) NODELET_WARN_THROTTLE(5.0, "dense_stereo: %s", w.c_str());
    NODELET_DEBUG("dense_stereo: %.1f %% of the ROI known, %.2f s (prepare %.2f, semi-global %.2f, refine %.2f)",
                  100.0 * map.valid_fraction, map.timing.total, map.timing.prepare, map.timing.sgbm,
                  map.timing.refine);

    std_msgs::Header header = li->header;
    header.frame_id = frame_id_;
    cv::Mat colour = left;
    if (left.depth() != CV_8U) left.convertTo(colour, CV_8U, 1.0 / 256.0);
    pub_points_.publish(ros_conv::toCloudMsg(cloud, colour, header));
    if (pub_disparity_.getNumSubscribers() > 0) {
      cv_bridge::CvImage d(li->header, sensor_msgs::image_encodings::TYPE_32FC1, map.disparity);
      pub_disparity_.publish(d.toImageMsg());
    }
  }

  /** The checked image as the matcher takes it: grey 8/16-bit or BGR 8-bit, sharing the message's data
   *  when it already is (the message outlives the callback's use of it). */
  static cv::Mat image(const Image::ConstPtr& img) {
    namespace enc = sensor_msgs::image_encodings;
    if (img->encoding == enc::MONO8 || img->encoding == enc::MONO16) return cv_bridge::toCvShare(img)->image;
    return cv_bridge::toCvShare(img, enc::BGR8)->image;
  }

  induration::PipelineOptions options_;
  std::string frame_id_;
  ros::Publisher pub_points_, pub_disparity_;
  ros_conv::StereoSync sync_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::DenseStereoNodelet, nodelet::Nodelet)
