// SPDX-License-Identifier: BSD-3-Clause
// make_dataset: the rendered workpiece and skin datasets.
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
#include <limits>
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

// ------------------------------------------------------------------ workpiece

namespace {

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
    writeImage(bag, "left", stamp, ros_conv::toMono8Msg(sim::applyRealism(left, c.images.left, fseed), kLeftFrame, stamp));
    writeImage(bag, "right", stamp,
              ros_conv::toMono8Msg(sim::applyRealism(right, c.images.right, fseed + 1), kRightFrame, stamp));
    bag.write("ground_truth/pose", stamp, poseMsg(T_W_L, stamp));
    progress.tick(k + 1);
  }
  progress.done();
}

}  // namespace

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

namespace {

/** Where the rectified left image sees skin that the right camera sees too: 0 = not, else 1 + the larger of the
 *  two views' incidence angles in degrees (1 ... 91). Rectified pixel -> raw pixel through the calibration in
 *  the bag (what the pipeline's rectification does) -> the true camera's ray. `disparity` (CV_32F): the true
 *  disparity there (rectified left column minus the rectified right column where the right camera sees the same
 *  skin point: what a perfect matcher finds on the pipeline's rectified pair), NaN elsewhere. */
cv::Mat skinVisibility(const sim::SkinScene& scene, const geometry::StereoRig& true_rig, const stereo::RectifiedPair& info,
                       const geometry::StereoRig& calib_rig, const Eigen::Isometry3d& T_W_L, cv::Mat* disparity) {
  const geometry::CameraInfo& li = info.left;
  const geometry::CameraInfo& ri = info.right;
  const Eigen::Isometry3d T_L_R = poseLeftRight(true_rig);
  const Eigen::Isometry3d T_W_R = T_W_L * T_L_R, T_R_W = T_W_R.inverse();
  cv::Mat out(li.height, li.width, CV_8U, cv::Scalar(0));
  *disparity = cv::Mat(li.height, li.width, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  const double fx = li.P(0, 0), fy = li.P(1, 1), cx = li.P(0, 2), cy = li.P(1, 2);
  cv::parallel_for_(cv::Range(0, li.height), [&](const cv::Range& rows) {
    sim::Hit hit, back;
    for (int v = rows.start; v < rows.end; ++v) {
      uchar* o = out.ptr<uchar>(v);
      float* dsp = disparity->ptr<float>(v);
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
        dsp[u] = static_cast<float>(u - ur);
      }
    }
  });
  return out;
}

}  // namespace

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
    truth << YAML::Key << "half_height_area_mm2" << YAML::Value << t.half_height_area * 1e6;
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
  // healthy relief: not plaques; a reference fitted to the limb cannot follow it (the measurement must say so)
  truth << YAML::Key << "ridges" << YAML::Value << YAML::BeginSeq;
  for (const sim::SkinRidge& r : g.ridges) {
    const double rm = g.meanRadius();
    const Eigen::Vector3d on = scene.surfacePoint(r.centre.x(), r.centre.y() / rm);
    truth << YAML::BeginMap;
    truth << YAML::Key << "height_mm" << YAML::Value << r.height * 1e3;
    truth << YAML::Key << "width_mm" << YAML::Value << r.width * 1e3;
    truth << YAML::Key << "length_mm" << YAML::Value << r.length * 1e3;
    truth << YAML::Key << "centre_left_m" << YAML::Value;
    emitVec(truth, T_L_W * on);
    // the ends of its line (on the raised surface), for finding it in an image
    const Eigen::Vector2d dir(std::cos(r.orientation), std::sin(r.orientation));
    for (const int e : {-1, 1}) {
      const Eigen::Vector2d st = r.centre + e * 0.5 * r.length * dir;
      truth << YAML::Key << (e < 0 ? "start_left_m" : "end_left_m") << YAML::Value;
      emitVec(truth, T_L_W * scene.surfacePoint(st.x(), st.y() / rm));
    }
    truth << YAML::Key << "angle_around_limb_deg" << YAML::Value << r.centre.y() / rm * 180.0 / M_PI;
    truth << YAML::EndMap;
  }
  truth << YAML::EndSeq;
}

stereo::RectifiedPair rectifyForSkin(const sim::SkinScene& scene, const geometry::StereoRig& true_rig,
                                     const geometry::StereoRig& calib_rig, const std::vector<Eigen::Isometry3d>& T_L_W,
                                     double phi_max, const std::string& field, double working_distance) {
  // points of interest: skin both cameras see, under the true rig and under the calibration the rectification uses
  // (a point at an image border may be inside under one and outside under the other: the rectification refuses it)
  const sim::SkinGeometry& g = scene.geometry();
  std::vector<Eigen::Vector3d> poi;
  auto seen = [](const geometry::StereoRig& rig, const Eigen::Vector3d& X) {
    Eigen::Vector2d uvl, uvr;
    return rig.project(X, &uvl, &uvr) && rig.left().inImage(uvl) && rig.right().inImage(uvr);
  };
  for (const Eigen::Isometry3d& T : T_L_W)
    for (double s = -0.5 * g.length; s <= 0.5 * g.length; s += 0.01)
      for (double phi = -phi_max; phi <= phi_max; phi += 0.1) {
        const Eigen::Vector3d X = T * scene.surfacePoint(s, phi);
        if (seen(true_rig, X) && seen(calib_rig, X)) poi.push_back(X);
      }
  if (poi.size() < 10)
    throw sim::SimConfigError(field, "the limb is not in both camera images at working distance " +
                                         std::to_string(working_distance * 1e3) + " mm");
  try {
    return stereo::rectifyStereo(calib_rig, poi);
  } catch (const std::runtime_error& e) {
    throw sim::SimConfigError(field, e.what());
  }
}

int makeSkin(const sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
             const std::string& visible_path) {
  const sim::SkinConfig& k = c.skin;
  if (k.sweep.enabled) return makeSkinSweep(c, frames, bag, truth, quiet, visible_path);
  const sim::RigConfig rc = k.scaledRig();
  const geometry::StereoRig true_rig = rc.makeRig();
  const sim::PerturbedCalibration calib = sim::perturbCalibration(true_rig, c.images.perturbation, c.seed, k.working_distance);
  double yaw = 0, tilt = 0, roll = 0;
  const sim::SkinScene scene(k.geometryFor(c.seed, &yaw, &tilt, &roll), c.seed);
  const sim::SkinGeometry& g = scene.geometry();

  // World = limb frame (sim::skinRigPose places the rig).
  const Eigen::Isometry3d T_W_rig = sim::skinRigPose(g, yaw, tilt, roll, k.working_distance);
  const Eigen::Matrix3d R = T_W_rig.linear();
  const Eigen::Isometry3d T_W_L = T_W_rig * rc.poseRigLeft();
  const Eigen::Isometry3d T_L_W = T_W_L.inverse();
  const stereo::RectifiedPair info = rectifyForSkin(scene, true_rig, calib.rig, {T_L_W}, 1.4, "skin", k.working_distance);
  sim::RenderOptions ro;
  ro.supersample = c.images.supersample;
  ro.light_dir = (R * Eigen::Vector3d(0.15, -0.25, 1.0)).normalized();  // a light beside the rig
  ro.ambient = 0.25;
  writeRenderedExposures(scene, c, rc, true_rig, info, T_W_L, ro, frames, k.fps, bag, quiet);
  cv::Mat true_disparity;
  const cv::Mat visible = skinVisibility(scene, true_rig, info, calib.rig, T_W_L, &true_disparity);
  if (!cv::imwrite(visible_path, visible)) throw std::runtime_error("cannot write " + visible_path);
  const std::string disparity_path = visible_path.substr(0, visible_path.size() - std::string(".visible.png").size()) +
                                     ".disparity.tiff";
  if (!cv::imwrite(disparity_path, true_disparity)) throw std::runtime_error("cannot write " + disparity_path);
  truth << YAML::Key << "visible_skin" << YAML::Value << YAML::BeginMap;
  truth << YAML::Key << "image" << YAML::Value << visible_path.substr(visible_path.find_last_of('/') + 1);
  truth << YAML::Key << "meaning" << YAML::Value
        << "rectified left image: 0 = no skin seen by both cameras, else 1 + the larger incidence angle (deg)";
  truth << YAML::Key << "disparity" << YAML::Value << disparity_path.substr(disparity_path.find_last_of('/') + 1);
  truth << YAML::Key << "disparity_meaning" << YAML::Value
        << "rectified left image, float px: the true disparity (left column - right column) where both cameras see "
           "the skin, NaN elsewhere";
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

}  // namespace make_dataset_detail
