// SPDX-License-Identifier: BSD-3-Clause
// Robust sphere fit: exact recovery, noise with outliers on a band (the SLAM map of the globe orbit),
// covariance against Monte Carlo scatter, bad input.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "skin3d/geometry/sphere_fit.h"

using skin3d::geometry::fitSphere;
using skin3d::geometry::SphereFit;

namespace {
const Eigen::Vector3d kCentre(0.01, -0.02, 0.6);
const double kRadius = 0.2;

// Points on a latitude band [-45, -5] deg around the sphere (like the orbit's map), radial noise sigma,
// a fraction of outliers displaced radially by 2..20 mm.
std::vector<Eigen::Vector3d> band(int n, double sigma, double outlier_fraction, std::mt19937& rng,
                                  std::vector<bool>* is_outlier = nullptr) {
  std::uniform_real_distribution<double> lon(-M_PI, M_PI), slat(std::sin(-45 * M_PI / 180), std::sin(-5 * M_PI / 180));
  std::uniform_real_distribution<double> u(0, 1), big(0.002, 0.02);
  std::normal_distribution<double> g(0, sigma);
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < n; ++i) {
    const double la = std::asin(slat(rng)), lo = lon(rng);
    const Eigen::Vector3d d(std::cos(la) * std::cos(lo), std::cos(la) * std::sin(lo), std::sin(la));
    double r = kRadius + g(rng);
    const bool out = u(rng) < outlier_fraction;
    if (out) r += (u(rng) < 0.5 ? -1 : 1) * big(rng);
    if (is_outlier) is_outlier->push_back(out);
    p.push_back(kCentre + r * d);
  }
  return p;
}
}  // namespace

TEST(SphereFit, ExactPointsGiveTheSphere) {
  std::mt19937 rng(1);
  const SphereFit f = fitSphere(band(200, 0.0, 0.0, rng));
  EXPECT_LT((f.centre - kCentre).norm(), 1e-9);
  EXPECT_NEAR(f.radius, kRadius, 1e-9);
  EXPECT_LT(f.rms_inliers, 1e-9);
  EXPECT_EQ(f.inliers, 200);
}

TEST(SphereFit, OutliersAreRejectedAndTheCovarianceMatchesTheScatter) {
  // 200 Monte Carlo fits of 1000 points, sigma 0.1 mm, 5 % outliers of 2-20 mm.
  std::mt19937 rng(7);
  const int runs = 200;
  double nees = 0.0, rms = 0.0;
  int flagged = 0, outliers = 0, false_flags = 0;
  for (int k = 0; k < runs; ++k) {
    std::vector<bool> truth;
    const auto p = band(1000, 1e-4, 0.05, rng, &truth);
    const SphereFit f = fitSphere(p);
    Eigen::Vector4d e;
    e << f.centre - kCentre, f.radius - kRadius;
    nees += e.dot(f.covariance.ldlt().solve(e));
    rms += f.rms_inliers;
    for (size_t i = 0; i < p.size(); ++i) {
      outliers += truth[i];
      flagged += truth[i] && !f.inlier[i];
      false_flags += !truth[i] && !f.inlier[i];
    }
  }
  nees /= runs;
  // Mean NEES of a 4-dof estimate over 200 runs: chi2(800)/200, 95 % interval [3.62, 4.40].
  EXPECT_GT(nees, 3.62);
  EXPECT_LT(nees, 4.40);
  EXPECT_NEAR(rms / runs, 1e-4, 1e-5);                 // inlier RMS = the generator's sigma
  EXPECT_GT(flagged, 0.9 * outliers);                  // outliers >= 2 mm = 20 sigma: nearly all flagged
  EXPECT_LT(false_flags, 0.001 * runs * 1000);         // Tukey at 4.685 sigma flags ~3e-6 of the inliers
}

TEST(SphereFit, BadInputNamesTheProblem) {
  EXPECT_THROW(fitSphere({Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()}),
               std::invalid_argument);
  std::vector<Eigen::Vector3d> plane;
  for (int i = 0; i < 10; ++i) plane.emplace_back(i, i * i % 7, 0.0);
  try {
    fitSphere(plane);
    FAIL() << "coplanar points accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("coplanar"), std::string::npos) << e.what();
  }
  std::mt19937 rng(3);
  auto p = band(50, 1e-4, 0.0, rng);
  p[7].x() = std::nan("");
  try {
    fitSphere(p);
    FAIL() << "NaN accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("point 7"), std::string::npos) << e.what();
  }
}
