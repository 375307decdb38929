// SPDX-License-Identifier: BSD-3-Clause
// Private helpers of the induration measurement, shared by its files (not installed):
//   induration_maps.cpp       height map, smoothing, detection threshold, incidence, footprints, regions;
//   induration_reference.cpp  reference surface fits (plane, quadratic, quadric) and their alternation;
//   induration_plaques.cpp    the plaque search;
//   induration.cpp            options, PASI class, measureInduration.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "skin3d/induration/induration.h"

namespace skin3d {
namespace induration {
namespace induration_detail {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

inline bool known(const cv::Vec3f& p) { return !std::isnan(p[0]); }

using Vec10 = Eigen::Matrix<double, 10, 1>;

/** F(y) = monomials(y) . theta, written out (the per-pixel height calls it a few times per pixel). */
inline double quadricValue(const Vec10& t, const Eigen::Vector3d& y) {
  const double a = y.x(), b = y.y(), c = y.z();
  return t(0) * a * a + t(1) * b * b + t(2) * c * c + t(3) * a * b + t(4) * a * c + t(5) * b * c + t(6) * a + t(7) * b + t(8) * c + t(9);
}

/** grad F(y) = monomialGradients(y)^T theta, written out. */
inline Eigen::Vector3d quadricGradient(const Vec10& t, const Eigen::Vector3d& y) {
  const double a = y.x(), b = y.y(), c = y.z();
  return Eigen::Vector3d(2 * t(0) * a + t(3) * b + t(4) * c + t(6), 2 * t(1) * b + t(3) * a + t(5) * c + t(7),
                         2 * t(2) * c + t(4) * a + t(5) * b + t(8));
}

/** What the measurement works on: the cloud with its outliers removed, and where it is known. */
struct Surface {
  const stereo::DenseCloud& cloud;
  const IndurationOptions& o;
  cv::Mat xyz;
  cv::Mat known_mask;
  int known_points = 0;
  /** m: the band that holds the surface's noise, max(ransac_threshold, kNoiseBand x its per-pixel noise): the RANSAC
   *  start's inlier distance, the reference fits' robust cut-off (a third of it) and the detection threshold's
   *  window. A constant band made for one rig cuts the noise of a coarser one down to its middle: the fits then
   *  follow whatever mode the start falls on, and the threshold measured inside it comes out too low. */
  double band = 0;
  double pixel_noise = 0;  //!< m: the surface's per-pixel noise (pixelNoise)
};

/** The band of `Surface::band` in units of the per-pixel noise: 3 sigma holds 99.7 % of it. */
constexpr double kNoiseBand = 3.0;

/** The reference fitted to one model by alternation, with its plaque mask and healthy-skin scale. */
struct Alternation {
  ReferenceSurface ref;
  cv::Mat plaque_mask;
  double healthy_fraction = 1.0, scale = std::numeric_limits<double>::infinity();
  double smoothing = 0;  // px: segmentation smoothing chosen for this model's heights
  cv::Mat band;          // the working band under this model's first fit
  bool ok = false;
};

/** The footprint of a plaque's region (measuredFootprint). */
struct Footprint {
  cv::Mat pixels;       //!< CV_8U in the region's box
  double open = 0;      //!< share of the pixels just outside it that are unmeasured and not a step edge's gap
};

// ---- induration_maps.cpp (each documented there)
/** Median and robust sigma (1.4826 MAD about the median) of `v` (reordered; at least one value). */
std::pair<double, double> medianAndScale(std::vector<float>& v);
int removeOutliers(cv::Mat& xyz, double std_ratio);
cv::Mat heights(const cv::Mat& xyz, const ReferenceSurface& ref);
cv::Mat smoothNaN(const cv::Mat& h, double sigma);
cv::Mat smoothFilled(const cv::Mat& h, double sigma, double gap_px);
cv::Mat footprint(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Rect& rect);
double detectionThreshold(const cv::Mat& hs, const cv::Mat& use, double min_height, double band);
double adaptiveSmoothing(const cv::Mat& h, const cv::Mat& use, double start, double limit, double min_height, double band,
                         cv::Mat* smoothed);
/** m: the widest segmentation smoothing (Gaussian sigma on the skin) that keeps 3/4 of the height at the centre of
 *  the smallest plaque (a disc of min_area): 1 - exp(-r^2 / 2 sigma^2) = 3/4. Wider smoothing spreads plaques over
 *  their surroundings and merges neighbours; min_area 20 mm^2 (r = 2.5 mm) gives 1.5 mm. */
inline double maxSmoothing(double min_area) { return std::sqrt(min_area / M_PI) / std::sqrt(2 * std::log(4.0)); }
/** m: a pixel's size on the reference (the square root of its footprint), the median over `use` (sampled). */
double pixelSize(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Mat& use);
double topHeight(const cv::Mat& mask, const cv::Mat& h, int margin, double noise_density, double* sigma);
/** The healthy skin's height noise: its robust per-pixel sigma about the heights' slow trend, and its correlation
 *  area (px^2: block^2 times the variance of block x block means over the per-pixel variance, 1 ... block^2). */
struct HeightNoise {
  double sigma = std::numeric_limits<double>::quiet_NaN();  //!< m
  double correlation_area = 1;                              //!< px^2
  int blocks = 0;                                           //!< blocks it was measured on
};
HeightNoise heightNoise(const cv::Mat& h, const cv::Mat& use, int block);
/** m: the surface's per-pixel noise before any reference: the robust sigma of the depths about their 8 px smoothing. */
double pixelNoise(const cv::Mat& xyz, const cv::Mat& known);
cv::Mat incidenceMap(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Vec3d& right_centre);
cv::Mat workingBand(const cv::Mat& ray, const ReferenceSurface& ref, const cv::Vec3d& right_centre, double max_deg);
cv::Mat holesOf(const cv::Mat& mask);
Footprint measuredFootprint(const cv::Mat& mask, const cv::Rect& box, const cv::Mat& known, const cv::Mat& h, double edge, int max_gap);
cv::Mat largeRegions(const cv::Mat& mask, const cv::Mat& ray, const ReferenceSurface& ref, double min_area);
/** Plaques are oval (round to about 3:1): a region longer than this against its width is relief or a reference
 *  that bends away from the body, not a plaque to leave out of the reference's fit. */
constexpr double kMaxPlaqueAspect = 4.0;
/** A point set's length over its width: the square root of the largest over the middle eigenvalue of the covariance
 *  of its `points` points (`sum`: their sum, `sq`: the sum of their outer products); 1 under 10 points. */
double aspectOf(const Eigen::Vector3d& sum, const Eigen::Matrix3d& sq, int points);
/** The regions of `regions` (8-connected) that look like plaques to leave out of the reference's fit: each rises
 *  above the skin around it (the median of its smoothed heights `hs` at least half `threshold` above that of a ring
 *  of known pixels beyond 2 `smoothing` px, at least 8 px wide) and is oval (the two largest extents of its points
 *  `xyz` at most kMaxPlaqueAspect : 1), or stands more than `max_height` above its ring (not skin). */
cv::Mat plaqueLikeRegions(const cv::Mat& regions, const cv::Mat& hs, const cv::Mat& xyz, const cv::Mat& known,
                          double smoothing, double threshold, double max_height);

// ---- induration_follow.cpp
/** Above this share of the working band departing from the reference, the reference does not follow the skin. */
constexpr double kMaxUnfollowedShare = 0.02;
/** Whether the reference follows the skin (res.reference_follows, unfollowed_share, unfollowed, reference_noise_ratio),
 *  after findPlaques; a warning names the regions where it does not. */
void checkReferenceFollows(const Surface& s, const cv::Mat& hs, const cv::Mat& band, IndurationResult& res);

// ---- induration_reference.cpp
/** The starting plane: RANSAC on a subsample of about 20000 points (normal towards the camera side). */
bool ransacStart(const Surface& s, ReferenceSurface* ref);
/** The reference: "auto" alternates the plane and the quadric and keeps the quadric only if it fits the healthy
 *  skin clearly better; otherwise the model asked for. `candidates`: each model tried with its scale. */
Alternation chooseReference(const Surface& s, const ReferenceSurface& start,
                            std::vector<std::pair<std::string, double>>* candidates);

// ---- induration_plaques.cpp
/** One scale of the plaque search: the heights smoothed by `smoothing` px, the detection threshold on them (m), and
 *  the fewest footprint pixels a plaque found at this scale must cover (0: min_area alone). */
struct SearchScale {
  cv::Mat hs;
  double threshold = 0, smoothing = 0;
  double min_pixels = 0;
  bool plaque_like_only = false;  //!< keep only cores that rise above a ring and are oval (plaqueLikeRegions)
};
/** The plaques (PlaqueSearch): into res.plaques, res.labels and res.warnings. The scales are searched in order: a
 *  later (wider) scale adds the plaques the earlier ones did not find (large, low plaques under their threshold). */
void findPlaques(const Surface& s, const std::vector<SearchScale>& scales, const cv::Mat& band, const cv::Mat& reach,
                 const HeightNoise& noise, IndurationResult& res);

}  // namespace induration_detail
}  // namespace induration
}  // namespace skin3d
