// SPDX-License-Identifier: BSD-3-Clause
// Ground truth moved onto a live SLAM run's first pose (see include/skin3d/slam/ground_truth.h).
#include "skin3d/slam/ground_truth.h"

#include <cmath>

namespace skin3d {
namespace slam {

bool GroundTruthAligner::add(const StampedPose& truth, double jump_back) {
  bool restarted = false;
  if (!truth_.empty() && truth.t < truth_.back().t - jump_back) {
    truth_.clear();
    anchored_ = false;
    restarted = true;
  }
  truth_.push_back(truth);
  if (truth_.size() > buffer_) truth_.pop_front();
  return restarted;
}

bool GroundTruthAligner::anchor(const StampedPose& s0) {
  if (anchored_) return false;
  const StampedPose* g0 = nullptr;
  for (const auto& g : truth_)
    if (std::abs(g.t - s0.t) <= window_ && (!g0 || std::abs(g.t - s0.t) < std::abs(g0->t - s0.t))) g0 = &g;
  if (!g0) return false;
  // T_slam_truth = T_slam_camera(t0) * T_truth_camera(t0)^-1
  q_ = (s0.q * g0->q.conjugate()).normalized();
  p_ = s0.p - q_ * g0->p;
  anchored_ = true;
  return true;
}

StampedPose GroundTruthAligner::align(const StampedPose& g) const {
  StampedPose out = g;
  out.p = p_ + q_ * g.p;
  out.q = (q_ * g.q).normalized();
  return out;
}

std::vector<StampedPose> GroundTruthAligner::alignedSince(double t0) const {
  std::vector<StampedPose> out;
  for (const auto& g : truth_)
    if (inRun(g.t, t0)) out.push_back(align(g));
  return out;
}

}  // namespace slam
}  // namespace skin3d
