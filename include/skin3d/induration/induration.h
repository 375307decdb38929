/**
 * @file induration.h
 * @brief Induration measurement on an organised dense cloud: outlier removal, healthy-skin reference
 * surface, height map, plaque segmentation, per-plaque statistics and the PASImeter induration class.
 *
 * Steps (measureInduration):
 *  1. Statistical outlier removal on the organised cloud (pixel neighbours instead of a k-d tree: the mean
 *     distance of a point to its known 8 neighbours; beyond mean + `sor_std_ratio` std of the cloud's
 *     distances = outlier; the same rule as PCL's StatisticalOutlierRemoval).
 *  2. Reference surface: a RANSAC plane (PCL SACSegmentation on a subsample) gives the start; then
 *     alternate (a) a robust (Tukey) least-squares fit of the reference model ("plane"; "quadric": an implicit
 *     quadric surface, Taubin fit, heights = distances to it, for a limb at any pose, its first (unweighted) fit on
 *     the largest connected surface only, not the background or another body in view; "quadratic": height over
 *     the plane as a quadric of the in-plane coordinates) to the points not marked as plaque, and (b) marking
 *     as plaque the regions of at least a quarter of `min_area` in the working band that stand above the
 *     detection threshold (see 4; dilated by `exclusion_margin_px`), until the mask stops changing. (Excluding
 *     every noisy pixel above the threshold instead would bias the fit downwards.) Only plaque-like regions are
 *     left out of the fit: ones that rise above the skin around them (their median at least half the threshold
 *     above that of a ring beyond the smoothing's reach) and are oval (at most 4:1 on the skin), or stand higher
 *     than `max_height` (not skin). A long region is the reference bending away from the body (or a fold): left
 *     out, the fit loses the skin that holds it and bends further (on a 2 MP rig, 2.7 % of the band excluded in
 *     the first pass grew to 60 % in ten). "auto" alternates for the plane and the quadric and keeps the quadric
 *     only if it halves the robust scatter of the healthy skin's heights.
 *     The noise band: the RANSAC inlier distance, the fits' robust cut-off (Tukey, c = 4.685 x a third of it)
 *     and the detection threshold's window are max(`ransac_threshold`, 3 x the surface's per-pixel noise), the
 *     noise measured first on the depths about their own 8 px smoothing: a band made for the thesis' rig cut
 *     a coarser rig's noise (0.3 mm per pixel on a 2 MP rig at 0.4 m) down to its middle.
 *  3. Height map: signed distance above the reference (m), smoothed with a Gaussian of `smoothing_px`
 *     (NaN-aware) for segmentation only; statistics use the unsmoothed heights.
 *  4. Plaques, searched within the working band: the pixels whose ray meets the reference where it faces both
 *     cameras within `max_incidence_deg` (the reference's geometry, not the measured points'; outside it no depth
 *     is reported: IndurationResult::oblique). Connected
 *     regions (8-connected) of the smoothed map above the detection threshold (`min_height`, or 3 robust sigma
 *     of the smoothed healthy-skin heights where the surface is noisier), at least `min_area` on the reference
 *     (20 mm^2: a lesion under 5 mm across is a papule, not a plaque); each
 *     region's boundary is then re-drawn at `edge_fraction` of its own median height (taken from 2 sigma of the
 *     segmentation smoothing inside the region, or its inner half: the smoothing spreads a tall plaque's region
 *     over a skirt of healthy skin up to 2 sigma wide, which would pull the median down) (a half-height boundary:
 *     the blur of the matching window moves it neither in nor out; where the matcher left the step edge
 *     unknown, the gap is bridged from both sides so the boundary falls in its middle), holes filled; largest
 *     cores first, the box around a core widened while the region reaches its border, and a core whose region
 *     reaches a plaque drawn already is that plaque's shoulder (no valley separates them), not a plaque. A region
 *     that rises above the skin around it (its border's profile) by less than the detection threshold and by less
 *     than that skin stands above the reference is a bump on raised skin (a low plaque the noise lifts above the
 *     threshold in pieces): it is drawn again at half its top's height, where the profile measured raised skin
 *     around it, as the plaque it is part of (or ignored, with a warning). Ignored,
 *     with a warning: regions whose surroundings within the band are less than 80 % known (the matcher's gaps of a
 *     few px closed first; the edge of the measured surface, islands of mismatches), with less than
 *     `min_measured_share` of their footprint measured (scattered matches), whose footprint fills less than half
 *     the ellipse of its second moments (pieces strung along an edge or scattered: a plaque is one patch of skin),
 *     smaller than 4 correlation areas of the height noise with a top not 3 stated sigma above the detection
 *     threshold (one mismatch of the matcher looks the same), or higher than `max_height`.
 *  5. Per plaque: centroid (mean of its points), area (sum of each pixel's footprint on the reference
 *     (its tangent plane at the plaque for the quadric): the ray's intersection with it, |n . (dX/du x dX/dv)|;
 *     a low plaque's, outlined at the detection threshold, scaled to the area within half its rise from the skin
 *     around to its top, from the border's profile),
 *     the share of its pixels that have a height (a warning under 90 %), volume (the footprint's and the skirt's
 *     outside the outline, from the border's profile), and over its interior (eroded by
 *     `interior_margin_px`: the matching window turns the edge into a ramp about a window wide) mean / std
 *     height, max height (the 99th percentile: one noisy pixel must not set it); the top height: the heights
 *     binned by their distance from the outline, the bins' medians from 2 `interior_margin_px` in (half way to the
 *     centre on a small plaque) fitted with
 *     a + b (d_max - d)^2 and read at the deepest point (flat or domed tops; the mean of the interior still reads
 *     a blurred ramp on a small, tall plaque), and the PASImeter class of the top height.
 *
 * PASImeter induration classes (thesis §1, app. B: five classes 0-4, 0.25 mm apart): class k is the card
 * step k * 0.25 mm that the plaque matches best, i.e. the boundaries are half-way between the steps:
 * 0: h < 0.125 mm, 1: 0.125-0.375, 2: 0.375-0.625, 3: 0.625-0.875, 4: >= 0.875 mm
 * (`pasi_boundaries`, configurable).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {
namespace induration {

/** @brief A bad option (names it). Problems with the data are warnings in the result, not exceptions. */
class IndurationError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct IndurationOptions {
  /** "auto" (default): the simplest of plane and quadric that fits the healthy skin (see ReferenceSurface);
   *  "plane", "quadric" (implicit quadric surface: a limb, cylinder, cone, ellipsoid, at any pose) or
   *  "quadratic" (a height field quadratic over the plane: gently curved skin seen face-on). */
  std::string reference_model = "auto";
  double min_height = 0.05e-3;       //!< m: a point this far above the reference belongs to a plaque
  /** m^2: smaller regions are not plaques. A lesion under 5 mm across (a 20 mm^2 disc) is a papule in
   *  dermatology, not a plaque; on noisy skin the matcher's noise makes raised blobs of 4-20 mm^2. */
  double min_area = 20e-6;
  double max_height = 5e-3;          //!< m: higher regions are not skin plaques (ignored with a warning)
  /** deg: plaques are searched only where the reference surface faces both cameras within this angle (the
   *  working band; beyond it one view is too foreshortened to measure reliably). 90 = everywhere. */
  double max_incidence_deg = 60.0;
  double smoothing_px = 2.0;         //!< Gaussian sigma for segmentation, px (0 = none): the smallest tried
  /** px: the segmentation smoothing grows from smoothing_px (sqrt 2 steps) until 3 robust sigma of the smoothed
   *  healthy heights are below 1.5 min_height, up to this (noisy skin needs more than a speckle plate), and up to
   *  the smoothing on the skin that keeps 3/4 of the height of the smallest plaque (a disc of min_area: 1.5 mm
   *  for 20 mm^2, about the smoothing that gives that plaque the best signal to noise), whichever is smaller.
   *  Wider smoothing spread plaques over their surroundings and merged them with the reference's departures.
   *  The search then runs again at a wider scale, for large plaques lower than that threshold: the smoothing grows
   *  on from there the same way, up to this, and a plaque it adds must be wider than that smoothing (a disc of
   *  radius sigma: the noise's excursions above the threshold cover 0.4 of it on average), oval, rising above the
   *  skin around it and measured over 80 % of its footprint. */
  double max_smoothing_px = 24.0;
  double edge_fraction = 0.5;        //!< plaque boundary at this fraction of its median height
  /** A raised region is a plaque only if at least this share of its footprint has a height; sparser ones (where
   *  the matcher answered for a few scattered pixels, mostly at the working band's edge) are listed in a warning. */
  double min_measured_share = 0.5;
  int exclusion_margin_px = 5;       //!< plaque mask dilation when fitting the reference
  int interior_margin_px = 8;        //!< heights are measured this far inside the plaque boundary (matching-window ramp)
  double sor_std_ratio = 3.0;        //!< statistical outlier removal threshold (std of neighbour distances)
  /** m: the noise band's least width (RANSAC inlier distance, 3 x the fits' robust scale, the threshold's window);
   *  3 x the surface's measured per-pixel noise where that is wider. */
  double ransac_threshold = 0.2e-3;
  int fit_points = 200000;           //!< at most this many points (a regular subsample) in each fit
  int max_iterations = 10;           //!< reference / plaque-mask alternations
  double min_reference_fraction = 0.15;  //!< healthy skin must be at least this fraction of the known points
  std::vector<double> pasi_boundaries = {0.125e-3, 0.375e-3, 0.625e-3, 0.875e-3};  //!< m, increasing
  void validate() const;             //!< throws IndurationError naming the option
};

/** @brief The healthy-skin reference: a plane n.x + d = 0 (n unit, towards the camera) and, for the
 *  quadratic model, a height offset c0 + c1 u + c2 v + c3 u^2 + c4 u v + c5 v^2 along n, with (u, v) the
 *  in-plane coordinates of x about `origin` along `e1`, `e2`. */
struct ReferenceSurface {
  // Model "quadric": the implicit surface F(x) = 0, F = m(y)^T coefficients, m = (y1^2, y2^2, y3^2, y1 y2, y1 y3,
  // y2 y3, y1, y2, y3, 1), y = (x - q_centre) / q_scale; the height is the signed distance to it (the foot
  // point by Newton steps along the gradient), positive on the camera's side (q_sign).
  Eigen::Matrix<double, 10, 1> coefficients = Eigen::Matrix<double, 10, 1>::Zero();
  Eigen::Vector3d q_centre = Eigen::Vector3d::Zero();
  double q_scale = 1.0, q_sign = 1.0;
  /** Every model tried by "auto" with the robust scale (1.4826 MAD, m) of its healthy-skin residuals. */
  std::vector<std::pair<std::string, double>> candidates;
  /** @brief Unit normal of the surface near x (towards the camera) and the tangent plane's d (n.x + d = 0). */
  Eigen::Vector4d tangentPlane(const Eigen::Vector3d& x) const;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double d = 0;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero(), e1 = Eigen::Vector3d::UnitX(), e2 = Eigen::Vector3d::UnitY();
  Eigen::Matrix<double, 6, 1> quadric = Eigen::Matrix<double, 6, 1>::Zero();  //!< m; zero for the plane model
  std::string model = "plane";
  double rms = 0;          //!< m, RMS of the healthy-skin points about the surface
  int points = 0;          //!< healthy-skin points used
  /** @brief Signed height of x above the surface (m, positive towards the camera). */
  double height(const Eigen::Vector3d& x) const;
  /** @brief The plane as (n, d) for messages. */
  Eigen::Vector4d plane() const { return Eigen::Vector4d(normal.x(), normal.y(), normal.z(), d); }
};

struct Plaque {
  int id = 0;                  //!< 1, 2, ... in order of decreasing area
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  //!< m, frame of the cloud
  double area = 0;             //!< m^2 on the reference, within the outline (a low plaque's: within half its rise)
  /** m: the top's height, the level the height profile reaches at the plaque's centre (flat or domed top; see the
   *  file comment); the PASImeter class is this height's, as the card is matched to a plaque's elevation. */
  double top_height = 0;
  double mean_height = 0, max_height = 0, std_height = 0;  //!< m, over the interior
  double mean_height_sigma = 0;  //!< m, standard error of the mean height (from the per-point sigmas)
  /** m: standard uncertainty of top_height: the plaque's own height noise (its interior's scatter about a
   *  quadratic, counted with the noise's correlation area) over the heights the top rests on and, added in
   *  quadrature, surround_offset beyond what the ring's own noise explains */
  double top_height_sigma = 0;
  /** m: median height of the healthy skin in a ring around the plaque (0 where the reference follows the skin
   *  there; its departure is part of the top's uncertainty) */
  double surround_offset = 0;
  int pasi_class = 0;
  int pixels = 0;
  double measured_fraction = 0;  //!< share of the plaque's footprint that has a height (the rest: matcher gaps)
  /** share of the footprint's outline that borders unmeasured skin (not a step edge's gap with measured skin
   *  across it): above 0.1 the plaque may extend there (a warning says so), and its area is what was measured */
  double outline_unmeasured = 0;
  /** m^3: sum of height x footprint over the measured pixels / measured_fraction, plus the skirt outside the
   *  outline (the border profile's rise over the skin around, ring by ring while it stands 2 errors above it, at
   *  most 3 border widths beyond the half-rise crossing) */
  double volume = 0;
  /** m on the skin: how wide the lower part of the border is, from 20 to 50 % of the rise from the skin around to
   *  the top (on a plaque's border ramp of at most 2 mm, blurred by the matcher; healthy relief rises from a longer
   *  foot: above 1.75 times a plaque's widest a raised region is relief, not a plaque). NaN where the profile was
   *  too short to tell. */
  double border_width = std::numeric_limits<double>::quiet_NaN();
  cv::Rect bbox;               //!< in the image
};

struct IndurationResult {
  ReferenceSurface reference;
  cv::Mat height_map;          //!< CV_32F, m above the reference (unsmoothed), NaN unknown
  cv::Mat labels;              //!< CV_32S: 0 healthy or unknown, k = plaque id k
  std::vector<Plaque> plaques;
  std::vector<std::string> warnings;  //!< e.g. "no healthy skin left to fit the reference"
  bool reference_ok = false;   //!< false: no height map (too few points or no healthy skin)
  int known_points = 0, outliers_removed = 0;
  double smoothing_px = 0;         //!< px: the segmentation smoothing chosen (see max_smoothing_px)
  double band_fraction = 1;        //!< share of the known points within the working band (max_incidence_deg)
  double detection_threshold = 0;  //!< m: max(min_height, 3 robust sigma of the smoothed healthy-skin heights)
  /** The wider scale's smoothing (px) and detection threshold (m), and the smallest plaque it can add (m^2, a
   *  disc of radius sigma on the skin); all 0 when the search ran at one scale (the first scale's threshold
   *  is min_height already, or max_smoothing_px leaves no wider one). */
  double wide_smoothing_px = 0, wide_detection_threshold = 0, wide_min_area = 0;
  /** Whether the reference follows the skin: false when more than 2 % of the working band (outside the plaques) lies
   *  beyond the detection threshold above or below it in regions of at least min_area; no plaque can be measured
   *  there, and a warning names the regions. */
  bool reference_follows = true;
  double unfollowed_share = 0;     //!< that share of the working band
  cv::Mat unfollowed;              //!< CV_8U: 255 where it does not follow (empty: nowhere)
  /** CV_8U: 255 on raised regions that are relief, not plaques (Plaque::border_width: a smooth rise, or two tops);
   *  part of `unfollowed` (empty: none) */
  cv::Mat relief;
  /** CV_8U: 255 on the measured points whose reference faces a camera at more than max_incidence_deg (empty when
   *  that is 90 or no reference was fitted). Their heights are NaN in height_map: matched so obliquely, skin's
   *  depths are wrong by pixels of disparity, far more than their stated sigma (docs/validation.md), and
   *  FrameMeasurer takes them out of the disparity map and the cloud too (UnknownReason::kOblique). */
  cv::Mat oblique;
  /** The healthy skin's robust scatter about the reference over the matcher's median stated depth sigma (1: the
   *  reference explains the skin down to the noise; skin relief and model error raise it). */
  double reference_noise_ratio = std::numeric_limits<double>::quiet_NaN();
  double height_noise = std::numeric_limits<double>::quiet_NaN();  //!< m: the healthy skin's robust per-pixel height sigma
  double noise_correlation_px2 = 1;  //!< px^2: the area over which that noise is correlated (the matcher's window)
};

/** @brief PASImeter class of a height (m) with the given increasing boundaries (m). */
int pasiClass(double height, const std::vector<double>& boundaries);

/**
 * @brief Measures the plaques in an organised cloud (see the file comment).
 * @throws IndurationError for bad options only; empty or hopeless data give warnings and reference_ok false.
 */
IndurationResult measureInduration(const stereo::DenseCloud& cloud, const IndurationOptions& options);

}  // namespace induration
}  // namespace skin3d
