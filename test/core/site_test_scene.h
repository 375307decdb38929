// SPDX-License-Identifier: BSD-3-Clause
// A camera's organised cloud cast through a rendered limb (the truth's geometry), noise along the rays: the site
// scan's unit tests (test_site_fusion, test_site_graph) fuse such clouds.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <random>

#include "skin3d/geometry/dense_cloud.h"
#include "skin3d/sim/skin.h"

namespace skin3d {
namespace site_test {

/** width x height pixels of focal length f (px) from pose T_W_C (world: the scene's frame); the right camera's centre
 *  `baseline` m along x; points seen beyond 75 deg from the surface normal are unknown; sigma = noise (m along the
 *  ray), the noise drawn from `seed`. */
inline geometry::DenseCloud castCloud(const sim::SkinScene& scene, const Eigen::Isometry3d& T_W_C, int width, int height,
                                      double f, double baseline, double noise, std::uint64_t seed) {
  geometry::DenseCloud c;
  c.xyz.create(height, width, CV_32FC3);
  c.sigma.create(height, width, CV_32F);
  c.ray.create(height, width, CV_32FC3);
  c.right_centre = cv::Vec3d(baseline, 0, 0);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0, 1);
  sim::Hit hit;
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3d ray = Eigen::Vector3d((u - 0.5 * width) / f, (v - 0.5 * height) / f, 1).normalized();
      c.ray.at<cv::Vec3f>(v, u) = cv::Vec3f(ray.x(), ray.y(), ray.z());
      const bool ok = scene.intersect(T_W_C.translation(), T_W_C.linear() * ray, &hit);
      if (!ok || -hit.normal.dot(T_W_C.linear() * ray) < std::cos(75 * M_PI / 180)) {
        c.xyz.at<cv::Vec3f>(v, u) = cv::Vec3f(NAN, NAN, NAN);
        c.sigma.at<float>(v, u) = NAN;
        continue;
      }
      const Eigen::Vector3d X = (hit.distance + noise * n01(rng)) * ray;
      c.xyz.at<cv::Vec3f>(v, u) = cv::Vec3f(X.x(), X.y(), X.z());
      c.sigma.at<float>(v, u) = static_cast<float>(noise);
    }
  return c;
}

}  // namespace site_test
}  // namespace skin3d
