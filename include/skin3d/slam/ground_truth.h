// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file ground_truth.h
 * @brief Ground truth shown beside a live SLAM run: the truth poses (world_truth <- camera, as a dataset bag
 * carries them) moved rigidly so that the one at the SLAM's first frame coincides with the SLAM's first pose.
 * A dataset's world already is its first camera frame: its poses are then unchanged.
 */
#pragma once

#include <cstddef>
#include <deque>
#include <vector>

#include "skin3d/slam/results.h"

namespace skin3d {
namespace slam {

class GroundTruthAligner {
 public:
  /** @param match_window s: the truth pose of the SLAM's first frame must lie this close to it in time
   *  @param buffer the last truth poses kept until the SLAM's first frame is known */
  explicit GroundTruthAligner(double match_window = 0.05, std::size_t buffer = 5000)
      : window_(match_window), buffer_(buffer) {}

  /** @brief Adds a truth pose. One older than the last by more than `jump_back` s is a restarted recording:
   *  the buffer and the alignment are forgotten first (return true then). */
  bool add(const StampedPose& truth, double jump_back);
  /** @brief Aligns on the SLAM's first pose if not aligned yet: needs a buffered truth pose within the match
   *  window of it (the closest is taken). @return true when the alignment was made by this call. */
  bool anchor(const StampedPose& slam_first);
  /** @brief Forgets the alignment (a SLAM reset), keeps the buffer. */
  void dropAnchor() { anchored_ = false; }
  bool anchored() const { return anchored_; }
  /** @brief The truth pose in the SLAM's world (requires anchored()). */
  StampedPose align(const StampedPose& truth) const;
  /** @brief The buffered truth poses from the match window before `t0` on, in the SLAM's world. */
  std::vector<StampedPose> alignedSince(double t0) const;
  /** @brief True when a truth pose at time t belongs to a run whose first SLAM frame was at t0. */
  bool inRun(double t, double t0) const { return t >= t0 - window_; }

 private:
  double window_;
  std::size_t buffer_;
  std::deque<StampedPose> truth_;
  bool anchored_ = false;
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();  // T_slam_truth
  Eigen::Vector3d p_ = Eigen::Vector3d::Zero();
};

}  // namespace slam
}  // namespace skin3d
