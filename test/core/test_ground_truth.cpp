// SPDX-License-Identifier: BSD-3-Clause
// Ground truth moved onto a live SLAM run's first pose (slam/ground_truth.h): the expected poses are built
// here from a known rigid motion, not from the code under test.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "skin3d/slam/ground_truth.h"

using skin3d::slam::GroundTruthAligner;
using skin3d::slam::StampedPose;

namespace {

StampedPose pose(double t, const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
  StampedPose s;
  s.t = t;
  s.p = p;
  s.q = q.normalized();
  return s;
}

// A truth trajectory in its own world, and the SLAM's world related to it by a known rigid motion T.
struct Scene {
  Eigen::Quaterniond qT{Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())};
  Eigen::Vector3d pT{0.1, -0.2, 0.3};
  StampedPose truth(double t) const {
    return pose(t, Eigen::Vector3d(0.01 * t, 0.02 * std::sin(t), 0.3),
                Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * t, Eigen::Vector3d::UnitY())));
  }
  StampedPose slam(double t) const {  // T * truth(t)
    const StampedPose g = truth(t);
    return pose(t, pT + qT * g.p, qT * g.q);
  }
};

}  // namespace

TEST(GroundTruthAligner, MovesTruthOntoTheSlamWorld) {
  Scene s;
  GroundTruthAligner a(0.05);
  for (int i = 0; i < 20; ++i) EXPECT_FALSE(a.add(s.truth(0.1 * i), 1.0));
  EXPECT_FALSE(a.anchored());
  ASSERT_TRUE(a.anchor(s.slam(0.5)));
  EXPECT_FALSE(a.anchor(s.slam(0.5)));  // once only
  for (double t : {0.5, 1.2, 1.9}) {
    const StampedPose g = a.align(s.truth(t)), e = s.slam(t);
    EXPECT_LT((g.p - e.p).norm(), 1e-12) << t;
    EXPECT_LT(g.q.angularDistance(e.q), 1e-9) << t;
  }
  // from the match window before the first frame on: 0.5 ... 1.9 (0.45 is outside the buffer's 0.1 s steps)
  const auto since = a.alignedSince(0.5);
  ASSERT_EQ(since.size(), 15u);
  EXPECT_NEAR(since.front().t, 0.5, 1e-9);
}

TEST(GroundTruthAligner, NeedsATruthPoseNearTheFirstFrame) {
  Scene s;
  GroundTruthAligner a(0.05);
  a.add(s.truth(0.0), 1.0);
  a.add(s.truth(1.0), 1.0);
  EXPECT_FALSE(a.anchor(s.slam(0.5)));  // nothing within 0.05 s
  a.add(s.truth(0.52), 1.0);            // out of order but not a restart (0.48 s back, < 1 s)
  EXPECT_TRUE(a.anchor(s.slam(0.5)));
  // the truth pose of 0.52 s is put onto the SLAM's pose of 0.5 s: T' = S(0.5) G(0.52)^-1, as isometries
  auto iso = [](const StampedPose& x) {
    Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
    m.linear() = x.q.toRotationMatrix();
    m.translation() = x.p;
    return m;
  };
  const Eigen::Isometry3d expected = iso(s.slam(0.5)) * iso(s.truth(0.52)).inverse() * iso(s.truth(1.0));
  const StampedPose g = a.align(s.truth(1.0));
  EXPECT_LT((g.p - expected.translation()).norm(), 1e-12);
  EXPECT_LT(g.q.angularDistance(Eigen::Quaterniond(expected.linear())), 1e-9);
  EXPECT_GT((g.p - s.slam(1.0).p).norm(), 1e-5);  // not the exact motion: the poses were 0.02 s apart
}

TEST(GroundTruthAligner, ARestartedRecordingForgetsTheOldRun) {
  Scene s;
  GroundTruthAligner a(0.05);
  for (int i = 0; i < 30; ++i) a.add(s.truth(10.0 + 0.1 * i), 1.0);
  ASSERT_TRUE(a.anchor(s.slam(10.0)));
  EXPECT_TRUE(a.add(s.truth(10.0), 1.0));  // 2.9 s back: restarted
  EXPECT_FALSE(a.anchored());
  EXPECT_EQ(a.alignedSince(0.0).size(), 1u);
  a.dropAnchor();
  EXPECT_TRUE(a.anchor(s.slam(10.0)));
}

TEST(GroundTruthAligner, KeepsOnlyTheLastPosesOfItsBuffer) {
  Scene s;
  GroundTruthAligner a(0.05, 10);
  for (int i = 0; i < 50; ++i) a.add(s.truth(0.1 * i), 100.0);
  EXPECT_FALSE(a.anchor(s.slam(0.0)));  // pushed out
  EXPECT_TRUE(a.anchor(s.slam(4.9)));
  EXPECT_EQ(a.alignedSince(0.0).size(), 10u);
}
