// SPDX-License-Identifier: BSD-3-Clause
// k-sigma covariance ellipsoids: axes and orientation rebuild the covariance, the axes come largest first,
// the rotation is proper, and bad covariances are refused.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <random>

#include "skin3d/geometry/covariance_ellipsoid.h"

using skin3d::geometry::covarianceEllipsoid;
using skin3d::geometry::CovarianceEllipsoid;

namespace {

// The covariance the ellipsoid stands for: R diag((a / k)^2) R^T.
Eigen::Matrix3d rebuild(const CovarianceEllipsoid& e, double k) {
  const Eigen::Matrix3d R = e.orientation.toRotationMatrix();
  return R * (e.semi_axes / k).cwiseAbs2().asDiagonal() * R.transpose();
}

TEST(CovarianceEllipsoid, DiagonalCovarianceGivesTheSigmasLargestFirst) {
  // sigma x = 2 mm, y = 1 mm, z = 3 mm: the ellipsoid's own x axis (largest) is the world z axis.
  const Eigen::Matrix3d C = Eigen::Vector3d(4e-6, 1e-6, 9e-6).asDiagonal();
  CovarianceEllipsoid e;
  ASSERT_TRUE(covarianceEllipsoid(C, 3.0, &e));
  EXPECT_NEAR(e.semi_axes[0], 9e-3, 1e-12);
  EXPECT_NEAR(e.semi_axes[1], 6e-3, 1e-12);
  EXPECT_NEAR(e.semi_axes[2], 3e-3, 1e-12);
  const Eigen::Matrix3d R = e.orientation.toRotationMatrix();
  EXPECT_NEAR(std::abs(R.col(0).dot(Eigen::Vector3d::UnitZ())), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(R.col(1).dot(Eigen::Vector3d::UnitX())), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(R.col(2).dot(Eigen::Vector3d::UnitY())), 1.0, 1e-12);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_TRUE(rebuild(e, 3.0).isApprox(C, 1e-12));
}

TEST(CovarianceEllipsoid, RotatedCovariancesRoundTrip) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0), s(1e-4, 5e-3);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Matrix3d R =
        Eigen::Quaterniond(Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
    const Eigen::Vector3d sig(s(rng), s(rng), s(rng));
    const Eigen::Matrix3d C = R * sig.cwiseAbs2().asDiagonal() * R.transpose();
    CovarianceEllipsoid e;
    ASSERT_TRUE(covarianceEllipsoid(C, 2.0, &e)) << trial;
    EXPECT_GE(e.semi_axes[0], e.semi_axes[1]);
    EXPECT_GE(e.semi_axes[1], e.semi_axes[2]);
    EXPECT_NEAR(e.semi_axes.prod(), 8.0 * sig.prod(), 1e-9 * 8.0 * sig.prod()) << trial;
    EXPECT_NEAR(e.orientation.norm(), 1.0, 1e-12);
    EXPECT_TRUE(rebuild(e, 2.0).isApprox(C, 1e-9)) << trial << "\n" << rebuild(e, 2.0) << "\nvs\n" << C;
    // A point on the ellipsoid's largest axis is at Mahalanobis distance 2.
    const Eigen::Vector3d x = e.orientation * Eigen::Vector3d(e.semi_axes[0], 0, 0);
    EXPECT_NEAR(std::sqrt(x.dot(C.ldlt().solve(x))), 2.0, 1e-6) << trial;
  }
}

TEST(CovarianceEllipsoid, RefusesBadCovariancesAndLeavesTheOutputAlone) {
  CovarianceEllipsoid e;
  e.semi_axes = Eigen::Vector3d(7, 7, 7);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::Matrix3d C = Eigen::Matrix3d::Identity() * 1e-6;
  Eigen::Matrix3d bad = C;
  bad(1, 2) = nan;
  EXPECT_FALSE(covarianceEllipsoid(bad, 3.0, &e));
  bad = C;
  bad(0, 0) = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(covarianceEllipsoid(bad, 3.0, &e));
  bad = C;
  bad(2, 2) = -1e-6;  // indefinite
  EXPECT_FALSE(covarianceEllipsoid(bad, 3.0, &e));
  bad = C;
  bad(2, 2) = 0.0;  // singular: a flat ellipsoid rviz cannot draw
  EXPECT_FALSE(covarianceEllipsoid(bad, 3.0, &e));
  bad = C;
  bad(0, 1) = 5e-7;  // not symmetric
  EXPECT_FALSE(covarianceEllipsoid(bad, 3.0, &e));
  EXPECT_FALSE(covarianceEllipsoid(Eigen::Matrix3d::Zero(), 3.0, &e));
  EXPECT_FALSE(covarianceEllipsoid(C, 0.0, &e));
  EXPECT_FALSE(covarianceEllipsoid(C, nan, &e));
  EXPECT_EQ(e.semi_axes, Eigen::Vector3d(7, 7, 7));
  // Symmetric up to rounding is accepted.
  C(0, 1) = 1e-7;
  C(1, 0) = 1e-7 * (1 + 1e-12);
  EXPECT_TRUE(covarianceEllipsoid(C, 3.0, &e));
}

}  // namespace
