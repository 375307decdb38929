// SPDX-License-Identifier: BSD-3-Clause
// Induration measurement: see include/skin3d/induration/induration.h.
#include "skin3d/induration/induration.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "../common/text.h"
#include "induration_detail.h"

namespace skin3d {
namespace induration {

using common::num;
using namespace induration_detail;  // NOLINT(build/namespaces): the private helpers of the induration files

void IndurationOptions::validate() const {
  if (reference_model != "plane" && reference_model != "quadratic" && reference_model != "quadric" && reference_model != "auto")
    throw IndurationError("reference_model '" + reference_model + "' is not auto, plane, quadric or quadratic");
  if (!(min_height > 0)) throw IndurationError("min_height " + num(min_height) + " m must be > 0");
  if (!(min_area >= 0)) throw IndurationError("min_area " + num(min_area) + " m^2 must be >= 0");
  if (!(smoothing_px >= 0) || smoothing_px > 50) throw IndurationError("smoothing_px " + num(smoothing_px) + " must be 0 ... 50");
  if (!(max_smoothing_px >= smoothing_px) || max_smoothing_px > 100)
    throw IndurationError("max_smoothing_px " + num(max_smoothing_px) + " must be smoothing_px ... 100");
  if (!(edge_fraction > 0 && edge_fraction < 1)) throw IndurationError("edge_fraction " + num(edge_fraction) + " must be in (0, 1)");
  if (!(min_measured_share >= 0 && min_measured_share <= 1))
    throw IndurationError("min_measured_share " + num(min_measured_share) + " must be 0 ... 1");
  if (exclusion_margin_px < 0 || exclusion_margin_px > 200)
    throw IndurationError("exclusion_margin_px " + std::to_string(exclusion_margin_px) + " must be 0 ... 200");
  if (!(sor_std_ratio > 0)) throw IndurationError("sor_std_ratio " + num(sor_std_ratio) + " must be > 0");
  if (!(ransac_threshold > 0)) throw IndurationError("ransac_threshold " + num(ransac_threshold) + " m must be > 0");
  if (!(max_height > min_height)) throw IndurationError("max_height " + num(max_height) + " m must be > min_height");
  if (!(max_incidence_deg > 0) || max_incidence_deg > 90)
    throw IndurationError("max_incidence_deg " + num(max_incidence_deg) + " must be in (0, 90]");
  if (interior_margin_px < 0 || interior_margin_px > 200)
    throw IndurationError("interior_margin_px " + std::to_string(interior_margin_px) + " must be 0 ... 200");
  if (fit_points < 100) throw IndurationError("fit_points " + std::to_string(fit_points) + " must be >= 100");
  if (max_iterations < 1) throw IndurationError("max_iterations " + std::to_string(max_iterations) + " must be >= 1");
  if (!(min_reference_fraction > 0 && min_reference_fraction < 1))
    throw IndurationError("min_reference_fraction " + num(min_reference_fraction) + " must be in (0, 1)");
  if (pasi_boundaries.size() != 4) throw IndurationError("pasi_boundaries must hold 4 heights (classes 0-4)");
  for (std::size_t i = 0; i < pasi_boundaries.size(); ++i)
    if (!(pasi_boundaries[i] > 0) || (i > 0 && !(pasi_boundaries[i] > pasi_boundaries[i - 1])))
      throw IndurationError("pasi_boundaries must be positive and increasing (m)");
}

int pasiClass(double height, const std::vector<double>& boundaries) {
  int k = 0;
  for (double b : boundaries)
    if (height >= b) ++k;
  return k;
}

IndurationResult measureInduration(const stereo::DenseCloud& cloud, const IndurationOptions& o) {
  o.validate();
  IndurationResult res;
  if (cloud.xyz.empty() || cloud.xyz.type() != CV_32FC3) {
    res.warnings.push_back("empty point cloud: nothing to measure");
    return res;
  }
  if (cloud.ray.size() != cloud.xyz.size() || cloud.ray.type() != CV_32FC3)
    throw IndurationError("the cloud has no viewing ray per pixel (DenseCloud::ray): triangulate it with triangulateDisparity");
  Surface s{cloud, o, cloud.xyz.clone(), cv::Mat(), 0};
  res.labels = cv::Mat(s.xyz.size(), CV_32S, cv::Scalar(0));
  res.height_map = cv::Mat(s.xyz.size(), CV_32F, cv::Scalar(kNaN));
  res.outliers_removed = removeOutliers(s.xyz, o.sor_std_ratio);
  s.known_mask.create(s.xyz.size(), CV_8U);
  for (int y = 0; y < s.xyz.rows; ++y)
    for (int x = 0; x < s.xyz.cols; ++x) s.known_mask.at<uchar>(y, x) = known(s.xyz.at<cv::Vec3f>(y, x)) ? 255 : 0;
  res.known_points = s.known_points = cv::countNonZero(s.known_mask);
  if (res.known_points < 1000) {
    res.warnings.push_back("too few surface points (" + std::to_string(res.known_points) +
                           ") to fit a reference: check the dense matching (texture, overlap, working range)");
    return res;
  }

  s.pixel_noise = pixelNoise(s.xyz, s.known_mask);
  s.band = std::max(o.ransac_threshold, kNoiseBand * s.pixel_noise);

  // ---- the reference: a RANSAC plane to start, then alternation (robust fit on the healthy points, plaque
  // mask from the heights) for the plane and the quadric
  ReferenceSurface start;
  if (!ransacStart(s, &start)) {
    res.warnings.push_back("no plane found in the surface points (RANSAC): no reference");
    return res;
  }
  std::vector<std::pair<std::string, double>> candidates;
  const Alternation best = chooseReference(s, start, &candidates);
  if (!best.ok && best.healthy_fraction >= o.min_reference_fraction) {
    res.warnings.push_back("the reference surface could not be fitted to the surface points");
    return res;
  }
  if (best.healthy_fraction < o.min_reference_fraction) {
    res.warnings.push_back("no healthy skin left to fit the reference: only " +
                           num(std::round(1000 * best.healthy_fraction) / 10) + " % of the points are not raised (minimum " +
                           num(100 * o.min_reference_fraction) + " %); widen the region of interest to include skin around the plaques");
    return res;
  }
  res.reference = best.ref;
  res.reference.candidates = candidates;
  res.reference_ok = true;
  res.height_map = heights(s.xyz, res.reference);
  res.smoothing_px = best.smoothing;
  const cv::Mat hs = smoothFilled(res.height_map, best.smoothing, o.interior_margin_px);

  // ---- the working band: where the reference faces both cameras within max_incidence_deg
  const cv::Mat inc = incidenceMap(cloud.ray, res.reference, cloud.right_centre);
  const cv::Mat reach = o.max_incidence_deg >= 90 ? cv::Mat(inc.size(), CV_8U, cv::Scalar(255)) : (inc <= o.max_incidence_deg);
  const cv::Mat band = reach & s.known_mask;
  res.band_fraction = res.known_points > 0 ? cv::countNonZero(band) / static_cast<double>(res.known_points) : 1.0;
  if (res.band_fraction < 0.995)
    res.warnings.push_back(num(std::round(1000 * (1 - res.band_fraction)) / 10) + " % of the measured surface faces a camera at more than " +
                           num(o.max_incidence_deg) + " deg (the sides of a limb): not measured there (depths matched so "
                           "obliquely are unreliable); turn the skin towards the rig to measure there");

  // ---- plaques: regions above the detection threshold, re-drawn at edge_fraction of their median height
  const cv::Mat healthy = s.known_mask & ~best.plaque_mask & band;
  res.detection_threshold = detectionThreshold(hs, healthy, o.min_height, s.band);
  std::vector<SearchScale> scales{{hs, res.detection_threshold, best.smoothing, 0.0, false}};
  // ---- a wider scale for large plaques under that threshold (the first scale's smoothing is bounded by the
  // smallest plaque's size): the smoothing grows on, as far as max_smoothing_px, until the noise allows
  // min_height again; what it adds must be wider than its noise's bumps, oval and rise above its surroundings
  // (only where the noise keeps the first scale from the 2 min_height, 0.1 mm, a plaque must have to count)
  if (res.detection_threshold > 2 * o.min_height && o.max_smoothing_px >= 1.5 * best.smoothing) {
    cv::Mat unused;
    const double wide = adaptiveSmoothing(res.height_map, healthy, 1.5 * best.smoothing, o.max_smoothing_px, o.min_height,
                                          s.band, &unused);
    const cv::Mat hw = smoothFilled(res.height_map, wide, o.interior_margin_px);
    const double tw = detectionThreshold(hw, healthy, o.min_height, s.band);
    if (tw < 0.8 * res.detection_threshold) {  // (a wider scale that lowers the threshold by less adds next to nothing)
      // wider than the smoothing itself (a disc of radius sigma): the noise's excursions above 3 sigma of its
      // smoothed heights cover 0.4 of that on average (4 pi sigma^2 / 9, Adler's mean excursion area), 90 % of them
      // less than 0.7-0.9 (simulated: white noise blurred by 1.5 px, smoothed by 8, 12 and 24 px)
      const double r = wide;
      scales.push_back({hw, tw, wide, M_PI * r * r, true});
      const double pixel_m = pixelSize(cloud.ray, res.reference, healthy);
      res.wide_smoothing_px = wide;
      res.wide_detection_threshold = tw;
      res.wide_min_area = M_PI * r * r * pixel_m * pixel_m;
    }
  }
  if (res.detection_threshold > 2 * o.min_height)  // the noise, not min_height, sets the smallest plaque found
    res.warnings.push_back("the height noise of this view only lets plaques higher than " +
                           num(std::round(res.detection_threshold * 1e5) / 100) + " mm be found (3 robust sigma of the "
                           "healthy skin's heights after " + num(best.smoothing) + " px of smoothing; min_height is " +
                           num(o.min_height * 1e3) + " mm)" +
                           (res.wide_smoothing_px > 0
                                ? ", and plaques of more than " + num(std::round(res.wide_min_area * 1e6)) + " mm^2 higher than " +
                                      num(std::round(res.wide_detection_threshold * 1e5) / 100) + " mm (after " +
                                      num(std::round(res.wide_smoothing_px * 10) / 10) + " px)"
                                : std::string()) +
                           ": lower ones cannot be told from the noise (a nearer working "
                           "distance, a longer baseline or a finer camera lowers it)");
  // the height noise the plaques' uncertainties rest on, in blocks of 4 matcher ramps (the noise's correlation
  // reaches about one matching window), on the healthy skin within the noise band (as the detection threshold: the
  // background or mismatches matched centimetres off the skin would widen it many times)
  const HeightNoise noise = heightNoise(res.height_map, healthy & (cv::abs(res.height_map) < s.band),
                                        std::max(8, 4 * o.interior_margin_px));
  res.height_noise = noise.sigma;
  res.noise_correlation_px2 = noise.correlation_area;
  findPlaques(s, scales, band, reach, noise, res);
  checkReferenceFollows(s, hs, band, res);
  if (o.max_incidence_deg < 90) {
    // not reported: the sides (the reference faces a camera at more than max_incidence_deg) and the points past its
    // silhouette within max_height of it (the rim and what was matched as the rim: wrong by pixels); the background
    // past the silhouette stays
    res.oblique = cv::Mat(inc.size(), CV_8U, cv::Scalar(0));
    for (int y = 0; y < inc.rows; ++y) {
      const float *i = inc.ptr<float>(y), *h = res.height_map.ptr<float>(y);
      const uchar* k = s.known_mask.ptr<uchar>(y);
      uchar* ob = res.oblique.ptr<uchar>(y);
      for (int x = 0; x < inc.cols; ++x)
        if (k[x] && (i[x] > o.max_incidence_deg || (std::isnan(i[x]) && std::fabs(h[x]) <= o.max_height))) ob[x] = 255;
    }
    res.height_map.setTo(kNaN, res.oblique);
  }
  if (res.plaques.empty())
    res.warnings.push_back(res.reference_follows
                               ? "no plaque stands more than " + num(o.min_height * 1e3) + " mm above the reference"
                               : "no plaque found where the reference follows the skin (" +
                                     num(std::round(1000 * (1 - res.unfollowed_share)) / 10) +
                                     " % of the working band); the rest cannot be measured");
  return res;
}

}  // namespace induration
}  // namespace skin3d
