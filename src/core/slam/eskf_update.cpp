// SPDX-License-Identifier: BSD-3-Clause
// Error-state EKF SLAM: the measurement updates (sparse and dense) and the innovations
// (see include/skin3d/slam/eskf.h for the model, the Jacobians and the costs).
#include "skin3d/slam/eskf.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "eskf_detail.h"

namespace skin3d {
namespace slam {

using geometry::Quat;
using geometry::skew;

using namespace eskf_detail;  // NOLINT(build/namespaces): the private helpers of the ES-EKF's files

// ============================================================================ update

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
