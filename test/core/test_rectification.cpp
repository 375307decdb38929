// SPDX-License-Identifier: BSD-3-Clause
// Rectification of parallel and strongly converged rigs into CameraInfo (K, D, R, P).
#include <gtest/gtest.h>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/stereo/rectification.h"

using namespace skin3d;

namespace {
Eigen::Matrix3d makeK(double f, double cx, double cy) {
  Eigen::Matrix3d K;
  K << f, 0, cx, 0, f, cy, 0, 0, 1;
  return K;
}

// The thesis' Part I rig, reduced to a quarter resolution (1056 x 784, 4.48 um pixels): 210 mm, 54.4 deg.
geometry::StereoRig partOneRig() {
  const geometry::PinholeCamera cam(makeK(2.94 / 4.48e-3, 527.5, 391.5), 1056, 784, {-0.02, 0.01, 0, 0, 0});
  const double a = 54.4 * M_PI / 180.0;
  const Eigen::Vector3d c_r = geometry::so3Exp(Eigen::Vector3d(0, -0.5 * a, 0)) * Eigen::Vector3d(0.21, 0, 0);
  return geometry::StereoRig::fromRightPose(cam, cam, geometry::so3Exp(Eigen::Vector3d(0, -a, 0)), c_r);
}

// A 100 x 80 mm plate 245 mm in front of the rig midpoint, facing it (left frame coordinates).
std::vector<Eigen::Vector3d> plate(const geometry::StereoRig& rig, double half_width = 0.05) {
  const double half = 0.5 * rig.opticalAxesAngle();
  const Eigen::Matrix3d R_rig_left = geometry::so3Exp(Eigen::Vector3d(0, half, 0));
  const Eigen::Vector3d c_left(-0.105, 0, 0);
  std::vector<Eigen::Vector3d> pts;
  for (double x = -half_width; x <= half_width + 1e-4; x += half_width / 5)
    for (double y = -0.04; y <= 0.0401; y += 0.01)
      pts.push_back(R_rig_left.transpose() * (Eigen::Vector3d(x, y, 0.245) - c_left));
  return pts;
}
}  // namespace

TEST(Rectification, ConvergedRigKeepsThePlateInsideBothImagesAndRowsAligned) {
  const auto rig = partOneRig();
  const auto pts = plate(rig);
  const auto pair = stereo::rectifyStereo(rig, pts);
  EXPECT_FALSE(pair.zero_disparity);
  double max_dv = 0.0;
  for (const auto& X : pts) {
    const Eigen::Vector2d l = stereo::projectRectified(pair, X, false), r = stereo::projectRectified(pair, X, true);
    max_dv = std::max(max_dv, std::abs(l.y() - r.y()));
    for (const auto& uv : {l, r}) {
      EXPECT_GE(uv.x(), 0.0);
      EXPECT_LE(uv.x(), 1055.0);
      EXPECT_GE(uv.y(), 0.0);
      EXPECT_LE(uv.y(), 783.0);
    }
    // Depth from the rectified disparity (with the principal-point offset) is the rectified z.
    const double fx = pair.right.P(0, 0), B = -pair.right.P(0, 3) / fx;
    const double d = (l.x() - pair.left.P(0, 2)) - (r.x() - pair.right.P(0, 2));
    EXPECT_NEAR(fx * B / d, (pair.left.R * X).z(), 1e-9);
  }
  EXPECT_LT(max_dv, 1e-6);
  // The baseline survives rectification.
  EXPECT_NEAR(-pair.right.P(0, 3) / pair.right.P(0, 0), 0.21, 1e-9);
  // Round trip: the rig rebuilt from the rectified CameraInfo pair is the original one.
  const auto back = geometry::StereoRig::fromCameraInfo(pair.left, pair.right);
  EXPECT_LT((back.R_rl() - rig.R_rl()).norm(), 1e-9);
  EXPECT_LT((back.t_rl() - rig.t_rl()).norm(), 1e-9);
}

TEST(Rectification, WidePlateGetsFittedProjections) {
  // 200 mm wide: both raw cameras see it, alpha 0 loses it, OpenCV's alpha > 0 degenerates for 54.4 deg.
  const auto rig = partOneRig();
  const auto pts = plate(rig, 0.10);
  const auto pair = stereo::rectifyStereo(rig, pts);
  EXPECT_TRUE(pair.projection_fitted);
  EXPECT_GT(pair.left.P(0, 0), 0.3 * rig.left().fx());  // not a degenerate, tiny focal length
  EXPECT_LE(pair.left.P(0, 0), rig.left().fx());
  for (const auto& X : pts) {
    const Eigen::Vector2d l = stereo::projectRectified(pair, X, false), r = stereo::projectRectified(pair, X, true);
    EXPECT_NEAR(l.y(), r.y(), 1e-6);
    for (const auto& uv : {l, r}) {
      EXPECT_GE(uv.x(), 0.0);
      EXPECT_LE(uv.x(), 1055.0);
      EXPECT_GE(uv.y(), 0.0);
      EXPECT_LE(uv.y(), 783.0);
    }
  }
  const auto back = geometry::StereoRig::fromCameraInfo(pair.left, pair.right);
  EXPECT_LT((back.t_rl() - rig.t_rl()).norm(), 1e-9);
}

TEST(Rectification, ZeroDisparityLosesTheConvergedScene) {
  // The platform fact in docs/design.md: CALIB_ZERO_DISPARITY moves the plate out of the rectified images.
  const auto rig = partOneRig();
  const auto pair = stereo::rectifyStereo(rig);
  ASSERT_TRUE(pair.zero_disparity);
  int outside = 0;
  for (const auto& X : plate(rig)) {
    const Eigen::Vector2d l = stereo::projectRectified(pair, X, false), r = stereo::projectRectified(pair, X, true);
    if (l.x() < 0 || l.x() > 1055 || r.x() < 0 || r.x() > 1055) ++outside;
  }
  EXPECT_GT(outside, 0);
}

TEST(Rectification, ParallelRigWithDistortion) {
  const geometry::PinholeCamera cam(makeK(803.6, 319.5, 239.5), 640, 480, {-0.1, 0.02, 0.001, -0.001, 0});
  const auto rig = geometry::StereoRig::fromRightPose(cam, cam, geometry::so3Exp(Eigen::Vector3d(0.002, -0.01, 0.003)),
                                                      Eigen::Vector3d(0.105, 0, 0.015));
  const auto pair = stereo::rectifyStereo(rig);
  for (double x = -0.1; x <= 0.1; x += 0.05)
    for (double y = -0.08; y <= 0.08; y += 0.04) {
      const Eigen::Vector3d X(x + 0.05, y, 0.4);
      EXPECT_NEAR(stereo::projectRectified(pair, X, false).y(), stereo::projectRectified(pair, X, true).y(), 1e-6);
    }
}

TEST(Rectification, ImpossibleWorkingAreaIsReported) {
  const auto rig = partOneRig();
  // A point far to the left of the left camera is never in the right image.
  EXPECT_THROW(stereo::rectifyStereo(rig, {Eigen::Vector3d(-2.0, 0.0, 0.3)}), std::runtime_error);
}
