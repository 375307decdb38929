// SPDX-License-Identifier: BSD-3-Clause
// make_dataset end to end: small bags are written by the real tool and read back with rosbag. The checks
// use only what a consumer of the bag has (camera_info, ground truth) plus the truth file, never the
// generator's internals.
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>
#include <sys/wait.h>
#include <topic_tools/shape_shifter.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <fstream>
#include <map>
#include <numeric>
#include <random>

#include "bag_reading.h"
#include "skin3d/ros/conversions.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/geometry/stereo_rig.h"

using namespace skin3d;

namespace {

const std::string kBin = SKIN3D_MAKE_DATASET_BIN;

std::string tmp(const std::string& name) { return ::testing::TempDir() + "skin3d_make_dataset_" + name; }

int run(const std::string& args, std::string* output = nullptr) {
  std::string out;
  FILE* p = popen((kBin + " " + args + " 2>&1").c_str(), "r");
  char buf[512];
  while (p && fgets(buf, sizeof buf, p)) out += buf;
  const int rc = p ? pclose(p) : -1;
  if (output) *output = out;
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

template <class M>
std::vector<M> read(const std::string& bag_path, const std::string& topic) {
  return skin3d::test::readTopic<M>(bag_path, topic);
}

// All messages of a bag, serialised, keyed by topic.
std::map<std::string, std::vector<std::vector<uint8_t>>> rawMessages(const std::string& bag_path) {
  rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
  rosbag::View view(bag);
  std::map<std::string, std::vector<std::vector<uint8_t>>> out;
  for (const auto& m : view) {
    const auto s = m.instantiate<topic_tools::ShapeShifter>();
    std::vector<uint8_t> buf(s->size());
    ros::serialization::OStream stream(buf.data(), buf.size());
    s->write(stream);
    out[m.getTopic()].push_back(buf);
  }
  return out;
}

Eigen::Isometry3d toIso(const geometry_msgs::PoseStamped& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(p.pose.position.x, p.pose.position.y, p.pose.position.z);
  T.linear() = Eigen::Quaterniond(p.pose.orientation.w, p.pose.orientation.x, p.pose.orientation.y,
                                  p.pose.orientation.z).normalized().toRotationMatrix();
  return T;
}

using skin3d::ros_conv::fromMsg;

Eigen::Vector3d vec3(const YAML::Node& n) { return Eigen::Vector3d(n[0].as<double>(), n[1].as<double>(), n[2].as<double>()); }

// Bilinear intensity of a mono8 image at (u, v); NaN outside.
double sample(const sensor_msgs::Image& img, const Eigen::Vector2d& uv) {
  const int u0 = static_cast<int>(std::floor(uv.x())), v0 = static_cast<int>(std::floor(uv.y()));
  if (u0 < 0 || v0 < 0 || u0 + 1 >= static_cast<int>(img.width) || v0 + 1 >= static_cast<int>(img.height))
    return std::nan("");
  const double a = uv.x() - u0, b = uv.y() - v0;
  const auto at = [&](int u, int v) { return static_cast<double>(img.data[static_cast<size_t>(v) * img.step + u]); };
  return (1 - a) * (1 - b) * at(u0, v0) + a * (1 - b) * at(u0 + 1, v0) + (1 - a) * b * at(u0, v0 + 1) +
         a * b * at(u0 + 1, v0 + 1);
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

double correlation(const std::vector<double>& a, const std::vector<double>& b) {
  const double ma = std::accumulate(a.begin(), a.end(), 0.0) / a.size();
  const double mb = std::accumulate(b.begin(), b.end(), 0.0) / b.size();
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return sab / std::sqrt(saa * sbb);
}

// Compares the two views' intensities at left-frame points, through the bag's own camera_info.
void expectViewsAgree(const std::string& bag, const std::vector<Eigen::Vector3d>& points_left, double max_median_dn,
                      double min_corr) {
  const auto li = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  const auto ri = read<sensor_msgs::CameraInfo>(bag, "stereo/right/camera_info");
  const auto limg = read<sensor_msgs::Image>(bag, "stereo/left/image_raw");
  const auto rimg = read<sensor_msgs::Image>(bag, "stereo/right/image_raw");
  ASSERT_FALSE(li.empty());
  ASSERT_FALSE(limg.empty());
  const auto rig = geometry::StereoRig::fromCameraInfo(fromMsg(li[0]), fromMsg(ri[0]));
  std::vector<double> a, b, diff;
  for (const auto& X : points_left) {
    Eigen::Vector2d uvl, uvr;
    if (!rig.project(X, &uvl, &uvr)) continue;
    const double il = sample(limg[0], uvl), ir = sample(rimg[0], uvr);
    if (std::isnan(il) || std::isnan(ir)) continue;
    a.push_back(il);
    b.push_back(ir);
    diff.push_back(std::abs(il - ir));
  }
  ASSERT_GT(a.size(), 100u) << "too few points seen by both cameras";
  EXPECT_LE(median(diff), max_median_dn);
  EXPECT_GE(correlation(a, b), min_corr);
}

}  // namespace

TEST(MakeDataset, GlobeLandmarksIsDeterministicAndSeedDependent) {
  ASSERT_EQ(run("globe-landmarks --quiet --frames 15 --seed 7 --out " + tmp("a.bag")), 0);
  ASSERT_EQ(run("globe-landmarks --quiet --frames 15 --seed 7 --out " + tmp("b.bag")), 0);
  ASSERT_EQ(run("globe-landmarks --quiet --frames 15 --seed 8 --out " + tmp("c.bag")), 0);
  const auto a = rawMessages(tmp("a.bag")), b = rawMessages(tmp("b.bag")), c = rawMessages(tmp("c.bag"));
  for (const char* topic : {"stereo/landmarks", "stereo/left/camera_info", "stereo/right/camera_info", "imu/data",
                            "ground_truth/pose"})
    EXPECT_GT(a.at(topic).size(), 0u) << topic;
  EXPECT_EQ(a.at("stereo/landmarks").size(), 15u);
  EXPECT_TRUE(a == b) << "same seed and config must give identical messages";
  EXPECT_FALSE(a.at("stereo/landmarks") == c.at("stereo/landmarks"));
  EXPECT_FALSE(a.at("imu/data") == c.at("imu/data"));
}

TEST(MakeDataset, RenderedDatasetsAreDeterministic) {
  // Rendering is multithreaded: the images must not depend on the thread schedule.
  ASSERT_EQ(run("globe-images --quiet --frames 2 --seed 4 --out " + tmp("ia.bag")), 0);
  ASSERT_EQ(run("globe-images --quiet --frames 2 --seed 4 --out " + tmp("ib.bag")), 0);
  const auto a = rawMessages(tmp("ia.bag")), b = rawMessages(tmp("ib.bag"));
  EXPECT_EQ(a.at("stereo/left/image_raw").size(), 2u);
  EXPECT_TRUE(a == b);
}

TEST(MakeDataset, GlobeLandmarksMatchTheTruthThroughCameraInfo) {
  const std::string bag = tmp("lm.bag");
  ASSERT_EQ(run("globe-landmarks --quiet --frames 30 --out " + bag), 0);
  const YAML::Node truth = YAML::LoadFile(tmp("lm.truth.yaml"));
  std::vector<Eigen::Vector3d> world;
  for (const auto& p : truth["landmarks_world_m"]) world.push_back(vec3(p));
  ASSERT_EQ(world.size(), 10000u);
  const double sigma = truth["pixel_sigma_px"].as<double>();
  const Eigen::Vector3d centre_w = vec3(truth["sphere"]["centre_world_m"]);
  const auto info = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  const auto poses = read<geometry_msgs::PoseStamped>(bag, "ground_truth/pose");
  const auto frames = read<skin3d::LandmarkArray>(bag, "stereo/landmarks");
  ASSERT_EQ(frames.size(), 30u);
  ASSERT_EQ(poses.size(), 30u);
  const geometry::PinholeCamera cam = geometry::PinholeCamera::fromCameraInfo(fromMsg(info[0]));
  size_t n = 0, matched = 0;
  double nees = 0.0;
  size_t n_nees = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    ASSERT_EQ(poses[k].header.stamp, frames[k].header.stamp);
    EXPECT_EQ(frames[k].header.frame_id, "stereo_left_optical_frame");
    EXPECT_GE(frames[k].landmarks.size(), 30u) << "frame " << k << ": too few landmarks for SLAM";
    const Eigen::Isometry3d T_L_W = toIso(poses[k]).inverse();
    std::vector<std::pair<Eigen::Vector2d, Eigen::Vector3d>> proj;
    const Eigen::Vector3d c = T_L_W * centre_w;
    for (const auto& m : world) {
      const Eigen::Vector3d X = T_L_W * m;
      if (X.z() > 0 && (X - c).dot(X) < 0) proj.emplace_back(cam.project(X), X);  // front side of the globe only
    }
    for (const auto& l : frames[k].landmarks) {
      ++n;
      const Eigen::Vector2d uv(l.u_left, l.v_left);
      double best = 1e9;
      Eigen::Vector3d X_true = Eigen::Vector3d::Zero();
      for (const auto& p : proj) {
        const double d = (p.first - uv).norm();
        if (d < best) {
        best = d;
        X_true = p.second;
      }
      }
      if (best > 6 * sigma) continue;
      ++matched;
      Eigen::Matrix3d C;
      for (int i = 0; i < 9; ++i) C(i / 3, i % 3) = l.covariance[i];
      const Eigen::Vector3d e = Eigen::Vector3d(l.position.x, l.position.y, l.position.z) - X_true;
      nees += e.dot(C.inverse() * e);
      ++n_nees;
    }
  }
  // Every measured landmark is the projection of a true one (within 6 sigma of pixel noise).
  EXPECT_GE(static_cast<double>(matched) / n, 0.995) << matched << " of " << n;
  // Covariances agree with the errors: the mean NEES of a 3-dof Gaussian is 3, and over N samples its
  // standard deviation is sqrt(6 / N) (0.02 for 10 000): +-0.2 leaves room only for linearisation error.
  ASSERT_GT(n_nees, 3000u);
  const double mean = nees / n_nees;
  std::cout << "globe-landmarks: " << matched << " of " << n << " measurements match a true landmark; mean NEES "
            << mean << " over " << n_nees << std::endl;
  EXPECT_NEAR(mean, 3.0, 0.2) << "over " << n_nees << " landmarks";
}

TEST(MakeDataset, GyroIntegratesToTheGroundTruthRotation) {
  const std::string bag = tmp("gyro.bag");
  ASSERT_EQ(run("globe-landmarks --quiet --frames 30 --out " + bag), 0);
  const YAML::Node truth = YAML::LoadFile(tmp("gyro.truth.yaml"));
  const double rate = truth["gyro"]["rate_hz"].as<double>(), sigma = truth["gyro"]["noise_rad_s"].as<double>();
  const auto imu = read<sensor_msgs::Imu>(bag, "imu/data");
  const auto poses = read<geometry_msgs::PoseStamped>(bag, "ground_truth/pose");
  ASSERT_GE(imu.size(), 280u);
  const ros::Time t0 = poses.front().header.stamp, t1 = poses.back().header.stamp;
  Eigen::Quaterniond q = Eigen::Quaterniond(toIso(poses.front()).linear());
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int n = 0;
  for (const auto& m : imu) {
    EXPECT_EQ(m.header.frame_id, "stereo_left_optical_frame");
    EXPECT_EQ(m.orientation_covariance[0], -1.0);
    if (m.header.stamp < t0 || m.header.stamp >= t1) continue;
    const Eigen::Vector3d w(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z);
    q = q * geometry::quatExp(w / rate);  // body-frame rate: right multiplication
    mean += w;
    ++n;
  }
  const Eigen::Quaterniond q_true(toIso(poses.back()).linear());
  const double err = geometry::quatLog(q_true.conjugate() * q).norm();
  // White noise integrates to sigma / rate * sqrt(n) per axis.
  EXPECT_LT(err, 4.0 * std::sqrt(3.0) * sigma / rate * std::sqrt(n)) << "integrated over " << n << " samples";
  mean /= n;
  const Eigen::Vector3d w_true = vec3(truth["orbit"]["angular_velocity_rig_rad_s"]);
  EXPECT_LT((mean - w_true).cwiseAbs().maxCoeff(), 4.0 * sigma / std::sqrt(n));
  EXPECT_NEAR(w_true.norm(), 0.15, 1e-9);  // the globe's spin, seen from the rig
}

TEST(MakeDataset, GlobeImagesViewsAgreeAndSilhouetteMatchesCameraInfo) {
  const std::string bag = tmp("img.bag");
  ASSERT_EQ(run("globe-images --quiet --ideal --frames 2 --out " + bag), 0);
  const YAML::Node truth = YAML::LoadFile(tmp("img.truth.yaml"));
  const Eigen::Vector3d centre_w = vec3(truth["sphere"]["centre_world_m"]);
  const double radius = truth["sphere"]["radius_m"].as<double>();
  const auto poses = read<geometry_msgs::PoseStamped>(bag, "ground_truth/pose");
  const auto li = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  const auto ri = read<sensor_msgs::CameraInfo>(bag, "stereo/right/camera_info");
  const auto limg = read<sensor_msgs::Image>(bag, "stereo/left/image_raw");
  ASSERT_EQ(limg.size(), 2u);
  EXPECT_EQ(limg[0].encoding, "mono8");
  const Eigen::Isometry3d T_L_W = toIso(poses[0]).inverse();
  const Eigen::Vector3d c = T_L_W * centre_w;
  const auto rig = geometry::StereoRig::fromCameraInfo(fromMsg(li[0]), fromMsg(ri[0]));

  // Surface points facing both cameras: same intensity in both views.
  std::vector<Eigen::Vector3d> pts;
  std::mt19937 rng(3);
  std::normal_distribution<double> nd(0, 1);
  while (pts.size() < 3000) {
    const Eigen::Vector3d n = Eigen::Vector3d(nd(rng), nd(rng), nd(rng)).normalized();
    const Eigen::Vector3d X = c + radius * n;
    if (n.dot(-X.normalized()) > 0.5 && n.dot((rig.rightCentre() - X).normalized()) > 0.5) pts.push_back(X);
  }
  expectViewsAgree(bag, pts, 4.0, 0.9);

  // The silhouette: just outside the limb is background, just inside is the globe.
  const geometry::PinholeCamera cam = geometry::PinholeCamera::fromCameraInfo(fromMsg(li[0]));
  const Eigen::Vector2d cuv = cam.project(c);
  int outside_bg = 0, inside_fg = 0, tested = 0;
  const Eigen::Vector3d axis = c.normalized();
  const Eigen::Vector3d e1 = axis.cross(Eigen::Vector3d::UnitY()).normalized(), e2 = axis.cross(e1);
  const double d = c.norm(), rho = std::sqrt(d * d - radius * radius);  // tangent length
  const double cone = std::asin(radius / d);
  for (int i = 0; i < 360; ++i) {
    const double a = 2 * M_PI * i / 360;
    const Eigen::Vector3d ray = std::cos(cone) * axis + std::sin(cone) * (std::cos(a) * e1 + std::sin(a) * e2);
    const Eigen::Vector2d limb = cam.project(rho * ray);
    const Eigen::Vector2d dir = (limb - cuv).normalized();
    const double out = sample(limg[0], limb + 3.0 * dir), in = sample(limg[0], limb - 3.0 * dir);
    if (std::isnan(out) || std::isnan(in)) continue;
    ++tested;
    outside_bg += std::abs(out - 0.05 * 255) <= 1.5;
    inside_fg += std::abs(in - 0.05 * 255) > 1.5;
  }
  ASSERT_GT(tested, 50);
  EXPECT_GE(outside_bg, 0.97 * tested);
  EXPECT_GE(inside_fg, 0.9 * tested);
}

TEST(MakeDataset, DistortedLensesAreConsistentWithTheirCameraInfo) {
  // Images rendered through a distorted lens, compared through the bag's camera_info (K and D).
  const std::string cfg = tmp("dist.yaml");
  std::ofstream(cfg) << "rig: {distortion: [-0.15, 0.04, 0.001, -0.0008, 0]}\n";
  const std::string bag = tmp("dist.bag");
  ASSERT_EQ(run("globe-images --quiet --ideal --frames 1 --config " + cfg + " --out " + bag), 0);
  const auto li = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  ASSERT_EQ(li[0].D.size(), 5u);
  EXPECT_DOUBLE_EQ(li[0].D[0], -0.15);
  const YAML::Node truth = YAML::LoadFile(tmp("dist.truth.yaml"));
  const Eigen::Vector3d c = toIso(read<geometry_msgs::PoseStamped>(bag, "ground_truth/pose")[0]).inverse() *
                            vec3(truth["sphere"]["centre_world_m"]);
  const double radius = truth["sphere"]["radius_m"].as<double>();
  const Eigen::Vector3d right_centre = vec3(truth["rig_true"]["right_centre_in_left_m"]);
  std::vector<Eigen::Vector3d> pts;
  std::mt19937 rng(5);
  std::normal_distribution<double> nd(0, 1);
  while (pts.size() < 3000) {
    const Eigen::Vector3d n = Eigen::Vector3d(nd(rng), nd(rng), nd(rng)).normalized();
    const Eigen::Vector3d X = c + radius * n;
    if (n.dot(-X.normalized()) > 0.5 && n.dot((right_centre - X).normalized()) > 0.5) pts.push_back(X);
  }
  expectViewsAgree(bag, pts, 4.0, 0.9);
}

TEST(MakeDataset, GlobeImagesRecordTheCalibrationErrorTheyWriteToCameraInfo) {
  const std::string bag = tmp("real.bag");
  ASSERT_EQ(run("globe-images --quiet --frames 1 --seed 5 --out " + bag), 0);
  const YAML::Node truth = YAML::LoadFile(tmp("real.truth.yaml"));
  EXPECT_FALSE(truth["realism"]["ideal"].as<bool>());
  const double b_true = truth["rig_true"]["baseline_mm"].as<double>();
  const double b_info = truth["rig_in_camera_info"]["baseline_mm"].as<double>();
  const auto li = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  const auto ri = read<sensor_msgs::CameraInfo>(bag, "stereo/right/camera_info");
  const auto rig = geometry::StereoRig::fromCameraInfo(fromMsg(li[0]), fromMsg(ri[0]));
  EXPECT_NEAR(rig.baseline() * 1e3, b_info, 1e-6);
  EXPECT_NE(b_info, b_true);
  EXPECT_LT(std::abs(b_info / b_true - 1.0), 0.015);  // 5 sigma of 0.3 %
  EXPECT_NEAR(b_true, std::hypot(105.0, 15.0), 1e-9);
  EXPECT_NEAR(truth["realism"]["right"]["gain"].as<double>(), 0.93, 1e-12);
}

TEST(MakeDataset, WorkpieceViewsAgreeAndThePlateStaysInsideTheRectifiedImages) {
  const std::string cfg = tmp("wp.yaml");
  std::ofstream(cfg) << "workpiece: {resolution_scale: 0.25, frames: 2}\n";
  const std::string bag = tmp("wp.bag");
  std::string out;
  ASSERT_EQ(run("workpiece --quiet --ideal --config " + cfg + " --out " + bag, &out), 0) << out;
  const YAML::Node truth = YAML::LoadFile(tmp("wp.truth.yaml"));
  const auto& pw = truth["plate"]["pose_world_left"];
  Eigen::Isometry3d T_W_L = Eigen::Isometry3d::Identity();
  T_W_L.translation() = vec3(pw["translation_m"]);
  T_W_L.linear() = Eigen::Quaterniond(pw["quaternion_wxyz"][0].as<double>(), pw["quaternion_wxyz"][1].as<double>(),
                                      pw["quaternion_wxyz"][2].as<double>(), pw["quaternion_wxyz"][3].as<double>())
                       .toRotationMatrix();
  const Eigen::Isometry3d T_L_W = T_W_L.inverse();
  // The ground-truth pose topic says the same.
  const auto poses = read<geometry_msgs::PoseStamped>(bag, "ground_truth/pose");
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_LT((toIso(poses[0]).matrix() - T_W_L.matrix()).norm(), 1e-9);

  // Points on the plateau tops and on the plate: the same intensity in both views.
  std::vector<Eigen::Vector3d> pts;
  for (const auto& p : truth["plateaus"]) {
    const double h = p["height_mm"].as<double>() * 1e-3;
    const double cx = p["centre_plate_mm"][0].as<double>() * 1e-3, cy = p["centre_plate_mm"][1].as<double>() * 1e-3;
    for (double dx = -0.006; dx <= 0.0061; dx += 0.0005)
      for (double dy = -0.006; dy <= 0.0061; dy += 0.0005) pts.push_back(T_L_W * Eigen::Vector3d(cx + dx, cy + dy, h));
  }
  expectViewsAgree(bag, pts, 6.0, 0.85);

  // Rectification through the bag's camera_info keeps the whole plate inside both images, rows aligned.
  const auto li = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  const auto ri = read<sensor_msgs::CameraInfo>(bag, "stereo/right/camera_info");
  const geometry::CameraInfo L = fromMsg(li[0]), R = fromMsg(ri[0]);
  EXPECT_EQ(L.width, 1056);
  const double sx = truth["plate"]["size_mm"][0].as<double>() * 5e-4, sy = truth["plate"]["size_mm"][1].as<double>() * 5e-4;
  for (double x : {-sx, 0.0, sx})
    for (double y : {-sy, 0.0, sy}) {
      const Eigen::Vector3d Xr = L.R * (T_L_W * Eigen::Vector3d(x, y, 0));
      const Eigen::Vector3d hl = L.P.leftCols<3>() * Xr + L.P.col(3), hr = R.P.leftCols<3>() * Xr + R.P.col(3);
      const Eigen::Vector2d ul = hl.head<2>() / hl.z(), ur = hr.head<2>() / hr.z();
      for (const auto& uv : {ul, ur}) {
        EXPECT_GE(uv.x(), 0);
        EXPECT_LT(uv.x(), L.width);
        EXPECT_GE(uv.y(), 0);
        EXPECT_LT(uv.y(), L.height);
      }
      EXPECT_NEAR(ul.y(), ur.y(), 1e-6);
    }
}

TEST(MakeDataset, BadInputNamesTheProblem) {
  std::string out;
  EXPECT_EQ(run("globe-spheres --out " + tmp("x.bag"), &out), 1);
  EXPECT_NE(out.find("unknown dataset kind"), std::string::npos) << out;
  const auto withConfig = [&](const std::string& yaml, const std::string& kind = "globe-landmarks") {
    std::ofstream(tmp("bad.yaml")) << yaml;
    return run(kind + " --quiet --frames 2 --config " + tmp("bad.yaml") + " --out " + tmp("bad.bag"), &out);
  };
  EXPECT_EQ(withConfig("globe: {radius_mm: -200}\n"), 1);
  EXPECT_NE(out.find("globe.radius_mm"), std::string::npos) << out;
  EXPECT_NE(out.find("-200"), std::string::npos) << out;
  EXPECT_EQ(withConfig("globe: {distance_mm: 150}\n"), 1);  // the camera inside the 200 mm sphere
  EXPECT_NE(out.find("globe.distance_mm"), std::string::npos) << out;
  EXPECT_EQ(withConfig("globe: {max_incidence_deg: 0.0001}\n"), 1);  // no landmark ever visible
  EXPECT_NE(out.find("globe.max_incidence_deg"), std::string::npos) << out;
  EXPECT_EQ(withConfig("globe: {radius_mm: [1, 2\n"), 1);
  EXPECT_NE(out.find("line"), std::string::npos) << out;
  EXPECT_EQ(withConfig("globe: {radius: 200}\n"), 1);
  EXPECT_NE(out.find("unknown field"), std::string::npos) << out;
  EXPECT_EQ(withConfig("workpiece: {plateaus: [{centre_mm: [0, 0], size_mm: [15, 15], height_mm: -1}]}\n", "workpiece"), 1);
  EXPECT_NE(out.find("height_mm"), std::string::npos) << out;
  EXPECT_EQ(run("globe-landmarks --frames 0 --out " + tmp("x.bag"), &out), 2);
  EXPECT_EQ(run("globe-landmarks --out /nonexistent/dir/x.bag", &out), 3);
  EXPECT_NE(out.find("cannot write"), std::string::npos) << out;
  EXPECT_EQ(run("globe-landmarks", &out), 2);
}
