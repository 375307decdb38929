// SPDX-License-Identifier: BSD-3-Clause
// Trajectory files and the ATE: TUM stamps keep their nanoseconds (epoch stamps 0.1 s apart stay
// distinct), time association, and the alignment of a reference that lives in another world (motion capture,
// EuRoC-style). The truth is generated here (a circular orbit, a known world transform, a known per-pose error),
// never taken from the code under test.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <random>
#include <set>
#include <string>

#include "skin3d/slam/results.h"

using namespace skin3d;

namespace {

const std::int64_t kEpochNs = 1700000000LL * 1000000000LL;  // a recording's epoch stamps

// A rig orbiting at 0.6 m, 10 Hz, looking inwards: poses of world <- camera.
std::vector<slam::StampedPose> orbit(int n, std::int64_t start_ns, double dt = 0.1) {
  std::vector<slam::StampedPose> out;
  for (int k = 0; k < n; ++k) {
    slam::StampedPose p;
    p.stamp_ns = start_ns + static_cast<std::int64_t>(std::llround(k * dt * 1e9));
    p.t = static_cast<double>(p.stamp_ns) * 1e-9;
    const double a = 0.15 * k * dt;
    p.p = Eigen::Vector3d(0.6 * std::sin(a), 0.05 * std::sin(3 * a), 0.6 - 0.6 * std::cos(a));
    p.q = Eigen::Quaterniond(Eigen::AngleAxisd(-a, Eigen::Vector3d::UnitY()));
    out.push_back(p);
  }
  return out;
}

Eigen::Isometry3d someWorld() {  // a motion-capture world: far away and rotated
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.5, 0.8).normalized())).toRotationMatrix();
  T.translation() = Eigen::Vector3d(2.4, -1.3, 0.9);
  return T;
}

std::vector<slam::StampedPose> moved(std::vector<slam::StampedPose> poses, const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  for (auto& p : poses) {
    p.p = T * p.p;
    p.q = (q * p.q).normalized();
  }
  return poses;
}

}  // namespace

TEST(TumStamps, EpochStampsKeepTheirNanoseconds) {
  const auto traj = orbit(50, kEpochNs + 123456789);
  std::set<std::string> seen;
  for (const auto& p : traj) seen.insert(slam::formatStamp(p));
  EXPECT_EQ(seen.size(), traj.size()) << "stamps 0.1 s apart must stay distinct";
  EXPECT_EQ(slam::formatStamp(traj[0]), "1700000000.123456789");
  EXPECT_EQ(slam::formatStamp(traj[3]), "1700000000.423456789");
  EXPECT_EQ(slam::parseStampNs("1700000000.1"), kEpochNs + 100000000);
  EXPECT_EQ(slam::parseStampNs("12.0000000015"), 12000000001LL);  // past nine decimals: dropped
  EXPECT_EQ(slam::parseStampNs("abc"), -1);
  EXPECT_EQ(slam::parseStampNs("-1.5"), -1);
  slam::StampedPose only_t;  // no exact stamp: nine decimals of t
  only_t.t = 1000.25;
  EXPECT_EQ(slam::formatStamp(only_t), "1000.250000000");
}

TEST(TumStamps, WriteReadRoundTripIsExact) {
  const auto traj = orbit(30, kEpochNs + 1);
  const std::string path = ::testing::TempDir() + "skin3d_epoch.tum";
  slam::writeTum(path, traj);
  const auto back = slam::readTum(path);
  ASSERT_EQ(back.size(), traj.size());
  for (size_t i = 0; i < traj.size(); ++i) {
    EXPECT_EQ(back[i].stamp_ns, traj[i].stamp_ns) << i;
    EXPECT_NEAR((back[i].p - traj[i].p).norm(), 0.0, 1e-9);
    EXPECT_NEAR(back[i].q.angularDistance(traj[i].q), 0.0, 1e-9);
  }
}

TEST(TrajectoryError, AssociationIsNearestWithinTheTolerance) {
  // estimate at 10 Hz; reference at 200 Hz, shifted by 1.3 ms: each estimate pairs with the nearest sample
  const auto est = orbit(20, kEpochNs);
  const auto ref = orbit(400, kEpochNs + 1300000, 0.005);
  const auto pairs = slam::associateByTime(est, ref, 0.01);
  ASSERT_EQ(pairs.size(), est.size());
  for (const auto& pr : pairs) {
    const double dt = std::abs(est[pr.first].t - ref[pr.second].t);
    EXPECT_NEAR(dt, 0.0013, 1e-6);  // the nearest 200 Hz sample is 1.3 ms away (the other one 3.7 ms)
  }
  EXPECT_TRUE(slam::associateByTime(est, ref, 0.001).empty()) << "1.3 ms apart is outside 1 ms";
}

TEST(TrajectoryError, ReferenceInAnotherWorldIsAlignedBySE3) {
  const auto truth = orbit(120, kEpochNs);
  // the estimate: truth + a known error per pose (generated), in the SLAM's world = the truth's own
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 0.5e-3);
  auto est = truth;
  for (auto& p : est) p.p += Eigen::Vector3d(n(rng), n(rng), n(rng));
  double ss = 0.0;
  for (size_t i = 0; i < est.size(); ++i) ss += (est[i].p - truth[i].p).squaredNorm();
  const double injected = std::sqrt(ss / est.size());

  const auto same = slam::trajectoryError(est, truth, slam::AteAlignment::Auto);
  EXPECT_EQ(same.alignment, slam::AteAlignment::None) << same.alignment_note;
  EXPECT_NEAR(same.rmse, injected, 1e-12);
  EXPECT_EQ(same.pairs, 120);

  const Eigen::Isometry3d W = someWorld();  // the reference as a motion-capture system gives it
  const auto mocap = moved(truth, W);
  const auto raw = slam::trajectoryError(est, mocap, slam::AteAlignment::None);
  EXPECT_GT(raw.rmse, 1.0) << "unaligned, the worlds are metres apart";
  const auto se3 = slam::trajectoryError(est, mocap, slam::AteAlignment::SE3);
  const auto autoe = slam::trajectoryError(est, mocap, slam::AteAlignment::Auto);
  EXPECT_EQ(autoe.alignment, slam::AteAlignment::SE3) << autoe.alignment_note;
  EXPECT_NEAR(autoe.rmse, se3.rmse, 1e-12);
  // the fit absorbs a little of the noise (6 dof over 360 coordinates), never more than the injected error
  EXPECT_LE(se3.rmse, injected + 1e-12);
  EXPECT_GT(se3.rmse, 0.95 * injected);
  // and it recovers the world transform, T * W = identity, to what the noise allows: the 6 fitted parameters
  // move the 3N coordinates by sigma * sqrt(6 / N) RMS (expected), and the rotation is known to about
  // sigma / (spread along the trajectory's thinnest axis * sqrt(N)); bounds at 3 and 4 times those
  const Eigen::Isometry3d I = se3.transform * W;
  double moved_ss = 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : truth) {
    moved_ss += (I * p.p - p.p).squaredNorm();
    mean += p.p / truth.size();
  }
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : truth) cov += (p.p - mean) * (p.p - mean).transpose() / truth.size();
  const double thinnest = std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues()(0));
  const double sigma = 0.5e-3, N = truth.size();
  EXPECT_LT(std::sqrt(moved_ss / N), 3.0 * sigma * std::sqrt(6.0 / N));
  EXPECT_LT(Eigen::AngleAxisd(I.linear()).angle(), 4.0 * sigma / (thinnest * std::sqrt(N)));
  EXPECT_NEAR(se3.rotation_rmse, Eigen::AngleAxisd(I.linear()).angle(), 1e-9) << "orientations carry no noise";

  // first-pose alignment: exact at the first pair
  const auto first = slam::trajectoryError(est, mocap, slam::AteAlignment::FirstPose);
  const Eigen::Vector3d p0 = first.transform * mocap[0].p;
  EXPECT_NEAR((p0 - est[0].p).norm(), 0.0, 1e-9);
  EXPECT_LT(first.rmse, 0.1) << "first-pose alignment is rough but not metres off";
}

TEST(TrajectoryError, FewPairsFallBackToTheFirstPose) {
  const auto truth = orbit(2, kEpochNs);
  const auto e = slam::trajectoryError(truth, moved(truth, someWorld()), slam::AteAlignment::SE3);
  EXPECT_EQ(e.alignment, slam::AteAlignment::FirstPose);
  EXPECT_NEAR(e.rmse, 0.0, 1e-9);
  EXPECT_THROW(slam::parseAteAlignment("umeyama"), std::invalid_argument);
  EXPECT_EQ(slam::parseAteAlignment("first_pose"), slam::AteAlignment::FirstPose);
}
