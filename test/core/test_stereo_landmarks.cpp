// SPDX-License-Identifier: BSD-3-Clause
// Triangulation of rectified matches back into the raw left optical frame.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/stereo/rectification.h"
#include "skin3d/stereo/stereo_landmarks.h"

using namespace skin3d;

namespace {
Eigen::Matrix3d makeK(double f, double cx, double cy) {
  Eigen::Matrix3d K;
  K << f, 0, cx, 0, f, cy, 0, 0, 1;
  return K;
}

// A raw rig (slightly rotated right camera, distortion) and its rectification.
struct Fixture {
  geometry::StereoRig rig;
  stereo::RectifiedPair pair;
  Fixture(bool converged) {
    const geometry::PinholeCamera cam(makeK(800.0, 319.5, 239.5), 640, 480, {-0.1, 0.02, 0.0, 0.0, 0.0});
    if (converged) {
      const double a = 30.0 * M_PI / 180.0;
      rig = geometry::StereoRig::fromRightPose(cam, cam, geometry::so3Exp(Eigen::Vector3d(0, -a, 0)),
                                               geometry::so3Exp(Eigen::Vector3d(0, -a / 2, 0)) * Eigen::Vector3d(0.15, 0, 0));
      std::vector<Eigen::Vector3d> poi;
      for (double x = -0.03; x <= 0.031; x += 0.03)
        for (double y = -0.03; y <= 0.031; y += 0.03) poi.push_back(Eigen::Vector3d(0.075 + x, y, 0.28));
      pair = stereo::rectifyStereo(rig, poi);
    } else {
      rig = geometry::StereoRig::fromRightPose(cam, cam, geometry::so3Exp(Eigen::Vector3d(0.003, -0.01, 0.002)),
                                               Eigen::Vector3d(0.105, 0.0, 0.015));
      pair = stereo::rectifyStereo(rig);
    }
  }
  // A rectified match of a left-frame point.
  stereo::StereoMatch match(const Eigen::Vector3d& X) const {
    stereo::StereoMatch m;
    m.left = stereo::projectRectified(pair, X, false);
    m.right = stereo::projectRectified(pair, X, true);
    m.descriptor = {1.0f, 2.0f};
    m.strength = 0.5f;
    return m;
  }
};

void expectRoundTrip(const Fixture& f, const std::vector<Eigen::Vector3d>& pts) {
  std::vector<stereo::StereoMatch> matches;
  for (const auto& X : pts) matches.push_back(f.match(X));
  int dropped = -1;
  stereo::TriangulateOptions o;
  o.sigma_px = 0.5;  // the default of CameraObservation, which the direct triangulation below uses
  const auto lms = stereo::triangulateMatches(f.pair.left, f.pair.right, matches, o, &dropped);
  ASSERT_EQ(lms.size(), pts.size());
  EXPECT_EQ(dropped, 0);
  for (size_t i = 0; i < pts.size(); ++i) {
    EXPECT_LT((lms[i].position - pts[i]).norm(), 1e-9);
    // The covariance is that of the raw rig's own MMSE triangulation of the same (noise-free) point.
    Eigen::Vector2d uvl, uvr;
    ASSERT_TRUE(f.rig.project(pts[i], &uvl, &uvr));
    const auto direct = geometry::triangulateMmse([&] {
      std::vector<geometry::CameraObservation> v(2);
      v[0].K = f.pair.left.P.leftCols<3>();
      v[0].R = f.pair.left.R;
      v[1].K = f.pair.right.P.leftCols<3>();
      v[1].R = f.pair.right.R * f.rig.R_rl();
      v[1].t = f.pair.right.R * f.rig.t_rl();
      v[0].uv = lms[i].uv_left;
      v[1].uv = lms[i].uv_right;
      return v;
    }());
    ASSERT_TRUE(direct.ok);
    EXPECT_LT((lms[i].covariance - direct.C).norm() / direct.C.norm(), 1e-6);
    EXPECT_EQ(lms[i].descriptor.size(), 2u);
    EXPECT_FLOAT_EQ(lms[i].strength, 0.5f);
  }
}
}  // namespace

TEST(StereoLandmarks, RectifiedMatchesTriangulateToTheRawLeftFrame) {
  const Fixture f(false);
  std::vector<Eigen::Vector3d> pts;
  for (double x = -0.1; x <= 0.2; x += 0.05)
    for (double y = -0.1; y <= 0.1; y += 0.05) pts.emplace_back(x, y, 0.4 + 0.2 * x);
  expectRoundTrip(f, pts);
}

TEST(StereoLandmarks, ConvergedRigRectifiedWithPrincipalPointOffset) {
  const Fixture f(true);
  EXPECT_FALSE(f.pair.zero_disparity);
  std::vector<Eigen::Vector3d> pts;
  for (double x = -0.02; x <= 0.021; x += 0.01)
    for (double y = -0.02; y <= 0.021; y += 0.01) pts.emplace_back(0.075 + x, y, 0.28 + x);
  expectRoundTrip(f, pts);
}

TEST(StereoLandmarks, NoisyMatchesAreConsistentWithTheirCovariance) {
  const Fixture f(false);
  std::mt19937 rng(9);
  std::normal_distribution<double> n(0.0, 0.5);
  double nees = 0.0;
  int count = 0;
  for (int k = 0; k < 3000; ++k) {
    const Eigen::Vector3d X(0.05 + 0.1 * std::sin(k), 0.05 * std::cos(3.0 * k), 0.45);
    auto m = f.match(X);
    m.left += Eigen::Vector2d(n(rng), n(rng));
    m.right += Eigen::Vector2d(n(rng), n(rng));
    stereo::TriangulateOptions o;
    o.sigma_px = 0.5;
    const auto l = stereo::triangulateMatches(f.pair.left, f.pair.right, {m}, o);
    ASSERT_EQ(l.size(), 1u);
    const Eigen::Vector3d e = l[0].position - X;
    nees += e.dot(l[0].covariance.inverse() * e);
    ++count;
  }
  EXPECT_NEAR(nees / count, 3.0, 0.2);  // mean of chi2(3) over 3000 samples: 3 +- 0.045 (1 sigma)
}

TEST(StereoLandmarks, LocalisationSigmaIsEstimatedFromTheRowResiduals) {
  const Fixture f(false);
  std::mt19937 rng(4);
  for (double sigma : {0.1, 0.3, 0.8}) {
    std::normal_distribution<double> n(0.0, sigma);
    std::vector<stereo::StereoMatch> ms;
    for (int k = 0; k < 2000; ++k) {
      auto m = f.match(Eigen::Vector3d(0.05 + 0.1 * std::sin(k), 0.05 * std::cos(3.0 * k), 0.45));
      m.left += Eigen::Vector2d(n(rng), n(rng));
      m.right += Eigen::Vector2d(n(rng), n(rng));
      if (k % 50 == 0) m.right.y() += 7.0;  // a few wrong matches
      ms.push_back(m);
    }
    EXPECT_NEAR(stereo::estimateLocalisationSigma(ms), sigma, 0.06 * sigma);
    double used = 0.0;
    stereo::triangulateMatches(f.pair.left, f.pair.right, ms, {}, nullptr, &used);  // sigma_px 0: estimated
    EXPECT_NEAR(used, sigma, 0.06 * sigma);
  }
  EXPECT_TRUE(std::isnan(stereo::estimateLocalisationSigma({})));
}

// Keypoints found at coarser scales are localised worse (TriangulateOptions::size_noise): with the noise of each
// match proportional to its size, the per-frame fit gives each size its own variance, and the landmarks of every
// size agree with their covariances; one pooled sigma would be too small for the large ones and too big for the
// small ones. Points on a fronto-parallel plane (no slant).
TEST(StereoLandmarks, LocalisationNoiseGrowsWithKeypointSize) {
  const Fixture f(false);
  std::mt19937 rng(11);
  std::normal_distribution<double> n(0.0, 1.0);
  const double sizes[3] = {4.0, 8.0, 16.0}, per_px = 0.015;  // sigma = 0.06, 0.12, 0.24 px
  std::vector<stereo::StereoMatch> ms;
  std::vector<Eigen::Vector3d> truth;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 30; ++j) {
      const Eigen::Vector3d X(-0.12 + 0.3 * i / 39.0, -0.1 + 0.2 * j / 29.0, 0.45);
      auto m = f.match(X);
      m.size = static_cast<float>(sizes[(i + j) % 3]);
      const double sg = per_px * m.size;
      m.left += sg * Eigen::Vector2d(n(rng), n(rng));
      m.right += sg * Eigen::Vector2d(n(rng), n(rng));
      ms.push_back(m);
      truth.push_back(X);
    }
  for (bool model : {true, false}) {
    stereo::TriangulateOptions o;
    o.size_noise = model;
    o.disparity_gate = 0.0;  // keep every match: the landmarks stay in the order of the matches
    o.row_gate = 0.0;
    const auto l = stereo::triangulateMatches(f.pair.left, f.pair.right, ms, o);
    ASSERT_EQ(l.size(), ms.size());
    double nees[3] = {0, 0, 0};
    int count[3] = {0, 0, 0};
    for (size_t k = 0; k < l.size(); ++k) {
      const int c = l[k].size < 6 ? 0 : (l[k].size < 12 ? 1 : 2);
      if (model) {
        EXPECT_NEAR(std::sqrt(l[k].var_v), per_px * l[k].size, 0.25 * per_px * l[k].size) << l[k].size;
      }
      const Eigen::Vector3d e = l[k].position - truth[k];
      nees[c] += e.dot(l[k].covariance.inverse() * e);
      ++count[c];
    }
    for (int c = 0; c < 3; ++c) {
      const double mean = nees[c] / count[c];  // 400 samples: chi2(3) mean 3 +- 0.12 (1 sigma)
      if (model) {
        EXPECT_NEAR(mean, 3.0, 0.6) << "size " << sizes[c];
      } else if (c == 0) {
        EXPECT_LT(mean, 1.5) << "pooled sigma, smallest keypoints: too conservative";
      } else if (c == 2) {
        EXPECT_GT(mean, 6.0) << "pooled sigma, largest keypoints: overconfident";
      }
    }
  }
}

// A keypoint on a slanted (foreshortened) surface is localised worse in both image coordinates: a flat patch and a
// patch slanted by 45 degrees, the same keypoint size everywhere, 0.06 px and 0.18 px of noise. The fitted variance
// (var = c0 + c2 tan^2(theta), the size column dropped since the sizes do not spread) tells them apart, and each
// patch's landmarks are consistent with their covariances.
TEST(StereoLandmarks, LocalisationNoiseGrowsWithTheSlant) {
  const Fixture f(false);
  std::mt19937 rng(12);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<stereo::StereoMatch> ms;
  std::vector<Eigen::Vector3d> truth;
  std::vector<bool> slanted;
  for (int side = 0; side < 2; ++side)
    for (int i = 0; i < 20; ++i)
      for (int j = 0; j < 30; ++j) {
        const double x = side ? 0.05 + 0.08 * i / 19.0 : -0.13 + 0.12 * i / 19.0, y = -0.1 + 0.2 * j / 29.0;
        const Eigen::Vector3d X(x, y, side ? 0.42 + (x - 0.05) : 0.45);  // side 1: tan(slant) ~ 1
        auto m = f.match(X);
        m.size = 8.0f;
        const double sg = side ? 0.18 : 0.06;
        m.left += sg * Eigen::Vector2d(n(rng), n(rng));
        m.right += sg * Eigen::Vector2d(n(rng), n(rng));
        ms.push_back(m);
        truth.push_back(X);
        slanted.push_back(side == 1);
      }
  stereo::TriangulateOptions o;
  o.disparity_gate = 0.0;  // keep every match: the landmarks stay in the order of the matches
  o.row_gate = 0.0;
  const auto l = stereo::triangulateMatches(f.pair.left, f.pair.right, ms, o);
  ASSERT_EQ(l.size(), ms.size());
  double nees[2] = {0, 0}, sigma_v[2] = {0, 0};
  int count[2] = {0, 0};
  for (size_t k = 0; k < l.size(); ++k) {
    const int c = slanted[k] ? 1 : 0;
    const Eigen::Vector3d e = l[k].position - truth[k];
    nees[c] += e.dot(l[k].covariance.inverse() * e);
    sigma_v[c] += std::sqrt(l[k].var_v);
    ++count[c];
  }
  for (int c = 0; c < 2; ++c) {
    nees[c] /= count[c];
    sigma_v[c] /= count[c];
    std::printf("  %s patch: mean modelled sigma_v %.3f px (noise %.2f), mean NEES %.2f\n", c ? "slanted" : "flat", sigma_v[c],
                c ? 0.18 : 0.06, nees[c]);
  }
  // The slant is measured from noisy local planes, so the model blurs the two patches somewhat.
  EXPECT_NEAR(sigma_v[0], 0.06, 0.03);
  EXPECT_NEAR(sigma_v[1], 0.18, 0.045);
  EXPECT_NEAR(nees[0], 3.0, 1.0);  // 600 landmarks each: chi2(3) mean 3 +- 0.1 (1 sigma)
  EXPECT_NEAR(nees[1], 3.0, 1.0);
}

TEST(StereoLandmarks, LocalDisparityGateDropsMismatches) {
  // A smooth surface seen with 0.2 px noise; every 25th match gets a wrong disparity (a mismatch).
  const Fixture f(false);
  std::mt19937 rng(8);
  std::normal_distribution<double> n(0.0, 0.2);
  std::vector<stereo::StereoMatch> ms;
  std::vector<bool> wrong;
  for (int i = 0; i < 600; ++i) {
    const double x = -0.1 + 0.3 * ((i * 37) % 600) / 600.0, y = -0.1 + 0.2 * ((i * 91) % 600) / 600.0;
    auto m = f.match(Eigen::Vector3d(x, y, 0.45 + 0.3 * x * x));
    m.left += Eigen::Vector2d(n(rng), n(rng));
    m.right += Eigen::Vector2d(n(rng), n(rng));
    const bool bad = i % 25 == 0;
    if (bad) m.right.x() += (i % 50 == 0 ? 6.0 : -6.0);
    ms.push_back(m);
    wrong.push_back(bad);
  }
  stereo::TriangulateOptions o;
  o.row_gate = 0.0;  // only the disparity gate
  int dropped = 0;
  const auto lms = stereo::triangulateMatches(f.pair.left, f.pair.right, ms, o, &dropped);
  int bad_kept = 0;
  for (const auto& l : lms)
    for (size_t i = 0; i < ms.size(); ++i)
      if (wrong[i] && (l.uv_left - ms[i].left).norm() < 1e-9) ++bad_kept;
  EXPECT_EQ(bad_kept, 0) << "mismatches survived the gate";
  EXPECT_LE(dropped, 24 + 6) << "the gate also dropped too many good matches";  // 24 wrong, <1 % of good ones
  o.disparity_gate = 0.0;
  EXPECT_EQ(stereo::triangulateMatches(f.pair.left, f.pair.right, ms, o).size(), ms.size());
}

TEST(StereoLandmarks, DropsImpossibleMatchesAndRejectsUncalibratedInfo) {
  const Fixture f(false);
  stereo::StereoMatch behind;  // negative disparity: behind the rig
  behind.left = Eigen::Vector2d(300, 240);
  behind.right = Eigen::Vector2d(320, 240);
  stereo::StereoMatch far = f.match(Eigen::Vector3d(0.0, 0.0, 50.0));
  int dropped = 0;
  EXPECT_TRUE(stereo::triangulateMatches(f.pair.left, f.pair.right, {behind, far}, {}, &dropped).empty());
  EXPECT_EQ(dropped, 2);
  geometry::CameraInfo bad = f.pair.right;
  bad.P.setZero();
  EXPECT_THROW(stereo::triangulateMatches(f.pair.left, bad, {}, {}), std::invalid_argument);
  bad = f.pair.right;
  bad.P(0, 3) = 0.0;
  EXPECT_THROW(stereo::triangulateMatches(f.pair.left, bad, {}, {}), std::invalid_argument);
}
