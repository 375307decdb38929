// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file stamped_pose.h
 * @brief A pose with its time stamp (world <- left optical frame): a geometry type shared by the SLAM's results,
 * the ground truth, the trajectory error and the tools that read trajectories.
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>

namespace skin3d {
namespace geometry {

struct StampedPose {
  double t = 0.0;  //!< s, for computing (a double holds an epoch stamp to ~0.2 us only)
  /** The exact stamp (ns since the epoch) when it came from a message header or a file; < 0: unknown (files
   *  then write t). trajectory.tum keeps every digit of it, so that tools that associate by time pair all poses. */
  std::int64_t stamp_ns = -1;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
};

}  // namespace geometry
}  // namespace skin3d
