// SPDX-License-Identifier: BSD-3-Clause
// Private helpers of the ES-EKF, shared by its files (not installed):
//   eskf_blas.cpp    the covariance kernels (threads; OpenBLAS when built with SKIN3D_HAVE_OPENBLAS);
//   eskf.cpp         options, model functions, set-up, slots, Jacobians, prediction;
//   eskf_update.cpp  the measurement updates and innovations.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <stdexcept>
#include <string>

#include "../common/text.h"

namespace skin3d {
namespace slam {
namespace eskf_detail {

template <typename Derived>
bool allFinite(const Eigen::MatrixBase<Derived>& m) {
  return m.allFinite();
}

[[noreturn]] inline void fail(const std::string& message) { throw std::invalid_argument(message); }

inline std::string str(double v) { return common::num(v); }

// z and C of a measurement: z finite, C finite, symmetric and positive definite (LLT).
inline void checkMeasurement(const Eigen::Vector3d& z, const Eigen::Matrix3d& C, const std::string& who) {
  if (!allFinite(z)) fail(who + ": measurement z is not finite");
  if (!allFinite(C)) fail(who + ": covariance C is not finite");
  const double scale = C.cwiseAbs().maxCoeff();
  if ((C - C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) fail(who + ": covariance C is not symmetric");
  Eigen::LLT<Eigen::Matrix3d> llt(C);
  if (scale <= 0.0 || llt.info() != Eigen::Success) fail(who + ": covariance C is not positive definite");
}

// ---- eskf_blas.cpp (each documented there)
void lowerUpdate(Eigen::MatrixXd& C, const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, double alpha,
                 int threads, bool use_blas);
void solveRightLowerTransposed(Eigen::MatrixXd& U, const Eigen::MatrixXd& L, int threads, bool use_blas);
void mirrorLower(Eigen::MatrixXd& C, int threads);

}  // namespace eskf_detail
}  // namespace slam
}  // namespace skin3d
