/**
 * @file dense_stereo.h
 * @brief Dense matching of a rectified stereo pair with sub-pixel disparity, left-right consistency and a
 * per-pixel disparity uncertainty, and its triangulation into an organised point cloud.
 *
 * Pipeline (computeDisparity):
 *  1. Region of interest of the left rectified image (bounds the time on 13-megapixel images).
 *  2. Coarse level: the pair is halved until it is at most `coarse_max_width` wide; OpenCV's semi-global
 *     matcher (StereoSGBM) runs there on the disparity range of the working depths, left-right checked
 *     (a right-to-left pass; disagreement > `lr_max_diff` px at that level = unknown), speckles removed;
 *     then `slant_passes` passes on the right image resampled by the previous, smoothed disparity (a residual
 *     of +-16 px searched), which makes slanted and curved surfaces look fronto-parallel to SGBM's blocks.
 *  3. Refinement, coarse to fine up to full resolution: iterative local correlation fit (1-D Lucas-Kanade
 *     along the rows, plus a vertical term that absorbs residual rectification error) on locally
 *     normalised images (zero mean, unit contrast in a window: gain, offset and gamma differences
 *     between the cameras drop out). The right image is resampled at the current disparity field with
 *     bicubic interpolation each iteration, so the local slant (foreshortening between converged views)
 *     is followed exactly and there is no pixel locking (no 1/16-px quantisation, no parabola bias).
 *     A pixel whose fit moves more than `refine_max_shift` (semi-global level) px from the semi-global
 *     value, or whose window has too little texture (`min_texture`), too large a sigma (`max_sigma`) or a
 *     normalised correlation of the low-passed pair below `min_correlation` (the images do not look alike
 *     there), becomes unknown; `unknown_reason` says which, per pixel. A fit that only disagrees with the
 *     semi-global value is kept when it lies on the plane of the agreeing fits around it (`neighbour_check`): on
 *     weak texture the coarse semi-global answer has scattered, row-streaked errors where the fit is right.
 *     On a slanted field a window's a^2-weighted answer belongs to its texture's centroid, not its centre: it
 *     is moved back along the field's slope (without this, a freckle near the edge of a window on the side of
 *     a limb, where the disparity changes by ~0.8 px per row, biased the window by a pixel or more in clumps
 *     that looked like plaques).
 *  4. Uncertainty: sigma_d^2 = s^2 / sum(w * Ix^2) over the window, s^2 the window's residual variance
 *     (the Gauss-Newton covariance of the fitted shift), inflated by (1 + phi)/(1 - phi) per direction with
 *     phi = the product of the lag-1 correlations of residual and gradient in the window (an AR(1) model of
 *     the correlated samples). Neighbouring pixels share most of their window, so their errors are
 *     correlated over about the window size.
 *
 * Disparity convention: d = x_left - x_right in rectified pixels (a rig rectified with flags 0 has a
 * different cx per camera, so d may be negative; depth Z = fx B / (d - (cx_left - cx_right))).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <opencv2/core.hpp>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/geometry/camera.h"
#include "skin3d/geometry/dense_cloud.h"

namespace skin3d {
namespace stereo {

/** @brief Bad dense-stereo input (empty or mismatched images, ROI outside the image, bad option): names it. */
class DenseStereoError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct DenseStereoOptions {
  /** Disparity search range at full resolution, px (x_left - x_right). Both NaN: the caller must set
   *  them (see disparityRangeForDepth); computeDisparity throws if they are not finite and ordered. */
  double min_disparity = std::numeric_limits<double>::quiet_NaN();
  double max_disparity = std::numeric_limits<double>::quiet_NaN();
  cv::Rect roi;                  //!< region of the left rectified image to match; empty = whole image
  // --- semi-global matching (coarse level)
  int coarse_max_width = 1400;   //!< px: the pair is halved (at most 6 times) until the ROI is at most this wide
  /** The pair is halved at least this many times before the semi-global search (0 ... 6). Skin's fine texture is
   *  only a few grey levels, about the sensor noise of one pixel: at full resolution SGBM's 5-px blocks match on
   *  noise, and on skin seen obliquely by one camera (the rims of a limb) they fail in patches from which the fit
   *  cannot recover. One halving averages four pixels (the noise halved); the fit still ends at full resolution. */
  int coarse_min_levels = 1;
  std::string sgbm_mode = "sgbm_3way";  //!< "sgbm" (5 paths), "hh" (8 paths, full-image memory), "sgbm_3way"
  int block_size = 5;            //!< odd, 1 ... 11
  int p1 = 0;                    //!< smoothness penalties; 0 = 8 * block^2 and 32 * block^2 (OpenCV's advice)
  int p2 = 0;
  int uniqueness_ratio = 10;     //!< %, best cost must beat the second best by this margin
  double lr_max_diff = 1.0;      //!< px at the coarse level: left-right check tolerance
  int speckle_window = 100;      //!< px: connected blobs smaller than this are removed (0 = off)
  double speckle_range = 2.0;    //!< px: disparity step that separates blobs
  /** Further semi-global passes on the right image resampled by the previous pass's smoothed disparity, so
   *  that slanted and curved surfaces (the sides of a limb) look fronto-parallel to SGBM; 0 = none. */
  int slant_passes = 1;
  // --- sub-pixel refinement
  std::string subpixel = "lk";   //!< "lk": local correlation fit (above); "sgbm": SGBM's own 1/16-px parabola
  int refine_window = 11;        //!< odd window of the local fit, px at each level
  int refine_iterations = 3;     //!< Gauss-Newton iterations per pyramid level (more at full resolution: +1)
  double refine_max_shift = 1.0; //!< px at the semi-global level: a fit farther than this from its value = unknown
  /** A fit farther than refine_max_shift from the semi-global value is kept when it lies on the plane of the
   *  agreeing fits within refine_window px around it (within 3 sigma of their scatter and its own), and they lie on
   *  one smooth surface (their scatter within twice their stated sigma; not at a step): on weak texture the
   *  semi-global answer has scattered errors of a coarse pixel, and the fit there is right. */
  bool neighbour_check = true;
  double max_sigma = 1.0;        //!< px: pixels with a larger disparity sigma are unknown
  double min_texture = 1e-3;     //!< mean squared normalised gradient in the window below which = unknown
  /** Normalised correlation below which = unknown, of the fitted pair low-passed (Gaussian, 1 px) over a window
   *  twice refine_window: two noisy views of the same texture correlate at SNR^2 / (1 + SNR^2) only, and at
   *  full resolution skin's weak texture is about as strong as the sensor noise; low-passed, the noise is
   *  averaged and a true match reaches 0.6-0.9 while a wrong one stays below ~0.45 (skin scenes, slant-corrected
   *  fit). 0.5 = the texture's signal at least equals the noise. */
  double min_correlation = 0.5;
  /** Weak-texture mode (skin): SGBM on locally normalised images, the fit decides where SGBM left holes (there
   *  with correlation >= 0.5), islands of valid pixels removed at full resolution; the default.
   *  Off: only SGBM's answers are refined (the speckle plate's matcher). */
  bool weak_texture = true;
  bool vertical = true;          //!< also fit a vertical shift (absorbs rectification error up to ~2 px)
};

/** @brief Timing of each stage, seconds (wall clock). */
struct DenseStereoTiming {
  double prepare = 0, sgbm = 0, refine = 0, total = 0;
};

/** @brief Why a pixel of the ROI has no disparity (DisparityMap::unknown_reason). */
enum class UnknownReason : uchar {
  kKnown = 0,
  kNoSemiGlobal = 1,   //!< weak_texture off and the semi-global matcher had no answer
  kTexture = 2,        //!< too little texture in the fit's window (min_texture)
  kSigma = 3,          //!< the fit's sigma above max_sigma
  kCorrelation = 4,    //!< the views do not look alike (min_correlation; stricter in the semi-global matcher's holes)
  kDisagreement = 5,   //!< the fit moved more than refine_max_shift from the semi-global value
  kIsland = 6,         //!< a small island of valid pixels (speckle filter at full resolution)
  kBorder = 7,         //!< the matching window reaches beyond either image
  kOblique = 8,        //!< matched, but the skin faces a camera at more than max_incidence_deg (induration.h)
  kCount = 9
};

/** @brief Short name of an UnknownReason ("texture", "sigma", ...). */
const char* unknownReasonName(UnknownReason r);

struct DisparityMap {
  cv::Mat disparity;        //!< CV_32F, size of the left image, px (x_left - x_right); NaN = unknown or outside ROI
  cv::Mat sigma;            //!< CV_32F, px, 1 sigma of the disparity; NaN where unknown
  cv::Mat vertical;         //!< CV_32F, px, fitted vertical shift y_right - y_left; NaN where unknown
  cv::Rect roi;             //!< the region actually matched (the option clipped to the image)
  int coarse_scale = 1;     //!< 2^levels: the semi-global matcher's downsampling factor
  double valid_fraction = 0;  //!< known pixels / ROI pixels
  /** CV_8U, size of the left image: an UnknownReason per pixel of the ROI (0 = known), 255 outside the ROI;
   *  empty if nothing could be matched (see warnings). */
  cv::Mat unknown_reason;
  /** Share of the ROI's pixels unknown for each reason (index = UnknownReason; [0] = valid_fraction). */
  std::vector<double> unknown_share;
  std::vector<std::string> warnings;  //!< human-readable problems (no texture, little overlap, saturation...)
  DenseStereoTiming timing;
};

/**
 * @brief Dense disparity of a rectified pair (8-bit or 16-bit, grey or BGR; both the same size and type).
 * @throws DenseStereoError naming the problem (empty or mismatched images, ROI outside the image,
 *         bad range or option). A pair that cannot be matched (no texture, no overlap) is not an
 *         error: the map is all NaN and `warnings` says why.
 */
DisparityMap computeDisparity(const cv::Mat& left, const cv::Mat& right, const DenseStereoOptions& options);

/** @brief "unknown: 12.3 % correlation, 4.1 % sigma, ..." (reasons over 0.05 % of the ROI, largest first). */
std::string describeUnknown(const DisparityMap& map);

/**
 * @brief Picture of why pixels have no disparity: the left image in grey, unknown pixels coloured by reason
 * (texture blue, sigma yellow, correlation red, disagreement magenta, island cyan, no semi-global answer
 * orange, border dark grey, oblique pink), a legend in the top-left corner. Empty if the map has no unknown_reason.
 */
cv::Mat unknownReasonImage(const DisparityMap& map, const cv::Mat& left);

/**
 * @brief Full-resolution disparity range [min, max] of depths z_min ... z_max (m, along the rectified
 * left camera's axis) for a rectified pair: d = fx B / Z + (cx_left - cx_right).
 * @throws DenseStereoError unless 0 < z_min < z_max and the pair is a horizontal rectified pair.
 */
std::pair<double, double> disparityRangeForDepth(const geometry::CameraInfo& left, const geometry::CameraInfo& right,
                                                 double z_min, double z_max);

/** @brief How searchDisparityRange looks for the working range. */
struct DisparitySearchOptions {
  int width = 320;            //!< px: the pair is halved until at most this wide for the search
  double percentile = 1.0;    //!< %: the range is the shortest interval holding all but twice this share of the matches
  double depth_margin = 0.1;  //!< the depths of those percentiles widened by this share (nearer / farther)
  double min_matched = 0.02;  //!< under this share of the image matched, the search has found nothing
  double min_correlation = 0.7;  //!< a match counts when its 11 x 11 windows (reduced scale) correlate this well
};

/** @brief The working disparity range a search found (searchDisparityRange). */
struct DisparitySearch {
  bool found = false;  //!< enough of the image matched (else the range is everything searched, and `note` says so)
  double min_disparity = 0, max_disparity = 0;  //!< px at full resolution: the range to match
  double z_near = 0, z_far = 0;                 //!< m along the rectified axis (z_far may be infinite)
  double searched_min = 0, searched_max = 0;    //!< px: the disparities searched (all both images can share)
  double matched_fraction = 0;                  //!< share of the (coarse) roi matched
  int scale = 1;                                //!< downsampling of the search
  std::string note;                             //!< one line for logs and reports
};

/**
 * @brief The working disparity range of a rectified pair, found from the images and the calibration alone: the
 * pair is reduced to about `width` px and matched (the matcher's semi-global level with its own checks: left-right,
 * uniqueness, weak texture) over every disparity both images can share (|d| < 0.9 w, in front of the rig); the
 * range is the shortest interval holding 98 % of the matches (mismatches of the wide search fall outside), widened by
 * `depth_margin` in depth and 2 coarse pixels. A
 * rig at any distance, baseline and convergence thus needs no depth range set by hand; a pair that matches under
 * `min_matched` gets the whole searched range (found = false).
 * @throws DenseStereoError for empty or mismatched images, a calibration that is not a horizontal rectified pair,
 *         or images that cannot overlap.
 */
DisparitySearch searchDisparityRange(const cv::Mat& left, const cv::Mat& right, const geometry::CameraInfo& left_info,
                                     const geometry::CameraInfo& right_info, const DenseStereoOptions& base,
                                     const DisparitySearchOptions& search = DisparitySearchOptions());

/** @brief Organised point cloud of a disparity map (geometry/dense_cloud.h). */
using DenseCloud = geometry::DenseCloud;

/**
 * @brief Triangulates a disparity map with the rectified pair's projections (P of each CameraInfo; the
 * left R rotates the result back into the left optical frame).
 * @throws DenseStereoError if the map is empty or the CameraInfos do not describe a rectified pair of its size.
 */
DenseCloud triangulateDisparity(const DisparityMap& map, const geometry::CameraInfo& left,
                                const geometry::CameraInfo& right);

}  // namespace stereo
}  // namespace skin3d
