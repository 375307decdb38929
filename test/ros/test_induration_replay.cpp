// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file test_induration_replay.cpp
 * @brief rostest of skin3d/induration through launch/replay_workpiece.launch on a
 * reduced bag made at build time (a quarter-resolution workpiece, or a half-resolution skin scene): the reports
 * against the generator's ground truth (BAG.truth.yaml; loose guards of the ROS path, the core's accuracy is
 * tested in test_induration), the height map, the results directory through ~save_results, and bad input that
 * must not stop either nodelet.
 *
 * Workpiece truth (`plateaus`): every plateau is checked. Skin truth (`plaques`): every plaque of at least
 * ~min_plaque_mm in the working band (its normal within ~max_incidence_deg of the rays to both cameras, the
 * induration nodelet's max_incidence_deg) is checked; the others are listed, not checked.
 *
 * Parameters (private): ~truth (BAG.truth.yaml), ~results (the launch's results directory), ~frames (2),
 * ~height_tol_mm (0.05), ~centroid_tol_mm (2.0), ~timeout (s of wall time for the reports, 200),
 * ~min_plaque_mm (0.1), ~max_incidence_deg (60).
 */
#include <gtest/gtest.h>
#include <rosgraph_msgs/Clock.h>
#include <rosgraph_msgs/Log.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <skin3d/IndurationReport.h>
#include <skin3d/SaveResults.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

namespace {

struct Listener {
  std::mutex m;
  std::vector<skin3d::IndurationReport> reports;
  std::vector<sensor_msgs::Image> height_maps;  // header and encoding only (data dropped)
  std::vector<rosgraph_msgs::Log> errors;
  void onReport(const skin3d::IndurationReport::ConstPtr& r) {
    std::lock_guard<std::mutex> l(m);
    reports.push_back(*r);
  }
  void onHeight(const sensor_msgs::Image::ConstPtr& h) {
    std::lock_guard<std::mutex> l(m);
    sensor_msgs::Image meta = *h;
    meta.data.clear();
    height_maps.push_back(meta);
  }
  void onLog(const rosgraph_msgs::Log::ConstPtr& log) {
    std::lock_guard<std::mutex> l(m);
    if (log->level >= rosgraph_msgs::Log::WARN) errors.push_back(*log);  // a dropped message: a warning
  }
  size_t numReports() {
    std::lock_guard<std::mutex> l(m);
    return reports.size();
  }
  bool hasError(const std::string& text) {
    std::lock_guard<std::mutex> l(m);
    for (const auto& e : errors)
      if (e.msg.find(text) != std::string::npos) return true;
    return false;
  }
};

Listener listener;

/** A raised region of the truth that the reports must contain. */
struct Target {
  int id = 0;
  double height = 0;  // m (top height for a skin plaque)
  Eigen::Vector3d centroid;
};

/** The truth's plateaus (workpiece), or its plaques in the working band (skin); the rest printed. */
std::vector<Target> targets(const YAML::Node& truth, double min_plaque_mm, double max_incidence_deg) {
  std::vector<Target> out;
  const bool skin = static_cast<bool>(truth["plaques"]);
  const YAML::Node list = skin ? truth["plaques"] : truth["plateaus"];
  if (!list || !list.IsSequence()) return out;
  Eigen::Vector3d right_centre = Eigen::Vector3d::Zero();
  if (skin) {
    const auto rc = truth["rig_true"]["right_centre_in_left_m"].as<std::vector<double>>();
    right_centre = Eigen::Vector3d(rc.at(0), rc.at(1), rc.at(2));
  }
  for (const auto& p : list) {
    Target t;
    t.id = p["id"].as<int>();
    t.height = p["height_mm"].as<double>() * 1e-3;
    const auto c = p["centroid_left_m"].as<std::vector<double>>();
    t.centroid = Eigen::Vector3d(c.at(0), c.at(1), c.at(2));
    if (skin) {
      const auto nv = p["normal_left"].as<std::vector<double>>();
      const Eigen::Vector3d n(nv.at(0), nv.at(1), nv.at(2));
      const double il = std::acos(n.dot(-t.centroid.normalized())) * 180.0 / M_PI;
      const double ir = std::acos(n.dot((right_centre - t.centroid).normalized())) * 180.0 / M_PI;
      if (t.height < min_plaque_mm * 1e-3 || std::max(il, ir) > max_incidence_deg) {
        std::printf("plaque %d (%.3f mm, incidence %.0f / %.0f deg): not checked (below %.2f mm or outside the "
                    "working band of %.0f deg)\n", t.id, t.height * 1e3, il, ir, min_plaque_mm, max_incidence_deg);
        continue;
      }
    }
    out.push_back(t);
  }
  return out;
}

bool waitFor(const std::function<bool()>& cond, double seconds) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::WallTime::now() < end) {
    if (cond()) return true;
    ros::WallDuration(0.05).sleep();
  }
  return cond();
}

sensor_msgs::CameraInfo cameraInfo(const std::string& frame, int width, int height, double tx, double fx = 100.0) {
  sensor_msgs::CameraInfo c;
  c.header.frame_id = frame;
  c.width = width;
  c.height = height;
  c.distortion_model = "plumb_bob";
  c.D.assign(5, 0.0);
  c.K = {fx, 0, width / 2.0, 0, fx, height / 2.0, 0, 0, 1};
  c.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  c.P = {fx, 0, width / 2.0, -fx * tx, 0, fx, height / 2.0, 0, 0, 0, 1, 0};
  return c;
}

sensor_msgs::Image image(const std::string& frame, int width, int height) {
  sensor_msgs::Image img;
  img.header.frame_id = frame;
  img.width = width;
  img.height = height;
  img.encoding = sensor_msgs::image_encodings::MONO8;
  img.step = width;
  img.data.resize(static_cast<size_t>(width) * height);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<uint8_t>((i * 2654435761u) >> 24);
  return img;
}

}  // namespace

// The bag's frames: a report per frame, with the true plateaus or plaques at their true heights and places.
TEST(IndurationReplay, ReportsMatchTheTruth) {
  ros::NodeHandle pnh("~");
  std::string truth_path;
  ASSERT_TRUE(pnh.getParam("truth", truth_path)) << "~truth not set";
  int frames = 2;
  double height_tol_mm = 0.05, centroid_tol_mm = 2.0, timeout = 200.0;
  pnh.param("frames", frames, 2);
  pnh.param("height_tol_mm", height_tol_mm, 0.05);
  pnh.param("centroid_tol_mm", centroid_tol_mm, 2.0);
  pnh.param("timeout", timeout, 200.0);
  double min_plaque_mm = 0.1, max_incidence_deg = 60.0;
  pnh.param("min_plaque_mm", min_plaque_mm, 0.1);
  pnh.param("max_incidence_deg", max_incidence_deg, 60.0);

  // Every frame of the bag (the dense stereo queue holds them), or at least one before the timeout.
  waitFor([&] { return static_cast<int>(listener.numReports()) >= frames; }, timeout);
  std::lock_guard<std::mutex> l(listener.m);
  ASSERT_GE(listener.reports.size(), 1u) << "no induration/report within " << timeout << " s";
  EXPECT_EQ(static_cast<int>(listener.reports.size()), frames);

  const YAML::Node truth = YAML::LoadFile(truth_path);
  const std::vector<Target> plateaus = targets(truth, min_plaque_mm, max_incidence_deg);
  ASSERT_FALSE(plateaus.empty()) << truth_path << " has no plateaus, or no plaque in the working band to check";
  for (const auto& report : listener.reports) {
    SCOPED_TRACE("report at t = " + std::to_string(report.header.stamp.toSec()));
    EXPECT_EQ(report.header.frame_id, "stereo_left_optical_frame");
    for (const auto& w : report.warnings) std::printf("warning: %s\n", w.c_str());
    // Every plateau is found (each by its own plaque); extra raised regions are reported, not failed here (the
    // core's segmentation is tested in test_induration).
    EXPECT_GE(report.plaques.size(), plateaus.size());
    if (report.plaques.size() > plateaus.size())
      std::printf("note: %zu plaques for %zu plateaus\n", report.plaques.size(), plateaus.size());
    std::vector<const skin3d::Plaque*> used;
    for (const auto& p : plateaus) {
      const double h_true = p.height;
      const Eigen::Vector3d& c_true = p.centroid;
      const skin3d::Plaque* best = nullptr;
      double best_d = 1e9;
      for (const auto& q : report.plaques) {
        const double d = (Eigen::Vector3d(q.centroid.x, q.centroid.y, q.centroid.z) - c_true).norm();
        if (d < best_d) best_d = d, best = &q;
      }
      ASSERT_NE(best, nullptr);
      EXPECT_EQ(std::count(used.begin(), used.end(), best), 0) << "plateau " << p.id
                                                               << " shares its nearest plaque with another";
      used.push_back(best);
      std::printf("plateau %d: height %.3f mm, measured top %.3f mm (interior mean %.3f, max %.3f, PASI %d), centroid off by %.3f mm\n",
                  p.id, h_true * 1e3, best->top_height * 1e3, best->mean_height * 1e3, best->max_height * 1e3,
                  static_cast<int>(best->pasi_class), best_d * 1e3);
      EXPECT_LT(best_d, centroid_tol_mm * 1e-3) << "plateau " << p.id;
      EXPECT_NEAR(best->top_height, h_true, height_tol_mm * 1e-3) << "plateau " << p.id;
      EXPECT_GT(best->area, 0.0);
    }
  }
  ASSERT_FALSE(listener.height_maps.empty()) << "no induration/height_map";
  for (const auto& h : listener.height_maps) {
    EXPECT_EQ(h.encoding, sensor_msgs::image_encodings::TYPE_32FC1);
    EXPECT_EQ(h.header.frame_id, "stereo_left_optical_frame");
    EXPECT_GT(h.width, 0u);
  }
}

// ~save_results writes the results directory of docs/design.md.
TEST(IndurationReplay, SaveResults) {
  ros::NodeHandle pnh("~");
  std::string results;
  ASSERT_TRUE(pnh.getParam("results", results)) << "~results not set";
  const std::vector<std::string> files = {"induration.yaml", "height_map.png", "surface.ply"};
  for (const auto& f : files) std::filesystem::remove(std::filesystem::path(results) / f);
  ASSERT_TRUE(ros::service::waitForService("induration/save_results", ros::Duration(10.0)));
  skin3d::SaveResults srv;  // empty directory: the node's ~results
  ASSERT_TRUE(ros::service::call("induration/save_results", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  for (const auto& f : files) {
    const std::filesystem::path p = std::filesystem::path(results) / f;
    EXPECT_TRUE(std::filesystem::exists(p)) << p;
    if (std::filesystem::exists(p)) {
      EXPECT_GT(std::filesystem::file_size(p), 0u) << p;
    }
  }
  const YAML::Node y = YAML::LoadFile((std::filesystem::path(results) / "induration.yaml").string());
  EXPECT_TRUE(y.IsMap());

  // A directory that cannot be made is an answer, not a crash.
  skin3d::SaveResults bad;
  bad.request.directory = "/proc/skin3d_cannot_write_here";
  ASSERT_TRUE(ros::service::call("induration/save_results", bad));
  EXPECT_FALSE(bad.response.success);
  EXPECT_FALSE(bad.response.message.empty());
}

// Bad input drops the frame with a warning that names the topic and the problem; the nodelet keeps running.
/** A mono8 image as image_transport's compressed transport carries it (PNG). */
sensor_msgs::CompressedImage compressed(const sensor_msgs::Image& img) {
  const cv::Mat m(static_cast<int>(img.height), static_cast<int>(img.width), CV_8UC1,
                  const_cast<uint8_t*>(img.data.data()), img.step);
  sensor_msgs::CompressedImage c;
  c.header = img.header;
  c.format = "mono8; png compressed mono8";
  cv::imencode(".png", m, c.data);
  return c;
}

TEST(IndurationReplay, BadInputKeepsRunning) {
  ros::NodeHandle nh, pnh("~");
  std::string transport = "raw";  // the nodelet's ~image_transport: the bad input goes where it listens
  pnh.param<std::string>("image_transport", transport, transport);
  const bool z = transport == "compressed";
  ros::Publisher li = z ? nh.advertise<sensor_msgs::CompressedImage>("stereo/left/image_raw/compressed", 2)
                        : nh.advertise<sensor_msgs::Image>("stereo/left/image_raw", 2);
  ros::Publisher ri = z ? nh.advertise<sensor_msgs::CompressedImage>("stereo/right/image_raw/compressed", 2)
                        : nh.advertise<sensor_msgs::Image>("stereo/right/image_raw", 2);
  ros::Publisher lc = nh.advertise<sensor_msgs::CameraInfo>("stereo/left/camera_info", 2);
  ros::Publisher rc = nh.advertise<sensor_msgs::CameraInfo>("stereo/right/camera_info", 2);
  // The nodelets' throttled errors count simulated time, which stopped with the bag: move it on before each
  // case, or the second error at the same call site would be throttled away.
  ros::Publisher clock = nh.advertise<rosgraph_msgs::Clock>("/clock", 1);
  double now = 5000.0;
  auto tick = [&] {
    rosgraph_msgs::Clock c;
    now += 10.0;
    c.clock = ros::Time(now);
    clock.publish(c);
    ros::WallDuration(0.3).sleep();
    return now;
  };
  ASSERT_TRUE(waitFor([&] { return li.getNumSubscribers() > 0 && ri.getNumSubscribers() > 0 &&
                                   lc.getNumSubscribers() > 0 && rc.getNumSubscribers() > 0 &&
                                   clock.getNumSubscribers() > 0; }, 10.0));

  auto publishPair = [&](double stamp, sensor_msgs::Image l, sensor_msgs::CameraInfo lci, sensor_msgs::Image r,
                         sensor_msgs::CameraInfo rci) {
    const ros::Time t(stamp);
    l.header.stamp = r.header.stamp = lci.header.stamp = rci.header.stamp = t;
    lc.publish(lci);
    rc.publish(rci);
    if (z) {
      li.publish(compressed(l));
      ri.publish(compressed(r));
    } else {
      li.publish(l);
      ri.publish(r);
    }
  };
  const std::string L = "stereo_left_optical_frame", R = "stereo_right_optical_frame";
  // Left and right of different sizes.
  publishPair(tick(), image(L, 64, 48), cameraInfo(L, 64, 48, 0.0), image(R, 80, 48), cameraInfo(R, 80, 48, 0.1));
  EXPECT_TRUE(waitFor([] { return listener.hasError("differ in size"); }, 20.0))
      << "no error about the left/right size mismatch on /rosout";
  // An uncalibrated camera_info (K = 0).
  sensor_msgs::CameraInfo uncal = cameraInfo(L, 64, 48, 0.0);
  uncal.K.fill(0.0);
  publishPair(tick(), image(L, 64, 48), uncal, image(R, 64, 48), cameraInfo(R, 64, 48, 0.1));
  EXPECT_TRUE(waitFor([] { return listener.hasError("uncalibrated"); }, 20.0))
      << "no error about the uncalibrated camera_info on /rosout";
  if (z) {  // a compressed image that does not decode
    sensor_msgs::CompressedImage junk = compressed(image(L, 64, 48));
    junk.header.stamp = ros::Time(tick());
    junk.data.assign(100, 7);
    li.publish(junk);
    EXPECT_TRUE(waitFor([] { return listener.hasError("cannot decode"); }, 20.0))
        << "no error about the undecodable compressed image on /rosout";
  }
  // Still alive: the manager answers the service.
  skin3d::SaveResults srv;
  srv.request.directory = ::testing::TempDir() + "skin3d_induration_rostest_alive";  // $TEST_TMPDIR/ or /tmp/
  EXPECT_TRUE(ros::service::call("induration/save_results", srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_induration_replay");
  ros::NodeHandle nh;
  ros::Subscriber s1 = nh.subscribe("induration/report", 10, &Listener::onReport, &listener);
  ros::Subscriber s2 = nh.subscribe("induration/height_map", 10, &Listener::onHeight, &listener);
  ros::Subscriber s3 = nh.subscribe("/rosout", 1000, &Listener::onLog, &listener);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
