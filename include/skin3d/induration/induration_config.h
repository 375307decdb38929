/**
 * @file induration_config.h
 * @brief Dense stereo and induration parameters by name: one table shared by config/induration.yaml
 * (process_bag, dense_stereo tool), the dense_stereo / induration nodelets' ROS parameters and the tests,
 * so that a key means the same everywhere. Keys and defaults are documented in config/induration.yaml.
 *
 * Keys (flat): z_min, z_max (m, working depth range -> disparity range; both 0: searched in each pair), roi (x y w h in px, "" or
 * "0 0 0 0" = whole image), every DenseStereoOptions field but min/max_disparity and roi under its own
 * name (coarse_max_width, coarse_min_levels, sgbm_mode, block_size, p1, p2, uniqueness_ratio, lr_max_diff, speckle_window,
 * speckle_range, slant_passes, subpixel, refine_window, refine_iterations, refine_max_shift, neighbour_check, max_sigma, min_texture, min_correlation, weak_texture,
 * vertical), and every IndurationOptions field (reference_model, min_height, min_area, smoothing_px, max_smoothing_px,
 * edge_fraction, min_measured_share, exclusion_margin_px, interior_margin_px, max_height, max_incidence_deg, sor_std_ratio, ransac_threshold, fit_points, max_iterations,
 * min_reference_fraction, pasi_boundaries as a YAML list or "a b c d" in m).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <string>
#include <vector>

#include "skin3d/induration/induration.h"
#include "skin3d/stereo/dense_stereo.h"

namespace skin3d {
namespace induration {

struct PipelineOptions {
  /** m, the working depth range (rectified left camera axis) -> the disparity range. Both 0 (the default): found
   *  in each pair by stereo::searchDisparityRange, from the images and the calibration alone (any rig). */
  double z_min = 0;
  double z_max = 0;
  bool autoDepthRange() const { return z_min == 0 && z_max == 0; }
  stereo::DenseStereoOptions dense;
  IndurationOptions induration;
  void validate() const;  //!< throws std::invalid_argument naming the key
};

/** @brief Every key, in the order of config/induration.yaml. */
const std::vector<std::string>& pipelineOptionKeys();

/** @brief Current value of a key as text (numbers in full precision, booleans true/false, lists space-separated). */
std::string getPipelineOption(const PipelineOptions& options, const std::string& key);

/** @brief Sets one option from text. @throws std::invalid_argument naming the key (unknown key, bad value). */
void setPipelineOption(PipelineOptions* options, const std::string& key, const std::string& value);

/** @brief Applies a flat YAML map of the keys above over `options` (missing keys keep their values).
 *  @throws std::invalid_argument naming the file and key (unknown key, bad value, unreadable file). */
void applyPipelineOptions(PipelineOptions* options, const std::string& yaml_path);

}  // namespace induration
}  // namespace skin3d
