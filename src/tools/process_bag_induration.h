// SPDX-License-Identifier: BSD-3-Clause
// process_bag's induration mode (process_bag_induration.cpp).
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace tools {

struct IndurationRun {
  std::string bag, out;
  std::vector<std::string> configs;                          //!< PipelineOptions YAML files, in order
  std::vector<std::pair<std::string, std::string>> sets;     //!< key=value overrides
  int frames = -1;
  int ply_step = 2;                                          //!< surface.ply: every ply_step-th pixel
  bool quiet = false;
  bool every_frame_maps = false;                             //!< also each frame's maps, in out/frames/NNNN/
  std::string ns;                                            //!< bag namespace (ros_io::BagTopics; "" = found)
  std::vector<std::string> command_line;                     //!< for parameters.yaml
  /** --site: fuse the frames into one site (site/site_fusion.h) with the poses of `site_poses` (PoseStamped or
   *  Odometry; "" = slam/odometry); `site_sets` are the site_* keys of --set. */
  bool site = false;
  std::string site_poses;
  std::vector<std::pair<std::string, std::string>> site_sets;
};

/** @brief Measures every pair; writes the results. @throws std::invalid_argument (bad data/config),
 *  std::runtime_error (cannot write). */
int runInduration(const IndurationRun& run);

}  // namespace tools
}  // namespace skin3d
