/**
 * @file eskf.h
 * @brief Error-state EKF SLAM of a stereo rig (thesis ch. 5-6, Algorithm 5.1; ESKF_NOTES.md "ES-EKF SLAM").
 *
 * Nominal state (SI units, frames of docs/design.md):
 *   p   position of the CCS (left optical frame) origin in the world (m),
 *   q   Hamilton unit quaternion, world <- CCS, R = R(q),
 *   v   linear velocity in the CCS (m/s),   w (omega) angular velocity in the CCS (rad/s),
 *   b_g gyroscope bias in the CCS (rad/s), estimated only when EskfOptions::estimate_gyro_bias,
 *   m_j landmark slots j = 0..S-1, points in the world (m).
 *
 * Error state (GLOBAL angular error, R_true = Exp(dtheta) R):
 *   [dp(0..2), dtheta(3..5), dv(6..8), dw(9..11), (db_g(12..14))] = rigDim() = 12 or 15 dims,
 *   then 3 dims per slot: slot j occupies indices rigDim() + 3 j .. rigDim() + 3 j + 2.
 * A slot is active (holds a landmark) or free; a free slot's rows and columns of the covariance are
 * exactly zero and no operation touches it.
 *
 * System model over a step dt (s):
 *   p+ = p + R v dt,  q+ = q (x) Exp(w dt),  v+ = gamma v + w1,  w+ = lambda w + w2,  b+ = b + w3,  m+ = m,
 *   w1 ~ N(0, velocity_noise^2 dt I), w2 ~ N(0, angular_rate_noise^2 dt I), w3 ~ N(0, gyro_bias_walk^2 dt I),
 *   and optionally a landmark random walk m+ = m + w4, w4 ~ N(0, s_j R diag(landmark_walk^2 dt) R^T) (default off;
 *   s_j = 1, or (|z_j| / reference distance)^4 with z_j the landmark's latest measurement).
 * Exact first-order error dynamics (verified numerically in test_eskf):
 *   dp+ = dp - [R v dt]x dtheta + R dt dv,   dtheta+ = dtheta + R Jl(w dt) dt dw,
 *   dv+ = gamma dv + w1,  dw+ = lambda dw + w2,  db+ = db + w3,  dm+ = dm.
 * (ESKF_NOTES' "R dt dw" drops Jl(w dt) = I + 1/2 [w dt]x + ...: an O(|w| dt^2) error.)
 *
 * Landmark measurement: z = R^T (m - p) + n, n ~ N(0, C) (stereo-triangulated point in the CCS), with
 *   H_dp = -R^T, H_dtheta = R^T [m - p]x, H_dm = R^T (every other column is zero).
 * Gyroscope measurement: z = w + b_g + n (b_g constant, usually zero, when it is not estimated),
 *   H_dw = I, H_db = I (when estimated).
 *
 * Update (Algorithm 5.1, all observations of a frame stacked): S = H C H^T + C_n, K = C H^T S^-1,
 * dx = K (z - h(x)), C <- Joseph's (I - K H) C (I - K H)^T + K C_n K^T; inject
 * (p += dp, q <- Exp(dtheta) (x) q, v += dv, w += dw, b += db, m += dm) and reset the error:
 * C <- G C G^T with G = I except G_theta = Jl(dtheta) on the angular block (Sola 2017 §7.2 writes
 * its first-order truncation I + 1/2 [dtheta]x; Jl is what numerical differentiation of the true
 * reset dtheta_new = Log(Exp(dtheta_old) Exp(-dtheta)) gives, and the two differ by O(|dtheta|^2)).
 *
 * Cost. The fast path never forms H, F or G as n x n matrices (n = rigDim() + 3 capacity()):
 *  - predict(): F is I outside the rig block, so only C_rr <- F_r C_rr F_r^T + Q and the rig-landmark
 *    cross-covariances C_rm <- F_r C_rm change: O(rigDim^2 n); landmark blocks are not touched (but for
 *    the 3x3 diagonal blocks when the landmark walk is on: O(n)).
 *  - update(): A = C H^T (n x m, m = 3 x number of observations) is built from the 9 non-zero columns of each
 *    observation's H (O(n m)); S = H A + C_n; with the Cholesky factor S = L L^T, U = A L^-T and the
 *    applied gain is K = U L^-1 = C H^T S^-1, dx = U (L^-1 y). Joseph's expression, expanded, is
 *    C - K (HC) - (HC)^T K^T + K S K^T (algebraically identical to the literal form for ANY K); for
 *    this K its three correction terms all equal U U^T, so the fast path evaluates it as the
 *    symmetric rank-m downdate C - U U^T on the lower triangle, O(n^2 m / 2), split over
 *    EskfOptions::threads threads (OpenBLAS dsyrk/dgemm per part when built with it, else Eigen), then
 *    mirrors the triangle (exact symmetry). With
 *    EskfOptions::joseph_explicit_gain the expanded expression is evaluated term by term with an
 *    explicit K (twice the flops); both agree with the literal dense form to rounding.
 *  - The reset touches only the 3 angular rows/columns: O(n).
 *  - propagateWithGyro(): the k gyro samples between two frames (predict + gyro update each) on rig-sized
 *    matrices, then one symmetric rank-rigDim() downdate of the landmark block: O(rigDim n^2 / 2) instead of
 *    k full updates O(k (3 n^2 / 2 + n^2 mirror)); same result to rounding (test_eskf, EskfGyroInterval).
 * Timings (bench_slam, with the dense reference side by side): docs/BENCHMARKS.md, "ES-EKF SLAM".
 * predictDense(), updateDense(), updateGyroDense() and updateKnownDense() are the textbook dense O(n^3) forms (full F,
 * full H, literal Joseph, full G) kept for tests and benchmarks only.
 *
 * Errors: every public mutator validates all its inputs first and throws std::invalid_argument with
 * a message naming the problem; a call that throws leaves the filter unchanged. (An innovation
 * covariance S that fails its Cholesky factorisation despite valid inputs, i.e. a numerically
 * broken filter, throws std::runtime_error, also before any change.)
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "skin3d/geometry/quaternion.h"

namespace skin3d {
namespace slam {

/** @brief Tuning of the ES-EKF. Defaults are for a hand-held rig scanning skin at 10-30 Hz. */
struct EskfOptions {
  /** Linear-velocity forgetting factor Gamma (times I), in [0, 1]: v+ = gamma v. The thesis uses 1. */
  double gamma = 1.0;
  /** Angular-velocity forgetting factor Lambda (times I), in [0, 1]: w+ = lambda w. The thesis uses 1. */
  double lambda = 1.0;
  /** Std of the velocity random walk w1 (m/s per sqrt(s)): Q_v = velocity_noise^2 dt I. Default
   *  0.05: a hand moving a camera at a few cm/s changes its speed by ~5 cm/s within a second. */
  double velocity_noise = 0.05;
  /** Std of the angular-rate random walk w2 (rad/s per sqrt(s)): Q_w = angular_rate_noise^2 dt I.
   *  Default 0.1 (about 6 deg/s change of turn rate within a second). */
  double angular_rate_noise = 0.1;
  /** Estimate a gyroscope bias (error state grows from 12 to 15 rig dimensions). Default false. */
  bool estimate_gyro_bias = false;
  /** Std of the gyro-bias random walk (rad/s per sqrt(s)): Q_b = gyro_bias_walk^2 dt I. Default 1e-4
   *  (conservative for a MEMS gyroscope). Used only when estimate_gyro_bias. */
  double gyro_bias_walk = 1e-4;
  /** Initial std of p (m) used by reset(const RigState&). Default 0: the world frame is the first
   *  camera frame (it removes SLAM's 6-dof gauge freedom). */
  double initial_position_std = 0.0;
  /** Initial std of the attitude error dtheta (rad) used by reset(const RigState&). Default 0 (gauge). */
  double initial_attitude_std = 0.0;
  /** Initial std of v (m/s) used by reset(const RigState&). Default 0.1. */
  double initial_velocity_std = 0.1;
  /** Initial std of w (rad/s) used by reset(const RigState&). Default 0.2. */
  double initial_angular_rate_std = 0.2;
  /** Initial std of b_g (rad/s) used by reset(const RigState&). Default 0.01 (~0.6 deg/s turn-on bias). */
  double initial_gyro_bias_std = 0.01;
  /** Gyroscope bias (rad/s, CCS) the SLAM starts from (SlamSystem puts it into the first state). Default zero.
   *  With estimate_gyro_bias it is the prior mean (std initial_gyro_bias_std); without, the bias assumed
   *  throughout. A value measured while the rig stood still (scripts/gyro_bias.py) removes most of what the
   *  images cannot tell from a bias in the first seconds of a scan. */
  Eigen::Vector3d initial_gyro_bias = Eigen::Vector3d::Zero();
  /** Landmark random walk (m per sqrt(s), along the camera's x, y, z axes at the time of the prediction):
   *  every active landmark gets Q_m = R diag(landmark_walk^2 dt) R^T in predict() (F is unchanged: dm+ = dm + w4).
   *  It models measurement errors that are correlated over frames (the image front end's: the same feature
   *  keeps most of its error from one frame to the next) as a slowly moving landmark, so the filter does
   *  not average them as if they were white. Default 0 (off): landmark-level simulations have white noise. */
  Eigen::Vector3d landmark_walk = Eigen::Vector3d::Zero();
  /** m; > 0: each landmark's walk scales as a stereo depth error does, with the square of its distance: its
   *  Q_m is multiplied by (|z| / landmark_walk_reference_distance)^4, z its latest measurement (m, CCS: set by
   *  addLandmark() and by every update() that observes it), so landmark_walk is the walk of a landmark seen
   *  at this distance. 0 (default): the same walk for every landmark. */
  double landmark_walk_reference_distance = 0.0;
  /** The default update's symmetric downdate C - U U^T through OpenBLAS (dsyrk/dgemm, kernels for the CPU
   *  chosen at run time) when the library was built with it (Eskf::blasAvailable()); false: Eigen's product
   *  (SSE2 in Debian's build). Same result to rounding; the benchmark compares the two. Default true. */
  bool blas_downdate = true;
  /** Threads for the O(n^2 m) covariance update (1 = the calling thread only). Default 2. */
  int threads = 2;
  /** Evaluate Joseph's expanded expression C - K(HC) - (HC)^T K^T + K S K^T term by term with an
   *  explicit gain (2x the flops of the default symmetric downdate; same result to rounding). */
  bool joseph_explicit_gain = false;

  /** @brief Throws std::invalid_argument naming the first bad field and its value. */
  void validate() const;
};

/** @brief Nominal rig state (see the file comment for frames and units). */
struct RigState {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();          //!< CCS origin in the world (m)
  geometry::Quat q = geometry::Quat::Identity();        //!< world <- CCS (Hamilton, unit)
  Eigen::Vector3d v = Eigen::Vector3d::Zero();          //!< linear velocity in the CCS (m/s)
  Eigen::Vector3d w = Eigen::Vector3d::Zero();          //!< angular velocity in the CCS (rad/s)
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  //!< gyroscope bias in the CCS (rad/s)
};

// ---------------------------------------------------------------------------------------------
// The true nonlinear functions of the model (used by the filter; exposed so tests can
// differentiate them numerically through a perturbation in the error state).

/** @brief Nominal transition over dt (s): p + R v dt, q (x) Exp(w dt), gamma v, lambda w, b. */
RigState propagateNominal(const RigState& x, double dt, double gamma, double lambda);
/** @brief Retraction x (+) dx, dx = [dp, dtheta, dv, dw(, db)] of size 12 or 15 (bias kept for 12):
 *  p + dp, Exp(dtheta) (x) q, v + dv, w + dw, b + db. */
RigState retract(const RigState& x, const Eigen::VectorXd& dx);
/** @brief a (-) b, of size rig_dim (12 or 15): the error d with retract(b, d) == a
 *  (dtheta = Log(R_a R_b^T), the global angular error). */
Eigen::VectorXd rigDifference(const RigState& a, const RigState& b, int rig_dim);
/** @brief Landmark measurement h = R^T (m - p) (m, CCS) of the world point m (m). */
Eigen::Vector3d observeLandmark(const RigState& x, const Eigen::Vector3d& m);
/** @brief Inverse measurement: world point p + R z of the CCS point z (m). */
Eigen::Vector3d landmarkFromObservation(const RigState& x, const Eigen::Vector3d& z);
/** @brief Gyroscope prediction w + b_g (rad/s, CCS). */
Eigen::Vector3d predictGyro(const RigState& x);

/** @brief The error-state EKF (see the file comment). Not thread-safe; one instance per estimator. */
class Eskf {
 public:
  /** @brief One stereo landmark observation. */
  struct Observation {
    int slot = -1;                                     //!< landmark slot (must be active)
    Eigen::Vector3d z = Eigen::Vector3d::Zero();       //!< measured point in the CCS (m)
    Eigen::Matrix3d C = Eigen::Matrix3d::Identity();   //!< its covariance (m^2), symmetric positive definite
  };
  /** @brief Outcome of an update. */
  struct UpdateResult {
    int used = 0;     //!< observations used
    double nis = 0;   //!< normalised innovation squared y^T S^-1 y of the stacked innovation
    int dof = 0;      //!< its degrees of freedom (3 per observation)
  };
  /** @brief Innovation of one observation against the current state (for gating). */
  struct Innovation {
    Eigen::Vector3d y = Eigen::Vector3d::Zero();      //!< z - h(x) (m, CCS)
    Eigen::Matrix3d S = Eigen::Matrix3d::Identity();  //!< H C H^T + C_obs (m^2)
    double d2 = 0;                                    //!< Mahalanobis distance y^T S^-1 y (chi^2, 3 dof)
  };
  /** @brief Observation of a landmark whose world position is known exactly (thesis experiment 1,
   *  "ES-EKF with known landmarks"): z = R^T (m - p) + n; H has only the dp, dtheta blocks. */
  struct KnownObservation {
    Eigen::Vector3d m = Eigen::Vector3d::Zero();       //!< known world position (m)
    Eigen::Vector3d z = Eigen::Vector3d::Zero();       //!< measured point in the CCS (m)
    Eigen::Matrix3d C = Eigen::Matrix3d::Identity();   //!< its covariance (m^2), symmetric positive definite
  };
  /** @brief Jacobians of the augmentation m = p + R z. */
  struct AugmentationJacobians {
    Eigen::MatrixXd Jx;  //!< 3 x rigDim(): [I, -[R z]x, 0 ...]
    Eigen::Matrix3d Jz;  //!< R
  };

  /** @brief Filter with zero slots; rig state at the origin, covariance from the options' initial stds.
   *  @throws std::invalid_argument if options.validate() does. */
  explicit Eskf(const EskfOptions& options = EskfOptions());

  const EskfOptions& options() const { return opt_; }
  /** @brief True when this build does the covariance downdate through OpenBLAS (EskfOptions::blas_downdate). */
  static bool blasAvailable();

  /** @brief Restart: rig state `initial`, rig covariance `initial_rig_covariance` (rigDim() square,
   *  m, rad, m/s, rad/s units; symmetric positive SEMI-definite, so an exactly known initial pose is
   *  allowed). Drops every landmark; the capacity is kept. */
  void reset(const RigState& initial, const Eigen::MatrixXd& initial_rig_covariance);
  /** @brief reset() with the diagonal covariance of the options' initial_*_std fields. */
  void reset(const RigState& initial);
  /** @brief The diagonal rig covariance that reset(const RigState&) uses. */
  Eigen::MatrixXd defaultRigCovariance() const;

  int rigDim() const { return rd_; }                              //!< 12, or 15 with the gyro bias
  int capacity() const { return static_cast<int>(active_.size()); }  //!< number of landmark slots
  int dim() const { return rd_ + 3 * capacity(); }                //!< error-state dimension n
  int slotIndex(int slot) const { return rd_ + 3 * slot; }        //!< error-state index of a slot
  bool isActive(int slot) const;  //!< false for free or out-of-range slots
  int activeCount() const { return active_count_; }

  /** @brief Grow (or shrink, only over free trailing slots) to `slots` slots, keeping state and covariance. */
  void setCapacity(int slots);

  /** @brief Add a landmark in the free `slot` from its stereo measurement z (m, CCS) with covariance Cz
   *  (m^2): m = p + R z, C_mm = Jx C_xx Jx^T + R Cz R^T, C_m. = Jx C_x. (exact stereo augmentation). */
  void addLandmark(int slot, const Eigen::Vector3d& z, const Eigen::Matrix3d& Cz);
  /** @brief Free an active slot: zero its rows and columns. */
  void removeLandmark(int slot);

  /** @brief Time update over dt (s, > 0), structure-aware (rig block and rig-landmark cross terms only). */
  void predict(double dt);
  /** @brief Stacked batch update with the frame's landmark observations (distinct active slots).
   *  An empty batch is a no-op. */
  UpdateResult update(const std::vector<Observation>& observations);
  /** @brief Gyroscope update: z (rad/s, CCS) = w + b_g + noise with covariance C ((rad/s)^2). */
  UpdateResult updateGyro(const Eigen::Vector3d& z, const Eigen::Matrix3d& C);
  /** @brief One step of propagateWithGyro(): predict over dt (s, >= 0; 0 = a sample at the current time),
   *  then the gyroscope update with z (rad/s, CCS) and its covariance C ((rad/s)^2). */
  struct GyroStep {
    double dt = 0;
    Eigen::Vector3d z = Eigen::Vector3d::Zero();
    Eigen::Matrix3d C = Eigen::Matrix3d::Identity();
  };
  /** @brief The sequence predict(dt_i) (skipped when dt_i = 0), updateGyro(z_i, C_i) for every step, in
   *  O(rigDim^2 n + rigDim n^2 / 2) instead of O(k n^2): the same result to rounding.
   *
   *  Between two frames nothing but the rig is measured, so each step is a linear map of the rig block
   *  only. The rig covariance P, the product T of the steps' maps of the rig error (F_i, then
   *  G_i (I - K_i H)), A = sum_i (H T_i)^T S_i^-1 (H T_i) and b = sum_i (H T_i)^T S_i^-1 y_i (T_i: T before
   *  step i's update) are carried on rigDim() x rigDim() matrices; at the end
   *  C_rm <- T C_rm, C_mm <- C_mm - C_mr A C_rm (one symmetric rank-rigDim() downdate) and m <- m + C_mr b.
   *  Returns the summed NIS and dof of the k updates. Throws as predict() and updateGyro() do, before any
   *  change. */
  UpdateResult propagateWithGyro(const std::vector<GyroStep>& steps);

  /** @brief Stacked update with observations of known world points (no landmark slot involved). */
  UpdateResult updateKnown(const std::vector<KnownObservation>& observations);
  /** @brief Innovation of one known-point observation (no state change). */
  Innovation innovationKnown(const KnownObservation& observation) const;

  /** @brief Innovation, its covariance and Mahalanobis distance of one observation (no state change). */
  Innovation innovation(const Observation& observation) const;
  /** @brief innovation(observation).d2: compare with the chi^2 (3 dof) quantile to gate. */
  double mahalanobis(const Observation& observation) const;

  // ------------------------------------------------------------------ read access
  const RigState& state() const { return x_; }
  /** @brief Position (m, world) of an active slot. @throws std::invalid_argument if it is not active. */
  const Eigen::Vector3d& landmark(int slot) const;
  /** @brief The full error-state covariance, dim() x dim() (free slots' rows/columns are zero). */
  const Eigen::MatrixXd& covariance() const { return C_; }
  Eigen::MatrixXd rigCovariance() const { return C_.topLeftCorner(rd_, rd_); }
  /** @brief 6x6 covariance of [dp, dtheta] (m^2, rad^2). */
  Eigen::Matrix<double, 6, 6> poseCovariance() const { return C_.topLeftCorner<6, 6>(); }
  /** @brief 3x3 covariance (m^2) of an active slot. @throws std::invalid_argument if it is not active. */
  Eigen::Matrix3d landmarkCovariance(int slot) const;
  double rigTrace() const;        //!< trace of the rig block (mixed units, as the thesis plots it)
  double landmarksTrace() const;  //!< sum of the landmark variances (m^2)
  double totalTrace() const;      //!< trace of the whole covariance

  // ------------------------------------------------------------------ Jacobians (for tests)
  /** @brief Rig block F_r (rigDim() square) of the transition Jacobian over dt at the current state. */
  Eigen::MatrixXd transitionJacobian(double dt) const;
  /** @brief Process noise Q of the rig block over dt. */
  Eigen::MatrixXd processNoise(double dt) const;
  /** @brief Process noise of one active landmark over dt: R diag(landmark_walk^2 dt) R^T (m^2; zero when off),
   *  before the landmark's own factor landmarkWalkScale(). */
  Eigen::Matrix3d landmarkProcessNoise(double dt) const;
  /** @brief The factor of an active slot's walk: (|z| / landmark_walk_reference_distance)^4 with z its latest
   *  measurement, or 1 when the reference distance is 0. @throws std::invalid_argument if it is not active. */
  double landmarkWalkScale(int slot) const;
  /** @brief Dense 3 x dim() measurement Jacobian of an observation of an active slot. */
  Eigen::MatrixXd measurementJacobian(const Observation& observation) const;
  /** @brief Non-zero blocks of it: pose (3x6, w.r.t. [dp, dtheta]) and landmark (3x3). */
  void measurementJacobianBlocks(int slot, Eigen::Matrix<double, 3, 6>* pose, Eigen::Matrix3d* landmark) const;
  /** @brief Dense 3 x dim() Jacobian of the gyroscope measurement. */
  Eigen::MatrixXd gyroJacobian() const;
  /** @brief Jacobians of m = p + R z at the current state. */
  AugmentationJacobians augmentationJacobians(const Eigen::Vector3d& z) const;
  /** @brief Angular block of the reset Jacobian G after injecting dtheta (rad): Jl(dtheta). */
  static Eigen::Matrix3d resetJacobian(const Eigen::Vector3d& dtheta);

  /** @brief Predicted measurement R^T (m - p) of an active slot. */
  Eigen::Vector3d predictObservation(int slot) const;
  /** @brief Add an error-state vector (size dim()) to the nominal state (retract rig, m += dm for
   *  active slots). The covariance is NOT changed (the update follows it with the reset). */
  void inject(const Eigen::VectorXd& dx);

  // ------------------------------------------------------------------ dense reference (tests, benchmark)
  /** @brief predict() as C <- F C F^T + Q with the full dim() x dim() F. */
  void predictDense(double dt);
  /** @brief update() with full H, K = C H^T S^-1, literal Joseph (I-KH) C (I-KH)^T + K R K^T, full G. */
  UpdateResult updateDense(const std::vector<Observation>& observations);
  /** @brief updateGyro() in the same dense form. */
  UpdateResult updateGyroDense(const Eigen::Vector3d& z, const Eigen::Matrix3d& C);
  /** @brief updateKnown() in the same dense form. */
  UpdateResult updateKnownDense(const std::vector<KnownObservation>& observations);

 private:
  struct BlockRow;  // one 3-row block of a sparse H
  void validateObservations(const std::vector<Observation>& observations, const char* who) const;
  void buildObservationRows(const std::vector<Observation>& observations, std::vector<BlockRow>* rows,
                            Eigen::VectorXd* y) const;
  void validateKnown(const std::vector<KnownObservation>& observations, const char* who) const;
  void buildKnownRows(const std::vector<KnownObservation>& observations, std::vector<BlockRow>* rows,
                      Eigen::VectorXd* y) const;
  void buildGyroRow(const Eigen::Vector3d& z, const Eigen::Matrix3d& C, std::vector<BlockRow>* rows,
                    Eigen::VectorXd* y) const;
  UpdateResult sparseUpdate(const std::vector<BlockRow>& rows, const Eigen::VectorXd& y);
  UpdateResult denseUpdate(const std::vector<BlockRow>& rows, const Eigen::VectorXd& y);
  void applyReset(const Eigen::Vector3d& dtheta);
  void addLandmarkProcessNoise(double dt);
  Eigen::MatrixXd transitionJacobianAt(const RigState& x, double dt) const;
  Eigen::Matrix3d landmarkProcessNoiseAt(const RigState& x, double dt) const;
  void checkSlot(int slot, const char* who) const;

  EskfOptions opt_;
  int rd_ = 12;
  RigState x_;
  std::vector<Eigen::Vector3d> lm_;
  std::vector<unsigned char> active_;
  std::vector<double> walk_scale_;  // per slot: landmarkWalkScale()
  double walkScaleOf(const Eigen::Vector3d& z) const;
  int active_count_ = 0;
  Eigen::MatrixXd C_;
};

}  // namespace slam
}  // namespace skin3d
