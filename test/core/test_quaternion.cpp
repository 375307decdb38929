// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <random>

#include "skin3d/geometry/quaternion.h"

using namespace skin3d::geometry;

namespace {
Quat randomQuat(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Quat q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q;
}
Eigen::Vector3d randomVec(std::mt19937& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  return Eigen::Vector3d(u(rng), u(rng), u(rng));
}
}  // namespace

TEST(Quaternion, HamiltonUnitsMultiplyAsIjkEqualsMinusOne) {
  const Eigen::Vector4d i(0, 1, 0, 0), j(0, 0, 1, 0), k(0, 0, 0, 1), one(1, 0, 0, 0);
  EXPECT_TRUE(quatProduct(i, j).isApprox(k));
  EXPECT_TRUE(quatProduct(j, k).isApprox(i));
  EXPECT_TRUE(quatProduct(k, i).isApprox(j));
  EXPECT_TRUE(quatProduct(j, i).isApprox(-k));
  EXPECT_TRUE(quatProduct(quatProduct(i, j), k).isApprox(-one));
}

TEST(Quaternion, ProductMatchesEigenAndMatrixForms) {
  std::mt19937 rng(1);
  for (int n = 0; n < 100; ++n) {
    const Quat p = randomQuat(rng), q = randomQuat(rng);
    const Eigen::Vector4d pq = quatProduct(toWxyz(p), toWxyz(q));
    EXPECT_TRUE(pq.isApprox(toWxyz(p * q), 1e-12));
    EXPECT_TRUE((quatLeftMatrix(toWxyz(p)) * toWxyz(q)).isApprox(pq, 1e-12));
    EXPECT_TRUE((quatRightMatrix(toWxyz(q)) * toWxyz(p)).isApprox(pq, 1e-12));
    // Composition of rotations: R(p q) = R(p) R(q).
    EXPECT_TRUE(toRotationMatrix(fromWxyz(pq)).isApprox(toRotationMatrix(p) * toRotationMatrix(q), 1e-12));
  }
}

TEST(Quaternion, ExpMatchesAngleAxisAndLogInverts) {
  std::mt19937 rng(2);
  for (int n = 0; n < 200; ++n) {
    Eigen::Vector3d phi = randomVec(rng, 1.8);  // |phi| < pi
    const Quat q = quatExp(phi);
    const Eigen::AngleAxisd aa(phi.norm(), phi.normalized());
    EXPECT_TRUE(toRotationMatrix(q).isApprox(aa.toRotationMatrix(), 1e-12));
    EXPECT_NEAR((quatLog(q) - phi).norm(), 0.0, 1e-12);
    EXPECT_NEAR((so3Log(so3Exp(phi)) - phi).norm(), 0.0, 1e-10);
  }
  // Tiny angles are exact to first order and do not divide by zero.
  const Eigen::Vector3d tiny(1e-12, -2e-12, 3e-12);
  EXPECT_NEAR((quatLog(quatExp(tiny)) - tiny).norm(), 0.0, 1e-20);
  EXPECT_NEAR(quatExp(Eigen::Vector3d::Zero()).w(), 1.0, 0.0);
  // q and -q are the same rotation.
  const Quat q = quatExp(Eigen::Vector3d(0.3, -0.2, 0.5));
  EXPECT_NEAR((quatLog(Quat(-q.coeffs())) - quatLog(q)).norm(), 0.0, 1e-12);
  // Near pi.
  const Eigen::Vector3d big = (M_PI - 1e-6) * Eigen::Vector3d(1, 2, 3).normalized();
  EXPECT_NEAR((quatLog(quatExp(big)) - big).norm(), 0.0, 1e-9);
}

TEST(Quaternion, RotationMatrixRoundTrip) {
  std::mt19937 rng(3);
  for (int n = 0; n < 100; ++n) {
    const Quat q = randomQuat(rng);
    const Quat back = fromRotationMatrix(toRotationMatrix(q));
    EXPECT_GE(back.w(), 0.0);
    EXPECT_NEAR(std::abs(back.coeffs().dot(q.coeffs())), 1.0, 1e-12);
  }
  Eigen::Matrix3d notR = Eigen::Matrix3d::Identity();
  notR(0, 0) = 2.0;
  EXPECT_THROW(fromRotationMatrix(notR), std::invalid_argument);
  EXPECT_THROW(fromRotationMatrix(-Eigen::Matrix3d::Identity()), std::invalid_argument);  // reflection
}

TEST(Quaternion, SkewIsCrossProduct) {
  const Eigen::Vector3d a(1, -2, 3), b(0.5, 4, -1);
  EXPECT_TRUE((skew(a) * b).isApprox(a.cross(b)));
  EXPECT_TRUE((skew(a) + skew(a).transpose()).isZero());
}

// Jacobians against central differences of the defining relations.
TEST(Quaternion, So3JacobiansMatchNumericalDifferentiation) {
  std::mt19937 rng(4);
  const double h = 1e-6;
  for (int n = 0; n < 50; ++n) {
    const Eigen::Vector3d phi = randomVec(rng, 1.5);
    Eigen::Matrix3d Jl_num, Jr_num;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d d = h * Eigen::Vector3d::Unit(i);
      // Exp(phi + d) = Exp(Jl d) Exp(phi)  =>  Jl d = Log(Exp(phi + d) Exp(phi)^T)
      Jl_num.col(i) = (so3Log(so3Exp(phi + d) * so3Exp(phi).transpose()) -
                       so3Log(so3Exp(phi - d) * so3Exp(phi).transpose())) / (2 * h);
      Jr_num.col(i) = (so3Log(so3Exp(phi).transpose() * so3Exp(phi + d)) -
                       so3Log(so3Exp(phi).transpose() * so3Exp(phi - d))) / (2 * h);
    }
    EXPECT_LT((Jl_num - so3LeftJacobian(phi)).norm(), 1e-7);
    EXPECT_LT((Jr_num - so3RightJacobian(phi)).norm(), 1e-7);
    EXPECT_LT((so3LeftJacobianInverse(phi) * so3LeftJacobian(phi) - Eigen::Matrix3d::Identity()).norm(), 1e-10);
  }
  // Small-angle branch.
  const Eigen::Vector3d small(1e-8, 2e-8, -1e-8);
  EXPECT_LT((so3LeftJacobian(small) - Eigen::Matrix3d::Identity()).norm(), 1e-7);
}

TEST(Quaternion, ExpOfRotationVectorRotatesVectors) {
  // Quarter turn about z takes x to y (right-handed, Hamilton).
  const Quat q = quatExp(Eigen::Vector3d(0, 0, M_PI / 2));
  EXPECT_TRUE((q * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-12));
}
