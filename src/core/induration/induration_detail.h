// SPDX-License-Identifier: BSD-3-Clause
// Private helpers of the induration measurement, shared by its files (not installed):
//   induration_maps.cpp       height map, smoothing, detection threshold, incidence, footprints, regions;
//   induration_ignored.cpp    the warnings listing the raised regions found not to be plaques;
//   induration_reference.cpp  reference surface fits (plane, quadratic, quadric) and their alternation;
//   induration_plaques.cpp    the plaque search;
//   induration_relief.cpp     the shape of a raised region's border: a plaque's or healthy relief's;
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

/** Pixels of `m` over the area of the ellipse of its second moments (4 pi sqrt of their eigenvalues' product: a
 *  filled ellipse's own area); 0 for fewer than 3 pixels or a degenerate (straight) set. */
double ellipseFill(const cv::Mat& m);
/** The 8-connected regions of `mask` of at least `pixels` pixels. */
cv::Mat largeEnough(const cv::Mat& mask, double pixels);
/** Robust per-pixel sigma of the heights `h` (m) of a plaque's interior (footprint `fp`, the same size, eroded by
 *  `margin` px) about their own shape (a least-squares quadratic in the pixel coordinates: a flat or domed top,
 *  tilted; its 6 parameters take a negligible share of the noise); NaN under 100 heights. */
double interiorNoise(const cv::Mat& h, const cv::Mat& fp, int margin);

// ---- induration_relief.cpp
/** m: half of a plaque's border ramp at its widest. Psoriatic plaques are sharply demarcated: the skin rises to the
 *  plateau within about 2 mm (the skin generator draws 0.5-1.5 mm), and the half-height outline lies mid-ramp. */
constexpr double kHalfRamp = 1.0e-3;
/** A psoriatic plaque is plateau-like and sharply demarcated: across its border the skin rises to the plateau
 *  within about 2 mm (kHalfRamp), a step, blurred by the matcher. The lower part of the step, from 20 to 50 % of the
 *  rise from the skin around to the top, lies on that step as long as the plateau's edge stands at least half the
 *  top (flat tops, and domes up to half the height), and spans 0.21 of the ramp (a smooth step) widened by the blur:
 *  20-50 % of a step blurred by a Gaussian of sigma s spans 0.84 s, and s follows from the height noise's
 *  correlation area (4 pi s^2). Healthy relief (a fold, a ridge, a nose, a tendon) rises smoothly from a long foot:
 *  a Gaussian cross-section of sigma w spans 0.62 w there, 1.2-2.5 mm for the 2-4 mm of a nose's side or a fold.
 *  A raised region whose 20-50 % rise spans more than this factor times a plaque's widest is relief, not a plaque.
 *  The factor leaves room for what the model leaves out: a matcher's window straddling a step widens it more than
 *  its noise's correlation says, and an outline that is not round mixes distances; on the rendered limb's plaques
 *  (two full-resolution sweeps, about 100 profiles) the span reached 1.4 times the model, relief 1.9-3.7 times it. */
constexpr double kMaxBorderFactor = 1.75;
/** A raised region that falls inward by more than this share of its rise after its highest level has two tops
 *  (the two sides of a fold, two ridges): a plaque's top is one plateau, flat or domed. */
constexpr double kMaxInwardDip = 0.5;
/** The border's shape is judged only where the rise stands this many standard errors of the profile above the
 *  profile's noise: a low plaque on a noisy rig keeps the benefit of the doubt. */
constexpr double kBorderClear = 10.0;

/** The shape of a raised region's border (PlaqueSearch::borderShape). */
struct BorderShape {
  double width = std::numeric_limits<double>::quiet_NaN();  //!< m on the skin: 20 -> 50 % of the rise
  double limit = std::numeric_limits<double>::quiet_NaN();  //!< m: the widest a plaque's border may be
  double dip = 0;      //!< share of the rise lost inward of the highest level
  double rise = 0;     //!< m: top level over the skin around
  double reach = 0;    //!< m: from the outline out to where the rise falls under the detection threshold
  double pixel = 0;    //!< m: the image's finest pixel on the skin there (along its shorter axis)
  double base = 0;           //!< m: the skin around's level
  double rise_error = std::numeric_limits<double>::quiet_NaN();  //!< m: the profile's standard error (median bin)
  double skirt_volume = 0;  //!< m^3: the rise over the skin around, outside the outline, out to where it ends
  /** the profile from outside in to its highest bin: (signed distance to the outline in grid px, inside > 0; the
   *  3-bin running mean, m) */
  std::vector<std::pair<double, double>> profile;
  std::vector<double> cells;  //!< grid cells by signed distance, bins of cell_bin px from -cells_reach (known or not)
  double cell_bin = 1, cells_reach = 0;
  /** The area within the profile's first crossing of `level` (m, scanning inward) over the area within the outline;
   *  NaN when the profile does not cross it. */
  double areaRatioAt(double level) const;
  bool clear = false;  //!< the rise stands kBorderClear profile errors above the noise
  bool relief() const { return clear && (width > limit || dip > kMaxInwardDip); }
};
/** The image's pixels on the tangent plane `local` at the centre of `box` (m per px, in an orthonormal basis of the
 *  plane: the rays of `ray` through the centre and through points `step` px beside it, met with the plane). */
Eigen::Matrix2d pixelOnPlane(const cv::Mat& ray, const cv::Rect& box, const ReferenceSurface& local, int step);
/** The shape of a raised region's border. `cls` (CV_8U): a window around the region, 1 inside it, 2 on the skin
 *  around that may be used, 0 neither; `heights` (CV_32F, m, NaN unknown) there; `J`: the window's pixels on the
 *  reference's tangent plane (pixelOnPlane). The window is resampled (nearest pixel) onto a square grid on that plane
 *  (an oblique view's pixels are longer across the limb than along it), and the heights are binned by their signed
 *  distance to the outline there, from as far outside as the region is deep (the foot of a bell lies outside a
 *  half-height outline) to its deepest point. The levels are the median of the outer half of the outside bins (the
 *  skin around) and the highest of the inside bins (3-bin running means); the crossings of 20 and 50 % of the rise
 *  are the first, scanning inward. The skirt: the bins outside the outline, scanning outward until the rise falls
 *  within 2 errors or 3 border widths beyond the half-rise crossing, each bin's rise over the skin around times its
 *  ring's area (every grid cell at that distance on the skin around that may be used, measured or not). `noise`:
 *  the healthy skin's height noise (the bins' errors, the blur); `threshold`: the detection threshold (m; the
 *  skirt's reach). */
BorderShape borderShape(const cv::Mat& cls, const cv::Mat& heights, const Eigen::Matrix2d& J, const HeightNoise& noise,
                        double threshold);

/** A plaque's footprint fills at least half the ellipse of its second moments (ellipseFill). */
constexpr double kMinEllipseFill = 0.5;
/** Under this many correlation areas of the height noise (about the fit's window one level below full resolution,
 *  where the matcher starts), with a top not 3 stated sigma above the threshold, a region is what one mismatch makes:
 *  a window-sized patch on a wrong disparity (rig study: mismatches of 1.2-4.2 areas, tops stated 0.3-1 mm). */
constexpr double kMismatchAreas = 4.0;

// ---- induration_ignored.cpp
/** The raised regions the plaque search found not to be plaques, by kind: (size in px, description) each. */
struct IgnoredRegions {
  using List = std::vector<std::pair<double, std::string>>;
  List at_edge;    //!< at the edge of the measured surface
  List sparse;     //!< too few heights
  List scattered;  //!< scattered pieces
  List relief;     //!< shaped like relief
  List low;        //!< the interior not above the threshold
  List on_raised;  //!< a bump on raised skin
  List mismatch;   //!< no larger or clearer than a mismatch
};
/** One warning per kind of ignored region (a limb's silhouette can leave dozens), the three largest named;
 *  `threshold`: the first scale's detection threshold (m). */
void warnIgnored(double threshold, double min_measured_share, double correlation_area, IgnoredRegions* ignored,
                 std::vector<std::string>* warnings);

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
