// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_features: feature detection and left-right matching on the rectified pair (core:
 * stereo/features.h).
 *
 * Subscribes: stereo/{left,right}/image_rect (mono8) and stereo/{left,right}/camera_info (for the
 *             principal-point offset cx_l - cx_r of the rectified P matrices).
 * Publishes:  stereo/matches (skin3d/StereoMatchArray), stereo/matches_image (bgr8 debug picture, only
 *             computed while someone subscribes).
 * Parameters: ~feature_type (kaze | akaze | orb, kaze), ~threshold (0.001), ~max_features (3000),
 *             ~octaves (4), ~octave_layers (4) of the KAZE/AKAZE scale space (fewer: faster, fewer features),
 *             ~ratio (0.8), ~max_row_diff (px, 1.5), ~min_disparity (px, 0.5), ~max_disparity (px, 1e9),
 *             ~cross_check (true), ~border_margin (keypoint diameters, 1), ~queue_size (5),
 *             ~approximate_sync (false).
 * Bad input (empty/black/textureless images, sizes, encodings, no features, no matches) drops the frame
 * with a throttled warning; the nodelet keeps running.
 */
#include <cv_bridge/cv_bridge.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <skin3d/StereoMatchArray.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/conversions.h"
#include "skin3d/ros/stereo_sync.h"
#include "skin3d/stereo/features.h"

namespace skin3d {

using sensor_msgs::CameraInfo;
using sensor_msgs::Image;

class StereoFeaturesNodelet : public nodelet::Nodelet {
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    stereo::FeatureOptions o;
    std::string type;
    pnh.param<std::string>("feature_type", type, "kaze");
    pnh.param("threshold", o.threshold, o.threshold);
    pnh.param("max_features", o.max_features, o.max_features);
    pnh.param("octaves", o.octaves, o.octaves);
    pnh.param("octave_layers", o.octave_layers, o.octave_layers);
    pnh.param("ratio", o.ratio, o.ratio);
    pnh.param("max_row_diff", o.max_row_diff, o.max_row_diff);
    pnh.param("min_disparity", o.min_disparity, o.min_disparity);
    pnh.param("max_disparity", o.max_disparity, o.max_disparity);
    pnh.param("cross_check", o.cross_check, o.cross_check);
    pnh.param("border_margin", o.border_margin, o.border_margin);
    try {
      o.type = stereo::parseFeatureType(type);
      matcher_ = std::make_unique<stereo::StereoFeatureMatcher>(o);
    } catch (const std::invalid_argument& e) {
      NODELET_ERROR("stereo_features: bad parameter: %s; using the defaults (KAZE)", e.what());
      matcher_ = std::make_unique<stereo::StereoFeatureMatcher>(stereo::FeatureOptions());
    }
    type_name_ = stereo::featureTypeName(matcher_->options().type);
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    pub_matches_ = nh.advertise<skin3d::StereoMatchArray>("stereo/matches", 5);
    pub_debug_ = it_->advertise("stereo/matches_image", 1);
    const auto on_pair = [this](const Image::ConstPtr& li, const CameraInfo::ConstPtr& lc, const Image::ConstPtr& ri,
                                const CameraInfo::ConstPtr& rc) { callback(li, lc, ri, rc); };
    const std::string sync_problem = sync_.subscribe(nh, pnh, "image_rect", on_pair);
    if (!sync_problem.empty()) NODELET_ERROR("stereo_features: %s", sync_problem.c_str());
    NODELET_INFO("stereo_features: %s features, ratio %.2f, row tolerance %.1f px", type_name_.c_str(),
                 matcher_->options().ratio, matcher_->options().max_row_diff);
  }

  void callback(const Image::ConstPtr& li, const CameraInfo::ConstPtr& lc, const Image::ConstPtr& ri,
                const CameraInfo::ConstPtr& rc) {
    std::string problem = ros_conv::checkCameraInfo(*lc, "stereo/left/camera_info");
    if (problem.empty()) problem = ros_conv::checkCameraInfo(*rc, "stereo/right/camera_info");
    if (problem.empty()) problem = ros_conv::checkImage(*li, nullptr, "stereo/left/image_rect");
    if (problem.empty()) problem = ros_conv::checkImage(*ri, nullptr, "stereo/right/image_rect");
    if (problem.empty() && (li->width != ri->width || li->height != ri->height))
      problem = "left and right rectified images differ in size";
    if (!problem.empty()) {
      NODELET_WARN_THROTTLE(2.0, "stereo_features: dropping frame: %s", problem.c_str());
      return;
    }
    cv::Mat left, right;
    try {
      left = ros_conv::toMono8(*li);
      right = ros_conv::toMono8(*ri);
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(2.0, "stereo_features: dropping frame: %s", e.what());
      return;
    }
    stereo::FeatureOptions o = matcher_->options();
    const double offset = lc->P[2] - rc->P[2];  // cx_l - cx_r of the rectified projections
    std::vector<stereo::StereoMatch> matches;
    stereo::MatchStats stats;
    {
      if (o.disparity_offset != offset) {
        o.disparity_offset = offset;
        matcher_ = std::make_unique<stereo::StereoFeatureMatcher>(o);
      }
      matches = matcher_->process(left, right, &stats);
    }
    if (stats.left_features == 0 || stats.right_features == 0) {
      NODELET_WARN_THROTTLE(2.0, "stereo_features: dropping frame: no features found in stereo/%s/image_rect "
                                 "(black, saturated or textureless image?)",
                            stats.left_features == 0 ? "left" : "right");
      return;
    }
    if (matches.empty()) {
      NODELET_WARN_THROTTLE(2.0, "stereo_features: dropping frame: %d / %d features but no match (%d with row "
                                 "candidates; check the rectification and ~max_row_diff, ~ratio)",
                            stats.left_features, stats.right_features, stats.candidates);
      return;
    }
    skin3d::StereoMatchArray msg;
    msg.header = li->header;
    msg.feature_type = type_name_;
    msg.matches.reserve(matches.size());
    for (const auto& m : matches) {
      skin3d::StereoMatch s;
      s.u_left = m.left.x();
      s.v_left = m.left.y();
      s.u_right = m.right.x();
      s.v_right = m.right.y();
      s.descriptor = m.descriptor;
      s.strength = m.strength;
      s.size = m.size;
      msg.matches.push_back(std::move(s));
    }
    pub_matches_.publish(msg);
    if (pub_debug_.getNumSubscribers() > 0) {
      cv_bridge::CvImage dbg(li->header, sensor_msgs::image_encodings::BGR8, stereo::drawStereoMatches(left, right, matches));
      pub_debug_.publish(dbg.toImageMsg());
    }
  }

  std::unique_ptr<stereo::StereoFeatureMatcher> matcher_;
  std::string type_name_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  ros::Publisher pub_matches_;
  image_transport::Publisher pub_debug_;
  ros_conv::StereoSync sync_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoFeaturesNodelet, nodelet::Nodelet)
