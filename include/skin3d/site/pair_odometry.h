// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file pair_odometry.h
 * @brief The motion of the rig between two stereo pairs from the pairs alone: their triangulated features
 * (stereo::FrontEnd's landmarks, each with its 3x3 covariance) matched by descriptor (mutual nearest neighbours,
 * Lowe's ratio), a rigid motion found by RANSAC on 3-point samples (Umeyama, no scale) with a Mahalanobis gate on
 * the 3D residual (both landmarks' covariances), then refined on the inliers by Gauss-Newton in that metric.
 *
 * The site scan uses it for the first pose of each pair when the recording has no pose of its own
 * (`~poses: images`, `--site-poses images`): the registration to the fused site then refines it.
 */
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/front_end.h"
#include "skin3d/stereo/stereo_landmarks.h"

namespace skin3d {
namespace site {

struct OdometryOptions {
  double ratio = 0.8;              //!< Lowe's ratio: nearest / second-nearest descriptor distance below this
  int ransac_iterations = 400;
  /** Mahalanobis gate on a match's 3D residual with the two landmarks' covariances: chi^2(3) at 99.7 %. */
  double gate_chi2 = 14.16;
  int min_inliers = 12;            //!< fewer: no motion (the pair is not placed)
  void validate() const;           //!< throws std::invalid_argument naming the option
};

struct RelativeMotion {
  bool ok = false;
  std::string why;                 //!< when not ok: why (too few features, matches or inliers)
  /** T_a_b: a point in pair b's left optical frame -> pair a's (pair a's pose times this is pair b's). */
  Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();  //!< [rotation (rad), translation (m)]
  int features_a = 0, features_b = 0, matches = 0, inliers = 0;
  double rms_mahalanobis = 0;      //!< RMS of the inliers' normalised residuals (about 1 when the covariances hold)
};

/** @brief The motion between pairs a and b (deterministic for a given seed). */
RelativeMotion relativeMotion(const std::vector<stereo::StereoLandmark>& a, const std::vector<stereo::StereoLandmark>& b,
                              const OdometryOptions& options, std::uint64_t seed = 1);

/** @brief The front end's options for the odometry: AKAZE keeping the strongest 2000 features of each image whatever
 *  their contrast (a detector threshold of 1e-5: skin's texture is faint, the globe's default of 1e-3 finds a
 *  handful of features on it). */
stereo::FrontEndOptions odometryFrontEndOptions();

/** @brief A pair's triangulated features for the odometry: the pair reduced by a whole factor to at most 1400 px
 *  wide (the features' scale space on 13 megapixels costs seconds; their triangulation at that size still places the
 *  motion to tens of micrometres), through `front_end`; the landmarks in the raw left optical frame, in metres.
 *  @throws std::invalid_argument for a pair the front end cannot process. */
std::vector<stereo::StereoLandmark> odometryFeatures(stereo::FrontEnd* front_end, const cv::Mat& left_raw,
                                                     const cv::Mat& right_raw, const geometry::CameraInfo& left,
                                                     const geometry::CameraInfo& right);

/** @brief A camera_info for the image resized by `s` (pixel centres kept: c' = s (c + 0.5) - 0.5). */
geometry::CameraInfo scaledCameraInfo(const geometry::CameraInfo& c, double s);

/** @brief The residual of one match, r = X_a - (R X_b + t), and its derivative with respect to a perturbation of
 *  the motion, R -> Exp(dphi) R, t -> t + dt ([dphi, dt]); exposed for the Jacobian test. */
Eigen::Vector3d motionResidual(const Eigen::Isometry3d& T_a_b, const Eigen::Vector3d& X_a, const Eigen::Vector3d& X_b,
                               Eigen::Matrix<double, 3, 6>* J);

}  // namespace site
}  // namespace skin3d
