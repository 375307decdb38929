// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file slam_messages.h
 * @brief skin3d_ros: the messages of the SLAM nodelet built from the core's state (TF, odometry, SlamState,
 * the landmark map as a cloud and as covariance ellipsoids) and its option loader.
 */
#pragma once

#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Odometry.h>
#include <ros/node_handle.h>
#include <sensor_msgs/PointCloud2.h>
#include <skin3d/SlamState.h>
#include <std_msgs/Header.h>
#include <tf2_ros/transform_broadcaster.h>
#include <nav_msgs/Path.h>
#include <visualization_msgs/MarkerArray.h>

#include <cstddef>
#include <string>
#include <vector>

#include "skin3d/slam/eskf.h"
#include "skin3d/slam/results.h"
#include "skin3d/slam/slam_config.h"
#include "skin3d/slam/slam_system.h"

namespace skin3d {
namespace ros_conv {

/** @brief The SLAM options from private parameters: every key of slamOptionKeys() that is set (as
 *  loadPipelineOptions does: problems go to `errors`, naming the key; a bad key keeps its default; options that
 *  do not validate are reset to the defaults). */
slam::SlamOptions loadSlamOptions(const ros::NodeHandle& pnh, std::vector<std::string>* errors);

/** @brief The SLAM nodelet's own parameters (besides the SLAM's options); see eskf_slam_nodelet.cpp. */
struct SlamNodeParams {
  std::string world_frame = "world";
  std::string camera_frame = "stereo_left_optical_frame";  //!< the frame the landmarks must come in
  std::string results;                                      //!< directory written on shutdown; empty = none
  std::string known_map;                                    //!< make_dataset's FILE.map.csv; empty = SLAM
  std::string ground_truth_topic = "ground_truth/pose";     //!< empty = no slam/ground_truth_path
  bool fit_sphere = true;
  int map_every = 10;          //!< frames between slam/map messages
  int queue_size = 10;
  double jump_back = 1.0;      //!< s (~reset_on_jump_back): an older stamp is a restarted bag
  double ellipsoid_sigma = 3.0;
  int max_ellipsoids = 2000;   //!< 0 = no slam/landmark_ellipsoids
};

/** @brief The nodelet's parameters from `pnh`; out-of-range values are reported in `errors` and replaced by
 *  the defaults. */
SlamNodeParams loadSlamNodeParams(const ros::NodeHandle& pnh, std::vector<std::string>* errors);

/** @brief TF header.frame_id <- `child`: the filter's pose. */
geometry_msgs::TransformStamped toTransformMsg(const std_msgs::Header& header, const std::string& child,
                                               const slam::RigState& x);

/** @brief Odometry: pose with the 6x6 [p, theta] covariance (world axes), twist in the camera frame with the
 *  [v, omega] covariance (the filter's first 12 error-state rows). */
nav_msgs::Odometry toOdometryMsg(const std_msgs::Header& header, const std::string& child, const slam::RigState& x,
                                 const Eigen::MatrixXd& covariance);

/** @brief The SlamState message of one frame (its row of state.csv and its statistics). */
skin3d::SlamState toSlamStateMsg(const std_msgs::Header& header, const slam::RigState& x, const slam::StateRow& row,
                                 const slam::FrameStats& stats);

/** @brief The landmarks as a cloud, fields x y z std id (float32; std = sqrt(trace of the covariance), m). */
sensor_msgs::PointCloud2 toMapCloudMsg(const std::vector<slam::MapPoint>& map, const std_msgs::Header& header);

/**
 * @brief The landmarks' covariance ellipsoids (`sigma` standard deviations) for rviz: a DELETEALL, then one
 * SPHERE per landmark (the `max_count` most often observed), coloured by its largest 1-sigma semi-axis on a log
 * scale (0.1 mm green, 1 mm yellow, 10 mm red). Landmarks with no ellipsoid (NaN, not positive definite) are
 * left out and counted in `skipped`.
 */
visualization_msgs::MarkerArray toEllipsoidMarkers(std::vector<slam::MapPoint> map, const std_msgs::Header& header,
                                                   double sigma, int max_count, int* skipped);

/**
 * @brief Everything the SLAM nodelet publishes per frame: TF world -> camera, slam/odometry, slam/path (latched),
 * slam/state, and every `map_every` frames slam/map and slam/landmark_ellipsoids (latched).
 */
class SlamPublisher {
 public:
  void advertise(ros::NodeHandle& nh, const SlamNodeParams& params);
  /** @brief One frame's messages. @return a warning to log (landmarks left out of the ellipsoids), or empty. */
  std::string publish(const ros::Time& stamp, const slam::SlamSystem& slam, const slam::StateRow& row,
                      const slam::FrameStats& stats, std::size_t frame);
  /** @brief A reset: slam/path starts again. */
  void clearPath() { path_.poses.clear(); }

 private:
  SlamNodeParams par_;
  ros::Publisher odom_, path_pub_, map_, state_, ellipsoids_;
  nav_msgs::Path path_;
  tf2_ros::TransformBroadcaster tf_;
};

}  // namespace ros_conv
}  // namespace skin3d
