// SPDX-License-Identifier: BSD-3-Clause
// rostest: the stereo_design nodelet publishes the Part I rig (config/part1_rig_design.yaml:
// b = 210 mm, 54.4 deg between the optical axes, working plane at 245 mm).
#include <gtest/gtest.h>
#include <nodelet/NodeletList.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <cmath>
#include <map>
#include <set>

namespace {
visualization_msgs::MarkerArray::ConstPtr g_markers;
void onMarkers(const visualization_msgs::MarkerArray::ConstPtr& m) { g_markers = m; }
}  // namespace

TEST(StereoDesignNodelet, PublishesFrustaOverlapEllipsoidsAndTf) {
  ros::NodeHandle nh;
  ros::Subscriber sub = nh.subscribe("stereo_design/markers", 1, onMarkers);
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(30.0);
  while (!g_markers && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(g_markers) << "no MarkerArray on stereo_design/markers within 30 s";

  std::map<std::string, int> count;
  for (const auto& m : g_markers->markers) {
    ++count[m.ns];
    EXPECT_EQ(m.header.frame_id, "stereo_rig");
  }
  EXPECT_EQ(count["frustum_left"], 1);
  EXPECT_EQ(count["frustum_right"], 1);
  EXPECT_EQ(count["overlap"], 1);
  EXPECT_GE(count["ellipsoids"], 10);
  for (const auto& m : g_markers->markers) {
    if (m.ns == "overlap") {
      ASSERT_GE(m.points.size(), 3u);
      for (const auto& p : m.points) EXPECT_NEAR(p.z, 0.245, 1e-9);  // on the working plane, in metres
    }
    if (m.ns == "ellipsoids") {
      EXPECT_NEAR(m.pose.position.z, 0.245, 1e-6);
      // 1-sigma of a few hundredths of a millimetre at scale 1: sub-millimetre, non-degenerate.
      EXPECT_GT(m.scale.x, 0.0);
      EXPECT_LT(m.scale.x, 1e-3);
      EXPECT_GE(m.scale.x, m.scale.z);
    }
    if (m.ns == "frustum_left") {
      // Starts at the left optical centre, 105 mm left of the rig origin.
      ASSERT_FALSE(m.points.empty());
      EXPECT_NEAR(m.points[0].x, -0.105, 1e-12);
    }
  }

  // The nodelet with a bad ~config logged an error and stayed loaded; the manager is alive with both.
  nodelet::NodeletList list;
  ASSERT_TRUE(ros::service::call("manager/list", list)) << "nodelet manager is gone";
  std::set<std::string> loaded(list.response.nodelets.begin(), list.response.nodelets.end());
  EXPECT_TRUE(loaded.count("/stereo_design"));
  EXPECT_TRUE(loaded.count("/stereo_design_bad"));

  geometry_msgs::TransformStamped l, r;
  ASSERT_NO_THROW(l = buffer.lookupTransform("stereo_rig", "stereo_left_optical_frame", ros::Time(0), ros::Duration(10.0)));
  ASSERT_NO_THROW(r = buffer.lookupTransform("stereo_rig", "stereo_right_optical_frame", ros::Time(0), ros::Duration(10.0)));
  const double dx = r.transform.translation.x - l.transform.translation.x;
  EXPECT_NEAR(dx, 0.210, 1e-9);
  // Angle between the optical axes from the two quaternions: relative rotation angle.
  const auto& ql = l.transform.rotation;
  const auto& qr = r.transform.rotation;
  const double dot = std::abs(ql.w * qr.w + ql.x * qr.x + ql.y * qr.y + ql.z * qr.z);
  EXPECT_NEAR(2.0 * std::acos(std::min(1.0, dot)) * 180.0 / M_PI, 54.4, 1e-6);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_stereo_design_nodelet");
  return RUN_ALL_TESTS();
}
