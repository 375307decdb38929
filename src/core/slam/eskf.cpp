// SPDX-License-Identifier: BSD-3-Clause
// Error-state EKF SLAM (see include/skin3d/slam/eskf.h for the model, the Jacobians and the costs).
#include "skin3d/slam/eskf.h"

#include "../common/text.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <system_error>
#include <mutex>
#include <thread>

#ifdef SKIN3D_HAVE_OPENBLAS
#include <cblas.h>
// OpenBLAS's own extensions (declared in its cblas.h; repeated here in case another cblas.h comes first)
extern "C" {
int openblas_get_parallel(void);
void openblas_set_num_threads(int num_threads);
}
#endif

namespace skin3d {
namespace slam {

using geometry::Quat;
using geometry::skew;

namespace {

template <typename Derived>
bool allFinite(const Eigen::MatrixBase<Derived>& m) {
  return m.allFinite();
}

[[noreturn]] void fail(const std::string& message) { throw std::invalid_argument(message); }

std::string str(double v) { return common::num(v); }

// z and C of a measurement: z finite, C finite, symmetric and positive definite (LLT).
void checkMeasurement(const Eigen::Vector3d& z, const Eigen::Matrix3d& C, const std::string& who) {
  if (!allFinite(z)) fail(who + ": measurement z is not finite");
  if (!allFinite(C)) fail(who + ": covariance C is not finite");
  const double scale = C.cwiseAbs().maxCoeff();
  if ((C - C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) fail(who + ": covariance C is not symmetric");
  Eigen::LLT<Eigen::Matrix3d> llt(C);
  if (scale <= 0.0 || llt.info() != Eigen::Success) fail(who + ": covariance C is not positive definite");
}

// Columns [begin, end) of an n x n matrix split into `parts` pieces holding equal areas of the lower
// triangle (piece k starts at n (1 - sqrt(1 - k / parts))).
std::vector<int> triangleSplit(int n, int parts) {
  std::vector<int> b(parts + 1);
  for (int k = 0; k <= parts; ++k)
    b[k] = static_cast<int>(std::lround(n * (1.0 - std::sqrt(1.0 - static_cast<double>(k) / parts))));
  b[parts] = n;
  return b;
}

// Runs body(k) for k = 0..parts-1, parts-1 of them on new threads and the last on the caller's. The
// pieces write disjoint data; if a thread cannot be started its piece runs on the calling thread.
template <typename Body>
void runParallel(int parts, const Body& body) {
  std::vector<std::thread> pool;
  std::vector<int> local;
  pool.reserve(parts - 1);
  for (int k = 0; k + 1 < parts; ++k) {
    try {
      pool.emplace_back(body, k);
    } catch (const std::system_error&) {
      local.push_back(k);
    }
  }
  local.push_back(parts - 1);
  for (int k : local) body(k);
  for (auto& t : pool) t.join();
}

int usefulThreads(int n, int threads) { return n < 384 ? 1 : std::max(1, std::min(threads, 8)); }

#ifdef SKIN3D_HAVE_OPENBLAS
// OpenBLAS picks its kernels for the CPU at run time (AVX2 / AVX-512 where Eigen is compiled for SSE2 only).
// The threads are ours (runParallel): a multi-threaded OpenBLAS found at run time is set to one thread.
void useSerialBlas() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (openblas_get_parallel() != 0) openblas_set_num_threads(1);
  });
}
#endif

// Lower triangle (diagonal included) of C += alpha X Y^T; the strict upper triangle is not touched.
// With OpenBLAS and X == Y (the default update's C - U U^T): dsyrk on each part's diagonal block, dgemm below it.
void lowerUpdate(Eigen::MatrixXd& C, const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, double alpha,
                 int threads, bool use_blas) {
  const int n = static_cast<int>(C.rows());
  const int parts = usefulThreads(n, threads);
  const std::vector<int> b = triangleSplit(n, parts);
#ifdef SKIN3D_HAVE_OPENBLAS
  const bool blas = use_blas && &X == &Y && X.cols() > 0;
  if (blas) useSerialBlas();
#else
  const bool blas = false;
  (void)use_blas;
#endif
  runParallel(parts, [&](int k) {
    const int c0 = b[k], w = b[k + 1] - b[k], below = n - b[k + 1];
    if (w <= 0) return;
#ifdef SKIN3D_HAVE_OPENBLAS
    if (blas) {
      const int m = static_cast<int>(X.cols()), ldx = static_cast<int>(X.outerStride());
      const int ldc = static_cast<int>(C.outerStride());
      double* c = C.data();
      cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, w, m, alpha, X.data() + c0, ldx, 1.0, c + c0 + c0 * ldc, ldc);
      if (below > 0)
        cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, below, w, m, alpha, X.data() + c0 + w, ldx, X.data() + c0,
                    ldx, 1.0, c + (c0 + w) + c0 * ldc, ldc);
      return;
    }
#endif
    (void)blas;
    C.block(c0, c0, w, w).triangularView<Eigen::Lower>() +=
        alpha * X.middleRows(c0, w) * Y.middleRows(c0, w).transpose();
    if (below > 0)
      C.block(c0 + w, c0, below, w).noalias() += alpha * X.bottomRows(below) * Y.middleRows(c0, w).transpose();
  });
}

// U <- U L^-T for the lower-triangular Cholesky factor L of S (m x m): the rows of U are independent, so they are
// split over the threads; each part through OpenBLAS's dtrsm (run-time CPU kernels) when use_blas, else Eigen.
void solveRightLowerTransposed(Eigen::MatrixXd& U, const Eigen::MatrixXd& L, int threads, bool use_blas) {
  const int n = static_cast<int>(U.rows()), m = static_cast<int>(U.cols());
  if (n == 0 || m == 0) return;
  const int parts = usefulThreads(n, threads);
#ifdef SKIN3D_HAVE_OPENBLAS
  if (use_blas) useSerialBlas();
#else
  use_blas = false;
#endif
  runParallel(parts, [&](int k) {
    const int r0 = static_cast<int>(static_cast<long>(n) * k / parts);
    const int r1 = static_cast<int>(static_cast<long>(n) * (k + 1) / parts);
    if (r1 <= r0) return;
#ifdef SKIN3D_HAVE_OPENBLAS
    if (use_blas) {
      cblas_dtrsm(CblasColMajor, CblasRight, CblasLower, CblasTrans, CblasNonUnit, r1 - r0, m, 1.0, L.data(),
                  static_cast<int>(L.outerStride()), U.data() + r0, static_cast<int>(U.outerStride()));
      return;
    }
#endif
    auto rows = U.middleRows(r0, r1 - r0);
    L.triangularView<Eigen::Lower>().transpose().solveInPlace<Eigen::OnTheRight>(rows);
  });
}

// Copies the strict lower triangle onto the upper one (exact symmetry), in cache-sized tiles.
void mirrorLower(Eigen::MatrixXd& C, int threads) {
  const int n = static_cast<int>(C.rows());
  constexpr int kTile = 64;
  // Upper-triangle area left of column j grows like j^2: split the columns at n sqrt(k / parts).
  const int parts = usefulThreads(n, threads);
  std::vector<int> b(parts + 1);
  for (int k = 0; k <= parts; ++k)
    b[k] = static_cast<int>(std::lround(n * std::sqrt(static_cast<double>(k) / parts)));
  b[parts] = n;
  double* data = C.data();
  const Eigen::Index ld = C.outerStride();
  runParallel(parts, [&](int k) {
    for (int j0 = b[k]; j0 < b[k + 1]; j0 += kTile) {
      const int j1 = std::min(j0 + kTile, b[k + 1]);
      for (int i0 = 0; i0 < j1; i0 += kTile) {
        const int i1 = std::min(i0 + kTile, j1);
        for (int j = j0; j < j1; ++j) {
          double* col = data + j * ld;   // C(., j)
          const int iend = std::min(i1, j);
          for (int i = i0; i < iend; ++i) col[i] = data[i * ld + j];  // C(i, j) = C(j, i)
        }
      }
    }
  });
}

}  // namespace

// ============================================================================ options

bool Eskf::blasAvailable() {
#ifdef SKIN3D_HAVE_OPENBLAS
  return true;
#else
  return false;
#endif
}

void EskfOptions::validate() const {
  auto in01 = [](const char* name, double v) {
    if (!std::isfinite(v) || v < 0.0 || v > 1.0)
      fail(std::string("EskfOptions: ") + name + " = " + str(v) + " must be in [0, 1]");
  };
  auto nonneg = [](const char* name, double v) {
    if (!std::isfinite(v) || v < 0.0)
      fail(std::string("EskfOptions: ") + name + " = " + str(v) + " must be finite and >= 0");
  };
  in01("gamma", gamma);
  in01("lambda", lambda);
  nonneg("velocity_noise", velocity_noise);
  nonneg("angular_rate_noise", angular_rate_noise);
  nonneg("gyro_bias_walk", gyro_bias_walk);
  nonneg("initial_position_std", initial_position_std);
  nonneg("initial_attitude_std", initial_attitude_std);
  nonneg("initial_velocity_std", initial_velocity_std);
  nonneg("initial_angular_rate_std", initial_angular_rate_std);
  nonneg("initial_gyro_bias_std", initial_gyro_bias_std);
  if (!initial_gyro_bias.allFinite())
    fail("EskfOptions: initial_gyro_bias = (" + str(initial_gyro_bias.x()) + ", " + str(initial_gyro_bias.y()) + ", " +
         str(initial_gyro_bias.z()) + ") must be finite");
  if (!landmark_walk.allFinite() || (landmark_walk.array() < 0.0).any())
    fail("EskfOptions: landmark_walk = (" + str(landmark_walk.x()) + ", " + str(landmark_walk.y()) + ", " +
         str(landmark_walk.z()) + ") must be finite and >= 0");
  nonneg("landmark_walk_reference_distance", landmark_walk_reference_distance);
  if (threads < 1) fail("EskfOptions: threads = " + std::to_string(threads) + " must be >= 1");
}

// ============================================================================ model functions

RigState propagateNominal(const RigState& x, double dt, double gamma, double lambda) {
  RigState out = x;
  const Eigen::Matrix3d R = geometry::toRotationMatrix(x.q);
  out.p = x.p + R * x.v * dt;
  out.q = (x.q * geometry::quatExp(x.w * dt)).normalized();
  out.v = gamma * x.v;
  out.w = lambda * x.w;
  return out;
}

RigState retract(const RigState& x, const Eigen::VectorXd& dx) {
  if (dx.size() != 12 && dx.size() != 15)
    fail("retract: dx has size " + std::to_string(dx.size()) + ", expected 12 or 15");
  RigState out = x;
  out.p += dx.segment<3>(0);
  out.q = (geometry::quatExp(dx.segment<3>(3)) * x.q).normalized();
  out.v += dx.segment<3>(6);
  out.w += dx.segment<3>(9);
  if (dx.size() == 15) out.gyro_bias += dx.segment<3>(12);
  return out;
}

Eigen::VectorXd rigDifference(const RigState& a, const RigState& b, int rig_dim) {
  if (rig_dim != 12 && rig_dim != 15)
    fail("rigDifference: rig_dim = " + std::to_string(rig_dim) + ", expected 12 or 15");
  Eigen::VectorXd d(rig_dim);
  d.segment<3>(0) = a.p - b.p;
  d.segment<3>(3) = geometry::quatLog(a.q.normalized() * b.q.normalized().conjugate());
  d.segment<3>(6) = a.v - b.v;
  d.segment<3>(9) = a.w - b.w;
  if (rig_dim == 15) d.segment<3>(12) = a.gyro_bias - b.gyro_bias;
  return d;
}

Eigen::Vector3d observeLandmark(const RigState& x, const Eigen::Vector3d& m) {
  return geometry::toRotationMatrix(x.q).transpose() * (m - x.p);
}

Eigen::Vector3d landmarkFromObservation(const RigState& x, const Eigen::Vector3d& z) {
  return x.p + geometry::toRotationMatrix(x.q) * z;
}

Eigen::Vector3d predictGyro(const RigState& x) { return x.w + x.gyro_bias; }

// ============================================================================ filter: set-up

/** One 3-row block of a sparse H: up to three non-zero 3x3 column blocks, and the block's noise. */
struct Eskf::BlockRow {
  int count = 0;
  std::array<int, 3> col{};
  std::array<Eigen::Matrix3d, 3> J;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  void add(int c, const Eigen::Matrix3d& j) {
    col[count] = c;
    J[count] = j;
    ++count;
  }
};

Eskf::Eskf(const EskfOptions& options) : opt_(options) {
  opt_.validate();
  rd_ = opt_.estimate_gyro_bias ? 15 : 12;
  C_ = defaultRigCovariance();
}

Eigen::MatrixXd Eskf::defaultRigCovariance() const {
  Eigen::VectorXd d(rd_);
  d.segment<3>(0).setConstant(opt_.initial_position_std * opt_.initial_position_std);
  d.segment<3>(3).setConstant(opt_.initial_attitude_std * opt_.initial_attitude_std);
  d.segment<3>(6).setConstant(opt_.initial_velocity_std * opt_.initial_velocity_std);
  d.segment<3>(9).setConstant(opt_.initial_angular_rate_std * opt_.initial_angular_rate_std);
  if (rd_ == 15) d.segment<3>(12).setConstant(opt_.initial_gyro_bias_std * opt_.initial_gyro_bias_std);
  return d.asDiagonal();
}

void Eskf::reset(const RigState& initial) { reset(initial, defaultRigCovariance()); }

void Eskf::reset(const RigState& initial, const Eigen::MatrixXd& P) {
  if (!allFinite(initial.p) || !allFinite(initial.v) || !allFinite(initial.w) || !allFinite(initial.gyro_bias) ||
      !allFinite(initial.q.coeffs()))
    fail("Eskf::reset: initial state is not finite");
  const double qn = initial.q.norm();
  if (!(qn > 1e-6)) fail("Eskf::reset: initial quaternion has norm " + str(qn));
  if (P.rows() != rd_ || P.cols() != rd_) {
    std::ostringstream os;
    os << "Eskf::reset: initial_rig_covariance is " << P.rows() << "x" << P.cols() << ", expected " << rd_ << "x"
       << rd_;
    fail(os.str());
  }
  if (!allFinite(P)) fail("Eskf::reset: initial_rig_covariance is not finite");
  const double scale = P.cwiseAbs().maxCoeff();
  if ((P - P.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale)
    fail("Eskf::reset: initial_rig_covariance is not symmetric");
  const Eigen::MatrixXd Ps = 0.5 * (P + P.transpose());
  // Positive semi-definite <=> the pivoted LDL^T factorisation has D >= 0 (to rounding).
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(Ps);
  const double min_d = ldlt.vectorD().minCoeff();
  if (ldlt.info() != Eigen::Success || min_d < -1e-12 * scale)
    fail("Eskf::reset: initial_rig_covariance is not positive semi-definite (LDL^T pivot " + str(min_d) + ")");

  x_ = initial;
  x_.q.normalize();
  C_.setZero();
  C_.topLeftCorner(rd_, rd_) = Ps;
  std::fill(lm_.begin(), lm_.end(), Eigen::Vector3d::Zero());
  std::fill(active_.begin(), active_.end(), 0);
  std::fill(walk_scale_.begin(), walk_scale_.end(), 1.0);
  active_count_ = 0;
}

bool Eskf::isActive(int slot) const { return slot >= 0 && slot < capacity() && active_[slot] != 0; }

void Eskf::checkSlot(int slot, const char* who) const {
  if (slot < 0 || slot >= capacity())
    fail(std::string(who) + ": slot " + std::to_string(slot) + " is out of range [0, " + std::to_string(capacity()) +
         ")");
}

void Eskf::setCapacity(int slots) {
  if (slots < 0) fail("Eskf::setCapacity: slots = " + std::to_string(slots) + " must be >= 0");
  for (int s = slots; s < capacity(); ++s)
    if (active_[s])
      fail("Eskf::setCapacity: cannot shrink to " + std::to_string(slots) + " slots, slot " + std::to_string(s) +
           " is active");
  if (slots == capacity()) return;
  const int n_old = dim(), n_new = rd_ + 3 * slots, keep = std::min(n_old, n_new);
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(n_new, n_new);
  C.topLeftCorner(keep, keep) = C_.topLeftCorner(keep, keep);
  C_.swap(C);
  lm_.resize(slots, Eigen::Vector3d::Zero());
  active_.resize(slots, 0);
  walk_scale_.resize(slots, 1.0);
}

// ============================================================================ landmarks

void Eskf::addLandmark(int slot, const Eigen::Vector3d& z, const Eigen::Matrix3d& Cz) {
  checkSlot(slot, "Eskf::addLandmark");
  if (active_[slot]) fail("Eskf::addLandmark: slot " + std::to_string(slot) + " is already active");
  checkMeasurement(z, Cz, "Eskf::addLandmark(slot " + std::to_string(slot) + ")");

  const Eigen::Matrix3d R = geometry::toRotationMatrix(x_.q);
  const Eigen::Matrix3d Jth = -skew(R * z);
  const int s = slotIndex(slot);
  // C_xm = C J_x^T (n x 3): J_x has I on dp and -[R z]x on dtheta, zero elsewhere.
  Eigen::MatrixXd Cxm = C_.leftCols<3>();
  Cxm.noalias() += C_.middleCols<3>(3) * Jth.transpose();
  Eigen::Matrix3d Cmm = Cxm.topRows<3>() + Jth * Cxm.middleRows<3>(3) + R * (0.5 * (Cz + Cz.transpose())) * R.transpose();
  Cmm = (0.5 * (Cmm + Cmm.transpose())).eval();
  Cxm.middleRows<3>(s).setZero();  // (already zero: the slot was free)
  C_.middleCols<3>(s) = Cxm;
  C_.middleRows<3>(s) = Cxm.transpose();
  C_.block<3, 3>(s, s) = Cmm;
  lm_[slot] = x_.p + R * z;
  walk_scale_[slot] = walkScaleOf(z);
  active_[slot] = 1;
  ++active_count_;
}

void Eskf::removeLandmark(int slot) {
  checkSlot(slot, "Eskf::removeLandmark");
  if (!active_[slot]) fail("Eskf::removeLandmark: slot " + std::to_string(slot) + " is not active");
  const int s = slotIndex(slot);
  C_.middleCols<3>(s).setZero();
  C_.middleRows<3>(s).setZero();
  lm_[slot].setZero();
  walk_scale_[slot] = 1.0;
  active_[slot] = 0;
  --active_count_;
}

const Eigen::Vector3d& Eskf::landmark(int slot) const {
  checkSlot(slot, "Eskf::landmark");
  if (!active_[slot]) fail("Eskf::landmark: slot " + std::to_string(slot) + " is not active");
  return lm_[slot];
}

Eigen::Matrix3d Eskf::landmarkCovariance(int slot) const {
  checkSlot(slot, "Eskf::landmarkCovariance");
  if (!active_[slot]) fail("Eskf::landmarkCovariance: slot " + std::to_string(slot) + " is not active");
  return C_.block<3, 3>(slotIndex(slot), slotIndex(slot));
}

double Eskf::rigTrace() const { return C_.topLeftCorner(rd_, rd_).trace(); }
double Eskf::landmarksTrace() const { return C_.diagonal().tail(dim() - rd_).sum(); }
double Eskf::totalTrace() const { return C_.trace(); }

// ============================================================================ Jacobians

Eigen::MatrixXd Eskf::transitionJacobian(double dt) const { return transitionJacobianAt(x_, dt); }

Eigen::MatrixXd Eskf::transitionJacobianAt(const RigState& x, double dt) const {
  const Eigen::Matrix3d R = geometry::toRotationMatrix(x.q);
  Eigen::MatrixXd F = Eigen::MatrixXd::Identity(rd_, rd_);
  F.block<3, 3>(0, 3) = -skew(R * x.v * dt);
  F.block<3, 3>(0, 6) = R * dt;
  F.block<3, 3>(3, 9) = R * geometry::so3LeftJacobian(x.w * dt) * dt;
  F.block<3, 3>(6, 6) = opt_.gamma * Eigen::Matrix3d::Identity();
  F.block<3, 3>(9, 9) = opt_.lambda * Eigen::Matrix3d::Identity();
  return F;
}

Eigen::MatrixXd Eskf::processNoise(double dt) const {
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(rd_, rd_);
  Q.block<3, 3>(6, 6).diagonal().setConstant(opt_.velocity_noise * opt_.velocity_noise * dt);
  Q.block<3, 3>(9, 9).diagonal().setConstant(opt_.angular_rate_noise * opt_.angular_rate_noise * dt);
  if (rd_ == 15) Q.block<3, 3>(12, 12).diagonal().setConstant(opt_.gyro_bias_walk * opt_.gyro_bias_walk * dt);
  return Q;
}

Eigen::Matrix3d Eskf::landmarkProcessNoise(double dt) const { return landmarkProcessNoiseAt(x_, dt); }

Eigen::Matrix3d Eskf::landmarkProcessNoiseAt(const RigState& x, double dt) const {
  const Eigen::Matrix3d R = geometry::toRotationMatrix(x.q);
  return R * Eigen::Vector3d(opt_.landmark_walk.array().square() * dt).asDiagonal() * R.transpose();
}

double Eskf::walkScaleOf(const Eigen::Vector3d& z) const {
  if (!(opt_.landmark_walk_reference_distance > 0.0)) return 1.0;
  const double r = z.norm() / opt_.landmark_walk_reference_distance;
  return (r * r) * (r * r);
}

double Eskf::landmarkWalkScale(int slot) const {
  checkSlot(slot, "Eskf::landmarkWalkScale");
  if (!active_[slot]) fail("Eskf::landmarkWalkScale: slot " + std::to_string(slot) + " is not active");
  return walk_scale_[slot];
}

void Eskf::addLandmarkProcessNoise(double dt) {
  if ((opt_.landmark_walk.array() == 0.0).all()) return;
  Eigen::Matrix3d Q = landmarkProcessNoise(dt);
  Q = 0.5 * (Q + Q.transpose());
  for (int j = 0; j < capacity(); ++j)
    if (active_[j]) C_.block<3, 3>(slotIndex(j), slotIndex(j)) += walk_scale_[j] * Q;
}

void Eskf::measurementJacobianBlocks(int slot, Eigen::Matrix<double, 3, 6>* pose, Eigen::Matrix3d* landmark) const {
  checkSlot(slot, "Eskf::measurementJacobianBlocks");
  if (!active_[slot]) fail("Eskf::measurementJacobianBlocks: slot " + std::to_string(slot) + " is not active");
  const Eigen::Matrix3d Rt = geometry::toRotationMatrix(x_.q).transpose();
  if (pose) {
    pose->leftCols<3>() = -Rt;
    pose->rightCols<3>() = Rt * skew(lm_[slot] - x_.p);
  }
  if (landmark) *landmark = Rt;
}

Eigen::MatrixXd Eskf::measurementJacobian(const Observation& o) const {
  Eigen::Matrix<double, 3, 6> P;
  Eigen::Matrix3d M;
  measurementJacobianBlocks(o.slot, &P, &M);
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(3, dim());
  H.leftCols<6>() = P;
  H.middleCols<3>(slotIndex(o.slot)) = M;
  return H;
}

Eigen::MatrixXd Eskf::gyroJacobian() const {
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(3, dim());
  H.middleCols<3>(9).setIdentity();
  if (rd_ == 15) H.middleCols<3>(12).setIdentity();
  return H;
}

Eskf::AugmentationJacobians Eskf::augmentationJacobians(const Eigen::Vector3d& z) const {
  const Eigen::Matrix3d R = geometry::toRotationMatrix(x_.q);
  AugmentationJacobians J;
  J.Jx = Eigen::MatrixXd::Zero(3, rd_);
  J.Jx.leftCols<3>().setIdentity();
  J.Jx.middleCols<3>(3) = -skew(R * z);
  J.Jz = R;
  return J;
}

Eigen::Matrix3d Eskf::resetJacobian(const Eigen::Vector3d& dtheta) { return geometry::so3LeftJacobian(dtheta); }

Eigen::Vector3d Eskf::predictObservation(int slot) const {
  checkSlot(slot, "Eskf::predictObservation");
  if (!active_[slot]) fail("Eskf::predictObservation: slot " + std::to_string(slot) + " is not active");
  return observeLandmark(x_, lm_[slot]);
}

void Eskf::inject(const Eigen::VectorXd& dx) {
  if (dx.size() != dim())
    fail("Eskf::inject: dx has size " + std::to_string(dx.size()) + ", expected " + std::to_string(dim()));
  if (!allFinite(dx)) fail("Eskf::inject: dx is not finite");
  x_ = retract(x_, dx.head(rd_));
  for (int j = 0; j < capacity(); ++j)
    if (active_[j]) lm_[j] += dx.segment<3>(slotIndex(j));
}

// ============================================================================ predict

void Eskf::predict(double dt) {
  if (!std::isfinite(dt) || dt <= 0.0) fail("Eskf::predict: dt = " + str(dt) + " must be finite and > 0");
  const Eigen::MatrixXd F = transitionJacobian(dt);
  const int n = dim(), L = n - rd_;
  if (L > 0) {
    // Rig-landmark cross-covariances: C_rm <- F_r C_rm (F is the identity on the landmark block).
    const Eigen::MatrixXd T = F * C_.block(0, rd_, rd_, L);
    C_.block(0, rd_, rd_, L) = T;
    C_.block(rd_, 0, L, rd_) = T.transpose();
  }
  Eigen::MatrixXd Crr = F * C_.topLeftCorner(rd_, rd_) * F.transpose() + processNoise(dt);
  C_.topLeftCorner(rd_, rd_) = 0.5 * (Crr + Crr.transpose());
  addLandmarkProcessNoise(dt);
  x_ = propagateNominal(x_, dt, opt_.gamma, opt_.lambda);
}

void Eskf::predictDense(double dt) {
  if (!std::isfinite(dt) || dt <= 0.0) fail("Eskf::predictDense: dt = " + str(dt) + " must be finite and > 0");
  const int n = dim();
  Eigen::MatrixXd F = Eigen::MatrixXd::Identity(n, n);
  F.topLeftCorner(rd_, rd_) = transitionJacobian(dt);
  Eigen::MatrixXd C = F * C_ * F.transpose();
  C.topLeftCorner(rd_, rd_) += processNoise(dt);
  if (!(opt_.landmark_walk.array() == 0.0).all()) {  // the full Q: rig block and every active landmark's block
    const Eigen::Matrix3d Qm = landmarkProcessNoise(dt);
    for (int j = 0; j < capacity(); ++j)
      if (active_[j]) C.block<3, 3>(slotIndex(j), slotIndex(j)) += walk_scale_[j] * Qm;
  }
  C_ = 0.5 * (C + C.transpose());
  x_ = propagateNominal(x_, dt, opt_.gamma, opt_.lambda);
}

// ============================================================================ update

void Eskf::validateObservations(const std::vector<Observation>& obs, const char* who) const {
  std::vector<unsigned char> seen(capacity(), 0);
  for (size_t i = 0; i < obs.size(); ++i) {
    const Observation& o = obs[i];
    const std::string tag = std::string(who) + ": observation " + std::to_string(i);
    if (o.slot < 0 || o.slot >= capacity())
      fail(tag + ": slot " + std::to_string(o.slot) + " is out of range [0, " + std::to_string(capacity()) + ")");
    if (!active_[o.slot]) fail(tag + ": slot " + std::to_string(o.slot) + " is not active");
    if (seen[o.slot]) fail(tag + ": slot " + std::to_string(o.slot) + " appears twice in one update");
    seen[o.slot] = 1;
    checkMeasurement(o.z, o.C, tag + " (slot " + std::to_string(o.slot) + ")");
  }
}

void Eskf::buildObservationRows(const std::vector<Observation>& obs, std::vector<BlockRow>* rows,
                                Eigen::VectorXd* y) const {
  const Eigen::Matrix3d Rt = geometry::toRotationMatrix(x_.q).transpose();
  rows->assign(obs.size(), BlockRow());
  y->resize(3 * static_cast<Eigen::Index>(obs.size()));
  for (size_t i = 0; i < obs.size(); ++i) {
    const Observation& o = obs[i];
    const Eigen::Vector3d d = lm_[o.slot] - x_.p;
    BlockRow& r = (*rows)[i];
    r.add(0, -Rt);
    r.add(3, Rt * skew(d));
    r.add(slotIndex(o.slot), Rt);
    r.R = 0.5 * (o.C + o.C.transpose());
    y->segment<3>(3 * i) = o.z - Rt * d;
  }
}

void Eskf::validateKnown(const std::vector<KnownObservation>& obs, const char* who) const {
  for (size_t i = 0; i < obs.size(); ++i) {
    const std::string tag = std::string(who) + ": observation " + std::to_string(i);
    if (!allFinite(obs[i].m)) fail(tag + ": known position m is not finite");
    checkMeasurement(obs[i].z, obs[i].C, tag);
  }
}

void Eskf::buildKnownRows(const std::vector<KnownObservation>& obs, std::vector<BlockRow>* rows,
                          Eigen::VectorXd* y) const {
  const Eigen::Matrix3d Rt = geometry::toRotationMatrix(x_.q).transpose();
  rows->assign(obs.size(), BlockRow());
  y->resize(3 * static_cast<Eigen::Index>(obs.size()));
  for (size_t i = 0; i < obs.size(); ++i) {
    const Eigen::Vector3d d = obs[i].m - x_.p;
    BlockRow& r = (*rows)[i];
    r.add(0, -Rt);
    r.add(3, Rt * skew(d));
    r.R = 0.5 * (obs[i].C + obs[i].C.transpose());
    y->segment<3>(3 * i) = obs[i].z - Rt * d;
  }
}

void Eskf::buildGyroRow(const Eigen::Vector3d& z, const Eigen::Matrix3d& C, std::vector<BlockRow>* rows,
                        Eigen::VectorXd* y) const {
  rows->assign(1, BlockRow());
  BlockRow& r = rows->front();
  r.add(9, Eigen::Matrix3d::Identity());
  if (rd_ == 15) r.add(12, Eigen::Matrix3d::Identity());
  r.R = 0.5 * (C + C.transpose());
  *y = z - predictGyro(x_);
}

Eskf::UpdateResult Eskf::sparseUpdate(const std::vector<BlockRow>& rows, const Eigen::VectorXd& y) {
  const int n = dim(), k = static_cast<int>(rows.size()), m = 3 * k;
  // A = C H^T (n x m) from the non-zero 3x3 blocks of H.
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, m);
  for (int i = 0; i < k; ++i)
    for (int b = 0; b < rows[i].count; ++b)
      A.middleCols<3>(3 * i).noalias() += C_.middleCols<3>(rows[i].col[b]) * rows[i].J[b].transpose();
  // S = H A + C_n (m x m).
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(m, m);
  for (int i = 0; i < k; ++i)
    for (int b = 0; b < rows[i].count; ++b)
      S.middleRows<3>(3 * i).noalias() += rows[i].J[b] * A.middleRows<3>(rows[i].col[b]);
  S = (0.5 * (S + S.transpose())).eval();
  for (int i = 0; i < k; ++i) S.block<3, 3>(3 * i, 3 * i) += rows[i].R;
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  if (llt.info() != Eigen::Success)
    throw std::runtime_error("Eskf::update: innovation covariance is not positive definite");

  // S = L L^T; U = A L^-T; K = C H^T S^-1 = U L^-1; e = L^-1 y; dx = K y = U e; NIS = |e|^2.
  Eigen::MatrixXd U = A;
  const Eigen::MatrixXd Lf = llt.matrixL();
  solveRightLowerTransposed(U, Lf, opt_.threads, opt_.blas_downdate);
  const Eigen::VectorXd e = llt.matrixL().solve(y);
  Eigen::VectorXd dx;
  if (!opt_.joseph_explicit_gain) {
    dx.noalias() = U * e;
    // Joseph, expanded: C - K(HC) - (HC)^T K^T + K S K^T; each correction term is U U^T for this K.
    lowerUpdate(C_, U, U, -1.0, opt_.threads, opt_.blas_downdate);
  } else {
    Eigen::MatrixXd K = U;
    llt.matrixL().solveInPlace<Eigen::OnTheRight>(K);  // K L = U
    dx.noalias() = K * y;
    // K S K^T - K (HC) - (HC)^T K^T = [K, A] [K S - A, -K]^T with HC = A^T.
    Eigen::MatrixXd X(n, 2 * m), Y(n, 2 * m);
    X.leftCols(m) = K;
    X.rightCols(m) = A;
    Y.leftCols(m).noalias() = K * S;
    Y.leftCols(m) -= A;
    Y.rightCols(m) = -K;
    lowerUpdate(C_, X, Y, 1.0, opt_.threads, false);
  }
  mirrorLower(C_, opt_.threads);

  // Inject the error estimate into the nominal state, then reset the error (G on the angular block).
  x_ = retract(x_, dx.head(rd_));
  for (int j = 0; j < capacity(); ++j)
    if (active_[j]) lm_[j] += dx.segment<3>(slotIndex(j));
  applyReset(dx.segment<3>(3));

  UpdateResult r;
  r.used = k;
  r.nis = e.squaredNorm();
  r.dof = m;
  return r;
}

void Eskf::applyReset(const Eigen::Vector3d& dtheta) {
  // C <- G C G^T with G = I except G_theta = Jl(dtheta): only the 3 angular rows and columns change.
  const Eigen::Matrix3d G = resetJacobian(dtheta);
  Eigen::MatrixXd T = G * C_.middleRows<3>(3);  // 3 x n: G C_theta.
  const Eigen::Matrix3d Ctt = T.middleCols<3>(3) * G.transpose();
  T.middleCols<3>(3) = 0.5 * (Ctt + Ctt.transpose());
  C_.middleRows<3>(3) = T;
  C_.middleCols<3>(3) = T.transpose();
}

Eskf::UpdateResult Eskf::denseUpdate(const std::vector<BlockRow>& rows, const Eigen::VectorXd& y) {
  const int n = dim(), k = static_cast<int>(rows.size()), m = 3 * k;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(m, n), Rn = Eigen::MatrixXd::Zero(m, m);
  for (int i = 0; i < k; ++i) {
    for (int b = 0; b < rows[i].count; ++b) H.block<3, 3>(3 * i, rows[i].col[b]) = rows[i].J[b];
    Rn.block<3, 3>(3 * i, 3 * i) = rows[i].R;
  }
  const Eigen::MatrixXd S = H * C_ * H.transpose() + Rn;
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  if (llt.info() != Eigen::Success)
    throw std::runtime_error("Eskf::updateDense: innovation covariance is not positive definite");
  const Eigen::MatrixXd K = llt.solve(H * C_).transpose();  // C H^T S^-1 (C, S symmetric)
  const Eigen::VectorXd dx = K * y;
  const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
  Eigen::MatrixXd C = IKH * C_ * IKH.transpose() + K * Rn * K.transpose();
  Eigen::MatrixXd G = Eigen::MatrixXd::Identity(n, n);
  G.block<3, 3>(3, 3) = resetJacobian(dx.segment<3>(3));
  C = G * C * G.transpose();
  C_ = 0.5 * (C + C.transpose());
  x_ = retract(x_, dx.head(rd_));
  for (int j = 0; j < capacity(); ++j)
    if (active_[j]) lm_[j] += dx.segment<3>(slotIndex(j));
  UpdateResult r;
  r.used = k;
  r.nis = y.dot(llt.solve(y));
  r.dof = m;
  return r;
}

Eskf::UpdateResult Eskf::update(const std::vector<Observation>& observations) {
  validateObservations(observations, "Eskf::update");
  if (observations.empty()) return UpdateResult();
  std::vector<BlockRow> rows;
  Eigen::VectorXd y;
  buildObservationRows(observations, &rows, &y);
  const UpdateResult res = sparseUpdate(rows, y);
  for (const Observation& o : observations) walk_scale_[o.slot] = walkScaleOf(o.z);
  return res;
}

Eskf::UpdateResult Eskf::updateDense(const std::vector<Observation>& observations) {
  validateObservations(observations, "Eskf::updateDense");
  if (observations.empty()) return UpdateResult();
  std::vector<BlockRow> rows;
  Eigen::VectorXd y;
  buildObservationRows(observations, &rows, &y);
  const UpdateResult res = denseUpdate(rows, y);
  for (const Observation& o : observations) walk_scale_[o.slot] = walkScaleOf(o.z);
  return res;
}

Eskf::UpdateResult Eskf::updateGyro(const Eigen::Vector3d& z, const Eigen::Matrix3d& C) {
  checkMeasurement(z, C, "Eskf::updateGyro");
  std::vector<BlockRow> rows;
  Eigen::VectorXd y;
  buildGyroRow(z, C, &rows, &y);
  return sparseUpdate(rows, y);
}

Eskf::UpdateResult Eskf::propagateWithGyro(const std::vector<GyroStep>& steps) {
  for (size_t i = 0; i < steps.size(); ++i) {
    const std::string tag = "Eskf::propagateWithGyro: step " + std::to_string(i);
    if (!std::isfinite(steps[i].dt) || steps[i].dt < 0.0) fail(tag + ": dt = " + str(steps[i].dt) + " must be finite and >= 0");
    checkMeasurement(steps[i].z, steps[i].C, tag);
  }
  UpdateResult res;
  if (steps.empty()) return res;
  // Everything is done on rig-sized copies and committed at the end, so a throw leaves the filter unchanged.
  const int r = rd_, L = dim() - rd_;
  RigState x = x_;
  Eigen::MatrixXd P = C_.topLeftCorner(r, r);
  Eigen::MatrixXd T = Eigen::MatrixXd::Identity(r, r), A = Eigen::MatrixXd::Zero(r, r);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(r);
  Eigen::Matrix3d Qm = Eigen::Matrix3d::Zero();  // summed landmark walk: additive, so it commutes with the rest
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(3, r);
  H.middleCols<3>(9).setIdentity();
  if (r == 15) H.middleCols<3>(12).setIdentity();
  const bool walk = !(opt_.landmark_walk.array() == 0.0).all();
  for (const GyroStep& st : steps) {
    if (st.dt > 0.0) {
      const Eigen::MatrixXd F = transitionJacobianAt(x, st.dt);
      P = (F * P * F.transpose() + processNoise(st.dt)).eval();
      P = (0.5 * (P + P.transpose())).eval();
      T = (F * T).eval();
      if (walk) Qm += landmarkProcessNoiseAt(x, st.dt);
      x = propagateNominal(x, st.dt, opt_.gamma, opt_.lambda);
    }
    const Eigen::Matrix3d Rn = 0.5 * (st.C + st.C.transpose());
    Eigen::Matrix3d S = H * P * H.transpose() + Rn;
    S = (0.5 * (S + S.transpose())).eval();
    const Eigen::LLT<Eigen::Matrix3d> llt(S);
    if (llt.info() != Eigen::Success)
      throw std::runtime_error("Eskf::propagateWithGyro: innovation covariance is not positive definite");
    const Eigen::Vector3d y = st.z - predictGyro(x);
    const Eigen::MatrixXd HT = H * T;                  // 3 x r
    const Eigen::MatrixXd SinvHT = llt.solve(HT);      // S^-1 H T
    A.noalias() += HT.transpose() * SinvHT;
    b.noalias() += SinvHT.transpose() * y;
    res.nis += y.dot(llt.solve(y));
    res.dof += 3;
    ++res.used;
    const Eigen::MatrixXd K = llt.solve(H * P).transpose();  // P H^T S^-1 (P, S symmetric)
    const Eigen::VectorXd dx = K * y;
    Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(r, r);
    IKH.noalias() -= K * H;
    P = (IKH * P * IKH.transpose() + K * Rn * K.transpose()).eval();
    T = (IKH * T).eval();
    x = retract(x, dx);
    const Eigen::Matrix3d G = resetJacobian(dx.segment<3>(3));  // G = I but on the angular rows
    P.middleRows<3>(3) = (G * P.middleRows<3>(3)).eval();
    P.middleCols<3>(3) = (P.middleCols<3>(3) * G.transpose()).eval();
    P = (0.5 * (P + P.transpose())).eval();
    T.middleRows<3>(3) = (G * T.middleRows<3>(3)).eval();
  }
  if (L > 0) {
    const Eigen::MatrixXd Crm0 = C_.block(0, r, r, L);
    // C_mm -= C_mr A C_rm as the symmetric downdate X X^T, X = C_mr V sqrt(Lambda) (A = V Lambda V^T, PSD).
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (A + A.transpose()));
    const Eigen::VectorXd lam = es.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    Eigen::MatrixXd X = Eigen::MatrixXd::Zero(dim(), r);
    X.bottomRows(L).noalias() = Crm0.transpose() * (es.eigenvectors() * lam.asDiagonal());
    lowerUpdate(C_, X, X, -1.0, opt_.threads, opt_.blas_downdate);
    const Eigen::VectorXd dm = Crm0.transpose() * b;
    C_.block(r, 0, L, r) = (T * Crm0).transpose();  // lower triangle; the mirror writes C_rm
    C_.topLeftCorner(r, r) = P;
    mirrorLower(C_, opt_.threads);
    for (int j = 0; j < capacity(); ++j)
      if (active_[j]) {
        lm_[j] += dm.segment<3>(3 * j);
        if (walk) C_.block<3, 3>(slotIndex(j), slotIndex(j)) += walk_scale_[j] * 0.5 * (Qm + Qm.transpose());
      }
  } else {
    C_ = P;
  }
  x_ = x;
  return res;
}

Eskf::UpdateResult Eskf::updateGyroDense(const Eigen::Vector3d& z, const Eigen::Matrix3d& C) {
  checkMeasurement(z, C, "Eskf::updateGyroDense");
  std::vector<BlockRow> rows;
  Eigen::VectorXd y;
  buildGyroRow(z, C, &rows, &y);
  return denseUpdate(rows, y);
}

Eskf::UpdateResult Eskf::updateKnown(const std::vector<KnownObservation>& observations) {
  validateKnown(observations, "Eskf::updateKnown");
  if (observations.empty()) return UpdateResult();
  std::vector<BlockRow> rows;
  Eigen::VectorXd y;
  buildKnownRows(observations, &rows, &y);
  return sparseUpdate(rows, y);
}

Eskf::UpdateResult Eskf::updateKnownDense(const std::vector<KnownObservation>& observations) {
  validateKnown(observations, "Eskf::updateKnownDense");
  if (observations.empty()) return UpdateResult();
  std::vector<BlockRow> rows;
  Eigen::VectorXd y;
  buildKnownRows(observations, &rows, &y);
  return denseUpdate(rows, y);
}

Eskf::Innovation Eskf::innovationKnown(const KnownObservation& o) const {
  validateKnown({o}, "Eskf::innovationKnown");
  const Eigen::Matrix3d Rt = geometry::toRotationMatrix(x_.q).transpose();
  Eigen::Matrix<double, 3, 6> Hp;
  Hp.leftCols<3>() = -Rt;
  Hp.rightCols<3>() = Rt * skew(o.m - x_.p);
  Innovation r;
  r.S = Hp * C_.topLeftCorner<6, 6>() * Hp.transpose() + 0.5 * (o.C + o.C.transpose());
  r.S = (0.5 * (r.S + r.S.transpose())).eval();
  r.y = o.z - Rt * (o.m - x_.p);
  r.d2 = r.y.dot(r.S.llt().solve(r.y));
  return r;
}

Eskf::Innovation Eskf::innovation(const Observation& o) const {
  validateObservations({o}, "Eskf::innovation");
  Eigen::Matrix<double, 3, 6> Hp;
  Eigen::Matrix3d Hm;
  measurementJacobianBlocks(o.slot, &Hp, &Hm);
  const int s = slotIndex(o.slot);
  // S = [Hp Hm] [C_xx C_xm; C_mx C_mm] [Hp Hm]^T + C_obs.
  const Eigen::Matrix<double, 6, 6> Cxx = C_.topLeftCorner<6, 6>();
  const Eigen::Matrix<double, 6, 3> Cxm = C_.block<6, 3>(0, s);
  const Eigen::Matrix3d Cmm = C_.block<3, 3>(s, s);
  const Eigen::Matrix3d HCH_xm = Hp * Cxm * Hm.transpose();
  Innovation r;
  r.S = Hp * Cxx * Hp.transpose() + HCH_xm + HCH_xm.transpose() + Hm * Cmm * Hm.transpose() +
        0.5 * (o.C + o.C.transpose());
  r.S = (0.5 * (r.S + r.S.transpose())).eval();
  r.y = o.z - observeLandmark(x_, lm_[o.slot]);
  r.d2 = r.y.dot(r.S.llt().solve(r.y));
  return r;
}

double Eskf::mahalanobis(const Observation& o) const { return innovation(o).d2; }

}  // namespace slam
}  // namespace skin3d
