// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <random>

#include "skin3d/geometry/camera.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/geometry/stereo_rig.h"

using namespace skin3d::geometry;

namespace {
Eigen::Matrix3d makeK(double fx, double fy, double cx, double cy) {
  Eigen::Matrix3d K;
  K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return K;
}
// A lens with noticeable distortion (values of a typical webcam calibration).
const std::vector<double> kD = {-0.28, 0.07, 0.0012, -0.0008, 0.02};

PinholeCamera distortedCamera() { return PinholeCamera(makeK(804.0, 806.0, 321.5, 238.2), 640, 480, kD); }
}  // namespace

TEST(Camera, ProjectionMatchesOpenCvProjectPoints) {
  const PinholeCamera cam = distortedCamera();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.25, 0.25), z(0.3, 1.0);
  std::vector<cv::Point3d> pts;
  for (int i = 0; i < 200; ++i) pts.emplace_back(u(rng), u(rng), z(rng));
  cv::Mat K, D(kD);
  cv::eigen2cv(cam.K(), K);
  std::vector<cv::Point2d> ref;
  cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, ref);
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d uv = cam.project(Eigen::Vector3d(pts[i].x, pts[i].y, pts[i].z));
    EXPECT_NEAR(uv.x(), ref[i].x, 1e-9);
    EXPECT_NEAR(uv.y(), ref[i].y, 1e-9);
  }
}

TEST(Camera, UndistortInvertsDistortionAndMatchesOpenCv) {
  const PinholeCamera cam = distortedCamera();
  cv::Mat K, D(kD);
  cv::eigen2cv(cam.K(), K);
  std::vector<cv::Point2d> px, ref;
  for (double v = 10; v < 480; v += 47)
    for (double u = 10; u < 640; u += 53) px.emplace_back(u, v);
  cv::undistortPoints(px, ref, K, D, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-14));
  for (size_t i = 0; i < px.size(); ++i) {
    const Eigen::Vector2d uv(px[i].x, px[i].y);
    const Eigen::Vector2d xn = cam.undistortToNormalized(uv);
    EXPECT_NEAR(xn.x(), ref[i].x, 1e-7);
    EXPECT_NEAR(xn.y(), ref[i].y, 1e-7);
    // Round trip through projection.
    const Eigen::Vector2d back = cam.project(cam.unproject(uv));
    EXPECT_NEAR((back - uv).norm(), 0.0, 1e-9);
  }
}

TEST(Camera, JacobiansMatchNumericalDifferentiation) {
  const PinholeCamera cam = distortedCamera();
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-0.2, 0.2), z(0.3, 1.0);
  const double h = 1e-6;
  for (int n = 0; n < 50; ++n) {
    const Eigen::Vector3d X(u(rng), u(rng), z(rng));
    Eigen::Matrix<double, 2, 3> J, Jn;
    cam.project(X, &J);
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d d = h * Eigen::Vector3d::Unit(i);
      Jn.col(i) = (cam.project(X + d) - cam.project(X - d)) / (2 * h);
    }
    EXPECT_LT((J - Jn).norm() / J.norm(), 1e-7) << "project at " << X.transpose();

    const Eigen::Vector2d xn(X.x() / X.z(), X.y() / X.z());
    Eigen::Matrix2d Jd, Jdn;
    cam.distortNormalized(xn, &Jd);
    for (int i = 0; i < 2; ++i) {
      const Eigen::Vector2d d = h * Eigen::Vector2d::Unit(i);
      Jdn.col(i) = (cam.distortNormalized(xn + d) - cam.distortNormalized(xn - d)) / (2 * h);
    }
    EXPECT_LT((Jd - Jdn).norm(), 1e-7);

    const Eigen::Vector2d uv = cam.project(X);
    Eigen::Matrix<double, 3, 2> Ju, Jun;
    Eigen::Matrix2d Jp, Jpn;
    cam.unproject(uv, &Ju);
    cam.undistortPixel(uv, &Jp);
    const double hp = 1e-4;  // pixels
    for (int i = 0; i < 2; ++i) {
      const Eigen::Vector2d d = hp * Eigen::Vector2d::Unit(i);
      Jun.col(i) = (cam.unproject(uv + d) - cam.unproject(uv - d)) / (2 * hp);
      Jpn.col(i) = (cam.undistortPixel(uv + d) - cam.undistortPixel(uv - d)) / (2 * hp);
    }
    EXPECT_LT((Ju - Jun).norm() / Ju.norm(), 1e-6);
    EXPECT_LT((Jp - Jpn).norm() / Jp.norm(), 1e-6);
  }
}

TEST(Camera, RejectsUncalibratedAndMalformedInput) {
  CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.K = makeK(0.0, 0.0, 320, 240);  // K[0] = 0: uncalibrated
  try {
    PinholeCamera::fromCameraInfo(info);
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("K[0]"), std::string::npos) << e.what();
  }
  info.K = makeK(800, 800, 320, 240);
  info.D = {0.1, 0.2, 0.3};
  EXPECT_THROW(PinholeCamera::fromCameraInfo(info), std::invalid_argument);
  info.D = {};
  info.distortion_model = "equidistant";
  EXPECT_THROW(PinholeCamera::fromCameraInfo(info), std::invalid_argument);
  info.distortion_model = "plumb_bob";
  info.width = 0;
  EXPECT_THROW(PinholeCamera::fromCameraInfo(info), std::invalid_argument);
  info.width = 640;
  EXPECT_NO_THROW(PinholeCamera::fromCameraInfo(info));
}

// A stereo calibration's CameraInfo pair (from OpenCV's own stereoRectify) gives back the rig's extrinsics.
TEST(StereoRig, FromCameraInfoRecoversExtrinsicsOfConvergedRig) {
  const Eigen::Matrix3d K = makeK(2625.0, 2625.0, 2111.5, 1567.5);
  const double half = 0.5 * 54.4 * M_PI / 180.0;
  // Rig: left turned +half about y, right -half, centres 0.21 m apart (rig frame).
  const Eigen::Matrix3d R_rig_l = so3Exp(Eigen::Vector3d(0, half, 0));
  const Eigen::Matrix3d R_rig_r = so3Exp(Eigen::Vector3d(0, -half, 0));
  const Eigen::Vector3d c_l(-0.105, 0, 0), c_r(0.105, 0, 0);
  const Eigen::Matrix3d R_rl = R_rig_r.transpose() * R_rig_l;
  const Eigen::Vector3d t_rl = R_rig_r.transpose() * (c_l - c_r);

  cv::Mat Kc, R, T, R1, R2, P1, P2, Q;
  cv::eigen2cv(K, Kc);
  cv::eigen2cv(R_rl, R);
  cv::eigen2cv(t_rl, T);
  const cv::Mat D = cv::Mat::zeros(1, 5, CV_64F);
  cv::stereoRectify(Kc, D, Kc, D, cv::Size(4224, 3136), R, T, R1, R2, P1, P2, Q, 0, -1);
  CameraInfo li, ri;
  li.width = ri.width = 4224;
  li.height = ri.height = 3136;
  li.K = ri.K = K;
  li.D = ri.D = std::vector<double>(5, 0.0);
  cv::cv2eigen(R1, li.R);
  cv::cv2eigen(R2, ri.R);
  cv::cv2eigen(P1, li.P);
  cv::cv2eigen(P2, ri.P);
  const StereoRig rig = StereoRig::fromCameraInfo(li, ri);
  EXPECT_LT((rig.R_rl() - R_rl).norm(), 1e-9);
  EXPECT_LT((rig.t_rl() - t_rl).norm(), 1e-9);
  EXPECT_NEAR(rig.baseline(), 0.21, 1e-12);
  EXPECT_NEAR(rig.opticalAxesAngle() * 180.0 / M_PI, 54.4, 1e-9);

  // Uncalibrated right P.
  ri.P.setZero();
  EXPECT_THROW(StereoRig::fromCameraInfo(li, ri), std::invalid_argument);
}

TEST(StereoRig, RightPoseConventions) {
  const PinholeCamera cam(makeK(804, 804, 319.5, 239.5), 640, 480);
  const Eigen::Vector3d centre(0.105, 0.0, 0.015);
  const StereoRig rig = StereoRig::fromRightPose(cam, cam, Eigen::Matrix3d::Identity(), centre);
  EXPECT_TRUE(rig.rightCentre().isApprox(centre));
  EXPECT_TRUE(rig.toRight(centre).isZero(1e-15));
  EXPECT_NEAR(rig.opticalAxesAngle(), 0.0, 1e-12);
  EXPECT_THROW(StereoRig(cam, cam, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()), std::invalid_argument);
}
