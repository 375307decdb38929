/**
 * @file induration_io.h
 * @brief Results of an induration measurement for people and programs: induration.yaml (docs/design.md,
 * "Results of an offline run"), the false-colour height map with a scale bar in mm, and the coloured
 * surface mesh (PLY).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <opencv2/core.hpp>
#include <limits>
#include <string>
#include <vector>

#include "skin3d/induration/induration.h"
#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {
namespace induration {

/** @brief One measured frame as induration.yaml lists it. */
struct FrameRecord {
  double stamp = 0;               //!< s
  IndurationResult result;        //!< height_map / labels may be empty (not written to YAML)
  double valid_fraction = 0;      //!< known disparity / ROI
  double z_near = 0, z_far = 0;   //!< m: the working depth range matched (searched or set; z_far may be infinite)
  double min_disparity = 0, max_disparity = 0;  //!< px: its disparity range
  bool range_searched = false;    //!< the range was searched in this pair (z_min = z_max = 0)
  /** px: the vertical disparity (y_right - y_left) the matcher fitted on the measured surface, its median and robust
   *  spread (1.4826 MAD): rectification error, unsynchronised or rolling-shutter frames show here (NaN: none). */
  double vertical_median = std::numeric_limits<double>::quiet_NaN();
  double vertical_spread = std::numeric_limits<double>::quiet_NaN();
  double seconds = 0;             //!< processing time of the frame
};

/**
 * @brief Writes induration.yaml: header (units: mm, mm^2; frame; source; options incl. the PASI boundaries),
 * per frame the reference plane (n, d in m), its RMS (mm), warnings and per plaque id, centroid (m),
 * area (mm^2), mean / max / std height (mm), sigma of the mean (mm), PASI class; and, over frames, per
 * plaque (matched across frames by the nearest centroid within 5 mm of frame 0's) the mean and std of
 * each figure: the repeatability.
 * @throws std::runtime_error naming the file if it cannot be written.
 */
void writeInduration(const std::string& path, const std::vector<FrameRecord>& frames, const IndurationOptions& options,
                     const std::string& frame_id, const std::string& source);

/**
 * @brief False-colour picture of a height map (CV_32F, m, NaN unknown): heights 0 ... `max_mm` (0 = 1.25 x the
 * highest plaque's max height, or with no plaque the 99th percentile of the known heights; at least 0.25 mm)
 * in a perceptual colour map, unknown pixels dark
 * grey, plaque outlines (labels CV_32S, may be empty) in white with their id and mean height in mm, and a
 * vertical colour scale bar labelled in mm; `unfollowed` (CV_8U, may be empty): hatched in magenta, where the reference
 * does not follow the skin. Wide maps are shrunk to at most `max_width` px.
 * @return 8-bit BGR image.
 */
cv::Mat heightMapImage(const cv::Mat& height_map, const cv::Mat& labels, const std::vector<Plaque>& plaques,
                       double max_mm = 0.0, int max_width = 1600, const cv::Mat& unfollowed = cv::Mat());

/**
 * @brief Writes the organised cloud as a binary little-endian PLY triangle mesh (vertex x y z float in m,
 * red green blue uchar from `colour`, the left rectified image (grey or BGR, same size) or white when
 * empty; two triangles per 2x2 cell of known pixels, every `step` px, skipping cells whose depth
 * jumps more than 20 x the cell size).
 * @throws std::runtime_error naming the file if it cannot be written.
 */
void writeSurfacePly(const std::string& path, const stereo::DenseCloud& cloud, const cv::Mat& colour, int step = 1);

}  // namespace induration
}  // namespace skin3d
