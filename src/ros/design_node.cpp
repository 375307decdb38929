// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the stereo_design nodelet's node (see include/skin3d/ros/design_node.h).
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>

#include "skin3d/geometry/design.h"

#include "skin3d/ros/design_node.h"

namespace skin3d {
namespace ros_run {
namespace {

namespace {
constexpr double kMm = 1e-3;

geometry_msgs::Point toPoint(const Eigen::Vector3d& p_mm) {
  geometry_msgs::Point p;
  p.x = p_mm.x() * kMm;
  p.y = p_mm.y() * kMm;
  p.z = p_mm.z() * kMm;
  return p;
}

std_msgs::ColorRGBA color(float r, float g, float b, float a) {
  std_msgs::ColorRGBA c;
  c.r = r;
  c.g = g;
  c.b = b;
  c.a = a;
  return c;
}

geometry_msgs::Quaternion toMsg(const Eigen::Quaterniond& q) {
  geometry_msgs::Quaternion m;
  m.w = q.w();
  m.x = q.x();
  m.y = q.y();
  m.z = q.z();
  return m;
}
}  // namespace

class StereoDesignNode {
 public:
  StereoDesignNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    std::string config;
    if (!pnh.getParam("config", config) || config.empty()) {
      ROS_ERROR("stereo_design: parameter ~config (path of a design YAML) is required; nothing is published");
      return;
    }
    pnh.param<std::string>("rig_frame", rig_frame_, "stereo_rig");
    pnh.param<std::string>("left_frame", left_frame_, "stereo_left_optical_frame");
    pnh.param<std::string>("right_frame", right_frame_, "stereo_right_optical_frame");
    pnh.param("ellipsoid_scale", ellipsoid_scale_, 100.0);
    if (!(ellipsoid_scale_ > 0.0)) {
      ROS_WARN("stereo_design: ~ellipsoid_scale = %g must be > 0; using 100", ellipsoid_scale_);
      ellipsoid_scale_ = 100.0;
    }
    geometry::DesignReport report;
    try {
      report = geometry::computeDesign(geometry::loadDesignConfig(config));
    } catch (const geometry::DesignConfigError& e) {
      ROS_ERROR("stereo_design: %s: %s", config.c_str(), e.what());
      return;
    }
    ROS_INFO_STREAM("stereo_design: " << report.config.name << "\n" << geometry::designReportTable(report));
    pub_ = nh.advertise<visualization_msgs::MarkerArray>("stereo_design/markers", 1, true);
    publishTf(report);
    pub_.publish(markers(report));
  }

  void publishTf(const geometry::DesignReport& r) {
    std::vector<geometry_msgs::TransformStamped> tfs;
    const auto add = [&](const std::string& child, const Eigen::Matrix3d& R, const Eigen::Vector3d& c) {
      geometry_msgs::TransformStamped t;
      t.header.stamp = ros::Time::now();
      t.header.frame_id = rig_frame_;
      t.child_frame_id = child;
      t.transform.translation.x = c.x() * kMm;
      t.transform.translation.y = c.y() * kMm;
      t.transform.translation.z = c.z() * kMm;
      t.transform.rotation = toMsg(Eigen::Quaterniond(R));
      tfs.push_back(t);
    };
    add(left_frame_, r.R_rig_left, r.c_left);
    add(right_frame_, r.R_rig_right, r.c_right);
    tf_.sendTransform(tfs);
  }

  visualization_msgs::MarkerArray markers(const geometry::DesignReport& r) const {
    visualization_msgs::MarkerArray out;
    const double Z = r.working_distance_mm;
    const auto base = [&](const std::string& ns, int type) {
      visualization_msgs::Marker m;
      m.header.frame_id = rig_frame_;
      m.header.stamp = ros::Time(0);
      m.ns = ns;
      m.id = static_cast<int>(out.markers.size());
      m.type = type;
      m.action = visualization_msgs::Marker::ADD;
      m.pose.orientation.w = 1.0;
      m.scale.x = m.scale.y = m.scale.z = 1.0;
      return m;
    };
    const auto frustum = [&](const std::string& ns, const Eigen::Vector3d& c, const std::vector<Eigen::Vector2d>& fp,
                             const std_msgs::ColorRGBA& col) {
      auto m = base(ns, visualization_msgs::Marker::LINE_LIST);
      m.scale.x = 0.001;
      m.color = col;
      for (size_t i = 0; i < fp.size(); ++i) {
        const Eigen::Vector3d a(fp[i].x(), fp[i].y(), Z), b(fp[(i + 1) % fp.size()].x(), fp[(i + 1) % fp.size()].y(), Z);
        m.points.push_back(toPoint(c));
        m.points.push_back(toPoint(a));
        m.points.push_back(toPoint(a));
        m.points.push_back(toPoint(b));
      }
      out.markers.push_back(m);
    };
    frustum("frustum_left", r.c_left, r.footprint_left, color(0.2f, 0.4f, 1.0f, 1.0f));
    frustum("frustum_right", r.c_right, r.footprint_right, color(1.0f, 0.3f, 0.2f, 1.0f));

    auto fill = base("overlap", visualization_msgs::Marker::TRIANGLE_LIST);
    fill.color = color(0.2f, 0.9f, 0.3f, 0.5f);
    // Fan triangulation of the convex overlap, both windings so that rviz shows it from either side.
    for (size_t i = 1; i + 1 < r.overlap.size(); ++i) {
      for (size_t k : {size_t(0), i, i + 1, size_t(0), i + 1, i})
        fill.points.push_back(toPoint(Eigen::Vector3d(r.overlap[k].x(), r.overlap[k].y(), Z)));
    }
    out.markers.push_back(fill);

    for (const auto& g : r.grid) {
      auto m = base("ellipsoids", visualization_msgs::Marker::SPHERE);
      m.pose.position = toPoint(g.X_est);
      Eigen::Matrix3d R = g.axis_dirs;
      if (R.determinant() < 0) R.col(2) = -R.col(2);
      m.pose.orientation = toMsg(Eigen::Quaterniond(R).normalized());
      m.scale.x = 2.0 * g.axes[0] * kMm * ellipsoid_scale_;
      m.scale.y = 2.0 * g.axes[1] * kMm * ellipsoid_scale_;
      m.scale.z = 2.0 * g.axes[2] * kMm * ellipsoid_scale_;
      m.color = color(1.0f, 0.8f, 0.1f, 0.8f);
      out.markers.push_back(m);
    }

    auto text = base("summary", visualization_msgs::Marker::TEXT_VIEW_FACING);
    text.pose.position = toPoint(Eigen::Vector3d(0.0, r.overlap_min.y() - 20.0, Z));
    text.scale.z = 0.012;
    text.color = color(1, 1, 1, 1);
    char buf[256];
    std::snprintf(buf, sizeof buf, "overlap %.0f mm^2, depth res %.3f mm/px, depth sigma %.3f mm (ellipsoids x%.0f)",
                  r.overlap_area_mm2, r.depth_resolution_mm, r.mean_depth_sigma_mm, ellipsoid_scale_);
    text.text = buf;
    out.markers.push_back(text);
    return out;
  }

  ros::Publisher pub_;
  tf2_ros::StaticTransformBroadcaster tf_;
  std::string rig_frame_, left_frame_, right_frame_;
  double ellipsoid_scale_ = 100.0;
};

}  // namespace

std::shared_ptr<void> startStereoDesign(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
  return std::make_shared<StereoDesignNode>(nh, pnh);
}

}  // namespace ros_run
}  // namespace skin3d

