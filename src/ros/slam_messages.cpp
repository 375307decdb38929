// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the SLAM nodelet's messages (see include/skin3d/ros/slam_messages.h).
#include "skin3d/ros/slam_messages.h"

#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <cmath>

#include "skin3d/geometry/covariance_ellipsoid.h"
#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_conv {

slam::SlamOptions loadSlamOptions(const ros::NodeHandle& pnh, std::vector<std::string>* errors) {
  slam::SlamOptions opt;
  loadOptionParams(
      pnh, slam::slamOptionKeys(), [&](const std::string& k, const std::string& v) { slam::setSlamOption(&opt, k, v); },
      [&](const std::string& k) { return slam::getSlamOption(opt, k); }, errors);
  try {
    opt.validate();
  } catch (const std::exception& e) {
    errors->push_back(std::string(e.what()) + "; using the defaults of config/slam.yaml for every parameter");
    opt = slam::SlamOptions();
  }
  return opt;
}

SlamNodeParams loadSlamNodeParams(const ros::NodeHandle& pnh, std::vector<std::string>* errors) {
  SlamNodeParams p;
  pnh.param<std::string>("world_frame", p.world_frame, p.world_frame);
  pnh.param<std::string>("camera_frame", p.camera_frame, p.camera_frame);
  pnh.param<std::string>("results", p.results, p.results);
  pnh.param<std::string>("known_map", p.known_map, p.known_map);
  pnh.param<std::string>("ground_truth_topic", p.ground_truth_topic, p.ground_truth_topic);
  pnh.param("fit_sphere", p.fit_sphere, p.fit_sphere);
  pnh.param("map_every", p.map_every, p.map_every);
  pnh.param("queue_size", p.queue_size, p.queue_size);
  pnh.param("reset_on_jump_back", p.jump_back, p.jump_back);
  pnh.param("ellipsoid_sigma", p.ellipsoid_sigma, p.ellipsoid_sigma);
  pnh.param("max_ellipsoids", p.max_ellipsoids, p.max_ellipsoids);
  if (!(p.ellipsoid_sigma > 0.0) || !std::isfinite(p.ellipsoid_sigma)) {
    errors->push_back("~ellipsoid_sigma = " + std::to_string(p.ellipsoid_sigma) + " must be > 0; using 3");
    p.ellipsoid_sigma = 3.0;
  }
  if (p.max_ellipsoids < 0) {
    errors->push_back("~max_ellipsoids = " + std::to_string(p.max_ellipsoids) + " must be >= 0 (0: none); using 2000");
    p.max_ellipsoids = 2000;
  }
  return p;
}

geometry_msgs::TransformStamped toTransformMsg(const std_msgs::Header& header, const std::string& child,
                                               const slam::RigState& x) {
  geometry_msgs::TransformStamped tf;
  tf.header = header;
  tf.child_frame_id = child;
  tf.transform.translation.x = x.p.x();
  tf.transform.translation.y = x.p.y();
  tf.transform.translation.z = x.p.z();
  tf.transform.rotation.w = x.q.w();
  tf.transform.rotation.x = x.q.x();
  tf.transform.rotation.y = x.q.y();
  tf.transform.rotation.z = x.q.z();
  return tf;
}

nav_msgs::Odometry toOdometryMsg(const std_msgs::Header& header, const std::string& child, const slam::RigState& x,
                                 const Eigen::MatrixXd& C) {
  nav_msgs::Odometry od;
  od.header = header;
  od.child_frame_id = child;
  od.pose.pose = toPoseMsg(x.p, x.q);
  // [dp, dtheta] (global angle = world axes, as ROS wants the pose covariance) and [dv, dw] (camera frame).
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) {
      od.pose.covariance[6 * i + j] = C(i, j);
      od.twist.covariance[6 * i + j] = C(6 + i, 6 + j);
    }
  od.twist.twist.linear.x = x.v.x();
  od.twist.twist.linear.y = x.v.y();
  od.twist.twist.linear.z = x.v.z();
  od.twist.twist.angular.x = x.w.x();
  od.twist.twist.angular.y = x.w.y();
  od.twist.twist.angular.z = x.w.z();
  return od;
}

skin3d::SlamState toSlamStateMsg(const std_msgs::Header& header, const slam::RigState& x, const slam::StateRow& r,
                                 const slam::FrameStats& st) {
  skin3d::SlamState s;
  s.header = header;
  s.linear_velocity.x = x.v.x();
  s.linear_velocity.y = x.v.y();
  s.linear_velocity.z = x.v.z();
  s.angular_velocity.x = x.w.x();
  s.angular_velocity.y = x.w.y();
  s.angular_velocity.z = x.w.z();
  s.trace_state = r.trace_rig;
  s.trace_landmarks = r.trace_landmarks;
  s.trace_all = r.trace_all;
  s.pool_size = r.pool_size;
  s.pool_in_use = r.pool_in_use;
  s.landmarks_ever_seen = static_cast<uint32_t>(r.ever_seen);
  s.measurements = st.measurements;
  s.associated = st.associated;
  s.initialised = st.initialised;
  s.rejected = st.rejected_invalid + (st.associated - st.used);
  return s;
}

sensor_msgs::PointCloud2 toMapCloudMsg(const std::vector<slam::MapPoint>& map, const std_msgs::Header& header) {
  sensor_msgs::PointCloud2 pc;
  pc.header = header;
  sensor_msgs::PointCloud2Modifier mod(pc);
  const auto F = sensor_msgs::PointField::FLOAT32;
  mod.setPointCloud2Fields(5, "x", 1, F, "y", 1, F, "z", 1, F, "std", 1, F, "id", 1, F);
  mod.resize(map.size());
  sensor_msgs::PointCloud2Iterator<float> px(pc, "x"), py(pc, "y"), pz(pc, "z"), ps(pc, "std"), pid(pc, "id");
  for (const auto& m : map) {
    *px = static_cast<float>(m.position.x());
    *py = static_cast<float>(m.position.y());
    *pz = static_cast<float>(m.position.z());
    *ps = static_cast<float>(std::sqrt(std::max(0.0, m.covariance.trace())));
    *pid = static_cast<float>(m.id);
    ++px, ++py, ++pz, ++ps, ++pid;
  }
  return pc;
}

visualization_msgs::MarkerArray toEllipsoidMarkers(std::vector<slam::MapPoint> map, const std_msgs::Header& header,
                                                   double sigma, int max_count, int* skipped) {
  if (static_cast<int>(map.size()) > max_count) {
    std::nth_element(map.begin(), map.begin() + max_count, map.end(),
                     [](const slam::MapPoint& a, const slam::MapPoint& b) { return a.times_observed > b.times_observed; });
    map.resize(max_count);
  }
  visualization_msgs::MarkerArray out;
  visualization_msgs::Marker m;
  m.header = header;
  m.ns = "landmarks";
  m.action = visualization_msgs::Marker::DELETEALL;
  out.markers.push_back(m);
  m.action = visualization_msgs::Marker::ADD;
  m.type = visualization_msgs::Marker::SPHERE;
  *skipped = 0;
  for (const auto& lm : map) {
    geometry::CovarianceEllipsoid e;
    if (!lm.position.allFinite() || !geometry::covarianceEllipsoid(lm.covariance, sigma, &e)) {
      ++*skipped;
      continue;
    }
    m.id = static_cast<int32_t>(lm.id);
    m.pose = toPoseMsg(lm.position, e.orientation);
    m.scale.x = 2.0 * e.semi_axes[0];  // a SPHERE's scale is its diameter
    m.scale.y = 2.0 * e.semi_axes[1];
    m.scale.z = 2.0 * e.semi_axes[2];
    const double s = std::clamp((std::log10(e.semi_axes[0] / sigma) + 4.0) / 2.0, 0.0, 1.0);
    m.color.r = static_cast<float>(std::min(1.0, 2.0 * s));
    m.color.g = static_cast<float>(std::min(1.0, 2.0 * (1.0 - s)));
    m.color.b = 0.1f;
    m.color.a = 0.8f;
    out.markers.push_back(m);
  }
  return out;
}

void SlamPublisher::advertise(ros::NodeHandle& nh, const SlamNodeParams& params) {
  par_ = params;
  odom_ = nh.advertise<nav_msgs::Odometry>("slam/odometry", 10);
  path_pub_ = nh.advertise<nav_msgs::Path>("slam/path", 2, true);
  map_ = nh.advertise<sensor_msgs::PointCloud2>("slam/map", 2, true);
  state_ = nh.advertise<skin3d::SlamState>("slam/state", 10);
  if (par_.max_ellipsoids > 0) ellipsoids_ = nh.advertise<visualization_msgs::MarkerArray>("slam/landmark_ellipsoids", 2, true);
}

std::string SlamPublisher::publish(const ros::Time& stamp, const slam::SlamSystem& slam, const slam::StateRow& row,
                                   const slam::FrameStats& stats, std::size_t frame) {
  const auto& f = slam.filter();
  std_msgs::Header header;
  header.stamp = stamp;
  header.frame_id = par_.world_frame;
  tf_.sendTransform(toTransformMsg(header, par_.camera_frame, f.state()));
  const nav_msgs::Odometry od = toOdometryMsg(header, par_.camera_frame, f.state(), f.covariance());
  odom_.publish(od);
  geometry_msgs::PoseStamped ps;
  ps.header = header;
  ps.pose = od.pose.pose;
  path_.header = header;
  path_.poses.push_back(ps);
  path_pub_.publish(path_);  // latched: an rviz started after the end of a bag still gets the whole path
  state_.publish(toSlamStateMsg(header, f.state(), row, stats));
  // Latched: published whether or not someone listens, so that an rviz started later sees the latest map.
  std::string warning;
  if (par_.map_every > 0 && frame % static_cast<std::size_t>(par_.map_every) == 1) {
    const auto map = slam.map();
    map_.publish(toMapCloudMsg(map, header));
    if (par_.max_ellipsoids > 0) {
      int skipped = 0;
      ellipsoids_.publish(toEllipsoidMarkers(map, header, par_.ellipsoid_sigma, par_.max_ellipsoids, &skipped));
      if (skipped > 0)
        warning = std::to_string(skipped) + " of " + std::to_string(map.size()) +
                  " landmarks have a covariance with no ellipsoid (NaN or not positive definite): left out of "
                  "slam/landmark_ellipsoids";
    }
  }
  return warning;
}

}  // namespace ros_conv
}  // namespace skin3d
