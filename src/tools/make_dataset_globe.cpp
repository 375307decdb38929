// SPDX-License-Identifier: BSD-3-Clause
// make_dataset: the globe datasets (landmarks and images).
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>
#include <sys/stat.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "skin3d/ros/conversions.h"
#include "skin3d/common/large_buffers.h"
#include "skin3d/common/run_info.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/dataset.h"
#include "skin3d/sim/globe.h"
#include "skin3d/sim/render.h"
#include "skin3d/stereo/rectification.h"

#include "make_dataset_detail.h"

namespace make_dataset_detail {

using namespace skin3d;  // NOLINT(build/namespaces)

namespace {

void writeImu(rosbag::Bag& bag, const sim::GlobeSimulator& s, double t_end) {
  const double var = s.config().gyro_noise * s.config().gyro_noise;
  for (const auto& g : s.gyro()) {
    if (g.t >= t_end) break;
    sensor_msgs::Imu m;
    m.header.frame_id = kLeftFrame;  // the rig frame is the left optical frame
    m.header.stamp = g_start + ros::Duration(g.t);
    m.orientation.w = 1.0;
    m.orientation_covariance[0] = -1.0;  // no orientation
    m.angular_velocity.x = g.omega.x();
    m.angular_velocity.y = g.omega.y();
    m.angular_velocity.z = g.omega.z();
    m.angular_velocity_covariance[0] = m.angular_velocity_covariance[4] = m.angular_velocity_covariance[8] = var;
    m.linear_acceleration_covariance[0] = -1.0;  // no accelerometer
    bag.write("imu/data", m.header.stamp, m);
  }
}

}  // namespace

int makeGlobe(const sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
              const std::string& map_path) {
  sim::GlobeConfig gc = c.globe;
  gc.seed = c.seed;
  const sim::GlobeSimulator s(gc);
  const bool images = c.kind == sim::DatasetKind::GlobeImages;
  const geometry::StereoRig true_rig = s.rig();
  const sim::PerturbedCalibration calib =
      images ? sim::perturbCalibration(true_rig, c.images.perturbation, c.seed, gc.distance - gc.radius)
             : sim::PerturbedCalibration{true_rig};
  const stereo::RectifiedPair info = stereo::rectifyStereo(calib.rig);

  std::unique_ptr<sim::SphereScene> scene;
  if (images) {
    const auto t0 = std::chrono::steady_clock::now();
    scene = std::make_unique<sim::SphereScene>(s.sphereCentreWorld(), gc.radius, c.seed);
    scene->setOrientation(s.poseWorldGlobe().linear());
    if (!quiet)
      std::cout << "  globe texture built in "
                << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s" << std::endl;
  }
  const Eigen::Isometry3d T_L_R = poseLeftRight(true_rig);
  common::Progress progress(frames, quiet, images ? "frames rendered" : "frames measured");
  size_t total_landmarks = 0;
  int min_lm = 1 << 30, max_lm = 0;
  for (int k = 0; k < frames; ++k) {
    const double t = s.stamp(k);
    const ros::Time stamp = g_start + ros::Duration(t);
    const Eigen::Isometry3d T_W_L = s.poseWorldLeft(t);
    bag.write("stereo/left/camera_info", stamp, ros_conv::toMsg(info.left, kLeftFrame, stamp));
    bag.write("stereo/right/camera_info", stamp, ros_conv::toMsg(info.right, kRightFrame, stamp));
    if (images) {
      sim::RenderOptions ro;
      ro.supersample = c.images.supersample;
      // The lamp is fixed to the rig (the thesis turned the globe in front of a fixed camera and lamp).
      const double el = c.images.light_elevation;
      ro.light_dir = T_W_L.linear() * Eigen::Vector3d(0.3, std::sin(el), std::cos(el)).normalized();
      const cv::Mat left = sim::renderIrradiance(*scene, true_rig.left(), T_W_L, ro);
      const cv::Mat right = sim::renderIrradiance(*scene, true_rig.right(), T_W_L * T_L_R, ro);
      const std::uint64_t fseed = c.seed * 1000003ull + static_cast<std::uint64_t>(k) * 2;
      writeImage(bag, "left", stamp, ros_conv::toMono8Msg(sim::applyRealism(left, c.images.left, fseed), kLeftFrame, stamp));
      writeImage(bag, "right", stamp,
                ros_conv::toMono8Msg(sim::applyRealism(right, c.images.right, fseed + 1), kRightFrame, stamp));
    } else {
      skin3d::LandmarkArray msg;
      msg.header.frame_id = kLeftFrame;
      msg.header.stamp = stamp;
      for (const auto& m : s.measure(k))  // pixels: raw (noisy, before triangulation)
        msg.landmarks.push_back(
            ros_conv::toLandmarkMsg(m.position, m.covariance, m.descriptor, m.strength, m.uv_left, m.uv_right));
      total_landmarks += msg.landmarks.size();
      min_lm = std::min<int>(min_lm, msg.landmarks.size());
      max_lm = std::max<int>(max_lm, msg.landmarks.size());
      bag.write("stereo/landmarks", stamp, msg);
    }
    bag.write("ground_truth/pose", stamp, poseMsg(T_W_L, stamp));
    progress.tick(k + 1);
  }
  progress.done();
  writeImu(bag, s, frames / gc.fps);
  if (!images && !quiet)
    std::cout << "  landmarks per frame: min " << min_lm << ", mean " << total_landmarks / std::max(1, frames)
              << ", max " << max_lm << std::endl;

  truth << YAML::Key << "sphere" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "centre_world_m" << YAML::Value;
  emitVec(truth, s.sphereCentreWorld());
  truth << YAML::Key << "radius_m" << YAML::Value << gc.radius;
  truth << YAML::EndMap;
  truth << YAML::Key << "orbit" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "distance_m" << YAML::Value << gc.distance << YAML::Key << "latitude_deg" << YAML::Value
        << gc.latitude * 180 / M_PI << YAML::Key << "tilt_deg" << YAML::Value << gc.tilt * 180 / M_PI
        << YAML::Key << "rate_rad_s" << YAML::Value << gc.rate << YAML::Key << "fps" << YAML::Value << gc.fps
        << YAML::Key << "frames" << YAML::Value << frames;
  truth << YAML::Key << "angular_velocity_rig_rad_s" << YAML::Value;
  emitVec(truth, s.angularVelocity(0.0));
  truth << YAML::Key << "linear_velocity_rig_m_s" << YAML::Value;
  emitVec(truth, s.linearVelocity(0.0));
  truth << YAML::EndMap;
  truth << YAML::Key << "gyro" << YAML::Value << YAML::BeginMap << YAML::Key << "rate_hz" << YAML::Value
        << gc.gyro_rate << YAML::Key << "noise_rad_s" << YAML::Value << gc.gyro_noise << YAML::Key << "bias_rad_s"
        << YAML::Value;
  emitVec(truth, gc.gyro_bias);
  truth << YAML::Key << "bias_walk" << YAML::Value << gc.gyro_bias_walk << YAML::EndMap;
  emitRig(truth, "rig_true", true_rig);
  emitRig(truth, "rig_in_camera_info", calib.rig);
  if (images) emitRealism(truth, c, calib);
  if (!images) {
    truth << YAML::Key << "pixel_sigma_px" << YAML::Value << gc.pixel_sigma;
    // The known map of thesis experiment 1: every landmark with its (noise-free) descriptor, as CSV.
    {
      std::ofstream csv(map_path);
      csv.precision(9);
      csv << "# skin3d globe landmarks (world frame, m) with their descriptors: id,x,y,z,d0,...\n";
      for (size_t i = 0; i < s.landmarksWorld().size(); ++i) {
        const auto& p = s.landmarksWorld()[i];
        csv << i << ',' << p.x() << ',' << p.y() << ',' << p.z();
        for (float d : s.descriptors()[i]) csv << ',' << d;
        csv << '\n';
      }
      if (!csv) throw std::runtime_error("cannot write " + map_path);
    }
    truth << YAML::Key << "landmark_map_csv" << YAML::Value << map_path;
    truth << YAML::Key << "landmarks_world_m" << YAML::Value << YAML::BeginSeq;
    for (const auto& p : s.landmarksWorld()) emitVec(truth, p);
    truth << YAML::EndSeq;
  }
  return 0;
}

}  // namespace make_dataset_detail
