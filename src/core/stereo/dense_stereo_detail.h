// SPDX-License-Identifier: BSD-3-Clause
// Private helpers of the dense matcher, shared by its files (not installed):
//   dense_stereo_coarse.cpp  image preparation, the crops and semi-global matching at the coarse level;
//   dense_stereo_refine.cpp  the coarse-to-fine local correlation fit and its per-pixel judgement;
//   dense_stereo.cpp         option checks, computeDisparity, the unknown-pixel diagnostics, triangulation.
#pragma once

#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {
namespace stereo {
namespace dense_detail {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/** The matcher's working frame: the crops around the roi and their pyramids (coarse level last). */
struct Crops {
  cv::Rect roi;          // in the image
  int d_min = 0;         // the right crop is shifted by d_min: crop disparity d_c = d - d_min in [0, range]
  int range = 0;
  int levels = 0;        // pyramid levels below full resolution; s = 2^levels
  int s = 1;
  int num_disp = 0;      // SGBM's search at the coarse level
  int pad = 0;           // the left crop starts pad columns before the roi (SGBM leaves them unknown)
  int margin_y = 8;
  std::vector<cv::Mat> pl, pr;  // grey float pyramids of the left and right crops
};

/** The fine-level answer over the crop from column c0 on: disparity, vertical shift, sigma, validity and why not. */
struct FineMaps {
  cv::Mat d, v, sigma, valid, reason;
  int c0 = 0;
};

// ---- dense_stereo_coarse.cpp (each documented there)
cv::Mat normaliseLocal(const cv::Mat& img, double s);
cv::Mat fillHoles(const cv::Mat& d);
int sgbmMode(const std::string& m);
Crops prepareCrops(const cv::Mat& left, const cv::Mat& right, const DenseStereoOptions& o, DisparityMap& out);
cv::Mat coarseSemiGlobal(const Crops& c, const DenseStereoOptions& o);
FineMaps fromSemiGlobal(const Crops& c, const cv::Mat& dc);
std::string nothingToMatch(const Crops& c, const cv::Mat& dc, const DenseStereoOptions& o);

// ---- dense_stereo_refine.cpp
FineMaps fitCoarseToFine(const Crops& c, const cv::Mat& dc, const DenseStereoOptions& o);
void removeIslands(FineMaps& f, const DenseStereoOptions& o, int s);
long keepFitsOnTheirNeighbours(const cv::Mat& d, const cv::Mat& sigma, cv::Mat& valid, cv::Mat& reason, int radius);

}  // namespace dense_detail
}  // namespace stereo
}  // namespace skin3d
