// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file front_end.h
 * @brief The stereo front end as one object: a raw stereo pair and its calibration -> rectification ->
 * features and left-right matching -> MMSE triangulation -> landmarks with their 3x3 covariance in the left
 * optical frame. Every door runs this class: the stereo_front_end nodelet (live) and process_bag (offline),
 * configured by one options table (frontEndOptionKeys(), the keys of config/frontend.yaml).
 */
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/features.h"
#include "skin3d/stereo/rectification.h"
#include "skin3d/stereo/stereo_landmarks.h"

namespace skin3d {
namespace stereo {

/** @brief The front end's options: the features, the triangulation and how many landmarks a frame keeps. */
struct FrontEndOptions {
  FrontEndOptions() { features.type = FeatureType::AKAZE; }  // 10 Hz on 2 cores at 640x480 (KAZE 4x4: ~3 Hz)
  FeatureOptions features;          //!< disparity_offset is set per calibration by the front end itself
  TriangulateOptions triangulate;
  int max_landmarks = 0;            //!< 0: all matches; else the strongest N per frame
  /** @throws std::invalid_argument naming the bad key and its value. */
  void validate() const;
};

/** @brief Every key of the front end's table, in the order of config/frontend.yaml. */
const std::vector<std::string>& frontEndOptionKeys();
/** @brief A key's value as text. @throws std::invalid_argument for an unknown key. */
std::string getFrontEndOption(const FrontEndOptions& options, const std::string& key);
/** @brief Sets a key from text. @throws std::invalid_argument naming the key (unknown key, bad value). */
void setFrontEndOption(FrontEndOptions* options, const std::string& key, const std::string& value);
/** @brief Every key of a flat YAML map over `options` (not validated). @throws std::invalid_argument naming the
 *  file and the key. */
void applyFrontEndOptions(FrontEndOptions* options, const std::string& yaml_path);

/** @brief The left and right rectifiers of one calibration, rebuilt when the calibration changes. */
class PairRectifier {
 public:
  /** @brief Rectifies a raw pair (mono8 or any type cv::remap takes) with these calibrations.
   *  @throws std::invalid_argument when an image's size is not its camera_info's, or the calibration is bad. */
  std::pair<cv::Mat, cv::Mat> operator()(const cv::Mat& left_raw, const cv::Mat& right_raw,
                                         const geometry::CameraInfo& left, const geometry::CameraInfo& right);

 private:
  geometry::CameraInfo left_, right_;
  std::unique_ptr<Rectifier> rect_l_, rect_r_;
};

/** @brief One frame through the front end. */
struct FrontEndFrame {
  std::vector<StereoLandmark> landmarks;  //!< left optical frame; pixels rectified
  std::vector<StereoMatch> matches;       //!< the matches that were triangulated (after max_landmarks)
  MatchStats stats;
  int dropped = 0;                        //!< matches the triangulation dropped (gates, depth range)
  double sigma_px = 0.0;                  //!< the pixel localisation error used
  cv::Mat left_rect, right_rect;          //!< the rectified pair
  double seconds = 0.0;                   //!< wall time of the whole frame
};

class FrontEnd {
 public:
  /** @throws std::invalid_argument for bad options (validate()). */
  explicit FrontEnd(const FrontEndOptions& options);
  const FrontEndOptions& options() const { return options_; }

  /** @brief A raw pair: rectification, matching, triangulation.
   *  @throws std::invalid_argument for a pair that cannot be processed (sizes, calibration), naming why. */
  FrontEndFrame process(const cv::Mat& left_raw, const cv::Mat& right_raw, const geometry::CameraInfo& left,
                        const geometry::CameraInfo& right);
  /** @brief An already rectified pair (the camera_infos are the raw calibration whose R and P rectified it). */
  FrontEndFrame processRectified(const cv::Mat& left_rect, const cv::Mat& right_rect,
                                 const geometry::CameraInfo& left, const geometry::CameraInfo& right);

 private:
  FrontEndOptions options_;
  PairRectifier rectify_;
  std::unique_ptr<StereoFeatureMatcher> matcher_;  // rebuilt when the principal-point offset changes
};

}  // namespace stereo
}  // namespace skin3d
