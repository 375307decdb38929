// SPDX-License-Identifier: BSD-3-Clause
// make_dataset skin with skin.sweep.enabled: the rig swept by hand on an arc around the limb (sim/skin_sweep.h).
// Every pair is rendered at its own pose; the bag holds the pairs, their camera_info (one rectification for the
// whole sweep: the rig does not change), the gyro on imu/data and ground_truth/pose; the truth is in `world`, the
// first frame's left optical frame, as a SLAM started on that frame defines it.
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <sensor_msgs/Imu.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "skin3d/common/run_info.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/ros/conversions.h"
#include "skin3d/sim/dataset.h"
#include "skin3d/sim/render.h"
#include "skin3d/sim/skin_sweep.h"
#include "skin3d/stereo/rectification.h"

#include "make_dataset_detail.h"

namespace make_dataset_detail {

using namespace skin3d;  // NOLINT(build/namespaces)

namespace {

constexpr double kCoverageCell = 0.5e-3;  // m, the coverage truth's grid in (s, t)
constexpr double kCoverageIncidence = 45.0;  // deg: "seen" = within this incidence in both cameras

/** Incidence (deg) of the base surface at (s, phi) seen from camera centre C, or 180 when it faces away or the point
 *  falls outside `cam`'s image (T_C_W maps the limb frame into the camera). */
double seenIncidence(const sim::SkinScene& scene, double s, double phi, const Eigen::Isometry3d& T_W_C,
                     const geometry::PinholeCamera& cam) {
  const Eigen::Vector3d X = scene.surfacePoint(s, phi);
  const Eigen::Vector3d to_c = T_W_C.translation() - X;
  const double c = scene.baseNormal(phi).dot(to_c.normalized());
  if (c <= 0) return 180.0;
  const Eigen::Vector3d Xc = T_W_C.inverse() * X;
  if (Xc.z() <= 0) return 180.0;
  const Eigen::Vector2d uv = cam.project(Xc);
  const double mx = 0.01 * cam.width(), my = 0.01 * cam.height();
  if (!(uv.x() >= mx && uv.y() >= my && uv.x() <= cam.width() - 1 - mx && uv.y() <= cam.height() - 1 - my)) return 180.0;
  return std::acos(std::min(1.0, c)) * 180.0 / M_PI;
}

void writeGyro(rosbag::Bag& bag, const std::vector<sim::GyroSample>& samples, double noise, double t_end) {
  for (const auto& g : samples) {
    if (g.t >= t_end) break;
    sensor_msgs::Imu m;
    m.header.frame_id = kLeftFrame;
    m.header.stamp = g_start + ros::Duration(g.t);
    m.orientation.w = 1.0;
    m.orientation_covariance[0] = -1.0;
    m.angular_velocity.x = g.omega.x();
    m.angular_velocity.y = g.omega.y();
    m.angular_velocity.z = g.omega.z();
    m.angular_velocity_covariance[0] = m.angular_velocity_covariance[4] = m.angular_velocity_covariance[8] = noise * noise;
    m.linear_acceleration_covariance[0] = -1.0;
    bag.write("imu/data", m.header.stamp, m);
  }
}

}  // namespace

int makeSkinSweep(const sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
                  const std::string& visible_path) {
  const sim::SkinConfig& k = c.skin;
  const sim::SkinSweepConfig& w = k.sweep;
  const sim::RigConfig rc = k.scaledRig();
  const geometry::StereoRig true_rig = rc.makeRig();
  const sim::PerturbedCalibration calib = sim::perturbCalibration(true_rig, c.images.perturbation, c.seed, k.working_distance);
  double yaw = 0, tilt = 0, roll = 0;
  const sim::SkinScene scene(k.geometryFor(c.seed, &yaw, &tilt, &roll), c.seed);
  const sim::SkinGeometry& g = scene.geometry();
  const sim::SkinSweepPath path(g, w, k.working_distance, yaw, tilt, roll, rc.poseRigLeft(), c.seed);
  const Eigen::Isometry3d T_L_R = poseLeftRight(true_rig);
  std::vector<Eigen::Isometry3d> T_W_L(w.frames);
  for (int i = 0; i < w.frames; ++i) T_W_L[i] = path.poseWorldLeft(path.frameTime(i));
  const Eigen::Isometry3d T_L0_W = T_W_L[0].inverse();  // world of the dataset = the first left optical frame

  // One rectification for the sweep, from the skin both cameras see in any frame.
  std::vector<Eigen::Isometry3d> T_L_Ws;
  for (const Eigen::Isometry3d& T : T_W_L) T_L_Ws.push_back(T.inverse());
  const stereo::RectifiedPair info =
      rectifyForSkin(scene, true_rig, calib.rig, T_L_Ws, M_PI, "skin.sweep", k.working_distance);

  // The pairs, each at its own pose; the light moves with the rig.
  sim::RenderOptions ro;
  ro.supersample = c.images.supersample;
  ro.ambient = 0.25;
  common::Progress progress(frames, quiet, "sweep pairs rendered");
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < frames && !g_truth_only; ++i) {
    const double t = path.frameTime(i);
    const ros::Time stamp = g_start + ros::Duration(t);
    ro.light_dir = (T_W_L[i].linear() * rc.poseRigLeft().linear().transpose() * Eigen::Vector3d(0.15, -0.25, 1.0)).normalized();
    const cv::Mat left = sim::renderIrradiance(scene, true_rig.left(), T_W_L[i], ro);
    const cv::Mat right = sim::renderIrradiance(scene, true_rig.right(), T_W_L[i] * T_L_R, ro);
    const std::uint64_t fseed = c.seed * 1000003ull + static_cast<std::uint64_t>(i) * 2;
    bag.write("stereo/left/camera_info", stamp, ros_conv::toMsg(info.left, kLeftFrame, stamp));
    bag.write("stereo/right/camera_info", stamp, ros_conv::toMsg(info.right, kRightFrame, stamp));
    writeImage(bag, "left", stamp, ros_conv::toMono8Msg(sim::applyRealism(left, c.images.left, fseed), kLeftFrame, stamp));
    writeImage(bag, "right", stamp, ros_conv::toMono8Msg(sim::applyRealism(right, c.images.right, fseed + 1), kRightFrame, stamp));
    bag.write("ground_truth/pose", stamp, poseMsg(T_L0_W * T_W_L[i], stamp));
    progress.tick(i + 1);
  }
  progress.done();
  if (!quiet && !g_truth_only)
    std::cout << "  rendered " << frames << " pairs of " << rc.width << "x" << rc.height << " in "
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s" << std::endl;
  if (!g_truth_only) writeGyro(bag, path.gyro(c.seed), w.gyro_noise, path.frameTime(frames - 1) + 0.5 / w.fps);

  // Coverage truth: the limb unrolled, (s, t = r_mean phi) in cells of kCoverageCell; each cell holds how many of
  // the frames see it within kCoverageIncidence in both cameras (the base surface's normal; a convex limb hides
  // nothing it faces).
  const double rm = g.meanRadius();
  const double s_max = std::min(0.5 * g.length, 0.1);
  const int ns = static_cast<int>(std::lround(2 * s_max / kCoverageCell));
  const int nt = static_cast<int>(std::lround(2 * M_PI * rm / kCoverageCell));
  cv::Mat cover(nt, ns, CV_8U, cv::Scalar(0));
  std::vector<Eigen::Isometry3d> T_W_R(frames);
  for (int i = 0; i < frames; ++i) T_W_R[i] = T_W_L[i] * T_L_R;
  cv::parallel_for_(cv::Range(0, nt), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r)
      for (int q = 0; q < ns; ++q) {
        const double s = -s_max + (q + 0.5) * kCoverageCell, phi = (-M_PI * rm + (r + 0.5) * kCoverageCell) / rm;
        int n = 0;
        for (int i = 0; i < frames; ++i)
          n += std::max(seenIncidence(scene, s, phi, T_W_L[i], true_rig.left()),
                        seenIncidence(scene, s, phi, T_W_R[i], true_rig.right())) <= kCoverageIncidence;
        cover.at<uchar>(r, q) = static_cast<uchar>(std::min(n, 255));
      }
  });
  if (!cv::imwrite(visible_path, cover)) throw std::runtime_error("cannot write " + visible_path);

  truth << YAML::Key << "frame" << YAML::Value << "world: the first pair's left optical frame";
  truth << YAML::Key << "sweep" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "frames" << YAML::Value << frames << YAML::Key << "arc_deg" << YAML::Value << w.arc * 180 / M_PI
        << YAML::Key << "fps" << YAML::Value << w.fps << YAML::Key << "jitter_mm" << YAML::Value << w.jitter * 1e3
        << YAML::Key << "jitter_deg" << YAML::Value << w.jitter_rot * 180 / M_PI;
  truth << YAML::Key << "gyro" << YAML::Value << YAML::BeginMap << YAML::Key << "rate_hz" << YAML::Value << w.gyro_rate
        << YAML::Key << "noise_rad_s" << YAML::Value << w.gyro_noise << YAML::Key << "bias_rad_s" << YAML::Value;
  emitVec(truth, w.gyro_bias);
  truth << YAML::EndMap;
  truth << YAML::Key << "poses_world_left" << YAML::Value << YAML::BeginSeq;
  for (int i = 0; i < frames; ++i) {
    const Eigen::Isometry3d T = T_L0_W * T_W_L[i];
    truth << YAML::Flow << YAML::BeginMap << YAML::Key << "t" << YAML::Value << path.frameTime(i) << YAML::Key
          << "translation_m" << YAML::Value;
    emitVec(truth, T.translation());
    truth << YAML::Key << "quaternion_wxyz" << YAML::Value;
    emitVec(truth, geometry::toWxyz(Eigen::Quaterniond(T.linear())));
    truth << YAML::EndMap;
  }
  truth << YAML::EndSeq << YAML::EndMap;
  truth << YAML::Key << "coverage" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "image" << YAML::Value << visible_path.substr(visible_path.find_last_of('/') + 1);
  truth << YAML::Key << "meaning" << YAML::Value
        << "the limb unrolled: column = s along the axis from -s_max, row = t = r_mean * phi around it from -pi r_mean "
           "(phi the elliptic angle, 0 at the limb's top), cells of cell_mm; value = frames that see the base surface "
           "there within max_incidence_deg in both cameras";
  truth << YAML::Key << "cell_mm" << YAML::Value << kCoverageCell * 1e3 << YAML::Key << "s_max_mm" << YAML::Value
        << s_max * 1e3 << YAML::Key << "r_mean_mm" << YAML::Value << rm * 1e3 << YAML::Key << "max_incidence_deg"
        << YAML::Value << kCoverageIncidence;
  truth << YAML::Key << "cells_seen" << YAML::Value << cv::countNonZero(cover);
  truth << YAML::EndMap;
  // how each plaque was seen: the first frame's incidence at its centre, the best over the sweep
  truth << YAML::Key << "plaques_seen" << YAML::Value << YAML::BeginSeq;
  for (std::size_t p = 0; p < g.plaques.size(); ++p) {
    const double s = g.plaques[p].centre.x(), phi = g.plaques[p].centre.y() / rm;
    double first = 0, best = 180;
    int within = 0;
    for (int i = 0; i < frames; ++i) {
      const double inc = std::max(seenIncidence(scene, s, phi, T_W_L[i], true_rig.left()),
                                  seenIncidence(scene, s, phi, T_W_R[i], true_rig.right()));
      if (i == 0) first = inc;
      best = std::min(best, inc);
      within += inc <= kCoverageIncidence;
    }
    truth << YAML::Flow << YAML::BeginMap << YAML::Key << "id" << YAML::Value << p << YAML::Key
          << "first_frame_incidence_deg" << YAML::Value << first << YAML::Key << "best_incidence_deg" << YAML::Value
          << best << YAML::Key << "frames_within_45_deg" << YAML::Value << within << YAML::EndMap;
  }
  truth << YAML::EndSeq;
  emitSkinTruth(truth, scene, T_L0_W);
  truth << YAML::Key << "pose" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "yaw_deg" << YAML::Value
        << yaw * 180 / M_PI << YAML::Key << "tilt_deg" << YAML::Value << tilt * 180 / M_PI << YAML::Key << "roll_deg"
        << YAML::Value << roll * 180 / M_PI << YAML::EndMap;
  truth << YAML::Key << "working_distance_mm" << YAML::Value << k.working_distance * 1e3;
  truth << YAML::Key << "resolution_scale" << YAML::Value << k.resolution_scale;
  truth << YAML::Key << "rectification_alpha" << YAML::Value << info.alpha;
  emitRig(truth, "rig_true", true_rig);
  emitRig(truth, "rig_in_camera_info", calib.rig);
  emitRealism(truth, c, calib);
  return 0;
}

}  // namespace make_dataset_detail
