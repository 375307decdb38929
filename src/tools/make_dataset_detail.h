// SPDX-License-Identifier: BSD-3-Clause
// Private helpers of make_dataset, shared by its files:
//   make_dataset_emit.cpp    pose messages and ground-truth YAML pieces;
//   make_dataset_globe.cpp   the globe datasets (landmarks and images);
//   make_dataset_scenes.cpp  the rendered workpiece and skin datasets;
//   make_dataset.cpp         the command line and main.
#pragma once

#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <sensor_msgs/Image.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "skin3d/geometry/stereo_rig.h"
#include "skin3d/sim/dataset.h"
#include "skin3d/stereo/rectification.h"

namespace make_dataset_detail {

inline const std::string kLeftFrame = "stereo_left_optical_frame";
inline const std::string kRightFrame = "stereo_right_optical_frame";
inline const std::string kWorldFrame = "world";
inline ros::Time g_start(1000.0);
/** --compress: -1 raw images (image_raw), 0 PNG, 1 ... 100 JPEG of that quality (image_raw/compressed). */
inline int g_compress = -1;
/** --truth-only: the sweep writes its truth without rendering a pair. */
inline bool g_truth_only = false;
/** One camera's image into `bag` on stereo/SIDE/image_raw, or image_raw/compressed as --compress says. */
void writeImage(rosbag::Bag& bag, const std::string& side, const ros::Time& stamp, const sensor_msgs::Image& img);  // the first stamp (--start): a fixed, valid ROS time, so that bags are deterministic

// ---- make_dataset_emit.cpp
geometry_msgs::PoseStamped poseMsg(const Eigen::Isometry3d& T, const ros::Time& t);
void emitVec(YAML::Emitter& e, const Eigen::VectorXd& v);
void emitRig(YAML::Emitter& e, const char* name, const skin3d::geometry::StereoRig& rig);
void emitRealism(YAML::Emitter& e, const skin3d::sim::DatasetConfig& c, const skin3d::sim::PerturbedCalibration& p);
/** Pose of the right optical frame in the left one (left <- right). */
Eigen::Isometry3d poseLeftRight(const skin3d::geometry::StereoRig& rig);

// ---- make_dataset_globe.cpp and make_dataset_scenes.cpp: one dataset kind each into `bag` and `truth`
int makeGlobe(const skin3d::sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
              const std::string& map_path);
int makeWorkpiece(const skin3d::sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet);
int makeSkin(const skin3d::sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
             const std::string& visible_path);
/** make_dataset_sweep.cpp: the skin dataset with skin.sweep.enabled (a hand-held sweep around the limb); writes
 *  the swept-skin coverage truth to `visible_path`. */
int makeSkinSweep(const skin3d::sim::DatasetConfig& c, int frames, rosbag::Bag& bag, YAML::Emitter& truth, bool quiet,
                  const std::string& visible_path);
/** The rectification of a skin dataset (make_dataset_scenes.cpp): fitted to the skin both cameras see, under the true
 *  rig and the calibrated one, from every pose in T_L_W (limb -> left optical frame), |phi| <= phi_max around the
 *  limb. @throws SimConfigError(field) when too little skin is seen or the rectification fails. */
skin3d::stereo::RectifiedPair rectifyForSkin(const skin3d::sim::SkinScene& scene, const skin3d::geometry::StereoRig& true_rig,
                                             const skin3d::geometry::StereoRig& calib_rig,
                                             const std::vector<Eigen::Isometry3d>& T_L_W, double phi_max,
                                             const std::string& field, double working_distance);
/** The limb and its plaques' truth (make_dataset_scenes.cpp), points in the frame T_L_W maps the limb frame to. */
void emitSkinTruth(YAML::Emitter& truth, const skin3d::sim::SkinScene& scene, const Eigen::Isometry3d& T_L_W);

}  // namespace make_dataset_detail
