// SPDX-License-Identifier: BSD-3-Clause
// process_bag's SLAM mode (process_bag_slam.cpp); the command line is process_bag.cpp's.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace tools {

struct SlamRun {
  std::string bag, out, known_map, features = "akaze", ns, input = "auto", ate_align = "auto";
  double ate_max_dt = 0.01;
  std::vector<std::string> configs;                                   //!< SLAM YAML files, in order
  std::vector<std::pair<std::string, std::string>> sets;              //!< SLAM key=value
  std::vector<std::string> front_end_configs;                         //!< front-end YAML files
  std::vector<std::pair<std::string, std::string>> front_end_sets;    //!< front-end key=value
  bool gyro = false, quiet = false, serial = false;
  int frames = -1;
  std::vector<std::string> command_line;
};

/** @brief The bag through the front-end and SLAM runners; writes the results directory.
 *  @throws std::invalid_argument (bad data or configuration), std::runtime_error (cannot write). */
int runSlam(const SlamRun& run);

}  // namespace tools
}  // namespace skin3d
