/**
 * @file features.h
 * @brief Feature detection and left-right matching on a rectified stereo pair (thesis §6.2.4, §6.2.6).
 *
 * KAZE with 64-element float descriptors (the thesis' choice) by default; AKAZE and ORB as options.
 * Matching on RECTIFIED images: for each left feature, candidates in the right image lie on the same
 * row (|v_l - v_r| <= max_row_diff) with a disparity d = u_l - u_r in [min_disparity, max_disparity]
 * (disparity measured after removing the principal-point offset `disparity_offset` = cx_l - cx_r of the
 * rectified P matrices, so d is the geometric disparity). Among candidates: Lowe's ratio test (best /
 * second-best descriptor distance < ratio) and, with cross_check, the left feature must also be the
 * best left candidate of its right match. Each match gets a strength in (0, 1]:
 * 1 - best / second_best (the ratio-test margin; 1 when there is only one candidate).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace skin3d {
namespace stereo {

enum class FeatureType { KAZE, AKAZE, ORB };
/** @throws std::invalid_argument listing the known names ("kaze", "akaze", "orb"). */
FeatureType parseFeatureType(const std::string& name);
std::string featureTypeName(FeatureType type);

struct FeatureOptions {
  FeatureType type = FeatureType::KAZE;
  double threshold = 0.001;       //!< detector response threshold (KAZE/AKAZE); ORB: FAST threshold if > 1
  int max_features = 3000;        //!< strongest features kept per image (0 = all)
  int octaves = 4;                //!< KAZE/AKAZE scale-space octaves (OpenCV's default 4; fewer is faster)
  int octave_layers = 4;          //!< KAZE/AKAZE sublevels per octave (default 4)
  double ratio = 0.8;             //!< Lowe's ratio test
  double max_row_diff = 1.5;      //!< px, epipolar (row) tolerance on rectified images
  double min_disparity = 0.5;     //!< px, geometric disparity (after the principal-point offset)
  double max_disparity = 1e9;     //!< px
  double disparity_offset = 0.0;  //!< px, cx_left - cx_right of the rectified P matrices
  bool cross_check = true;
  /** A match is dropped when either keypoint lies closer to its image's border than border_margin times the
   *  larger of the two keypoint diameters: the support of the correspondence is cut there, and the true partner
   *  of a left feature near the right image's edge may lie where the detector cannot see it, leaving a wrong
   *  single candidate (0 = keep all; needs ImageFeatures::image_size, which detect() sets). */
  double border_margin = 1.0;
  /** @throws std::invalid_argument naming a bad field and its value. */
  void validate() const;
};

/** @brief Detected features of one image. */
struct ImageFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;            //!< one row per keypoint (CV_32F for KAZE/AKAZE-float, CV_8U for binary)
  cv::Size image_size;            //!< of the image they were found in (set by detect(); empty: unknown)
};

/** @brief One left-right correspondence on the rectified pair. */
struct StereoMatch {
  Eigen::Vector2d left = Eigen::Vector2d::Zero();   //!< rectified left pixel
  Eigen::Vector2d right = Eigen::Vector2d::Zero();  //!< rectified right pixel
  std::vector<float> descriptor;  //!< the left feature's descriptor (binary descriptors: one float per bit)
  float strength = 0.0f;          //!< ratio-test margin in (0, 1]
  float size = 0.0f;              //!< keypoint diameter, px (scale)
  int octave = 0;
};

struct MatchStats {
  int left_features = 0, right_features = 0;
  int candidates = 0;             //!< left features with at least one row/disparity candidate
  int ratio_rejected = 0, cross_rejected = 0;
  int border_rejected = 0;        //!< matches dropped by FeatureOptions::border_margin
  int matches = 0;
};

class StereoFeatureMatcher {
 public:
  /** @throws std::invalid_argument for bad options. */
  explicit StereoFeatureMatcher(const FeatureOptions& options);
  const FeatureOptions& options() const { return options_; }

  /** @brief Detects and describes features of an 8-bit grayscale image. Empty image: no features. */
  ImageFeatures detect(const cv::Mat& gray) const;
  /** @brief Matches left to right features under the rectified-pair constraints. */
  std::vector<StereoMatch> match(const ImageFeatures& left, const ImageFeatures& right, MatchStats* stats = nullptr) const;
  /** @brief detect() on both images (in parallel) and match(). */
  std::vector<StereoMatch> process(const cv::Mat& left_rect, const cv::Mat& right_rect, MatchStats* stats = nullptr) const;

 private:
  FeatureOptions options_;
};

/** @brief Side-by-side debug image (BGR) of the rectified pair with the matches drawn, coloured by strength. */
cv::Mat drawStereoMatches(const cv::Mat& left_rect, const cv::Mat& right_rect, const std::vector<StereoMatch>& matches);

}  // namespace stereo
}  // namespace skin3d
