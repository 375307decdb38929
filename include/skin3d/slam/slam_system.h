/**
 * @file slam_system.h
 * @brief The ES-EKF SLAM of a stereo rig, frame by frame: prediction (with gyroscope updates in time order),
 * data association through the landmark pool, the stacked landmark update, and landmark initialisation
 * (thesis ch. 5-6; ESKF_NOTES.md). Both the nodelet and the offline `process_bag` tool run this class.
 *
 * One frame (processFrame):
 *  1. Bad measurements (non-finite position or covariance, covariance not symmetric positive definite,
 *     point behind the camera) are dropped and counted in FrameStats::rejected_invalid.
 *  2. Prediction from the previous frame's time to this one; buffered gyroscope samples up to this time are
 *     applied in time order (predict to the sample's stamp, then a gyro update). Gyro samples older than
 *     the filter's time are dropped (counted).
 *  3. Association (LandmarkPool): descriptor distance plus the Mahalanobis gate of the innovation (the gate
 *     is the filter's d^2 = y^T S^-1 y; landmarks predicted behind the camera or farther than max_depth are
 *     not candidates). Fork duplicates are deleted.
 *  3b. Consensus: the associations must agree on one rigid motion (RANSAC, see SlamOptions::consensus_*).
 *  4. Update with at most max_updates_per_frame associated measurements (strongest first; a stacked
 *     batch, Joseph form). Every associated measurement counts for the pool's run lengths.
 *  5. Initialisation: the strongest unassociated measurements (at most max_new_per_frame) become new
 *     landmarks through the exact stereo augmentation, in slots the pool hands out (growing the pool, or
 *     evicting by its policy when full).
 * The first frame defines the world: the rig starts at the identity with the options' initial velocity
 * uncertainty, so world = left optical frame of the first frame (docs/design.md "world").
 *
 * Known map (thesis experiment 1): setKnownMap() gives landmark positions (and descriptors) that are
 * exact; associated measurements then update only the rig (no landmark states).
 *
 * Units: SI (m, s, rad). Not thread-safe.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "skin3d/slam/eskf.h"
#include "skin3d/slam/landmark_pool.h"

namespace skin3d {
namespace slam {

struct SlamOptions {
  EskfOptions filter;
  LandmarkPoolOptions pool;
  bool use_gyro = false;            //!< apply gyroscope samples (addGyro) as measurements of omega
  /** Gyroscope noise, rad/s (1 sigma per sample per axis), used when a sample comes without covariance. */
  double gyro_noise = 0.002;
  int max_updates_per_frame = 40;   //!< associated measurements used per update (strongest first), >= 1
  int max_new_per_frame = 20;       //!< new landmarks per frame (strongest unassociated first), >= 0
  /** New landmarks only while fewer than this many landmarks are associated in the frame (0 = always).
   *  Keeps the pool from churning when the view is well covered. */
  int min_tracked_for_no_new = 0;
  double max_depth = 5.0;           //!< m; landmarks predicted farther are not association candidates
  /** Consensus check of the associations (RANSAC of the rigid motion from 3 point pairs, world landmark vs
   *  measured point): associations inconsistent with the best motion (squared Mahalanobis distance above
   *  consensus_gate, chi2 3 dof) are rejected before the update. Individually gated wrong associations can
   *  each explain a different pose error; together they are not consistent. 0 iterations = off. */
  int consensus_iterations = 100;
  double consensus_gate = 16.27;    //!< chi2 3 dof, 99.9 %
  std::uint64_t consensus_seed = 1; //!< RANSAC's random sequence (deterministic runs)
  /** Share of a measurement's covariance that is white (independent from frame to frame), in (0, 1]: the
   *  association gate, the consensus and the update of mapped landmarks use measurement_white_fraction * C;
   *  a new landmark is placed with the whole C. The rest of the error, correlated over frames, belongs to
   *  filter.landmark_walk. Default 1 (all white: the landmark-level simulations). */
  double measurement_white_fraction = 1.0;
  /** Back end run over the whole recording when the results are written (SlamRunner::save): "batch" smooths
   *  every frame's pose, the landmarks and the gyro bias together (smoother.h) and trajectory.tum is its
   *  trajectory (the filter's is kept as trajectory_filter.tum); "off" = the filter's. */
  std::string smoother = "batch";
  double smoother_huber = 2.80;     //!< Huber radius of a landmark residual, in sigmas (chi^2 3 dof 95 %)
  int smoother_iterations = 50;     //!< Levenberg-Marquardt iterations at most
  /** m: loop closure in the smoother (a landmark found again under a new id, within this distance of the old
   *  one on the first solution's map and alike in descriptor, joins it); 0 = off. */
  double smoother_loop_radius = 0.005;
  /** @throws std::invalid_argument naming the bad field (also validates filter and pool options). */
  void validate() const;
};

/** @brief One stereo landmark measurement of a frame (left optical frame, SI units). */
struct Measurement {
  Eigen::Vector3d z = Eigen::Vector3d::Zero();
  Eigen::Matrix3d C = Eigen::Matrix3d::Identity();
  std::vector<float> descriptor;
  float strength = 0.0f;
};

/** @brief What happened in one frame (for logs, SlamState and plots). */
struct FrameStats {
  double time = 0.0;
  int measurements = 0;         //!< received
  int rejected_invalid = 0;     //!< dropped as bad input (step 1)
  int associated = 0;           //!< associated with pool / known-map landmarks
  int used = 0;                 //!< of those, used in the update
  int initialised = 0;          //!< new landmarks
  int forks_deleted = 0;        //!< duplicate landmarks deleted (forking)
  int rejected_consensus = 0;   //!< associations rejected by the rigid-motion consensus (RANSAC)
  int pruned = 0;               //!< landmarks deleted by the pool (stale / evicted)
  int gyro_used = 0, gyro_dropped = 0;
  double nis = 0.0;             //!< NIS of the stacked update
  int nis_dof = 0;
};

/** @brief A landmark of the map (world frame). */
struct MapPoint {
  std::int64_t id = -1;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  int times_observed = 0;
};

class SlamSystem {
 public:
  /** @throws std::invalid_argument for bad options. */
  explicit SlamSystem(const SlamOptions& options = SlamOptions());
  const SlamOptions& options() const { return opt_; }

  /** @brief Forget everything (the next frame defines the world again). */
  void reset();
  /** @brief Velocities (m/s, rad/s, left optical frame) the next initialisation starts from (default zero,
   *  with the options' initial_velocity_std / initial_angular_rate_std as their uncertainty). */
  void setInitialTwist(const Eigen::Vector3d& v, const Eigen::Vector3d& w);
  /** @brief Known landmark positions (world, m) with descriptors (same size) for experiment 1; empty = SLAM. */
  void setKnownMap(const std::vector<Eigen::Vector3d>& positions, const std::vector<std::vector<float>>& descriptors);

  /** @brief Buffers a gyroscope sample (time s, omega rad/s in the left optical frame, covariance (rad/s)^2;
   *  a zero covariance means options.gyro_noise). Ignored unless options.use_gyro: then nothing is checked and
   *  nothing thrown (the runners check and drop bad samples through their InputLedger first, whatever the option).
   *  @throws std::invalid_argument (use_gyro only) for non-finite values or a covariance that is not positive
   *  definite. */
  void addGyro(double time, const Eigen::Vector3d& omega, const Eigen::Matrix3d& covariance = Eigen::Matrix3d::Zero());
  /**
   * @brief Processes one frame of stereo landmarks at `time` (s).
   * @throws std::invalid_argument if time is not finite or not after the previous frame's time (the
   *         caller decides: e.g. a bag loop is a reset). Bad individual measurements are dropped, not thrown.
   */
  FrameStats processFrame(double time, const std::vector<Measurement>& measurements);

  /** @brief The last processFrame()'s landmark id (LandmarkPool ids, never reused) for each of its input
   *  measurements, in input order: the landmark it was associated with or initialised as, -1 for neither
   *  (dropped, rejected or not used; all -1 with a known map). What a smoother needs to tie frames together. */
  const std::vector<std::int64_t>& lastAssociations() const { return last_ids_; }

  bool initialised() const { return initialised_; }
  double time() const { return time_; }
  const Eskf& filter() const { return filter_; }
  const LandmarkPool& pool() const { return pool_; }
  /** @brief Current map: every landmark in the state (or the known map). */
  std::vector<MapPoint> map() const;
  /** @brief Correlation coefficient of v_x and omega_y in the rig covariance (the thesis' gauge ambiguity). */
  double correlationVxWy() const;

 private:
  void predictTo(double t, FrameStats* stats);
  void applyChanges(const PoolChanges& changes, FrameStats* stats);
  FrameStats knownMapFrame(double time, const std::vector<Measurement>& m, FrameStats stats);
  std::vector<bool> consensus(const std::vector<Association>& matches, const std::vector<Measurement>& meas,
                              const std::vector<Eigen::Matrix3d>& covariances) const;

  SlamOptions opt_;
  Eskf filter_;
  LandmarkPool pool_;
  bool initialised_ = false;
  double time_ = 0.0;
  std::deque<std::pair<double, std::pair<Eigen::Vector3d, Eigen::Matrix3d>>> gyro_;
  Eigen::Vector3d initial_v_ = Eigen::Vector3d::Zero(), initial_w_ = Eigen::Vector3d::Zero();
  std::vector<std::int64_t> last_ids_;
  std::vector<Eigen::Vector3d> known_positions_;
  std::vector<std::vector<float>> known_descriptors_;
};

}  // namespace slam
}  // namespace skin3d
