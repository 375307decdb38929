// SPDX-License-Identifier: BSD-3-Clause
// Private helper of the core (not installed): keeps PCL's headers out of every other translation unit.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace skin3d {
namespace induration {

/** @brief RANSAC plane (PCL) of `points` with inlier distance `threshold` (m): plane = (n, d), |n| = 1.
 *  False if there are too few points or no model. Deterministic for a given input (PCL seeds its RNG). */
bool ransacPlane(const std::vector<Eigen::Vector3f>& points, double threshold, Eigen::Vector4d* plane, int* inliers);

}  // namespace induration
}  // namespace skin3d
