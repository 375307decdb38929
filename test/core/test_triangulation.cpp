// SPDX-License-Identifier: BSD-3-Clause
// MMSE triangulation (thesis Algorithm 2.1): exactness, covariance against
// Monte Carlo and against the numerical Jacobian, parallel and converged rigs.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <random>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/geometry/stereo_rig.h"
#include "skin3d/geometry/triangulation.h"

using namespace skin3d::geometry;

namespace {

Eigen::Matrix3d makeK(double f, double cx, double cy) {
  Eigen::Matrix3d K;
  K << f, 0, cx, 0, f, cy, 0, 0, 1;
  return K;
}

// The SLAM rig of docs/design.md: f 1.8 mm / 2.24 um, 640x480, right camera at (105, 0, 15) mm.
StereoRig slamRig(std::vector<double> D = {}) {
  const PinholeCamera cam(makeK(1.8 / 2.24e-3, 319.5, 239.5), 640, 480, D);
  return StereoRig::fromRightPose(cam, cam, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.105, 0.0, 0.015));
}

// The thesis' Part I rig: f 2.94 mm / 1.12 um, 4224x3136, b = 210 mm, 54.4 deg between the axes.
StereoRig convergedRig(std::vector<double> D = {}) {
  const PinholeCamera cam(makeK(2.94 / 1.12e-3, 2111.5, 1567.5), 4224, 3136, D);
  const double a = 54.4 * M_PI / 180.0;
  // Left frame = reference (turned +a/2 towards the right camera in the rig frame); the right camera
  // is turned -a/2, so R_lr = Ry(-a) and its centre is Ry(-a/2) (0.21, 0, 0).
  const Eigen::Vector3d c_r = so3Exp(Eigen::Vector3d(0, -0.5 * a, 0)) * Eigen::Vector3d(0.21, 0, 0);
  return StereoRig::fromRightPose(cam, cam, so3Exp(Eigen::Vector3d(0, -a, 0)), c_r);
}

// Points seen by both cameras: random pixel in the left image, random depth, kept if the right sees it.
std::vector<Eigen::Vector3d> visiblePoints(const StereoRig& rig, double zmin, double zmax, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, rig.left().width() - 1), v(0, rig.left().height() - 1), z(zmin, zmax);
  std::vector<Eigen::Vector3d> pts;
  while (static_cast<int>(pts.size()) < n) {
    const Eigen::Vector3d X = rig.left().unproject(Eigen::Vector2d(u(rng), v(rng))) * z(rng);
    Eigen::Vector2d uvl, uvr;
    if (rig.project(X, &uvl, &uvr) && rig.right().inImage(uvr)) pts.push_back(X);
  }
  return pts;
}

void expectExact(const StereoRig& rig, double zmin, double zmax) {
  for (const auto& X : visiblePoints(rig, zmin, zmax, 300, 11)) {
    Eigen::Vector2d uvl, uvr;
    ASSERT_TRUE(rig.project(X, &uvl, &uvr));
    const TriangulationResult r = rig.triangulate(uvl, uvr, 0.5);
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_LT((r.X - X).norm(), 1e-9) << "at " << X.transpose();
    // The covariance is symmetric positive definite.
    EXPECT_LT((r.C - r.C.transpose()).norm(), 1e-18);
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(r.C).eigenvalues().minCoeff(), 0.0);
  }
}

// Sample covariance of >= 2000 noisy triangulations against the predicted one.
void expectCovarianceMatchesMonteCarlo(const StereoRig& rig, double zmin, double zmax, unsigned seed) {
  const double sigma = 0.5;
  const int trials = 2500;
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  for (const auto& X : visiblePoints(rig, zmin, zmax, 4, seed + 1)) {
    Eigen::Vector2d uvl, uvr;
    ASSERT_TRUE(rig.project(X, &uvl, &uvr));
    const TriangulationResult pred = rig.triangulate(uvl, uvr, sigma);
    ASSERT_TRUE(pred.ok);
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    double nees = 0.0;
    std::vector<Eigen::Vector3d> errs;
    for (int t = 0; t < trials; ++t) {
      const Eigen::Vector2d nl(noise(rng), noise(rng)), nr(noise(rng), noise(rng));
      const TriangulationResult r = rig.triangulate(uvl + nl, uvr + nr, sigma);
      ASSERT_TRUE(r.ok);
      const Eigen::Vector3d e = r.X - X;
      errs.push_back(e);
      mean += e;
      nees += e.dot(r.C.inverse() * e);
    }
    mean /= trials;
    for (const auto& e : errs) S += (e - mean) * (e - mean).transpose();
    S /= (trials - 1);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(S(i, i) / pred.C(i, i), 1.0, 0.10)
          << "axis " << i << " at " << X.transpose() << ": sample " << S(i, i) << " predicted " << pred.C(i, i);
    }
    // Average NEES of a 3-dof Gaussian is 3; with 2500 trials its 99.9 % band is about 3 +- 0.16.
    EXPECT_NEAR(nees / trials, 3.0, 0.25) << "at " << X.transpose();
  }
}

// The covariance is the first-order propagation of the pixel noise: C = J (sigma^2 I) J^T.
void expectCovarianceMatchesNumericalJacobian(const StereoRig& rig, double zmin, double zmax) {
  const double sigma = 0.5, h = 1e-4;
  for (const auto& X : visiblePoints(rig, zmin, zmax, 20, 5)) {
    Eigen::Vector2d uvl, uvr;
    ASSERT_TRUE(rig.project(X, &uvl, &uvr));
    Eigen::Matrix<double, 3, 4> J;
    for (int i = 0; i < 4; ++i) {
      Eigen::Vector4d d = Eigen::Vector4d::Zero();
      d[i] = h;
      const auto plus = rig.triangulate(uvl + d.head<2>(), uvr + d.tail<2>(), sigma);
      const auto minus = rig.triangulate(uvl - d.head<2>(), uvr - d.tail<2>(), sigma);
      J.col(i) = (plus.X - minus.X) / (2 * h);
    }
    const Eigen::Matrix3d C_num = sigma * sigma * J * J.transpose();
    const Eigen::Matrix3d C = rig.triangulate(uvl, uvr, sigma).C;
    EXPECT_LT((C - C_num).norm() / C.norm(), 0.01) << "at " << X.transpose();
  }
}

const std::vector<double> kDistortion = {-0.12, 0.03, 0.0005, -0.0004, 0.0};

}  // namespace

TEST(Triangulation, NoiseFreeIsExactParallelRig) { expectExact(slamRig(), 0.25, 0.8); }
TEST(Triangulation, NoiseFreeIsExactConvergedRig) { expectExact(convergedRig(), 0.15, 0.4); }
TEST(Triangulation, NoiseFreeIsExactWithDistortion) {
  expectExact(slamRig(kDistortion), 0.25, 0.8);
  expectExact(convergedRig(kDistortion), 0.15, 0.4);
}

TEST(Triangulation, CovarianceMatchesMonteCarloParallelRig) { expectCovarianceMatchesMonteCarlo(slamRig(), 0.3, 0.6, 21); }
TEST(Triangulation, CovarianceMatchesMonteCarloConvergedRig) {
  expectCovarianceMatchesMonteCarlo(convergedRig(), 0.18, 0.32, 31);
}
TEST(Triangulation, CovarianceMatchesMonteCarloWithDistortion) {
  expectCovarianceMatchesMonteCarlo(slamRig(kDistortion), 0.3, 0.6, 41);
}

TEST(Triangulation, CovarianceMatchesNumericalJacobian) {
  expectCovarianceMatchesNumericalJacobian(slamRig(), 0.25, 0.8);
  expectCovarianceMatchesNumericalJacobian(convergedRig(kDistortion), 0.15, 0.4);
}

TEST(Triangulation, DepthUncertaintyFollowsTheStereoFormula) {
  // Parallel rig, point on the left optical axis: sigma_Z = Z^2 / (f b) * sigma_d, sigma_d = sqrt(2) sigma.
  const PinholeCamera cam(makeK(800.0, 319.5, 239.5), 640, 480);
  const StereoRig rig = StereoRig::fromRightPose(cam, cam, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.1, 0, 0));
  const Eigen::Vector3d X(0.05, 0.0, 0.5);  // midway, so both rays are symmetric
  Eigen::Vector2d uvl, uvr;
  ASSERT_TRUE(rig.project(X, &uvl, &uvr));
  const auto r = rig.triangulate(uvl, uvr, 0.5);
  const double expected = X.z() * X.z() / (800.0 * 0.1) * std::sqrt(2.0) * 0.5;
  EXPECT_NEAR(std::sqrt(r.C(2, 2)) / expected, 1.0, 1e-3);
}

TEST(Triangulation, RejectsBadInput) {
  std::vector<CameraObservation> one(1);
  EXPECT_FALSE(triangulateMmse(one).ok);
  const StereoRig rig = slamRig();
  // Rays that meet behind the cameras (disparity of the wrong sign).
  auto r = rig.triangulate(Eigen::Vector2d(300, 240), Eigen::Vector2d(400, 240), 0.5);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("behind"), std::string::npos) << r.message;
  r = rig.triangulate(Eigen::Vector2d(std::nan(""), 240), Eigen::Vector2d(300, 240), 0.5);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("NaN"), std::string::npos) << r.message;
  r = rig.triangulate(Eigen::Vector2d(320, 240), Eigen::Vector2d(300, 240), 0.0);
  EXPECT_FALSE(r.ok);
}
