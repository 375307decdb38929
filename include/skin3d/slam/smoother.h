/**
 * @file smoother.h
 * @brief Batch smoother over a whole recording (Ceres): every frame's pose, every landmark seen in two frames
 * or more, and the gyroscope bias, estimated together from the stereo landmark measurements the filter
 * associated and from the gyroscope's rotation between frames (preintegrated, with the bias's first-order
 * correction). The causal ES-EKF (SlamSystem) gives the associations and the starting values.
 *
 * Factors (all whitened, SI units):
 *  - landmark: r = L^-1 (R_k^T (m - p_k) - z), C = L L^T the measurement's covariance (the stereo
 *    triangulation of its pixels), with a Huber loss at the chi^2 (3 dof, 95 %) radius;
 *  - gyro, between consecutive frames i, j: r = Log(dR_ij(b_i)^T R_i^T R_j) / sigma, dR_ij the product of
 *    Exp((omega_s - b) dt_s) over the samples (piecewise constant between stamps), corrected to first order
 *    in the bias, its covariance propagated from the per-sample noise;
 *  - bias random walk between frames (gyro_bias_walk sqrt(dt)) and the bias prior at the first frame;
 *  - motion: the filter's model, the velocity in the rig's frame R_k^T (p_k+1 - p_k) / dt changing between frames
 *    by its random walk (velocity_noise sqrt(dt)): holds frames with few landmarks, weak elsewhere.
 * The first frame's pose is held fixed (it defines the world).
 *
 * Not thread-safe. SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

namespace skin3d {
namespace slam {

struct SmootherOptions {
  /** Huber radius of a landmark residual (whitened, so in sigmas of its norm); chi^2 3 dof 95 % = 2.80. */
  double huber = 2.80;
  int min_observations = 2;       //!< a landmark seen in fewer frames is left out (it constrains no motion)
  int max_iterations = 50;        //!< Levenberg-Marquardt iterations
  double gyro_noise = 0.002;      //!< rad/s per sample per axis, for samples without covariance
  double gyro_bias_walk = 1e-4;   //!< rad/s per sqrt(s)
  double initial_gyro_bias_std = 0.01;                    //!< rad/s, prior at the first frame
  Eigen::Vector3d initial_gyro_bias = Eigen::Vector3d::Zero();  //!< rad/s, its mean
  double velocity_noise = 0.05;   //!< m/s per sqrt(s): the motion factor's random walk (the filter's)
  bool estimate_gyro_bias = true; //!< false: the bias is held at initial_gyro_bias
  /** Estimate the landmark measurements' variance factor from the recording (a first solve's chi^2 per degree
   *  of freedom) and solve again with it: the front end's covariances include what each landmark keeps from
   *  frame to frame, which the landmark's own position absorbs here. */
  bool estimate_variance_factor = true;
  int threads = 2;
  /** Loop closure: a landmark first seen after another was last seen, within this distance of it on the first
   *  solution's map (m) and with a descriptor closer than loop_descriptor_distance (and than 0.8 of the next
   *  candidate's), is that landmark found again; the problem is solved again with the two joined. 0 = off. */
  double loop_radius = 0.005;
  double loop_descriptor_distance = 0.3;  //!< the pool's max_descriptor_distance
  /** @throws std::invalid_argument naming the bad field. */
  void validate() const;
};

/** @brief One frame: its stamp, the filter's pose (world <- left optical frame) and its associated measurements. */
struct SmootherFrame {
  double t = 0.0;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  struct Observation {
    std::int64_t landmark = -1;   //!< the pool's landmark id
    Eigen::Vector3d z = Eigen::Vector3d::Zero();  //!< m, left optical frame
    Eigen::Matrix3d C = Eigen::Matrix3d::Identity();
    std::vector<float> descriptor;  //!< for loop closure (may be empty)
  };
  std::vector<Observation> observations;
};

struct GyroSample {
  double t = 0.0;
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();   //!< rad/s, left optical frame
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();       //!< (rad/s)^2; zero = SmootherOptions::gyro_noise
};

using Matrix6d = Eigen::Matrix<double, 6, 6>;

struct SmootherResult {
  bool ok = false;
  std::string message;                  //!< what was solved, or why nothing was
  std::vector<Eigen::Vector3d> p;       //!< per frame (same order as the input)
  std::vector<Eigen::Quaterniond> q;
  std::vector<Eigen::Vector3d> gyro_bias;  //!< per frame, rad/s (the initial bias when not estimated)
  Eigen::Matrix3d final_bias_covariance = Eigen::Matrix3d::Zero();  //!< (rad/s)^2 at the last frame; zero if unknown
  /** (rad/s)^2 of the mean of the per-frame biases over the recording (mean_bias()); zero if unknown. */
  Eigen::Matrix3d mean_bias_covariance = Eigen::Matrix3d::Zero();
  /** The per-frame biases' mean over the recording: what a constant bias is best compared with. */
  Eigen::Vector3d mean_bias() const {
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (const auto& x : gyro_bias) m += x / static_cast<double>(gyro_bias.size());
    return m;
  }
  /** Per frame, the marginal covariance of [p, theta] (m, rad; theta: R_true = Exp(theta) R, the world-frame
   *  rotation error, as the filter's): from the solution's Gauss-Newton information (the poses, landmarks and
   *  biases together). The first frame's is zero (it defines the world), as is any that could not be found. */
  std::vector<Matrix6d> pose_covariance;
  int landmarks = 0, observations = 0, outliers = 0;
  int loops = 0;                        //!< landmarks found again under a new id and joined (loop closure)
  int iterations = 0;
  double sigma0 = 1.0;                  //!< the landmark measurements' sigma factor used (1: not estimated)
  /** id, world (m), ascending id; an id joined to an earlier one by loop closure has that one's position. */
  std::vector<std::pair<std::int64_t, Eigen::Vector3d>> landmark_positions;
  double initial_cost = 0.0, final_cost = 0.0;
  double seconds = 0.0, solve_seconds = 0.0, covariance_seconds = 0.0;
};

/** @brief Rotation preintegrated between two stamps from the gyro samples (exposed for its test). */
struct GyroDelta {
  Eigen::Matrix3d dR = Eigen::Matrix3d::Identity();  //!< at the linearisation bias
  Eigen::Matrix3d J_bias = Eigen::Matrix3d::Zero();  //!< d Log(dR(b_lin)^T dR(b)) / d b
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  //!< rad^2 of Log(dR_true^T dR)
  Eigen::Vector3d bias_lin = Eigen::Vector3d::Zero();
  double dt = 0.0;
};
/** Integrates omega - bias over [t0, t1]: each sample's rate holds from its stamp to the next one (the sample
 *  before t0 from t0). @param samples time-ordered. Empty range or no sample before t1: identity, no information
 *  (covariance infinite on the diagonal: check `dt`). */
GyroDelta preintegrate(const std::vector<GyroSample>& samples, double t0, double t1, const Eigen::Vector3d& bias,
                       double default_noise);

/** @brief Solves the batch problem. Frames must be in time order; gyro samples may be empty (no gyro factors,
 *  no bias). Never throws for bad data (the result says why it did nothing); throws std::invalid_argument for
 *  bad options. */
SmootherResult smooth(const std::vector<SmootherFrame>& frames, const std::vector<GyroSample>& gyro,
                      const SmootherOptions& options);

}  // namespace slam
}  // namespace skin3d
