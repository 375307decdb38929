// SPDX-License-Identifier: BSD-3-Clause
// make_dataset: pose messages and the pieces of the ground-truth YAML.
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

geometry_msgs::PoseStamped poseMsg(const Eigen::Isometry3d& T, const ros::Time& t) {
  geometry_msgs::PoseStamped m;
  m.header.frame_id = kWorldFrame;
  m.header.stamp = t;
  m.pose.position.x = T.translation().x();
  m.pose.position.y = T.translation().y();
  m.pose.position.z = T.translation().z();
  const Eigen::Quaterniond q(T.linear());
  m.pose.orientation.w = q.w();
  m.pose.orientation.x = q.x();
  m.pose.orientation.y = q.y();
  m.pose.orientation.z = q.z();
  return m;
}

void emitVec(YAML::Emitter& e, const Eigen::VectorXd& v) {
  e << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < v.size(); ++i) e << v[i];
  e << YAML::EndSeq;
}

void emitRig(YAML::Emitter& e, const char* name, const geometry::StereoRig& rig) {
  e << YAML::Key << name << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "K_left" << YAML::Value;
  emitVec(e, Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix3d(rig.left().K().transpose()).data()));
  e << YAML::Key << "K_right" << YAML::Value;
  emitVec(e, Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix3d(rig.right().K().transpose()).data()));
  e << YAML::Key << "D" << YAML::Value;
  emitVec(e, Eigen::Map<const Eigen::VectorXd>(rig.left().D().data(), rig.left().D().size()));
  e << YAML::Key << "size" << YAML::Value << YAML::Flow << YAML::BeginSeq << rig.left().width() << rig.left().height()
    << YAML::EndSeq;
  e << YAML::Key << "right_centre_in_left_m" << YAML::Value;
  emitVec(e, rig.rightCentre());
  e << YAML::Key << "R_right_left" << YAML::Value;
  emitVec(e, Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix3d(rig.R_rl().transpose()).data()));
  e << YAML::Key << "baseline_mm" << YAML::Value << rig.baseline() * 1e3;
  e << YAML::Key << "optical_axes_angle_deg" << YAML::Value << rig.opticalAxesAngle() * 180.0 / M_PI;
  e << YAML::EndMap;
}

void emitRealism(YAML::Emitter& e, const sim::DatasetConfig& c, const sim::PerturbedCalibration& p) {
  const auto& im = c.images;
  e << YAML::Key << "realism" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "ideal" << YAML::Value << im.ideal;
  e << YAML::Key << "supersample" << YAML::Value << im.supersample;
  for (const auto* r : {&im.left, &im.right}) {
    e << YAML::Key << (r == &im.left ? "left" : "right") << YAML::Value << YAML::BeginMap;
    e << YAML::Key << "blur_sigma_px" << YAML::Value << r->blur_sigma << YAML::Key << "vignetting" << YAML::Value
      << r->vignetting << YAML::Key << "gain" << YAML::Value << r->gain << YAML::Key << "offset" << YAML::Value
      << r->offset << YAML::Key << "gamma" << YAML::Value << r->gamma << YAML::Key << "full_well" << YAML::Value
      << r->full_well << YAML::Key << "read_noise_dn" << YAML::Value << r->read_noise << YAML::EndMap;
  }
  e << YAML::Key << "calibration_error" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "enabled" << YAML::Value << im.perturbation.enabled;
  e << YAML::Key << "model" << YAML::Value << sim::calibrationErrorModelName(im.perturbation.model);
  if (im.perturbation.enabled && im.perturbation.model == sim::CalibrationErrorModel::Chessboard) {
    e << YAML::Key << "views" << YAML::Value << im.perturbation.views;
    e << YAML::Key << "corner_sigma_px" << YAML::Value << im.perturbation.corner_sigma_px;
    e << YAML::Key << "k_coefficients" << YAML::Value << im.perturbation.k_coefficients;
    e << YAML::Key << "board_square_mm" << YAML::Value << p.board_square_m * 1e3;
    e << YAML::Key << "calibration_rms_px" << YAML::Value << p.calibration_rms_px;
  }
  e << YAML::Key << "depth_error_at_working_distance_mm" << YAML::Value << p.depth_error_m * 1e3;
  e << YAML::Key << "largest_depth_error_at_working_distance_mm" << YAML::Value << p.depth_error_max_m * 1e3;
  e << YAML::Key << "baseline_scale" << YAML::Value << p.baseline_scale;
  e << YAML::Key << "rotation_error_deg" << YAML::Value;
  emitVec(e, p.rotation_error * 180.0 / M_PI);
  e << YAML::Key << "principal_point_error_left_px" << YAML::Value;
  emitVec(e, p.principal_left);
  e << YAML::Key << "principal_point_error_right_px" << YAML::Value;
  emitVec(e, p.principal_right);
  e << YAML::Key << "focal_scale_left" << YAML::Value << p.focal_scale_left;
  e << YAML::Key << "focal_scale_right" << YAML::Value << p.focal_scale_right;
  // The frame this calibration defines (PerturbedCalibration::frame_*): slam_nees.py --calibrated-frame reads it.
  e << YAML::Key << "measured_frame" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "rotation_rad" << YAML::Value;
  emitVec(e, p.frame_rotation);
  e << YAML::Key << "translation_m" << YAML::Value;
  emitVec(e, p.frame_translation);
  e << YAML::Key << "scale" << YAML::Value << p.frame_scale;
  e << YAML::Key << "residual_rms_mm" << YAML::Value << p.frame_residual_rms_m * 1e3;
  e << YAML::Key << "points" << YAML::Value << p.frame_points;
  e << YAML::EndMap;
  e << YAML::EndMap << YAML::EndMap;
}

Eigen::Isometry3d poseLeftRight(const geometry::StereoRig& rig) {
  return Eigen::Isometry3d(Eigen::Translation3d(rig.rightCentre()) * Eigen::Quaterniond(rig.R_rl().transpose()));
}

void writeImage(rosbag::Bag& bag, const std::string& side, const ros::Time& stamp, const sensor_msgs::Image& img) {
  const std::string topic = "stereo/" + side + "/image_raw";
  if (g_compress < 0)
    bag.write(topic, stamp, img);
  else
    bag.write(topic + "/compressed", stamp, skin3d::ros_conv::toCompressed(img, g_compress));
}

}  // namespace make_dataset_detail
