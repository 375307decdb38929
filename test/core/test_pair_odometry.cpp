// SPDX-License-Identifier: BSD-3-Clause
// The rig's motion between two stereo pairs from their triangulated features (site/pair_odometry.h): the residual's
// Jacobian against numerical differences; a known motion recovered from landmarks drawn with their covariances
// and a third of false matches, its error consistent with the covariance stated.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/site/pair_odometry.h"

using skin3d::site::motionResidual;
using skin3d::site::relativeMotion;
using skin3d::stereo::StereoLandmark;

namespace {

Eigen::Isometry3d motion(const Eigen::Vector3d& phi, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = skin3d::geometry::so3Exp(phi);
  T.translation() = t;
  return T;
}

/** A stereo-like covariance at depth z: lateral sigma s, along the ray 4 s (the depth is the least known). */
Eigen::Matrix3d stereoCovariance(const Eigen::Vector3d& X, double s) {
  const Eigen::Vector3d r = X.normalized();
  return s * s * Eigen::Matrix3d::Identity() + 15 * s * s * r * r.transpose();
}

}  // namespace

TEST(PairOdometry, ResidualJacobianMatchesNumericalDifferences) {
  const Eigen::Isometry3d T = motion(Eigen::Vector3d(0.1, -0.2, 0.15), Eigen::Vector3d(0.02, -0.01, 0.03));
  const Eigen::Vector3d Xa(0.01, 0.02, 0.25), Xb(-0.03, 0.01, 0.27);
  Eigen::Matrix<double, 3, 6> J;
  const Eigen::Vector3d r0 = motionResidual(T, Xa, Xb, &J);
  const double h = 1e-7;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d[k] = h;
    Eigen::Isometry3d Tp = T;
    Tp.linear() = skin3d::geometry::so3Exp(d.head<3>()) * T.linear();
    Tp.translation() += d.tail<3>();
    const Eigen::Vector3d num = (motionResidual(Tp, Xa, Xb, nullptr) - r0) / h;
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(J(i, k), num[i], 1e-6) << "row " << i << " column " << k;
  }
}

TEST(PairOdometry, AKnownMotionIsRecoveredWithinItsCovariance) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n01(0, 1);
  std::uniform_real_distribution<double> u(-1, 1);
  const double s = 30e-6;  // m, lateral sigma of a landmark
  double nees_sum = 0;
  const int runs = 20;
  for (int run = 0; run < runs; ++run) {
    // the motion of a hand-held sweep between two pairs: ~9 deg about an axis 0.3 m away, some jitter
    const Eigen::Isometry3d T_a_b = motion(Eigen::Vector3d(0.15 + 0.02 * n01(rng), 0.02 * n01(rng), 0.02 * n01(rng)),
                                           Eigen::Vector3d(0.002 * n01(rng), -0.04 + 0.002 * n01(rng), 0.006 * n01(rng)));
    std::vector<StereoLandmark> a, b;
    const int n = 120, outliers = 60;
    for (int i = 0; i < n + outliers; ++i) {
      StereoLandmark la, lb;
      la.descriptor.resize(32);
      for (auto& v : la.descriptor) v = static_cast<float>(u(rng));
      lb.descriptor = la.descriptor;
      for (auto& v : lb.descriptor) v += static_cast<float>(0.05 * n01(rng));
      const Eigen::Vector3d Xb(0.05 * u(rng), 0.04 * u(rng), 0.26 + 0.02 * u(rng));
      Eigen::Vector3d Xa = T_a_b * Xb;
      if (i >= n) Xa = Eigen::Vector3d(0.05 * u(rng), 0.04 * u(rng), 0.26 + 0.02 * u(rng));  // a false match
      la.covariance = stereoCovariance(Xa, s);
      lb.covariance = stereoCovariance(Xb, s);
      const Eigen::LLT<Eigen::Matrix3d> ca(la.covariance), cb(lb.covariance);
      la.position = Xa + ca.matrixL() * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
      lb.position = Xb + cb.matrixL() * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
      a.push_back(la);
      b.push_back(lb);
    }
    std::shuffle(b.begin(), b.end(), rng);  // the order says nothing
    skin3d::site::OdometryOptions o;
    const auto r = relativeMotion(a, b, o, 7 + run);
    ASSERT_TRUE(r.ok) << r.why;
    EXPECT_GE(r.inliers, n - 5);
    EXPECT_LE(r.inliers, n + 2) << "false matches taken as inliers";
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = skin3d::geometry::so3Log(r.T_a_b.linear() * T_a_b.linear().transpose());
    e.tail<3>() = r.T_a_b.translation() - T_a_b.translation();
    // the scene's centre moves as it truly does: its error is about the depth noise of a match (4 s for each of
    // two landmarks) over sqrt(inliers), 15 um; 50 um is beyond 3 sigma
    const Eigen::Vector3d centre(0, 0, 0.26);
    EXPECT_LT((r.T_a_b * centre - T_a_b * centre).norm(), 50e-6) << "run " << run;
    nees_sum += e.dot(r.covariance.ldlt().solve(e));
    EXPECT_GT(r.rms_mahalanobis, 0.5);
    EXPECT_LT(r.rms_mahalanobis, 1.5);
  }
  // NEES averaged over the runs: 6 degrees of freedom, chi^2(120) / 20 within [4.6, 7.6] at 99 %
  const double nees = nees_sum / runs;
  EXPECT_GT(nees, 4.0);
  EXPECT_LT(nees, 8.0);
}

TEST(PairOdometry, UnrelatedPairsGiveNoMotion) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<StereoLandmark> a(80), b(80);
  for (auto* v : {&a, &b})
    for (auto& l : *v) {
      l.descriptor.resize(32);
      for (auto& d : l.descriptor) d = static_cast<float>(u(rng));
      l.position = Eigen::Vector3d(0.05 * u(rng), 0.04 * u(rng), 0.26);
      l.covariance = 1e-9 * Eigen::Matrix3d::Identity();
    }
  const auto r = relativeMotion(a, b, skin3d::site::OdometryOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_FALSE(r.why.empty());
  EXPECT_FALSE(relativeMotion({}, b, skin3d::site::OdometryOptions()).ok);
}
