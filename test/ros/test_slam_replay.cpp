// SPDX-License-Identifier: BSD-3-Clause
// rostest of a thesis experiment through launch/replay_globe.launch (experiment 1, 2 or 3 on a 40-frame
// landmark bag made at build time): every frame's slam/odometry against the simulator's ground truth.
// Parameters (private): ~frames (frames in the bag), ~rms_bound_m (bound on the RMS position error).
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>

#include <skin3d/SaveResults.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <mutex>
#include <vector>

#include <unistd.h>

#include "skin3d/sim/globe.h"

namespace {
std::mutex m;
std::vector<nav_msgs::Odometry> odometry;
void onOdom(const nav_msgs::Odometry::ConstPtr& o) {
  std::lock_guard<std::mutex> l(m);
  odometry.push_back(*o);
}
}  // namespace

TEST(SlamReplay, TrajectoryAgainstGroundTruth) {
  ros::NodeHandle nh, pnh("~");
  int frames = 40;
  double bound = 0.0;
  pnh.param("frames", frames, 40);
  ASSERT_TRUE(pnh.getParam("rms_bound_m", bound)) << "~rms_bound_m not set";
  ros::Subscriber s = nh.subscribe("slam/odometry", 100, onOdom);
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(90.0);
  size_t n = 0;
  while (ros::WallTime::now() < end) {
    ros::spinOnce();
    {
      std::lock_guard<std::mutex> l(m);
      n = odometry.size();
    }
    if (static_cast<int>(n) >= frames) break;
    ros::WallDuration(0.05).sleep();
  }
  std::lock_guard<std::mutex> l(m);
  // Played at 1x with a queue of 10 frames: every frame is processed.
  ASSERT_EQ(static_cast<int>(odometry.size()), frames);
  const skin3d::sim::GlobeSimulator sim{skin3d::sim::GlobeConfig()};  // the bag's generator and defaults
  double ss = 0.0;
  for (const auto& o : odometry) {
    const double t = o.header.stamp.toSec() - 1000.0;  // make_dataset's bags start at 1000 s
    const Eigen::Vector3d truth = sim.poseWorldLeft(t).translation();
    const Eigen::Vector3d p(o.pose.pose.position.x, o.pose.pose.position.y, o.pose.pose.position.z);
    ss += (p - truth).squaredNorm();
  }
  const double rms = std::sqrt(ss / odometry.size());
  std::printf("RMS position error over %zu frames: %.3f mm (bound %.3f mm)\n", odometry.size(), 1e3 * rms, 1e3 * bound);
  EXPECT_LT(rms, bound);

  // The results directory written by the nodelet: the ground truth it received on ground_truth/pose
  // gives the ATE in summary.yaml (the same figure as above, from the nodelet's own pairing), and
  // parameters.yaml lists the effective parameters.
  ros::ServiceClient save = nh.serviceClient<skin3d::SaveResults>("eskf_slam/save_results");
  ASSERT_TRUE(save.waitForExistence(ros::Duration(5.0)));
  skin3d::SaveResults srv;
  srv.request.directory = ::testing::TempDir() + "skin3d_slam_replay_" + std::to_string(::getpid());
  ASSERT_TRUE(save.call(srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  const YAML::Node summary = YAML::LoadFile(srv.request.directory + "/summary.yaml");
  ASSERT_TRUE(summary["ate"]) << "no ATE: the nodelet did not record the ground truth";
  EXPECT_EQ(summary["ate"]["pairs"].as<int>(), frames);
  // the live odometry is the filter's; the smoother (on by default) writes trajectory.tum and the ATE from its
  // own trajectory, and keeps the filter's as trajectory_filter.tum: the same poses as the odometry
  const bool smoothed = summary["trajectory"] && summary["trajectory"].as<std::string>().rfind("smoother", 0) == 0;
  if (!smoothed) {
    EXPECT_NEAR(summary["ate"]["rmse_mm"].as<double>(), 1e3 * rms, 1e-3);
  } else {
    std::ifstream tum(srv.request.directory + "/trajectory_filter.tum");
    ASSERT_TRUE(tum.good()) << "the smoother ran but trajectory_filter.tum is missing";
    std::string line;
    double ssf = 0.0;
    int rows = 0;
    while (std::getline(tum, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream in(line);
      double t, x, y, z;
      in >> t >> x >> y >> z;
      ssf += (Eigen::Vector3d(x, y, z) - sim.poseWorldLeft(t - 1000.0).translation()).squaredNorm();
      ++rows;
    }
    ASSERT_EQ(rows, frames);
    EXPECT_NEAR(1e3 * std::sqrt(ssf / rows), 1e3 * rms, 1e-3) << "trajectory_filter.tum is not the live odometry";
  }
  const YAML::Node params = YAML::LoadFile(srv.request.directory + "/parameters.yaml");
  ASSERT_TRUE(params["parameters"]["use_gyro"]);
  bool gyro = false;
  pnh.param("gyro", gyro, false);
  EXPECT_EQ(params["parameters"]["use_gyro"].as<bool>(), gyro);
  EXPECT_TRUE(std::ifstream(srv.request.directory + "/ground_truth.tum").good());
  EXPECT_TRUE(std::ifstream(srv.request.directory + "/rig_covariance.csv").good());
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_slam_replay");
  return RUN_ALL_TESTS();
}
