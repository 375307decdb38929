/**
 * @file results.h
 * @brief The results directory of a SLAM run (DESIGN.md "Results of an offline run"): trajectory.tum,
 * map.ply, sphere_fit.yaml, state.csv (per-frame filter state for plots) and summary.yaml; plus the absolute
 * trajectory error against a reference trajectory. Used by the eskf_slam nodelet and by process_bag.
 *
 * Units: SI in the files that programs read (tum, ply, csv); the human-facing YAML says mm where it says so.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <map>
#include <string>
#include <vector>

#include "skin3d/geometry/sphere_fit.h"
#include "skin3d/slam/slam_system.h"

namespace skin3d {
namespace slam {

/** @brief One pose of a trajectory: time (s), world <- left optical frame. */
struct StampedPose {
  double t = 0.0;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
};

/** @brief Per-frame filter state for plots (one row of state.csv). */
struct StateRow {
  double t = 0.0;
  FrameStats stats;
  Eigen::Vector3d v = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero();
  double trace_rig = 0.0, trace_landmarks = 0.0, trace_all = 0.0;
  double pose_position_std = 0.0;  //!< sqrt(trace of the position covariance), m
  double corr_vx_wy = 0.0;
  int pool_size = 0, pool_in_use = 0;
  long ever_seen = 0;
  /** Rig block of the error-state covariance (rigDim() square: dp, dtheta, dv, dw(, db_g)), for the
   *  per-axis error bounds and the correlation matrix of the plots (float: a long live session keeps
   *  one per frame). */
  Eigen::MatrixXf rig_covariance;
};

/** @brief Snapshot of the filter after a frame. */
StateRow stateRow(const SlamSystem& slam, const FrameStats& stats);

/** @brief Absolute trajectory error (positions, m) of `estimate` against `reference`, poses paired by time
 *  (nearest reference stamp within `max_dt` s); no alignment (both are expressed in the same world: SLAM's
 *  world is the first camera frame, as the datasets' is). */
struct TrajectoryError {
  int pairs = 0;
  double rmse = 0.0, mean = 0.0, max = 0.0, final = 0.0;  //!< m
  double rotation_rmse = 0.0;                             //!< rad
};
TrajectoryError trajectoryError(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& reference,
                                double max_dt = 1e-3);

/** @throws std::runtime_error naming the file when it cannot be written. */
void writeTum(const std::string& path, const std::vector<StampedPose>& trajectory);
void writePly(const std::string& path, const std::vector<MapPoint>& map);
void writeStateCsv(const std::string& path, const std::vector<StateRow>& rows);
/** @brief rig_covariance.csv: a '# variables:' comment naming the rig error-state variables, a header
 *  "t,P_0_0,P_0_1,...", then one row per frame: t and the rig covariance, row-major (SI: m, rad, s). */
void writeRigCovarianceCsv(const std::string& path, const std::vector<StateRow>& rows);
/** @brief sphere_fit.yaml: centre (m), radius and residuals (mm), inliers. */
void writeSphereFit(const std::string& path, const geometry::SphereFit& fit);
/** @brief Everything a run leaves behind (what writeResults writes). */
struct RunRecord {
  std::vector<StampedPose> trajectory;        //!< one pose per processed frame
  std::vector<StateRow> rows;                 //!< one row per processed frame
  std::vector<MapPoint> map;                  //!< final map (world)
  std::vector<StampedPose> ground_truth;      //!< optional (datasets): ATE and ground_truth.tum
  /** How ground_truth relates to the SLAM's world (summary.yaml, ate/alignment). */
  std::string ground_truth_alignment = "none (both worlds are the first camera frame)";
  bool fit_sphere = true;                     //!< robust sphere fit of the map -> sphere_fit.yaml
  std::vector<std::pair<std::string, std::string>> info;  //!< extra summary lines (key, value as text)
};

/**
 * @brief Writes the results directory (created if missing): trajectory.tum, map.ply, state.csv, rig_covariance.csv,
 * ground_truth.tum (if any), sphere_fit.yaml (if fit_sphere and the fit succeeds) and summary.yaml
 * (frames, map size, final covariance traces, v_x-omega_y correlation, ATE, sphere fit; mm where the key says).
 * @return the summary text. @throws std::runtime_error naming the path when something cannot be written.
 */
std::string writeResults(const std::string& dir, const RunRecord& run);

/** @brief A known landmark map (thesis experiment 1): make_dataset's FILE.map.csv, one landmark per line
 *  `id,x,y,z,d0,d1,...` (world frame, m; descriptor optional), '#' comments.
 *  @throws std::invalid_argument naming the file and line. */
std::pair<std::vector<Eigen::Vector3d>, std::vector<std::vector<float>>> readLandmarkMap(const std::string& path);

/** @brief Reads a TUM trajectory (t x y z qx qy qz qw per line, '#' comments). @throws std::runtime_error. */
std::vector<StampedPose> readTum(const std::string& path);

}  // namespace slam
}  // namespace skin3d
