/**
 * @file results.h
 * @brief The results directory of a SLAM run (docs/design.md "Results of an offline run"): trajectory.tum,
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
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "skin3d/geometry/sphere_fit.h"
#include "skin3d/geometry/stamped_pose.h"
#include "skin3d/slam/slam_system.h"

namespace skin3d {
namespace slam {

/** @brief One pose of a trajectory: time (s), world <- left optical frame. */
using StampedPose = geometry::StampedPose;  //!< geometry/stamped_pose.h

/** @brief Per-frame filter state for plots (one row of state.csv). */
struct StateRow {
  double t = 0.0;
  FrameStats stats;
  Eigen::Vector3d v = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  //!< estimated gyroscope bias, rad/s (0 when not estimated)
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

/** @brief How a reference trajectory is brought into the estimate's world before the trajectory error. */
enum class AteAlignment {
  Auto,       //!< None when the reference's pose at the first paired frame is the estimate's (within 10 mm and
              //!< 10 mrad: the same world, e.g. a dataset whose world is the first camera frame), else SE3
  None,       //!< as given (the same world)
  FirstPose,  //!< the rigid motion that puts the reference's first paired pose onto the estimate's
  SE3         //!< the rigid motion that best fits all paired positions (Umeyama, no scale; as evo_ape --align)
};
/** @brief "auto", "none", "first_pose", "se3". @throws std::invalid_argument naming the accepted words. */
AteAlignment parseAteAlignment(const std::string& name);
std::string ateAlignmentName(AteAlignment a);

/** @brief Pairs of (estimate index, reference index) by time: for each estimate pose the nearest reference
 *  stamp within max_dt s (as the TUM benchmark's associate.py and evo do, without interpolation). */
std::vector<std::pair<int, int>> associateByTime(const std::vector<StampedPose>& estimate,
                                                 const std::vector<StampedPose>& reference, double max_dt);

/** @brief The rigid motion T (estimate world <- reference world) that minimises sum |p_est - T p_ref|^2 over the
 *  pairs (Umeyama 1991 without scale). Needs >= 3 pairs; @throws std::invalid_argument otherwise. */
Eigen::Isometry3d alignSE3(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& reference,
                           const std::vector<std::pair<int, int>>& pairs);

/** @brief Absolute trajectory error (positions, m) of `estimate` against `reference`, poses paired by time
 *  (associateByTime), after the stated alignment of the reference. */
struct TrajectoryError {
  int pairs = 0;
  double rmse = 0.0, mean = 0.0, max = 0.0, final = 0.0;  //!< m
  double rotation_rmse = 0.0;                             //!< rad
  AteAlignment alignment = AteAlignment::None;            //!< what was applied (Auto resolved)
  std::string alignment_note;                             //!< why (Auto) or a fallback (too few pairs)
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();  //!< estimate world <- reference world
  double max_dt = 0.0;                                    //!< s, the association tolerance used
  /** RMS spread of the paired estimate positions along their principal axes, largest first (m): when the two
   *  smaller ones are tiny (a short, straight piece), an SE(3) fit of the positions cannot fix the rotation about
   *  the long axis and the rotation error after it says little (alignment_note says so). */
  Eigen::Vector3d spread = Eigen::Vector3d::Zero();
};
TrajectoryError trajectoryError(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& reference,
                                AteAlignment alignment = AteAlignment::None, double max_dt = 0.01);

/** @brief A stamp as TUM files and evo write it: seconds with nine decimals ("1700000000.100000000"), from
 *  stamp_ns when known, else from t. */
std::string formatStamp(const StampedPose& p);
/** @brief "1700000000.1" -> 1700000000100000000 ns (digits past the ninth decimal are dropped); -1 if not a
 *  non-negative decimal number. */
std::int64_t parseStampNs(const std::string& text);

/** @brief trajectory.tum / ground_truth.tum: `t x y z qx qy qz qw`, stamps with nanosecond digits.
 *  @throws std::runtime_error naming the file when it cannot be written. */
void writeTum(const std::string& path, const std::vector<StampedPose>& trajectory);
void writePly(const std::string& path, const std::vector<MapPoint>& map);
/** @brief map_covariance.csv: per landmark id, position (m, world), the upper triangle of its covariance (m^2)
 *  and its observation count (what slam_nees.py --landmarks reads). */
void writeMapCovarianceCsv(const std::string& path, const std::vector<MapPoint>& map);
void writeStateCsv(const std::string& path, const std::vector<StateRow>& rows);
/** @brief rig_covariance.csv: a '# variables:' comment naming the rig error-state variables, a header
 *  "t,P_0_0,P_0_1,...", then one row per frame: t and the rig covariance, row-major (SI: m, rad, s). */
void writeRigCovarianceCsv(const std::string& path, const std::vector<StateRow>& rows);
/** @brief smoother_covariance.csv: as rig_covariance.csv with the 6 variables px py pz thx thy thz, one row per
 *  pose of `trajectory` (the smoother's marginal covariances). */
void writePoseCovarianceCsv(const std::string& path, const std::vector<StampedPose>& trajectory,
                            const std::vector<Eigen::Matrix<double, 6, 6>>& covariance);
/** @brief sphere_fit.yaml: centre (m), radius and residuals (mm), inliers. */
void writeSphereFit(const std::string& path, const geometry::SphereFit& fit);
/** @brief Everything a run leaves behind (what writeResults writes). */
struct RunRecord {
  std::vector<StampedPose> trajectory;        //!< one pose per processed frame
  std::vector<StateRow> rows;                 //!< one row per processed frame
  std::vector<MapPoint> map;                  //!< final map (world)
  std::vector<StampedPose> ground_truth;      //!< optional (datasets): ATE and ground_truth.tum
  /** How ground_truth was already moved before it was recorded here (summary.yaml, ate/ground_truth); empty:
   *  as the input gave it. */
  std::string ground_truth_alignment;
  /** summary.yaml's `ate`: this alignment (Auto: none when the worlds coincide, else SE(3)); `ate_se3` is always
   *  written too (the figure evo_ape --align reports). */
  AteAlignment ate_alignment = AteAlignment::Auto;
  double ate_max_dt = 0.01;  //!< s, the time association tolerance of the ATE
  bool fit_sphere = true;                     //!< robust sphere fit of the map -> sphere_fit.yaml
  std::vector<std::pair<std::string, std::string>> info;  //!< extra summary lines (key, value as text)
  /** The smoother's gyro bias at the last frame, rad/s, with its std (summary.yaml smoother_final_gyro_bias), and
   *  its mean over the recording (smoother_mean_gyro_bias); written when `smoother_bias_valid`. */
  bool smoother_bias_valid = false;
  Eigen::Vector3d smoother_bias = Eigen::Vector3d::Zero(), smoother_bias_std = Eigen::Vector3d::Zero();
  Eigen::Vector3d smoother_mean_bias = Eigen::Vector3d::Zero(), smoother_mean_bias_std = Eigen::Vector3d::Zero();
  /** The smoother's [p, theta] covariance per trajectory pose (smoother_covariance.csv); empty: no smoother run
   *  (an older smoother_covariance.csv in the directory is removed). */
  std::vector<Eigen::Matrix<double, 6, 6>> smoother_pose_covariance;
};

/**
 * @brief Writes the results directory (created if missing): trajectory.tum, map.ply, map_covariance.csv, state.csv, rig_covariance.csv,
 * ground_truth.tum (if any), sphere_fit.yaml (if fit_sphere and the fit succeeds) and summary.yaml
 * (frames, map size, final covariance traces, v_x-omega_y correlation, ATE, sphere fit; mm where the key says).
 * @return the summary text. @throws std::runtime_error naming the path when something cannot be written.
 */
std::string writeResults(const std::string& dir, const RunRecord& run);

/** @brief A known landmark map (thesis experiment 1): make_dataset's FILE.map.csv, one landmark per line
 *  `id,x,y,z,d0,d1,...` (world frame, m; descriptor optional), '#' comments.
 *  @throws std::invalid_argument naming the file and line. */
std::pair<std::vector<Eigen::Vector3d>, std::vector<std::vector<float>>> readLandmarkMap(const std::string& path);

/** @brief Reads a TUM trajectory (t x y z qx qy qz qw per line, '#' comments); stamps keep their nanoseconds
 *  (stamp_ns). @throws std::runtime_error. */
std::vector<StampedPose> readTum(const std::string& path);

}  // namespace slam
}  // namespace skin3d
