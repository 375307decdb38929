/**
 * @file stereo_landmarks.h
 * @brief MMSE triangulation of rectified stereo matches into landmarks in the left optical frame.
 *
 * The rectified cameras come from the two CameraInfo's P (left: P_l = [K_l | 0], right: P_r = [K_r | p4],
 * both in the rectified-left frame); the point is triangulated there with the core's MMSE triangulation
 * (geometry/triangulation.h; pixel noise sigma, horizontally inflated with the surface slant, see
 * TriangulateOptions::slant_noise) and rotated back to the raw left optical frame
 * with R_left^T (CameraInfo R = rectified <- raw), covariance C = R^T C_rect R.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <vector>

#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/features.h"

namespace skin3d {
namespace stereo {

struct StereoLandmark {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();     //!< m, raw left optical frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();   //!< m^2
  std::vector<float> descriptor;
  float strength = 0.0f;
  Eigen::Vector2d uv_left = Eigen::Vector2d::Zero(), uv_right = Eigen::Vector2d::Zero();  //!< rectified pixels
  float size = 0.0f;                  //!< the left keypoint's diameter, px
  double var_u = 0.0, var_v = 0.0;    //!< pixel variances used for both images (horizontal, vertical), px^2
};

struct TriangulateOptions {
  /** Pixel localisation error of a matched feature (1 sigma). 0 (the default): estimated per frame from
   *  the matches themselves (estimateLocalisationSigma), clamped to [min_sigma_px, max_sigma_px]. */
  double sigma_px = 0.0;
  double min_sigma_px = 0.05;
  double max_sigma_px = 2.0;
  /** Epipolar gate: matches whose row residual v_l - v_r is further than row_gate * sqrt(2) sigma from the
   *  median residual are dropped (0 = no gate). 3 keeps 99.7 % of true matches. */
  double row_gate = 3.0;
  /** Local disparity-consistency gate: the disparity of each match is compared with a plane fitted to the
   *  disparities of its `neighbours` nearest matches (left image); matches further than disparity_gate times
   *  max(robust spread of the neighbours' residuals, sqrt(2) sigma) are dropped as mismatches (a smooth
   *  surface has a locally smooth disparity). 0 = no gate; skipped when there are fewer than 2 * neighbours. */
  double disparity_gate = 4.0;
  int neighbours = 12;
  /** Slant-dependent disparity noise. A feature on a surface slanted by theta from the viewing direction is
   *  foreshortened differently in the two images and its horizontal localisation error grows with tan(theta).
   *  The slant of each match is measured from the local disparity gradient of a quadratic through its neighbours'
   *  disparities, tan(theta) ~ |grad d| f / d, and smoothed (the median over the match and its neighbours: one
   *  local gradient is noisy, and a noisy regressor flattens the fitted slopes); the model var(u) = sigma^2 + (b / 2) tan^2(theta) (per image, horizontal; the
   *  vertical stays sigma^2) has b fitted per frame to the plane residuals (robust, binned by slant). true:
   *  on (needs > 2 neighbours and >= 50 matches; otherwise the isotropic sigma). */
  bool slant_noise = true;
  /** Scale- and slant-dependent localisation noise. A keypoint found at a coarser scale is localised less
   *  precisely, and so is one on a slanted (foreshortened) surface: the model
   *  var = c0 + c1 (size / median size)^2 + c2 (size / median size)^2 tan^2(theta) (size = keypoint diameter, px;
   *  theta from the local disparity surface as for slant_noise, the last term only with slant_noise) is fitted
   *  per frame by least squares to the squared row residuals (a second moment: the NEES is one; slopes kept
   *  >= 0; needs >= 50 matches, otherwise the pooled sigma), clamped to [min_sigma_px, max_sigma_px]^2. With it
   *  the slant term of var(u) grows with the size too: var(u) = var + (b / 2) (size / median size)^2
   *  tan^2(theta), since the foreshortening difference between the views moves a larger keypoint further. Only
   *  with an estimated sigma (sigma_px 0). false: one sigma for every match. */
  bool size_noise = true;
  double min_depth = 0.05;        //!< m; matches triangulated nearer are dropped
  double max_depth = 5.0;         //!< m; farther ones too (tiny disparity: useless depth)
};

/**
 * @brief Localisation error (1 sigma, px) of the matches' pixels, from their row residuals: on a rectified
 * pair v_left - v_right of a true match is the difference of two localisation errors, so
 * sigma = 1.4826 MAD(v_l - v_r) / sqrt(2) (robust to a few wrong matches). It also absorbs any vertical
 * misalignment left by the calibration. NaN with fewer than 10 matches.
 */
double estimateLocalisationSigma(const std::vector<StereoMatch>& matches);

/**
 * @brief Triangulates every match; drops (and counts in *dropped) those behind the rig or out of range.
 * @param sigma_used if not null: the localisation sigma used (estimated when options.sigma_px is 0; with
 *        fewer than 10 matches the estimate falls back to 0.5 px).
 * @throws std::invalid_argument if the CameraInfo pair is not a calibrated, rectified stereo pair.
 */
std::vector<StereoLandmark> triangulateMatches(const geometry::CameraInfo& left, const geometry::CameraInfo& right,
                                               const std::vector<StereoMatch>& matches,
                                               const TriangulateOptions& options, int* dropped = nullptr,
                                               double* sigma_used = nullptr);

}  // namespace stereo
}  // namespace skin3d
