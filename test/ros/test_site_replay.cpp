// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file test_site_replay.cpp
 * @brief rostest of skin3d/site_fusion through launch/replay_sweep.launch on a reduced sweep made at build time:
 * every pair reaches the site (site/frame), the operator's view arrives (site/coverage, site/points with height and
 * sigma fields, on the limb), ~save_results writes the site, and site.yaml matches the generator's truth
 * (BAG.truth.yaml, in world = the first left optical frame) with the reduced sweep's bars of test_site_scan: every
 * true plaque of at least 0.2 mm that some pair sees within 45 deg found exactly once, its top within
 * max(20 um, 3 x its stated sigma), its PASI class right; no site plaque that no true plaque claims.
 *
 * Parameters (private): ~truth, ~results (the nodelet's ~results), ~frames (pairs in the bag), ~timeout (s of wall
 * time for all the pairs), ~poses (the nodelet's: ground_truth/pose or tf).
 */
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <skin3d/SaveResults.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/TransformStamped.h>
#include <skin3d/SiteFrameReport.h>
#include <tf2_ros/transform_broadcaster.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "../integration/site_truth.h"

namespace {

struct Listener {
  std::mutex m;
  std::vector<skin3d::SiteFrameReport> frames;
  sensor_msgs::Image coverage;  // the last one
  sensor_msgs::PointCloud2 points;
  int coverage_count = 0, points_count = 0;
  void onFrame(const skin3d::SiteFrameReport::ConstPtr& r) {
    std::lock_guard<std::mutex> l(m);
    frames.push_back(*r);
  }
  void onCoverage(const sensor_msgs::Image::ConstPtr& c) {
    std::lock_guard<std::mutex> l(m);
    coverage = *c;
    ++coverage_count;
  }
  void onPoints(const sensor_msgs::PointCloud2::ConstPtr& p) {
    std::lock_guard<std::mutex> l(m);
    points = *p;
    ++points_count;
  }
};

Listener listener;

}  // namespace

TEST(SiteReplay, EveryPairReachesTheSiteAndTheOperatorSeesIt) {
  ros::NodeHandle pnh("~");
  int frames = 5;
  double timeout = 400;
  pnh.param("frames", frames, frames);
  pnh.param("timeout", timeout, timeout);
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout);
  while (ros::ok() && ros::WallTime::now() < end) {
    {
      std::lock_guard<std::mutex> l(listener.m);
      if (static_cast<int>(listener.frames.size()) >= frames && listener.points_count > 0) break;
    }
    ros::WallDuration(0.2).sleep();
  }
  std::lock_guard<std::mutex> l(listener.m);
  ASSERT_EQ(static_cast<int>(listener.frames.size()), frames) << "site/frame reports within " << timeout << " s";
  for (std::size_t k = 0; k < listener.frames.size(); ++k) {
    const auto& f = listener.frames[k];
    EXPECT_EQ(f.index, static_cast<int>(k));
    EXPECT_TRUE(f.fused) << "pair " << k << " left out: " << f.reason;
    EXPECT_EQ(f.header.frame_id, "world");
    EXPECT_EQ(f.frames_fused, static_cast<int>(k) + 1);
    if (k > 0) {
      EXPECT_GT(f.overlap, 0.2) << "pair " << k;
      EXPECT_LT(f.correction_rms, 5e-3) << "pair " << k;
    }
  }
  EXPECT_GE(listener.coverage_count, 1);
  EXPECT_EQ(listener.coverage.encoding, "bgr8");
  EXPECT_GT(listener.coverage.width, 100u);
  // the cloud: x y z height sigma frames, in world; every point on the limb: the truth's axis and radius
  ASSERT_GE(listener.points_count, 1);
  const auto& pc = listener.points;
  EXPECT_EQ(pc.header.frame_id, "world");
  ASSERT_GT(pc.width * pc.height, 1000u);
  bool has_height = false, has_sigma = false;
  for (const auto& f : pc.fields) {
    has_height |= f.name == "height";
    has_sigma |= f.name == "sigma";
  }
  ASSERT_TRUE(has_height && has_sigma);
  std::string truth_path;
  ASSERT_TRUE(pnh.getParam("truth", truth_path));
  const YAML::Node limb = YAML::LoadFile(truth_path)["limb"];
  ASSERT_TRUE(limb && limb["axis_point_left_m"] && limb["axis_direction_left"] && limb["semi_axes_mm"])
      << truth_path << " holds no limb axis (limb.axis_point_left_m, axis_direction_left, semi_axes_mm)";
  const Eigen::Vector3d c = skin3d_test::vec(limb["axis_point_left_m"]);
  const Eigen::Vector3d a = skin3d_test::vec(limb["axis_direction_left"]).normalized();
  const double r_min = 1e-3 * std::min(limb["semi_axes_mm"][0].as<double>(), limb["semi_axes_mm"][1].as<double>());
  const double r_max = 1e-3 * std::max(limb["semi_axes_mm"][0].as<double>(), limb["semi_axes_mm"][1].as<double>());
  sensor_msgs::PointCloud2ConstIterator<float> x(pc, "x"), h(pc, "height");
  int off = 0, n = 0, bad = 0;
  for (; x != x.end(); ++x, ++h, ++n) {  // world = the first left optical frame, as the truth's "_left" figures
    const Eigen::Vector3d d = Eigen::Vector3d(x[0], x[1], x[2]) - c;
    const double r = (d - d.dot(a) * a).norm();
    off += r < r_min - 1e-3 || r > r_max + 2.5e-3;  // the skin, or a plaque on it
    bad += !std::isfinite(h[0]);
  }
  EXPECT_EQ(bad, 0);
  EXPECT_LT(off, n / 100) << off << " of " << n << " points are not on the limb";
}

TEST(SiteReplay, SavedSiteMatchesTheTruth) {
  ros::NodeHandle pnh("~");
  std::string results, truth_path;
  ASSERT_TRUE(pnh.getParam("results", results));
  ASSERT_TRUE(pnh.getParam("truth", truth_path));
  const std::string dir = results + "_saved";
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(ros::service::waitForService("site_fusion/save_results", ros::Duration(10.0)));
  skin3d::SaveResults srv;
  srv.request.directory = dir;
  ASSERT_TRUE(ros::service::call("site_fusion/save_results", srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  for (const char* f : {"site.yaml", "site_height_map.png", "site_coverage.png", "site_surface.ply", "induration.yaml"})
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir) / f)) << f;
  const YAML::Node truth = YAML::LoadFile(truth_path);
  const YAML::Node site = YAML::LoadFile(dir + "/site.yaml");
  EXPECT_EQ(site["frame"].as<std::string>(""), "world");
  std::string poses = "ground_truth/pose";  // the source site.yaml names
  pnh.param<std::string>("poses", poses, poses);
  EXPECT_NE(site["source"].as<std::string>("").find(poses == "tf" ? "TF (world)" : poses), std::string::npos)
      << site["source"].as<std::string>("");
  EXPECT_EQ(site["surface"]["model"].as<std::string>(), "cylinder");
  // the frames agree where they overlap: with the generator's poses only the noise is left (under 10 um of rigid
  // disagreement at half resolution); a pose error, or points that are not skin, leave hundreds of um
  EXPECT_LT(site["seams"]["rigid_um"].as<double>(), 25.0);
  skin3d_test::expectPlaquesMatchTheTruth(truth, site);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_site_replay");
  ros::NodeHandle nh;
  ros::Subscriber s1 = nh.subscribe("site/frame", 100, &Listener::onFrame, &listener);
  ros::Subscriber s2 = nh.subscribe("site/coverage", 2, &Listener::onCoverage, &listener);
  ros::Subscriber s3 = nh.subscribe("site/points", 2, &Listener::onPoints, &listener);
  // ~poses: tf: the bag's poses (world <- stereo_left_optical_frame) republished as TF for the nodelet to look up
  std::string poses;
  ros::param::param<std::string>("~poses", poses, "ground_truth/pose");
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf;
  ros::Subscriber s4;
  if (poses == "tf") {
    tf = std::make_unique<tf2_ros::TransformBroadcaster>();
    s4 = nh.subscribe<geometry_msgs::PoseStamped>("ground_truth/pose", 1000, [&tf](const geometry_msgs::PoseStamped::ConstPtr& p) {
      geometry_msgs::TransformStamped t;
      t.header = p->header;
      t.child_frame_id = "stereo_left_optical_frame";
      t.transform.translation.x = p->pose.position.x;
      t.transform.translation.y = p->pose.position.y;
      t.transform.translation.z = p->pose.position.z;
      t.transform.rotation = p->pose.orientation;
      tf->sendTransform(t);
    });
  }
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
