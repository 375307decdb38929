// SPDX-License-Identifier: BSD-3-Clause
// Error-state EKF SLAM: options, model functions, set-up, slots, Jacobians and prediction (see
// include/skin3d/slam/eskf.h for the model, the Jacobians and the costs; the updates: eskf_update.cpp).
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

#include "eskf_detail.h"

namespace skin3d {
namespace slam {

using geometry::Quat;
using geometry::skew;

using namespace eskf_detail;  // NOLINT(build/namespaces): the private helpers of the ES-EKF's files

// ============================================================================ options

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

}  // namespace slam
}  // namespace skin3d
