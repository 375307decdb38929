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

/** @brief Options from a flat YAML map of the keys above (missing keys keep their defaults).
 *  @throws std::invalid_argument naming the file and key (unknown key, bad value, unreadable file). */
SlamOptions loadSlamOptions(const std::string& yaml_path);

/** @brief Like loadSlamOptions, but over the given options (files can be layered: later keys win). Not validated. */
void applySlamOptions(SlamOptions* options, const std::string& yaml_path);

}  // namespace slam
}  // namespace skin3d
