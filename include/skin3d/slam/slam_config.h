/**
 * @file slam_config.h
 * @brief The SLAM's parameters by name: one table shared by config/slam.yaml (process_bag), the eskf_slam
 * nodelet's ROS parameters and the tests, so a key means the same everywhere. Keys and defaults are
 * documented in config/slam.yaml.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "skin3d/slam/slam_system.h"

namespace skin3d {
namespace slam {

/** @brief Every key setSlamOption accepts, in the order of config/slam.yaml. */
const std::vector<std::string>& slamOptionKeys();

/** @brief Current value of a key as text (numbers in full precision, booleans true/false, enums by name). */
std::string getSlamOption(const SlamOptions& options, const std::string& key);

/** @brief Sets one option from text. @throws std::invalid_argument naming the key for an unknown key or a
 *  value of the wrong kind (the options are validated as a whole by SlamOptions::validate()). */
void setSlamOption(SlamOptions* options, const std::string& key, const std::string& value);

/** @brief What a run whose measurements come through the stereo image front end sets over config/slam.yaml
 *  (process_bag with image input, and the eskf_slam nodelet with ~front_end set, as rig.launch and
 *  replay_globe.launch images:=true do; this list is the model's one statement):
 *  - the front end's measurement model: its errors are correlated over frames (a feature keeps most of its
 *    localisation error, and the calibration's small non-rigid error, from one frame to the next), so only
 *    measurement_white_fraction = 0.1 of each covariance is white and the rest is the landmark random walk
 *    landmark_walk_{x,y,z} (m per sqrt(s) along the camera's axes, the same for every landmark); values from
 *    the front end's tracks on two exact-calibration renders (seeds 1, 2; docs/slam.md);
 *  - for binary descriptors (features other than "kaze": AKAZE, ORB, one float 0/1 per bit, L2 = sqrt(Hamming)),
 *    max_descriptor_distance 5.5 (Hamming <= 30): slam.yaml's 0.3 is for KAZE's unit-norm floats.
 *  Returns (key, value) pairs in the order to apply them; config files and --set given by the user win. */
std::vector<std::pair<std::string, std::string>> imageInputOptions(const std::string& features);

/** @brief Options from a flat YAML map of the keys above (missing keys keep their defaults).
 *  @throws std::invalid_argument naming the file and key (unknown key, bad value, unreadable file). */
SlamOptions loadSlamOptions(const std::string& yaml_path);

/** @brief Like loadSlamOptions, but over the given options (files can be layered: later keys win). Not validated. */
void applySlamOptions(SlamOptions* options, const std::string& yaml_path);

}  // namespace slam
}  // namespace skin3d
