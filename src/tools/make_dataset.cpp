// SPDX-License-Identifier: BSD-3-Clause
/**
 * make_dataset KIND --out FILE.bag [--seed N] [--config FILE.yaml] [--ideal] [--frames N] [--start S] [--quiet]
 *
 * Generates a simulated dataset (DESIGN.md "Datasets") as a rosbag, deterministically from the seed,
 * without a ROS master, plus FILE.truth.yaml beside it (and FILE.map.csv, the landmarks with their descriptors, for
 * globe-landmarks). KIND: globe-landmarks, globe-images, workpiece.
 * Topics: stereo/{left,right}/camera_info, stereo/{left,right}/image_raw (image kinds),
 * stereo/landmarks (landmark kind), imu/data (globe kinds), ground_truth/pose.
 * Exit codes: 0 ok, 1 bad configuration, 2 bad command line, 3 cannot write the output.
 */
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

namespace {

using namespace skin3d;

const char* kUsage =
    "usage: make_dataset KIND --out FILE.bag [--seed N] [--config FILE.yaml] [--ideal] [--frames N] [--start S] [--quiet]\n"
    "  KIND            globe-landmarks | globe-images | workpiece | skin\n"
    "  --out FILE.bag  the bag to write; the ground truth goes to FILE.truth.yaml beside it\n"
    "  --seed N        random seed (default 1, or the config's seed); same seed + config = same data\n"
    "  --config FILE   YAML overrides of the defaults (config/datasets/globe.yaml, workpiece.yaml, skin.yaml)\n"
    "  --ideal         no realism (blur, vignetting, photometry, noise) and an exact calibration\n"
    "  --frames N      only the first N frames (quick tests)\n"
    "  --start SECONDS stamp of the first frame (default 1000; e.g. 1700000000 for epoch stamps as a recording has)\n"
    "  --quiet         no progress output (progress goes to stderr)\n";

const std::string kLeftFrame = "stereo_left_optical_frame";
const std::string kRightFrame = "stereo_right_optical_frame";
const std::string kWorldFrame = "world";
ros::Time g_start(1000.0);  // the first stamp (--start): a fixed, valid ROS time, so that bags are deterministic

struct Options {
  std::string kind, out, config;
  long long seed = -1;
  bool ideal = false, quiet = false;
  int frames = -1;
};

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

bool writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  return static_cast<bool>(out);
}

long long fileSize(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0 ? static_cast<long long>(st.st_size) : -1;
}

std::string stemOf(const std::string& bag) {
  return bag.size() > 4 && bag.substr(bag.size() - 4) == ".bag" ? bag.substr(0, bag.size() - 4) : bag;
}
/** Pose of the right optical frame in the left one (left <- right). */
Eigen::Isometry3d poseLeftRight(const geometry::StereoRig& rig) {
  return Eigen::Isometry3d(Eigen::Translation3d(rig.rightCentre()) * Eigen::Quaterniond(rig.R_rl().transpose()));
}

std::string truthPath(const std::string& bag) { return stemOf(bag) + ".truth.yaml"; }
std::string mapPath(const std::string& bag) { return stemOf(bag) + ".map.csv"; }
std::string visiblePath(const std::string& bag) { return stemOf(bag) + ".visible.png"; }

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

// ------------------------------------------------------------------ globe (landmarks and images)

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
      bag.write("stereo/left/image_raw", stamp, ros_conv::toMono8Msg(sim::applyRealism(left, c.images.left, fseed), kLeftFrame, stamp));
      bag.write("stereo/right/image_raw", stamp,
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

// ------------------------------------------------------------------ workpiece

/** Renders the pair once (noise-free irradiance) and writes `frames` exposures of it (realism with fresh noise
 *  each), the camera_infos and the ground-truth pose. */
void writeRenderedExposures(const sim::Scene& scene, const sim::DatasetConfig& c, const sim::RigConfig& rc,
                            const geometry::StereoRig& true_rig, const stereo::RectifiedPair& info,
                            const Eigen::Isometry3d& T_W_L, const sim::RenderOptions& ro, int frames, double fps,
                            rosbag::Bag& bag, bool quiet) {
  const Eigen::Isometry3d T_L_R = poseLeftRight(true_rig);
  const auto t0 = std::chrono::steady_clock::now();
  const cv::Mat left = sim::renderIrradiance(scene, true_rig.left(), T_W_L, ro);
  const cv::Mat right = sim::renderIrradiance(scene, true_rig.right(), T_W_L * T_L_R, ro);
  if (!quiet)
    std::cout << "  rendered " << rc.width << "x" << rc.height << " pair (" << ro.supersample << "x" << ro.supersample
              << " samples) in " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
              << " s" << std::endl;
  common::Progress progress(frames, quiet, "exposures rendered");
  for (int k = 0; k < frames; ++k) {
    const ros::Time stamp = g_start + ros::Duration(k / fps);
    const std::uint64_t fseed = c.seed * 1000003ull + static_cast<std::uint64_t>(k) * 2;
    bag.write("stereo/left/camera_info", stamp, ros_conv::toMsg(info.left, kLeftFrame, stamp));
    bag.write("stereo/right/camera_info", stamp, ros_conv::toMsg(info.right, kRightFrame, stamp));
    bag.write("stereo/left/image_raw", stamp, ros_conv::toMono8Msg(sim::applyRealism(left, c.images.left, fseed), kLeftFrame, stamp));
    bag.write("stereo/right/image_raw", stamp,
              ros_conv::toMono8Msg(sim::applyRealism(right, c.images.right, fseed + 1), kRightFrame, stamp));
    bag.write("ground_truth/pose", stamp, poseMsg(T_W_L, stamp));
    progress.tick(k + 1);
  }
  progress.done();
}


int makeWorkpiece(const sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet) {
  const sim::WorkpieceConfig& w = c.workpiece;
  const sim::RigConfig rc = w.scaledRig();
  const geometry::StereoRig true_rig = rc.makeRig();
  const sim::PerturbedCalibration calib =
      sim::perturbCalibration(true_rig, c.images.perturbation, c.seed, w.working_distance);

  // World = plate frame (top surface z = 0). The rig axis points down at the plate centre, tilted about x.
  Eigen::Isometry3d T_W_rig = Eigen::Isometry3d::Identity();
  T_W_rig.linear() = geometry::so3Exp(Eigen::Vector3d(M_PI + w.tilt, 0.0, 0.0));
  T_W_rig.translation() = -T_W_rig.linear() * Eigen::Vector3d(0.0, 0.0, w.working_distance);
  const Eigen::Isometry3d T_W_L = T_W_rig * rc.poseRigLeft();
  const Eigen::Isometry3d T_L_W = T_W_L.inverse();

  std::vector<Eigen::Vector3d> corners;
  for (double sx : {-0.5, 0.5})
    for (double sy : {-0.5, 0.5}) corners.push_back(T_L_W * Eigen::Vector3d(sx * w.plate_size.x(), sy * w.plate_size.y(), 0));
  for (const auto& X : corners) {
    Eigen::Vector2d uvl, uvr;
    if (!true_rig.project(X, &uvl, &uvr) || !true_rig.left().inImage(uvl) || !true_rig.right().inImage(uvr))
      throw sim::SimConfigError("workpiece.plate_size_mm",
                                "field 'workpiece.plate_size_mm': the plate is not inside both camera images at "
                                "working distance " + std::to_string(w.working_distance * 1e3) +
                                    " mm; make it smaller or move the rig away");
  }
  stereo::RectifiedPair info;
  try {
    info = stereo::rectifyStereo(calib.rig, corners);
  } catch (const std::runtime_error& e) {
    throw sim::SimConfigError("workpiece", e.what());
  }

  const auto t0 = std::chrono::steady_clock::now();
  const sim::WorkpieceScene scene(w.plate_size, w.plateaus, c.seed, w.texel);
  if (!quiet)
    std::cout << "  pattern built in " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
              << " s" << std::endl;
  sim::RenderOptions ro;
  ro.supersample = c.images.supersample;
  writeRenderedExposures(scene, c, rc, true_rig, info, T_W_L, ro, frames, w.fps, bag, quiet);

  // Ground truth in the left optical frame.
  const Eigen::Vector3d n_L = T_L_W.linear() * Eigen::Vector3d::UnitZ();
  truth << YAML::Key << "plate" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "size_mm" << YAML::Value;
  emitVec(truth, w.plate_size * 1e3);
  truth << YAML::Key << "plane_left" << YAML::Value;  // n . X + d = 0, n towards the rig
  const Eigen::Vector3d n_towards = n_L.z() < 0 ? n_L : Eigen::Vector3d(-n_L);
  emitVec(truth, Eigen::Vector4d(n_towards.x(), n_towards.y(), n_towards.z(), -n_towards.dot(T_L_W.translation())));
  truth << YAML::Key << "pose_world_left" << YAML::Value << YAML::BeginMap << YAML::Key << "translation_m"
        << YAML::Value;
  emitVec(truth, T_W_L.translation());
  truth << YAML::Key << "quaternion_wxyz" << YAML::Value;
  emitVec(truth, geometry::toWxyz(Eigen::Quaterniond(T_W_L.linear())));
  truth << YAML::EndMap << YAML::EndMap;
  truth << YAML::Key << "plateaus" << YAML::Value << YAML::BeginSeq;
  for (size_t i = 0; i < w.plateaus.size(); ++i) {
    const auto& p = w.plateaus[i];
    truth << YAML::BeginMap;
    truth << YAML::Key << "id" << YAML::Value << i;
    truth << YAML::Key << "height_mm" << YAML::Value << p.height * 1e3;
    truth << YAML::Key << "area_mm2" << YAML::Value << p.size.x() * p.size.y() * 1e6;
    truth << YAML::Key << "size_mm" << YAML::Value;
    emitVec(truth, p.size * 1e3);
    truth << YAML::Key << "centre_plate_mm" << YAML::Value;
    emitVec(truth, p.centre * 1e3);
    truth << YAML::Key << "centroid_left_m" << YAML::Value;  // centre of the top face
    emitVec(truth, T_L_W * Eigen::Vector3d(p.centre.x(), p.centre.y(), p.height));
    truth << YAML::EndMap;
  }
  truth << YAML::EndSeq;
  truth << YAML::Key << "working_distance_mm" << YAML::Value << w.working_distance * 1e3;
  truth << YAML::Key << "tilt_deg" << YAML::Value << w.tilt * 180 / M_PI;
  truth << YAML::Key << "resolution_scale" << YAML::Value << w.resolution_scale;
  truth << YAML::Key << "rectification_alpha" << YAML::Value << info.alpha;
  truth << YAML::Key << "rectification_projection_fitted" << YAML::Value << info.projection_fitted;
  emitRig(truth, "rig_true", true_rig);
  emitRig(truth, "rig_in_camera_info", calib.rig);
  emitRealism(truth, c, calib);
  return 0;
}

// ------------------------------------------------------------------ skin

/** Where the rectified left image sees skin that the right camera sees too: 0 = not, else 1 + the larger of the
 *  two views' incidence angles in degrees (1 ... 91). Rectified pixel -> raw pixel through the calibration in
 *  the bag (what the pipeline's rectification does) -> the true camera's ray. */
cv::Mat skinVisibility(const sim::SkinScene& scene, const geometry::StereoRig& true_rig, const stereo::RectifiedPair& info,
                       const geometry::StereoRig& calib_rig, const Eigen::Isometry3d& T_W_L) {
  const geometry::CameraInfo& li = info.left;
  const geometry::CameraInfo& ri = info.right;
  const Eigen::Isometry3d T_L_R = poseLeftRight(true_rig);
  const Eigen::Isometry3d T_W_R = T_W_L * T_L_R, T_R_W = T_W_R.inverse();
  cv::Mat out(li.height, li.width, CV_8U, cv::Scalar(0));
  const double fx = li.P(0, 0), fy = li.P(1, 1), cx = li.P(0, 2), cy = li.P(1, 2);
  cv::parallel_for_(cv::Range(0, li.height), [&](const cv::Range& rows) {
    sim::Hit hit, back;
    for (int v = rows.start; v < rows.end; ++v) {
      uchar* o = out.ptr<uchar>(v);
      for (int u = 0; u < li.width; ++u) {
        const Eigen::Vector3d ray_cal = li.R.transpose() * Eigen::Vector3d((u - cx) / fx, (v - cy) / fy, 1.0);
        if (ray_cal.z() <= 0) continue;
        const Eigen::Vector2d raw = calib_rig.left().project(ray_cal);
        if (!true_rig.left().inImage(raw)) continue;
        const Eigen::Vector3d dir = (T_W_L.linear() * true_rig.left().unproject(raw)).normalized();
        if (!scene.intersect(T_W_L.translation(), dir, &hit)) continue;
        const Eigen::Vector3d XR = T_R_W * hit.point;
        if (XR.z() <= 0) continue;
        const Eigen::Vector2d raw_r = true_rig.right().project(XR);
        if (!true_rig.right().inImage(raw_r)) continue;
        const Eigen::Vector3d rect_r = ri.R * calib_rig.right().unproject(raw_r);
        if (rect_r.z() <= 0) continue;
        const double ur = ri.P(0, 0) * rect_r.x() / rect_r.z() + ri.P(0, 2), vr = ri.P(1, 1) * rect_r.y() / rect_r.z() + ri.P(1, 2);
        if (ur < 0 || vr < 0 || ur > ri.width - 1 || vr > ri.height - 1) continue;
        const Eigen::Vector3d to_r = hit.point - T_W_R.translation();
        if (!scene.intersect(T_W_R.translation(), to_r.normalized(), &back) || std::fabs(back.distance - to_r.norm()) > 20e-6)
          continue;  // the right camera sees something else in front of it
        const double cl = -hit.normal.dot(dir), cr = -hit.normal.dot(to_r.normalized());
        if (cl <= 0 || cr <= 0) continue;
        const double inc = std::acos(std::min(cl, cr)) * 180.0 / M_PI;
        o[u] = static_cast<uchar>(1 + std::lround(std::min(90.0, inc)));
      }
    }
  });
  return out;
}

void emitSkinTruth(YAML::Emitter& truth, const sim::SkinScene& scene, const Eigen::Isometry3d& T_L_W) {
  const sim::SkinGeometry& g = scene.geometry();
  truth << YAML::Key << "limb" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "semi_axes_mm" << YAML::Value;
  emitVec(truth, Eigen::Vector2d(g.semi_axis_y, g.semi_axis_z) * 1e3);
  truth << YAML::Key << "length_mm" << YAML::Value << g.length * 1e3;
  truth << YAML::Key << "axis_point_left_m" << YAML::Value;
  emitVec(truth, T_L_W.translation());
  truth << YAML::Key << "axis_direction_left" << YAML::Value;  // limb x
  emitVec(truth, Eigen::Vector3d(T_L_W.linear().col(0)));
  truth << YAML::Key << "semi_axis_y_direction_left" << YAML::Value;
  emitVec(truth, Eigen::Vector3d(T_L_W.linear().col(1)));
  truth << YAML::Key << "semi_axis_z_direction_left" << YAML::Value;
  emitVec(truth, Eigen::Vector3d(T_L_W.linear().col(2)));
  truth << YAML::EndMap;
  const std::vector<double> bounds = {0.125e-3, 0.375e-3, 0.625e-3, 0.875e-3};
  truth << YAML::Key << "plaques" << YAML::Value << YAML::BeginSeq;
  for (std::size_t i = 0; i < g.plaques.size(); ++i) {
    const sim::SkinPlaque& p = g.plaques[i];
    const sim::SkinPlaqueTruth t = scene.plaqueTruth(i);
    int pasi = 0;
    for (double b : bounds) pasi += t.top_height >= b;
    truth << YAML::BeginMap;
    truth << YAML::Key << "id" << YAML::Value << i;
    truth << YAML::Key << "height_mm" << YAML::Value << t.top_height * 1e3;  // top height along the normal
    truth << YAML::Key << "mean_height_mm" << YAML::Value << t.mean_height * 1e3;  // over the footprint
    truth << YAML::Key << "area_mm2" << YAML::Value << t.footprint_area * 1e6;
    truth << YAML::Key << "top_area_mm2" << YAML::Value << t.top_area * 1e6;
    truth << YAML::Key << "volume_mm3" << YAML::Value << t.volume * 1e9;
    truth << YAML::Key << "pasi_class" << YAML::Value << pasi;
    truth << YAML::Key << "centroid_left_m" << YAML::Value;
    emitVec(truth, T_L_W * t.centroid);
    truth << YAML::Key << "top_point_left_m" << YAML::Value;
    emitVec(truth, T_L_W * t.top_point);
    truth << YAML::Key << "normal_left" << YAML::Value;
    emitVec(truth, Eigen::Vector3d(T_L_W.linear() * t.normal));
    truth << YAML::Key << "angle_around_limb_deg" << YAML::Value << p.centre.y() / g.meanRadius() * 180.0 / M_PI;
    truth << YAML::Key << "shape" << YAML::Value << YAML::Flow << YAML::BeginMap;
    truth << YAML::Key << "centre_mm" << YAML::Value;
    emitVec(truth, p.centre * 1e3);
    truth << YAML::Key << "radii_mm" << YAML::Value;
    emitVec(truth, p.radii * 1e3);
    truth << YAML::Key << "ramp_mm" << YAML::Value << p.ramp * 1e3 << YAML::Key << "dome" << YAML::Value << p.dome;
    truth << YAML::Key << "irregularity" << YAML::Value << p.irregularity << YAML::EndMap;
    truth << YAML::EndMap;
  }
  truth << YAML::EndSeq;
}

int makeSkin(const sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
             const std::string& visible_path) {
  const sim::SkinConfig& k = c.skin;
  const sim::RigConfig rc = k.scaledRig();
  const geometry::StereoRig true_rig = rc.makeRig();
  const sim::PerturbedCalibration calib = sim::perturbCalibration(true_rig, c.images.perturbation, c.seed, k.working_distance);
  double yaw = 0, tilt = 0, roll = 0;
  const sim::SkinScene scene(k.geometryFor(c.seed, &yaw, &tilt, &roll), c.seed);
  const sim::SkinGeometry& g = scene.geometry();

  // World = limb frame. The rig looks at the top of the limb (rolled about its axis), the baseline along the
  // limb turned by yaw about the rig axis, the rig axis tilted by `tilt` along the limb.
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  const Eigen::Vector3d zaxis = R.col(2);  // from the rig towards the limb
  const Eigen::Vector2d u = Eigen::Vector2d(-zaxis.y(), -zaxis.z()).normalized();
  const double tc = 1.0 / std::hypot(u.x() / g.semi_axis_y, u.y() / g.semi_axis_z);
  const Eigen::Vector3d target(0.0, tc * u.x(), tc * u.y());
  Eigen::Isometry3d T_W_rig = Eigen::Isometry3d::Identity();
  T_W_rig.linear() = R;
  T_W_rig.translation() = target - k.working_distance * zaxis;
  const Eigen::Isometry3d T_W_L = T_W_rig * rc.poseRigLeft();
  const Eigen::Isometry3d T_L_W = T_W_L.inverse();
  // points of interest for the rectification: skin both cameras see, under the true rig and under the
  // calibration the rectification uses (a point at an image border may be inside under one and outside under
  // the other: the rectification refuses such a point)
  std::vector<Eigen::Vector3d> poi;
  auto seen = [](const geometry::StereoRig& rig, const Eigen::Vector3d& X) {
    Eigen::Vector2d uvl, uvr;
    return rig.project(X, &uvl, &uvr) && rig.left().inImage(uvl) && rig.right().inImage(uvr);
  };
  for (double s = -0.5 * g.length; s <= 0.5 * g.length; s += 0.01)
    for (double phi = -1.4; phi <= 1.4; phi += 0.1) {
      const Eigen::Vector3d X = T_L_W * scene.surfacePoint(s, phi);
      if (seen(true_rig, X) && seen(calib.rig, X)) poi.push_back(X);
    }
  if (poi.size() < 10)
    throw sim::SimConfigError("skin", "the limb is not in both camera images at working distance " +
                                          std::to_string(k.working_distance * 1e3) + " mm");
  stereo::RectifiedPair info;
  try {
    info = stereo::rectifyStereo(calib.rig, poi);
  } catch (const std::runtime_error& e) {
    throw sim::SimConfigError("skin", e.what());
  }
  sim::RenderOptions ro;
  ro.supersample = c.images.supersample;
  ro.light_dir = (R * Eigen::Vector3d(0.15, -0.25, 1.0)).normalized();  // a light beside the rig
  ro.ambient = 0.25;
  writeRenderedExposures(scene, c, rc, true_rig, info, T_W_L, ro, frames, k.fps, bag, quiet);
  const cv::Mat visible = skinVisibility(scene, true_rig, info, calib.rig, T_W_L);
  if (!cv::imwrite(visible_path, visible)) throw std::runtime_error("cannot write " + visible_path);
  truth << YAML::Key << "visible_skin" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "image" << YAML::Value << visible_path.substr(visible_path.find_last_of('/') + 1);
  truth << YAML::Key << "meaning" << YAML::Value
        << "rectified left image: 0 = no skin seen by both cameras, else 1 + the larger incidence angle (deg)";
  truth << YAML::Key << "pixels" << YAML::Value << cv::countNonZero(visible);
  truth << YAML::EndMap;
  emitSkinTruth(truth, scene, T_L_W);
  truth << YAML::Key << "pose" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "yaw_deg" << YAML::Value
        << yaw * 180 / M_PI << YAML::Key << "tilt_deg" << YAML::Value << tilt * 180 / M_PI << YAML::Key << "roll_deg"
        << YAML::Value << roll * 180 / M_PI << YAML::EndMap;
  truth << YAML::Key << "pose_world_left" << YAML::Value << YAML::BeginMap << YAML::Key << "translation_m" << YAML::Value;
  emitVec(truth, T_W_L.translation());
  truth << YAML::Key << "quaternion_wxyz" << YAML::Value;
  emitVec(truth, geometry::toWxyz(Eigen::Quaterniond(T_W_L.linear())));
  truth << YAML::EndMap;
  truth << YAML::Key << "working_distance_mm" << YAML::Value << k.working_distance * 1e3;
  truth << YAML::Key << "resolution_scale" << YAML::Value << k.resolution_scale;
  truth << YAML::Key << "rectification_alpha" << YAML::Value << info.alpha;
  emitRig(truth, "rig_true", true_rig);
  emitRig(truth, "rig_in_camera_info", calib.rig);
  emitRealism(truth, c, calib);
  return 0;
}

bool parseArgs(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (a == "--out" && has_value) {
      o->out = argv[++i];
    } else if (a == "--config" && has_value) {
      o->config = argv[++i];
    } else if ((a == "--seed" || a == "--frames") && has_value) {
      const std::string v = argv[++i];
      char* end = nullptr;
      const long long n = std::strtoll(v.c_str(), &end, 10);
      if (v.empty() || *end != '\0' || n < (a == "--seed" ? 0 : 1)) {
        std::cerr << "make_dataset: " << a << " takes a whole number" << (a == "--seed" ? " >= 0" : " >= 1")
                  << ", got '" << v << "'\n";
        return false;
      }
      if (a == "--seed")
        o->seed = n;
      else
        o->frames = static_cast<int>(std::min<long long>(n, 1 << 30));
    } else if (a == "--start" && has_value) {
      const std::string v = argv[++i];
      char* end = nullptr;
      const double t = std::strtod(v.c_str(), &end);
      if (v.empty() || *end != '\0' || !(t > 0.0) || t > 4.0e9) {
        std::cerr << "make_dataset: --start takes seconds in (0, 4e9] (a ROS time), got '" << v << "'\n";
        return false;
      }
      g_start = ros::Time(t);
    } else if (a == "--ideal") {
      o->ideal = true;
    } else if (a == "--quiet") {
      o->quiet = true;
    } else if (a.rfind("__", 0) == 0) {
      // roslaunch/rosrun remapping arguments: ignore.
    } else if (a[0] != '-' && o->kind.empty()) {
      o->kind = a;
    } else {
      std::cerr << "make_dataset: unknown or incomplete argument '" << a << "'\n";
      return false;
    }
  }
  if (o->kind.empty() || o->out.empty()) {
    std::cerr << "make_dataset: KIND and --out FILE.bag are required\n";
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  skin3d::keepLargeBuffers();  // 13-megapixel buffers from the heap, not fresh mmap()s
  Options o;
  if (!parseArgs(argc, argv, &o)) {
    std::cerr << kUsage;
    return 2;
  }
  sim::DatasetConfig c;
  int frames = 0;
  try {
    c = sim::defaultDatasetConfig(sim::parseDatasetKind(o.kind));
    if (!o.config.empty()) {
      std::ifstream in(o.config);
      if (!in) throw sim::SimConfigError("--config", "cannot read config file '" + o.config + "'");
      std::stringstream ss;
      ss << in.rdbuf();
      sim::applyDatasetYaml(&c, ss.str(), o.config);
    }
    if (o.seed >= 0) c.seed = static_cast<std::uint64_t>(o.seed);
    if (o.ideal) sim::makeIdeal(&c);
    sim::validateDatasetConfig(c);
    frames = c.kind == sim::DatasetKind::Workpiece ? c.workpiece.frames
             : c.kind == sim::DatasetKind::Skin    ? c.skin.frames
                                                   : c.globe.frames;
    if (o.frames > 0) frames = std::min(frames, o.frames);
  } catch (const sim::SimConfigError& e) {
    std::cerr << "make_dataset: " << (o.config.empty() ? "" : o.config + ": ") << e.what() << "\n";
    return 1;
  }

  const auto t0 = std::chrono::steady_clock::now();
  rosbag::Bag bag;
  try {
    bag.open(o.out, rosbag::bagmode::Write);
  } catch (const std::exception& e) {
    std::cerr << "make_dataset: cannot write '" << o.out << "': " << e.what() << "\n";
    return 3;
  }
  if (!o.quiet)
    std::cout << "make_dataset: " << o.kind << ", seed " << c.seed << ", " << frames << " frames -> " << o.out
              << std::endl;
  YAML::Emitter truth;
  truth.SetDoublePrecision(12);
  truth << YAML::Comment("skin3d simulated dataset ground truth (SI units unless the key says mm/deg/px)");
  truth << YAML::BeginMap;
  truth << YAML::Key << "kind" << YAML::Value << o.kind << YAML::Key << "seed" << YAML::Value << c.seed;
  truth << YAML::Key << "frames" << YAML::Value << frames;
  truth << YAML::Key << "config" << YAML::Value << (o.config.empty() ? std::string("(defaults)") : o.config);
  truth << YAML::Key << "world_frame" << YAML::Value
        << (c.kind == sim::DatasetKind::Workpiece ? "plate frame (top surface z = 0)"
            : c.kind == sim::DatasetKind::Skin    ? "limb frame (x along the axis, cross-section in y, z)"
                                                  : "left optical frame at t = 0");
  int rc = 0;
  try {
    if (c.kind == sim::DatasetKind::Workpiece)
      rc = makeWorkpiece(c, frames, bag, truth, o.quiet);
    else if (c.kind == sim::DatasetKind::Skin)
      rc = makeSkin(c, frames, bag, truth, o.quiet, visiblePath(o.out));
    else
      rc = makeGlobe(c, frames, bag, truth, o.quiet, mapPath(o.out));
  } catch (const sim::SimConfigError& e) {
    bag.close();
    std::remove(o.out.c_str());
    std::cerr << "make_dataset: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    bag.close();
    std::cerr << "make_dataset: failed while writing '" << o.out << "': " << e.what() << "\n";
    return 3;
  }
  truth << YAML::EndMap;
  bag.close();
  const std::string tpath = truthPath(o.out);
  if (!writeText(tpath, std::string(truth.c_str()) + "\n")) {
    std::cerr << "make_dataset: cannot write " << tpath << "\n";
    return 3;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!o.quiet)
    std::cout << "make_dataset: wrote " << o.out << " (" << fileSize(o.out) / 1e6 << " MB) and " << tpath << " in "
              << secs << " s" << std::endl;
  return rc;
}
