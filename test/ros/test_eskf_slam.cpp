// SPDX-License-Identifier: BSD-3-Clause
// rostest of skin3d/eskf_slam through launch/replay_globe.launch: a small landmark bag is replayed (with the
// gyroscope), then this node feeds frames of its own (the same simulated globe, continuing the orbit) and
// every kind of bad input, and checks that the node keeps publishing, resets on a time jump back, and saves
// its results through the service.
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>
#include <skin3d/SaveResults.h>
#include <skin3d/SlamState.h>
#include <std_srvs/Empty.h>
#include <sys/stat.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <limits>
#include <mutex>

#include "skin3d/ros/conversions.h"
#include "skin3d/sim/globe.h"

using namespace skin3d;

namespace {

struct Listener {
  std::mutex m;
  int odometry = 0, states = 0;
  nav_msgs::Odometry last;
  ros::Time last_state_stamp;
  void onOdom(const nav_msgs::Odometry::ConstPtr& o) {
    std::lock_guard<std::mutex> l(m);
    ++odometry;
    last = *o;
  }
  void onState(const skin3d::SlamState::ConstPtr& s) {
    std::lock_guard<std::mutex> l(m);
    ++states;
    last_state_stamp = s->header.stamp;
  }
  int count() {
    std::lock_guard<std::mutex> l(m);
    return odometry;
  }
  nav_msgs::Odometry lastOdom() {
    std::lock_guard<std::mutex> l(m);
    return last;
  }
};

bool waitFor(const std::function<bool()>& cond, double seconds) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::WallTime::now() < end) {
    if (cond()) return true;
    ros::WallDuration(0.02).sleep();
  }
  return cond();
}

skin3d::LandmarkArray frame(const sim::GlobeSimulator& sim, int k, double t) {
  skin3d::LandmarkArray a;
  a.header.frame_id = "stereo_left_optical_frame";
  a.header.stamp = ros::Time(t);
  for (const auto& m : sim.measure(k))
    a.landmarks.push_back(ros_conv::toLandmarkMsg(m.position, m.covariance, m.descriptor, m.strength, m.uv_left, m.uv_right));
  return a;
}

bool exists(const std::string& p) {
  struct stat st;
  return stat(p.c_str(), &st) == 0;
}

}  // namespace

TEST(EskfSlam, ReplaysTheBagSurvivesBadInputAndSavesResults) {
  ros::NodeHandle nh;
  Listener l;
  ros::Subscriber so = nh.subscribe("slam/odometry", 100, &Listener::onOdom, &l);
  ros::Subscriber ss = nh.subscribe("slam/state", 100, &Listener::onState, &l);
  ros::Publisher pub = nh.advertise<skin3d::LandmarkArray>("stereo/landmarks", 10);
  ros::Publisher imu = nh.advertise<sensor_msgs::Imu>("imu/data", 10);
  tf2_ros::Buffer tf;
  tf2_ros::TransformListener tl(tf);
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // 1. The bag (40 frames at 10 Hz) goes through the SLAM: odometry for (nearly) every frame, and the TF.
  ASSERT_TRUE(waitFor([&] { return l.count() >= 30; }, 60.0)) << "only " << l.count() << " odometry messages from the bag";
  EXPECT_TRUE(waitFor([&] { return tf.canTransform("world", "stereo_left_optical_frame", ros::Time(0)); }, 5.0));
  // Wait until the bag is over (no new odometry for 1 s).
  int n = 0;
  do {
    n = l.count();
  } while (waitFor([&] { return l.count() != n; }, 1.5));
  EXPECT_GE(n, 38);
  {
    std::lock_guard<std::mutex> lk(l.m);
    EXPECT_GE(l.states, 38);
    // The orbit: 40 frames = 3.9 s at 0.15 rad/s on a 0.6 m circle = 0.35 m from the first camera pose.
    const auto& p = l.last.pose.pose.position;
    const Eigen::Vector3d truth = sim::GlobeSimulator(sim::GlobeConfig()).poseWorldLeft(3.9).translation();
    EXPECT_LT((Eigen::Vector3d(p.x, p.y, p.z) - truth).norm(), 0.01) << "the replayed trajectory is off by > 1 cm";
    EXPECT_GT(l.last.pose.covariance[0], 0.0);
  }

  // 2. Frames of our own, continuing the orbit, with bad input in between.
  const sim::GlobeSimulator sim{sim::GlobeConfig()};
  auto expectProcessed = [&](const skin3d::LandmarkArray& a, bool processed, const char* what) {
    const int before = l.count();
    pub.publish(a);
    const bool got = waitFor([&] { return l.count() > before; }, processed ? 10.0 : 1.0);
    EXPECT_EQ(got, processed) << what;
  };
  expectProcessed(frame(sim, 40, 1004.0), true, "a good frame after the bag");
  auto wrong_frame = frame(sim, 41, 1004.1);
  wrong_frame.header.frame_id = "some_other_frame";
  expectProcessed(wrong_frame, false, "landmarks in the wrong frame must be dropped");
  auto nan = frame(sim, 41, 1004.1);
  nan.landmarks[0].position.x = std::numeric_limits<double>::quiet_NaN();
  nan.landmarks[1].covariance[0] = -1.0;                                      // not positive definite
  nan.landmarks[2].covariance[4] = std::numeric_limits<double>::infinity();
  expectProcessed(nan, true, "a frame with a few bad landmarks is processed without them");
  expectProcessed(frame(sim, 41, 1004.1), false, "a repeated stamp must be dropped");
  skin3d::LandmarkArray empty;
  empty.header.frame_id = "stereo_left_optical_frame";
  empty.header.stamp = ros::Time(1004.2);
  expectProcessed(empty, true, "a frame without landmarks is a prediction step");
  sensor_msgs::Imu bad_imu;
  bad_imu.header.frame_id = "imu_link";
  bad_imu.header.stamp = ros::Time(1004.25);
  imu.publish(bad_imu);
  sensor_msgs::Imu nan_imu;
  nan_imu.header.frame_id = "stereo_left_optical_frame";
  nan_imu.header.stamp = ros::Time(1004.26);
  nan_imu.angular_velocity.x = std::numeric_limits<double>::quiet_NaN();
  imu.publish(nan_imu);
  expectProcessed(frame(sim, 43, 1004.3), true, "a good frame after bad gyro messages");
  const auto before_reset = l.lastOdom();
  EXPECT_TRUE(std::isfinite(before_reset.pose.pose.position.x));

  // 3. A jump back in time (the bag restarted) resets: the next frame defines the world again.
  expectProcessed(frame(sim, 0, 1000.0), true, "a frame 4 s in the past resets the SLAM");
  const auto after = l.lastOdom();
  EXPECT_NEAR(after.pose.pose.position.x, 0.0, 1e-12);
  EXPECT_NEAR(after.pose.pose.orientation.w, 1.0, 1e-12);
  expectProcessed(frame(sim, 1, 1000.1), true, "and it carries on");

  // 4. Services: save the results now, then reset.
  ros::ServiceClient save = nh.serviceClient<skin3d::SaveResults>("eskf_slam/save_results");
  ASSERT_TRUE(save.waitForExistence(ros::Duration(5.0)));
  skin3d::SaveResults srv;
  srv.request.directory = ::testing::TempDir() + "skin3d_eskf_slam_saved";
  ASSERT_TRUE(save.call(srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  for (const char* f : {"trajectory.tum", "map.ply", "state.csv", "summary.yaml"})
    EXPECT_TRUE(exists(srv.request.directory + "/" + f)) << f;
  std::ifstream tum(srv.request.directory + "/trajectory.tum");
  std::string line;
  int lines = 0;
  while (std::getline(tum, line)) lines += !line.empty() && line[0] != '#';
  EXPECT_EQ(lines, 2) << "two frames since the reset";
  srv.request.directory = "/proc/no_such_dir/x";
  ASSERT_TRUE(save.call(srv));
  EXPECT_FALSE(srv.response.success) << "writing to an impossible directory must fail with a message";
  EXPECT_NE(srv.response.message.find("cannot"), std::string::npos) << srv.response.message;
  ros::ServiceClient reset = nh.serviceClient<std_srvs::Empty>("eskf_slam/reset");
  std_srvs::Empty e;
  EXPECT_TRUE(reset.call(e));
  expectProcessed(frame(sim, 2, 1000.2), true, "after the reset service");
  EXPECT_NEAR(l.lastOdom().pose.pose.position.x, 0.0, 1e-12);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_eskf_slam");
  return RUN_ALL_TESTS();
}
