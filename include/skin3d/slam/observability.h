/**
 * @file observability.h
 * @brief Observability analysis of the ES-EKF SLAM's linearised error system (thesis §5.3;
 * ESKF_NOTES.md "Observability"), with the configurations of the thesis' experiments 1-3.
 *
 * 1. Generic part (any linear time-varying system, so it can be checked on textbook systems):
 *      x_{k+1} = F_k x_k,   y_k = H_k x_k + n_k,   W_k = information of n_k (Cov(n_k)^-1, or I),
 *    over the steps k = 0 .. N-1. With Phi_0 = I, Phi_k = F_{k-1} ... F_0, the (local) observability
 *    matrix of the initial state is O = [H_0; H_1 F_0; H_2 F_1 F_0; ...] (thesis eq. 5.15) and the
 *    observability Gramian (thesis eq. 5.12, with the measurement information as weight) is
 *      G = sum_k Phi_k^T H_k^T W_k H_k Phi_k = O_W^T O_W,
 *    where O_W is O with every row block whitened, L_k^T H_k Phi_k (W_k = L_k L_k^T, Cholesky).
 *    G is the Fisher information of x_0 (noise-free dynamics), G^-1 its Cramer-Rao bound.
 *    The analysis works on O_W (never on G, which would square the condition number): a compact
 *    n x n factor R with R^T R = G is accumulated by sequential (column-pivoted Householder) QR, and
 *    its one-sided Jacobi SVD gives sigma_i(O_W) = sqrt(eig_i(G)) and the right singular vectors.
 *    Numerical rank: the number of sigma_i > relative_tolerance * sigma_max (default 1e-9). Rank is
 *    invariant to the (non-singular) weighting and to the state units; the tolerance and the singular
 *    values are not: they are in whitened-measurement units per state unit (SI: m, rad, m/s, rad/s).
 *    The right singular vectors of the sigma_i below the tolerance span the unobservable subspace.
 *
 * 2. The SLAM configurations (error state of slam/eskf.h: [dp, dtheta, dv, dw, (db_g)], then 3 per
 *    landmark; GLOBAL angular error). F_k and H_k are the filter's own Jacobians, taken from an Eskf
 *    put at the true state of step k (Eskf::transitionJacobian, measurementJacobianBlocks,
 *    gyroJacobian); the full F is block diagonal: F_r for the rig, I for the landmarks.
 *    The trajectory is generated here (not by skin3d/sim): the thesis' globe geometry (a rig 0.6 m from
 *    the centre of a 0.2 m sphere, looking at the centre, orbiting at 0.15 rad/s at latitude -25 deg
 *    with a 23 deg axial tilt, 10 Hz), so v and w are constant in the rig frame
 *    (v ~ (-0.074, -0.035, 0) m/s, w ~ (-0.058, 0.123, -0.063) rad/s); the world is the first camera
 *    frame. By default the poses are propagated with the filter's own discrete model
 *    (slam::propagateNominal), so the linearisation points are a trajectory of the model; with
 *    model_consistent_trajectory = false the exact circular orbit is used instead (the model's Euler
 *    step then disagrees with it by O(|w| |v| dt^2), which spoils the rotation gauge - the classical
 *    EKF-SLAM inconsistency). Landmarks: a deterministic Fibonacci pattern on the sphere's cap facing the
 *    rig at mid-window; landmark j is measured at step k when it is in front of the left camera,
 *    inside its image and its surface faces the rig.
 *      Experiment 1 ("ES-EKF with known landmarks"): state = rig (12); z = R^T (m - p), m known.
 *      Experiment 2 (SLAM without gyroscope): state = rig + landmarks (12 + 3K).
 *      Experiment 3 (SLAM with gyroscope): plus z_g = w (+ b_g): 12 + 3K, or 15 + 3K with the bias.
 *    Theory: 1 is fully observable; 2 and 3 miss exactly the 6-dof gauge of the world frame (translate
 *    or rotate p, every m and the attitude together: all measurements are relative) - skin3d removes it
 *    by fixing the first pose with zero covariance (EskfOptions::initial_position_std = 0,
 *    initial_attitude_std = 0). slamGaugeBasis() gives those 6 directions analytically.
 *
 * 3. Restriction to a subset of the state (e.g. (v, w), the thesis' v_x - w_y ambiguity): the
 *    columns of the kept states are projected onto the orthogonal complement of the span of the
 *    nuisance columns (states that must be estimated too), after deleting the columns of known /
 *    anchored states. Its Gramian is the Schur complement of G, i.e. the marginal information.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "skin3d/slam/eskf.h"

namespace skin3d {
namespace slam {

// ============================================================================================ generic

/** @brief A linearised time-varying system over N = H.size() steps (see the file comment). */
struct LinearizedSystem {
  /** F[k] (n x n) maps the state of step k to step k+1; at least N-1 of them (extra ones are unused). */
  std::vector<Eigen::MatrixXd> F;
  /** H[k] (m_k x n, m_k >= 0) is the measurement Jacobian of step k. */
  std::vector<Eigen::MatrixXd> H;
  /** Empty (W_k = I for every k) or one per step: W[k] (m_k x m_k) symmetric positive definite
   *  information of the measurement noise (inverse covariance). */
  std::vector<Eigen::MatrixXd> W;

  int dim() const;                                          //!< n (from H[0], or F[0]); 0 if empty
  int steps() const { return static_cast<int>(H.size()); }  //!< N
  /** @brief Throws std::invalid_argument naming the first inconsistent matrix (sizes, finiteness, W not SPD). */
  void validate() const;
};

/** @brief Options of the rank decision. */
struct ObservabilityOptions {
  /** sigma_i counts for the rank iff sigma_i > relative_tolerance * sigma_max. In (0, 1). Default 1e-9. */
  double relative_tolerance = 1e-9;
  /** Right singular vectors returned in `weakest` (the smallest sigma first): at least the rank
   *  deficiency, at least this many (capped at n). Default 0 (= the deficiency only). */
  int weakest_count = 0;
};

/** @brief Result of a rank / SVD analysis. */
struct ObservabilityReport {
  int dim = 0;                      //!< n
  int rank = 0;                     //!< numerical rank
  double tolerance = 0.0;           //!< absolute threshold relative_tolerance * sigma_max
  Eigen::VectorXd singular_values;  //!< all n, descending (zeros appended if the matrix has < n rows)
  /** n x c: right singular vectors of the c smallest sigma, smallest first (column i belongs to
   *  singular_values(n - 1 - i)); the first deficiency() columns are an orthonormal basis of the
   *  numerically unobservable subspace. Sign: the largest-magnitude component is positive. */
  Eigen::MatrixXd weakest;
  int deficiency() const { return dim - rank; }
  bool fullRank() const { return rank == dim; }
  Eigen::MatrixXd nullSpace() const { return weakest.leftCols(deficiency()); }
  /** sigma_max / sigma_min over the observable part (sigma_max / sigma_rank); inf if rank == 0. */
  double observableCondition() const;
};

/** @brief The stacked observability matrix [H_0; H_1 Phi_1; ...] over the first `steps` steps
 *  (all if < 0), rows whitened by L_k^T (W_k = L_k L_k^T) when `weighted` and W is given. */
Eigen::MatrixXd observabilityMatrix(const LinearizedSystem& sys, bool weighted = false, int steps = -1);
/** @brief The Gramian sum_k Phi_k^T H_k^T W_k H_k Phi_k (W_k = I when sys.W is empty) over the first
 *  `steps` steps (all if < 0). */
Eigen::MatrixXd observabilityGramian(const LinearizedSystem& sys, int steps = -1);
/** @brief An n x n factor R, R^T R = observabilityGramian(sys, steps) (upper triangular up to a column
 *  permutation), accumulated by sequential QR of the whitened rows: memory O(n^2), the stacked matrix is
 *  never formed; it has the singular values and right singular vectors of the whitened O. */
Eigen::MatrixXd observabilityFactor(const LinearizedSystem& sys, int steps = -1);

/** @brief Rank and SVD analysis of any matrix M (m x n, m may be < n): the observability matrix, its
 *  factor, or any other matrix whose right null space is wanted. @throws std::invalid_argument on an
 *  empty or non-finite M or bad options. */
ObservabilityReport analyseMatrix(const Eigen::MatrixXd& M, const ObservabilityOptions& options = {});
/** @brief analyseMatrix(observabilityFactor(sys, steps)) after sys.validate(). */
ObservabilityReport analyseObservability(const LinearizedSystem& sys, const ObservabilityOptions& options = {},
                                         int steps = -1);

/** @brief Largest distance of a column of `directions` (each normalised first) from span(basis)
 *  (basis: orthonormal columns): 0 when every direction lies in the subspace. */
double subspaceResidual(const Eigen::MatrixXd& directions, const Eigen::MatrixXd& basis);

/** @brief Observability of a subset of the state (file comment, part 3). */
struct RestrictedObservability {
  std::vector<int> kept;            //!< state indices analysed, in this order
  int nuisance_rank = 0;            //!< numerical rank of the nuisance columns
  Eigen::VectorXd singular_values;  //!< of the projected kept columns, descending
  Eigen::MatrixXd directions;       //!< their right singular vectors (|kept| square, same order)
  Eigen::MatrixXd information;      //!< marginal information (|kept| square): the projected Gramian
  /** Numerical rank of the projected columns: sigma_i > relative_tolerance x the largest singular value
   *  of the kept columns before the projection. */
  int rank = 0;
  /** Inverse of `information` (Cramer-Rao bound) and its correlation matrix, when rank == |kept|;
   *  empty otherwise. */
  Eigen::MatrixXd covariance, correlation;
};

/** @brief Restrict M (rows x n: observability matrix or factor) to the columns `kept`, deleting the
 *  columns `known` (states known exactly, e.g. an anchored first pose) and projecting out the span of
 *  all other columns (nuisance states estimated as well).
 *  @throws std::invalid_argument on bad or overlapping indices. */
RestrictedObservability restrictObservability(const Eigen::MatrixXd& M, const std::vector<int>& kept,
                                              const std::vector<int>& known = {},
                                              double relative_tolerance = 1e-9);

// ====================================================================================== state layout

/** @brief A named block of the state vector. */
struct StateBlock {
  std::string name;  //!< "p", "theta", "v", "w", "b_g", "m0", "m1", ... (or any name)
  int start = 0;
  int size = 0;
};
/** @brief The Eskf error-state layout: p, theta, v, w (, b_g when rig_dim == 15), m0 .. m{K-1}. */
std::vector<StateBlock> errorStateBlocks(int rig_dim, int landmarks);
/** @brief "p_x", "theta_y", "m3_z", ...: one label per component (3-blocks get _x,_y,_z, others _0,_1,..). */
std::vector<std::string> componentLabels(const std::vector<StateBlock>& blocks);
/** @brief Words for a direction: its share (norm fraction) per block, largest first, landmark blocks
 *  m0, m1, ... pooled as "m*" (with the mean 3-vector), e.g. "p 0.57 [0.10 -0.55 0.10]; m* 0.82 ...".
 *  Blocks below `min_share` are omitted. */
std::string describeDirection(const Eigen::VectorXd& direction, const std::vector<StateBlock>& blocks,
                              double min_share = 0.05);

/** @brief The 6 gauge directions of SLAM at the state (x0, landmarks), in the Eskf error state of
 *  dimension rig_dim + 3 K: columns 0-2 translation along world x, y, z (dp = dm_j = e_i), columns 3-5
 *  rotation about world x, y, z through the world origin (dtheta = e_i, dp = e_i x p, dm_j = e_i x m_j;
 *  v, w, b_g unchanged). Columns are normalised. */
Eigen::MatrixXd slamGaugeBasis(const RigState& x0, const std::vector<Eigen::Vector3d>& landmarks, int rig_dim);

// ==================================================================== the thesis' experiments 1-3

/** @brief The orbit scenario (SI units; defaults: the thesis' globe, ch. 7). */
struct OrbitScenario {
  double sphere_radius = 0.2;     //!< m
  double distance = 0.6;          //!< m, rig to sphere centre
  double rate = 0.15;             //!< rad/s, orbit rate
  double latitude = -25.0 * 3.14159265358979323846 / 180.0;  //!< rad, latitude of the orbit
  double tilt = 23.0 * 3.14159265358979323846 / 180.0;       //!< rad, axial tilt (sets the image roll)
  double fps = 10.0;              //!< Hz, frame (and gyro measurement) rate
  int landmarks = 10;             //!< K
  int steps = 20;                 //!< N frames
  double cap_half_angle = 30.0 * 3.14159265358979323846 / 180.0;  //!< rad, landmark cap seen from the centre
  double focal_px = 1.8e-3 / 2.24e-6;  //!< px, left camera (SLAM rig of the thesis, 2x2 binning)
  int image_width = 640, image_height = 480;  //!< px
  double baseline = 0.106;        //!< m, stereo baseline (|(105, 0, 15)| mm) of the covariance model
  double pixel_sigma = 0.5;       //!< px, 1 sigma per image coordinate (disparity: sqrt(2) x this)
  double gyro_sigma = 0.002;      //!< rad/s, 1 sigma per axis of one gyro measurement per frame
  /** W_k = measurement information (stereo triangulation covariance, gyro_sigma) when true; W_k = I
   *  when false (every row weighted 1 in SI units). */
  bool information_weighting = true;
  /** Propagate with slam::propagateNominal (true) or sample the exact circular orbit (false). */
  bool model_consistent_trajectory = true;
  /** @brief Throws std::invalid_argument naming the first bad field. */
  void validate() const;
};

/** @brief The generated truth. */
struct OrbitTrajectory {
  double dt = 0.1;                            //!< s
  std::vector<RigState> states;               //!< N rig states (state 0: p = 0, q = I: the world frame)
  std::vector<Eigen::Vector3d> landmarks;     //!< K world points (m)
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  //!< sphere centre in the world (m)
  std::vector<std::vector<int>> visible;      //!< per step: the landmarks measured
  int neverSeen() const;                      //!< landmarks measured at no step
};
/** @brief Generate the trajectory and landmarks of `scenario` (validated). */
OrbitTrajectory makeOrbitTrajectory(const OrbitScenario& scenario);

enum class Experiment {
  KnownLandmarks = 1,  //!< thesis experiment 1: rig only, known landmarks
  Slam = 2,            //!< experiment 2: SLAM without gyroscope
  SlamGyro = 3,        //!< experiment 3: SLAM with gyroscope (no bias state)
  SlamGyroBias = 4     //!< experiment 3 with the gyro-bias state (15 + 3K)
};
const char* experimentName(Experiment e);
/** @brief Rig dimension (12 or 15) and total state dimension of an experiment with K landmarks. */
int experimentRigDim(Experiment e);
int experimentDim(Experiment e, int landmarks);

/** @brief The linearised system of an experiment along `traj`, built from the Eskf's Jacobians
 *  (gamma = lambda = 1), W per scenario.information_weighting. */
LinearizedSystem buildExperiment(const OrbitTrajectory& traj, const OrbitScenario& scenario, Experiment e);

/** @brief The per-frame stereo covariance model (m^2) of a point p_c in the camera frame (m):
 *  J diag(s^2, s^2, 2 s^2) J^T of (u, v, disparity) -> point, s = pixel_sigma. */
Eigen::Matrix3d stereoPointCovariance(const Eigen::Vector3d& p_c, const OrbitScenario& scenario);

/** @brief The real filter run along `traj` with noise-free measurements (innovations are zero, so
 *  the nominal state stays on the truth and the covariance is the one linearised at the truth):
 *  Eskf with `options` (estimate_gyro_bias forced to match e), reset to state 0 with
 *  defaultRigCovariance(), landmarks added at their first sighting (stereoPointCovariance), then per
 *  frame predict(dt), update(), updateGyro() (exp. 3), updateKnown() (exp. 1). Returns, per step,
 *  the correlation coefficient of the errors of v_x and w_y, and their standard deviations. */
struct FilterCorrelation {
  std::vector<double> corr_vx_wy, std_vx, std_wy;  //!< per step (1, m/s, rad/s)
};
FilterCorrelation runFilterCorrelation(const OrbitTrajectory& traj, const OrbitScenario& scenario, Experiment e,
                                       const EskfOptions& options = EskfOptions());

}  // namespace slam
}  // namespace skin3d
