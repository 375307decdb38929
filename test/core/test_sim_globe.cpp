// SPDX-License-Identifier: BSD-3-Clause
//
// Tests of the landmark-level globe simulator (include/skin3d/sim/globe.h). Ground truth comes from
// geometry (sphere, orbit, projection, chi-square statistics), never from the simulator's own figures.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <set>
#include <string>
#include <vector>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/globe.h"

using skin3d::geometry::quatExp;
using skin3d::geometry::so3Log;
using skin3d::sim::GlobeConfig;
using skin3d::sim::GlobeSimulator;
using skin3d::sim::LandmarkMeasurement;
using skin3d::sim::SimConfigError;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// The thesis' set-up (ch. 7, docs/design.md "globe"), typed in independently of the header's defaults.
constexpr double kRadius = 0.200, kDistance = 0.600, kLatitude = -25.0 * kDeg, kTilt = 23.0 * kDeg, kRate = 0.15;

/** The globe's spin axis z_G in the world, from the poses alone: the rig turns by -rate t about z_G. */
Eigen::Vector3d spinAxisFromPoses(const GlobeSimulator& sim) {
  const double t = 1.0;
  const Eigen::Matrix3d dR = sim.poseWorldLeft(t).linear() * sim.poseWorldLeft(0.0).linear().transpose();
  return so3Log(dR) / (-sim.config().rate * t);
}

/** Nearest intersection (> 1e-9) of the ray o + s u (u unit) with the sphere (c, r), or +inf. */
double raySphere(const Eigen::Vector3d& o, const Eigen::Vector3d& u, const Eigen::Vector3d& c, double r) {
  const Eigen::Vector3d oc = o - c;
  const double b = oc.dot(u), q = oc.squaredNorm() - r * r, disc = b * b - q;
  if (disc < 0.0) return std::numeric_limits<double>::infinity();
  const double s1 = -b - std::sqrt(disc), s2 = -b + std::sqrt(disc);
  if (s1 > 1e-9) return s1;
  if (s2 > 1e-9) return s2;
  return std::numeric_limits<double>::infinity();
}

/** Brute-force visibility from the stated definition, using only the rig's cameras. */
bool reallyVisible(const GlobeSimulator& sim, int id, double t) {
  const GlobeConfig& c = sim.config();
  const Eigen::Isometry3d T = sim.poseWorldLeft(t);
  const Eigen::Vector3d m = sim.landmarksWorld()[id], o = sim.sphereCentreWorld();
  const Eigen::Vector3d n = (m - o).normalized();
  const Eigen::Vector3d cl = T.translation(), cr = T * sim.rig().rightCentre();
  for (const Eigen::Vector3d& cam : {cl, cr}) {
    const double cosang = n.dot((cam - m).normalized());
    if (!(cosang >= std::cos(c.max_incidence))) return false;
  }
  const Eigen::Vector3d XL = T.inverse() * m, XR = sim.rig().toRight(XL);
  if (!(XL.z() > 0.0) || !(XR.z() > 0.0)) return false;
  return sim.rig().left().inImage(sim.rig().left().project(XL)) &&
         sim.rig().right().inImage(sim.rig().right().project(XR));
}

/** Position of landmark id in the left optical frame at time t. */
Eigen::Vector3d trueInLeft(const GlobeSimulator& sim, int id, double t) {
  return sim.poseWorldLeft(t).inverse() * sim.landmarksWorld()[id];
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

// ============================================================================================ rig
TEST(GlobeRig, MakeRigFromDesignNumbers) {
  skin3d::sim::RigConfig rc;  // the SLAM rig: 1.8 mm, 2.24 um, 640x480, right at (105, 0, 15) mm
  const auto rig = rc.makeRig();
  EXPECT_NEAR(rig.left().fx(), 1.8 / 2.24e-3, 1e-9);
  EXPECT_NEAR(rig.left().fy(), 1.8 / 2.24e-3, 1e-9);
  EXPECT_DOUBLE_EQ(rig.left().cx(), 319.5);
  EXPECT_DOUBLE_EQ(rig.left().cy(), 239.5);
  EXPECT_DOUBLE_EQ(rig.right().fx(), rig.left().fx());
  EXPECT_LT((rig.rightCentre() - Eigen::Vector3d(0.105, 0.0, 0.015)).norm(), 1e-12);
  EXPECT_LT((rig.R_rl() - Eigen::Matrix3d::Identity()).norm(), 1e-12);

  // Converged: left turned +c/2 about y, right -c/2 (design.h) -> the right optical axis, seen from the left
  // frame, is turned by c towards the left camera: (-sin c, 0, cos c).
  rc.convergence = 10.0 * kDeg;
  const auto conv = rc.makeRig();
  const Eigen::Vector3d axis_right_in_left = conv.R_rl().transpose() * Eigen::Vector3d::UnitZ();
  EXPECT_LT((axis_right_in_left - Eigen::Vector3d(-std::sin(10 * kDeg), 0, std::cos(10 * kDeg))).norm(), 1e-12);
  EXPECT_NEAR(conv.opticalAxesAngle(), 10.0 * kDeg, 1e-12);
  // The baseline is given in the midpoint frame (design.h): in the left frame it is turned by -c/2 about y.
  const double h = 5.0 * kDeg;
  const Eigen::Vector3d b = rc.baseline;
  const Eigen::Vector3d expected(std::cos(h) * b.x() - std::sin(h) * b.z(), b.y(), std::sin(h) * b.x() + std::cos(h) * b.z());
  EXPECT_LT((conv.rightCentre() - expected).norm(), 1e-12);
  EXPECT_NEAR(conv.baseline(), b.norm(), 1e-12);
}

// ============================================================================================ geometry
TEST(GlobeGeometry, PoseAtZeroIsIdentityAndOpticalAxisHitsTheCentre) {
  const GlobeSimulator sim{GlobeConfig()};
  const Eigen::Isometry3d T0 = sim.poseWorldLeft(0.0);
  EXPECT_LT((T0.matrix() - Eigen::Matrix4d::Identity()).norm(), 1e-12);
  EXPECT_LT((sim.sphereCentreWorld() - Eigen::Vector3d(0, 0, kDistance)).norm(), 1e-12);
}

TEST(GlobeGeometry, OrbitKeepsDistanceLatitudeAndLookAtTheCentre) {
  const GlobeSimulator sim{GlobeConfig()};
  const Eigen::Vector3d o = sim.sphereCentreWorld();
  const Eigen::Vector3d zG = spinAxisFromPoses(sim);
  ASSERT_NEAR(zG.norm(), 1.0, 1e-9);
  // The spin axis in the rig frame is fixed (the globe's axis is fixed in the lab).
  const Eigen::Vector3d zG_L0 = sim.poseWorldLeft(0.0).linear().transpose() * zG;
  for (double t = 0.0; t <= 42.0; t += 0.7) {
    const Eigen::Isometry3d T = sim.poseWorldLeft(t);
    const Eigen::Vector3d r = T.translation() - o;
    EXPECT_NEAR(r.norm(), kDistance, 1e-12) << "t = " << t;
    EXPECT_NEAR(std::asin(zG.dot(r) / r.norm()), kLatitude, 1e-9) << "t = " << t;
    // Left optical axis through the centre: the centre is at (0, 0, distance) in the left frame.
    EXPECT_LT((T.inverse() * o - Eigen::Vector3d(0, 0, kDistance)).norm(), 1e-12) << "t = " << t;
    const Eigen::Vector3d zG_L = T.linear().transpose() * zG;
    EXPECT_LT((zG_L - zG_L0).norm(), 1e-12) << "t = " << t;
  }
  // Tilt and no roll. The lab up vector u is perpendicular to the image x axis (horizontal x), points "up"
  // (u_y < 0), and leans sideways, perpendicular to the line of sight e_r = -z_L, so u . e_r = cos(tilt) sin(lat)
  // (z_G . e_r = sin(lat)). That fixes u_L = (0, -sqrt(1 - u_z^2), u_z) with u_z = -cos(tilt) sin(lat); the angle
  // between u and the spin axis must then be the tilt.
  const double uz = -std::cos(kTilt) * std::sin(kLatitude);
  const Eigen::Vector3d u_L(0.0, -std::sqrt(1.0 - uz * uz), uz);
  EXPECT_NEAR(std::acos(u_L.dot(zG_L0)), kTilt, 1e-9);
  // Seen in the image the spin axis leans by atan(tan(tilt) / cos(lat)) from the image up direction (-y);
  // north pole towards +x (the chosen side).
  EXPECT_NEAR(std::atan2(zG_L0.x(), -zG_L0.y()), std::atan(std::tan(kTilt) / std::cos(kLatitude)), 1e-9);
  // The camera is south of the equator: it looks "up" along the axis (z_L . z_G = -sin(lat) > 0).
  EXPECT_NEAR(zG_L0.z(), -std::sin(kLatitude), 1e-9);
}

TEST(GlobeGeometry, FullOrbitReturnsToTheStart) {
  const GlobeSimulator sim{GlobeConfig()};
  const Eigen::Isometry3d T = sim.poseWorldLeft(2.0 * kPi / kRate);
  EXPECT_LT((T.matrix() - Eigen::Matrix4d::Identity()).norm(), 1e-9);
  // Half an orbit: on the other side of the axis, 2 distance cos(lat) away.
  const Eigen::Isometry3d H = sim.poseWorldLeft(kPi / kRate);
  EXPECT_NEAR(H.translation().norm(), 2.0 * kDistance * std::cos(kLatitude), 1e-9);
  // The run (420 frames at 10 Hz) covers one loop: the last frame is within one frame step of the start.
  EXPECT_NEAR(sim.stamp(sim.frames() - 1) * kRate, 2.0 * kPi, kRate / sim.config().fps);
}

TEST(GlobeGeometry, VelocitiesMatchFiniteDifferencesOfPoses) {
  GlobeConfig cfg;
  for (double rate : {0.15, -0.4}) {
    cfg.rate = rate;
    const GlobeSimulator sim(cfg);
    for (double t : {0.0, 3.3, 17.0, 41.0}) {
      const double h = 1e-3;
      const Eigen::Isometry3d Tm = sim.poseWorldLeft(t - h), Tp = sim.poseWorldLeft(t + h), T = sim.poseWorldLeft(t);
      // R(t + h) = R(t - h) Exp(omega 2h) for a body-frame angular velocity.
      const Eigen::Vector3d w_num = so3Log(Tm.linear().transpose() * Tp.linear()) / (2.0 * h);
      const Eigen::Vector3d v_num = T.linear().transpose() * (Tp.translation() - Tm.translation()) / (2.0 * h);
      EXPECT_LT((sim.angularVelocity(t) - w_num).norm(), 1e-6) << "rate " << rate << " t " << t;
      EXPECT_LT((sim.linearVelocity(t) - v_num).norm(), 1e-6) << "rate " << rate << " t " << t;
      // Closed forms: |omega| = |rate|, |v| = |rate| distance cos(lat), v perpendicular to omega and to the
      // line of sight (a circle about the spin axis).
      EXPECT_NEAR(sim.angularVelocity(t).norm(), std::abs(rate), 1e-12);
      EXPECT_NEAR(sim.linearVelocity(t).norm(), std::abs(rate) * kDistance * std::cos(kLatitude), 1e-12);
      EXPECT_NEAR(sim.linearVelocity(t).dot(sim.angularVelocity(t)), 0.0, 1e-12);
      EXPECT_NEAR(sim.linearVelocity(t).z(), 0.0, 1e-12);
    }
  }
}

// ============================================================================================ landmarks
TEST(GlobeLandmarks, UniformOnTheSphere) {
  const GlobeSimulator sim{GlobeConfig()};
  const auto& L = sim.landmarksWorld();
  const int N = static_cast<int>(L.size());
  ASSERT_EQ(N, 10000);
  const Eigen::Vector3d o = sim.sphereCentreWorld();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  for (const auto& m : L) {
    EXPECT_NEAR((m - o).norm(), kRadius, 1e-12);
    mean += (m - o) / N;
    M += (m - o) * (m - o).transpose() / N;
  }
  // Uniform on a sphere: each coordinate has mean 0 and variance r^2/3, so the sample mean has
  // sigma = r / sqrt(3 N) = 1.15 mm per axis; bound 4 sigma.
  const double s_mean = kRadius / std::sqrt(3.0 * N);
  for (int i = 0; i < 3; ++i) EXPECT_LT(std::abs(mean[i]), 4.0 * s_mean) << "axis " << i;
  // Second moment r^2/3 I: var(x^2) = r^4 (1/5 - 1/9), var(x y) = r^4 / 15; bound 4 sigma of the sample mean.
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const double expect = i == j ? kRadius * kRadius / 3.0 : 0.0;
      const double sd = kRadius * kRadius * std::sqrt((i == j ? 4.0 / 45.0 : 1.0 / 15.0) / N);
      EXPECT_NEAR(M(i, j), expect, 4.0 * sd) << i << "," << j;
    }
  // Archimedes: the projection onto any axis is uniform on [-r, r]. Chi-square with 20 bins (19 dof):
  // the 0.999 quantile is 43.8.
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<int> bins(20, 0);
    for (const auto& m : L) {
      const int b = std::min(19, static_cast<int>((((m - o)[axis] / kRadius) + 1.0) * 10.0));
      ++bins[std::max(0, b)];
    }
    double chi2 = 0.0;
    const double e = N / 20.0;
    for (int b : bins) chi2 += (b - e) * (b - e) / e;
    EXPECT_LT(chi2, 43.8) << "axis " << axis;
  }
}

TEST(GlobeLandmarks, VisibleLandmarksAreReallyVisible) {
  const GlobeSimulator sim{GlobeConfig()};
  const Eigen::Vector3d o = sim.sphereCentreWorld();
  for (int k : {0, 105, 210, 315, 419}) {
    const double t = sim.stamp(k);
    const std::vector<int> vis = sim.visible(k);
    ASSERT_GT(vis.size(), 50u) << "frame " << k;
    const std::set<int> vset(vis.begin(), vis.end());
    EXPECT_EQ(vset.size(), vis.size()) << "duplicate ids";
    int mismatches = 0;
    for (int id = 0; id < static_cast<int>(sim.landmarksWorld().size()); ++id)
      if (reallyVisible(sim, id, t) != (vset.count(id) > 0)) ++mismatches;
    EXPECT_EQ(mismatches, 0) << "frame " << k;
    // Unoccluded: the first hit of the ray from either optical centre towards the landmark is the landmark.
    const Eigen::Isometry3d T = sim.poseWorldLeft(t);
    for (int id : vis) {
      const Eigen::Vector3d m = sim.landmarksWorld()[id];
      for (const Eigen::Vector3d& cam :
           {Eigen::Vector3d(T.translation()), Eigen::Vector3d(T * sim.rig().rightCentre())}) {
        const double hit = raySphere(cam, (m - cam).normalized(), o, kRadius);
        EXPECT_NEAR(hit, (m - cam).norm(), 1e-9) << "landmark " << id << " occluded in frame " << k;
      }
    }
  }
}

TEST(GlobeLandmarks, DescriptorsAndLookalikes) {
  GlobeConfig cfg;
  cfg.landmarks = 2000;
  for (double fraction : {0.0, 0.1}) {
    cfg.lookalike_fraction = fraction;
    cfg.lookalike_distance = 0.05;
    const GlobeSimulator sim(cfg);
    const auto& D = sim.descriptors();
    ASSERT_EQ(D.size(), 2000u);
    for (const auto& d : D) {
      ASSERT_EQ(d.size(), 64u);
      double n2 = 0.0;
      for (float x : d) n2 += double(x) * x;
      EXPECT_NEAR(n2, 1.0, 1e-5);
    }
    // Independent random unit vectors in 64-D lie ~sqrt(2) +- 0.09 apart; "near" = below 0.5.
    int pairs = 0;
    std::set<int> involved;
    for (size_t i = 0; i < D.size(); ++i)
      for (size_t j = i + 1; j < D.size(); ++j) {
        double d2 = 0.0;
        for (int e = 0; e < 64; ++e) d2 += (double(D[i][e]) - D[j][e]) * (double(D[i][e]) - D[j][e]);
        if (d2 < 0.25) {
          ++pairs;
          involved.insert(int(i));
          involved.insert(int(j));
          EXPECT_NEAR(std::sqrt(d2), 0.05, 1e-5);
        }
      }
    // fraction = look-alike pairs / landmarks; every pair has its own two landmarks.
    EXPECT_EQ(pairs, static_cast<int>(std::lround(fraction * 2000))) << "fraction " << fraction;
    EXPECT_EQ(static_cast<int>(involved.size()), 2 * pairs);
  }
}

// ============================================================================================ measurements
TEST(GlobeMeasurements, ConsistentWithTheirCovariance) {
  const GlobeSimulator sim{GlobeConfig()};
  const double sigma = sim.config().pixel_sigma;
  double nees_sum = 0.0;
  Eigen::Vector3d z_sum = Eigen::Vector3d::Zero(), z2_sum = Eigen::Vector3d::Zero();
  double pix2_sum = 0.0;
  long n = 0, n_pix = 0;
  double desc_d2_sum = 0.0, strength_sum = 0.0;
  for (int k = 0; k < 400; k += 10) {  // 40 frames spread over the loop
    const double t = sim.stamp(k);
    const std::vector<int> vis = sim.visible(k);
    const std::set<int> vset(vis.begin(), vis.end());
    const std::vector<LandmarkMeasurement> ms = sim.measure(k);
    ASSERT_GT(ms.size(), 0.9 * vis.size()) << "frame " << k;  // only features pushed out of an image are lost
    for (const auto& m : ms) {
      ASSERT_TRUE(vset.count(m.id)) << "measured but not visible: " << m.id;
      EXPECT_TRUE(sim.rig().left().inImage(m.uv_left));
      EXPECT_TRUE(sim.rig().right().inImage(m.uv_right));
      // Covariance symmetric positive definite.
      EXPECT_LT((m.covariance - m.covariance.transpose()).norm(), 1e-15);
      Eigen::LLT<Eigen::Matrix3d> llt(m.covariance);
      ASSERT_EQ(llt.info(), Eigen::Success);
      // Descriptor: unit norm; strength in (0, 1].
      ASSERT_EQ(m.descriptor.size(), 64u);
      double n2 = 0.0, d2 = 0.0;
      for (int e = 0; e < 64; ++e) {
        n2 += double(m.descriptor[e]) * m.descriptor[e];
        const double diff = double(m.descriptor[e]) - sim.descriptors()[m.id][e];
        d2 += diff * diff;
      }
      EXPECT_NEAR(n2, 1.0, 1e-5);
      desc_d2_sum += d2;
      EXPECT_GT(m.strength, 0.0f);
      EXPECT_LE(m.strength, 1.0f);
      strength_sum += m.strength;
      // Pixel noise: against the true projection.
      const Eigen::Vector3d X = trueInLeft(sim, m.id, t);
      const Eigen::Vector2d uvl = sim.rig().left().project(X), uvr = sim.rig().right().project(sim.rig().toRight(X));
      pix2_sum += ((m.uv_left - uvl).squaredNorm() + (m.uv_right - uvr).squaredNorm()) / (sigma * sigma);
      n_pix += 4;
      // Position error against the truth.
      const Eigen::Vector3d e = m.position - X;
      nees_sum += e.dot(llt.solve(e));
      for (int i = 0; i < 3; ++i) {
        const double z = e[i] / std::sqrt(m.covariance(i, i));
        z_sum[i] += z;
        z2_sum[i] += z * z;
      }
      ++n;
    }
  }
  ASSERT_GT(n, 1000);
  const double nees = nees_sum / n;
  // If consistent, the sum of NEES is chi-square with 3n dof: mean 3, standard deviation of the average
  // sqrt(6 / n) (0.014 for ~30 000 measurements). Bound: 4 of those.
  const double nees_bound = 4.0 * std::sqrt(6.0 / n);
  std::printf(
      "[ globe ] %ld measurements in 40 frames: mean NEES %.4f (chi2 bound 3 +- %.4f), "
      "pixel noise variance / sigma^2 %.4f\n",
      n, nees, nees_bound, pix2_sum / n_pix);
  EXPECT_NEAR(nees, 3.0, nees_bound);
  EXPECT_NEAR(pix2_sum / n_pix, 1.0, 4.0 * std::sqrt(2.0 / n_pix));
  for (int i = 0; i < 3; ++i) {
    const double mean = z_sum[i] / n, var = z2_sum[i] / n - mean * mean;
    std::printf("[ globe ] axis %d: normalised error mean %+.4f variance %.4f\n", i, mean, var);
    EXPECT_NEAR(var, 1.0, 0.1) << "axis " << i;
    EXPECT_NEAR(mean, 0.0, 0.05) << "axis " << i;
  }
  // Descriptor noise sigma per element, then renormalised: the radial part is removed, so
  // E|d_noisy - d|^2 ~= sigma^2 (D - 1) for small sigma. Strength = 1 - |d_left - d_right| / 2 with two
  // independent noisy copies: ~= 1 - sigma sqrt(2 (D - 1)) / 2.
  const double sd = sim.config().descriptor_noise;
  EXPECT_NEAR(desc_d2_sum / n, sd * sd * 63.0, 0.05 * sd * sd * 63.0);
  EXPECT_NEAR(strength_sum / n, 1.0 - sd * std::sqrt(2.0 * 63.0) / 2.0, 0.002);
}

TEST(GlobeMeasurements, NoiseFreeDescriptorsAreExactAndStrengthIsOne) {
  GlobeConfig cfg;
  cfg.descriptor_noise = 0.0;
  const GlobeSimulator sim(cfg);
  const auto ms = sim.measure(7);
  ASSERT_FALSE(ms.empty());
  for (const auto& m : ms) {
    EXPECT_FLOAT_EQ(m.strength, 1.0f);
    for (int e = 0; e < 64; ++e) EXPECT_NEAR(m.descriptor[e], sim.descriptors()[m.id][e], 1e-6);
  }
}

TEST(GlobeMeasurements, Deterministic) {
  const GlobeConfig cfg;
  const GlobeSimulator a(cfg), b(cfg);
  // b is asked in another order: measure(k) must not depend on what was asked before.
  const std::vector<int> order_a = {0, 5, 200, 419}, order_b = {419, 200, 5, 0};
  std::vector<std::vector<LandmarkMeasurement>> ma, mb(4);
  for (int k : order_a) ma.push_back(a.measure(k));
  for (int i = 0; i < 4; ++i) mb[3 - i] = b.measure(order_b[i]);
  for (int i = 0; i < 4; ++i) {
    ASSERT_EQ(ma[i].size(), mb[i].size());
    ASSERT_FALSE(ma[i].empty());
    for (size_t j = 0; j < ma[i].size(); ++j) {
      EXPECT_EQ(ma[i][j].id, mb[i][j].id);
      EXPECT_EQ(ma[i][j].position, mb[i][j].position);
      EXPECT_EQ(ma[i][j].covariance, mb[i][j].covariance);
      EXPECT_EQ(ma[i][j].descriptor, mb[i][j].descriptor);
      EXPECT_EQ(ma[i][j].strength, mb[i][j].strength);
      EXPECT_EQ(ma[i][j].uv_left, mb[i][j].uv_left);
      EXPECT_EQ(ma[i][j].uv_right, mb[i][j].uv_right);
    }
  }
  EXPECT_EQ(a.landmarksWorld(), b.landmarksWorld());
  EXPECT_EQ(a.descriptors(), b.descriptors());
  const auto ga = a.gyro(), gb = b.gyro();
  ASSERT_EQ(ga.size(), gb.size());
  for (size_t i = 0; i < ga.size(); ++i) {
    EXPECT_EQ(ga[i].t, gb[i].t);
    EXPECT_EQ(ga[i].omega, gb[i].omega);
  }
  // Two frames' noise differs; another seed gives other landmarks, descriptors, noise and gyro samples.
  GlobeConfig other = cfg;
  other.seed = 2;
  const GlobeSimulator c(other);
  EXPECT_NE(a.landmarksWorld()[0], c.landmarksWorld()[0]);
  EXPECT_NE(a.descriptors()[0], c.descriptors()[0]);
  EXPECT_NE(a.gyro()[10].omega, c.gyro()[10].omega);
  // The noise realisation (measured minus true pixel) of one landmark: other in frame 1, other with seed 2.
  auto residual = [](const GlobeSimulator& s, int k, int id) {
    for (const auto& m : s.measure(k))
      if (m.id == id) return Eigen::Vector2d(m.uv_left - s.rig().left().project(trueInLeft(s, id, s.stamp(k))));
    return Eigen::Vector2d(Eigen::Vector2d::Constant(std::nan("")));
  };
  int id = -1;  // a landmark measured in frames 0 and 1 by a and in frame 0 by c
  {
    std::set<int> s1, sc;
    for (const auto& m : a.measure(1)) s1.insert(m.id);
    for (const auto& m : c.measure(0)) sc.insert(m.id);
    for (const auto& m : a.measure(0))
      if (s1.count(m.id) && sc.count(m.id)) {
        id = m.id;
        break;
      }
  }
  ASSERT_GE(id, 0);
  const Eigen::Vector2d r0 = residual(a, 0, id), r1 = residual(a, 1, id), r0c = residual(c, 0, id);
  ASSERT_TRUE(r0.allFinite() && r1.allFinite() && r0c.allFinite());
  EXPECT_GT((r0 - r1).norm(), 1e-6);
  EXPECT_GT((r0 - r0c).norm(), 1e-6);
}

// ============================================================================================ gyroscope
TEST(GlobeGyro, NoiseFreeSamplesIntegrateToTheTrueRotation) {
  GlobeConfig cfg;
  cfg.gyro_noise = 0.0;
  cfg.gyro_bias.setZero();
  cfg.gyro_bias_walk = 0.0;
  const GlobeSimulator sim(cfg);
  const auto g = sim.gyro();
  ASSERT_EQ(g.size(), 4200u);  // 42 s at 100 Hz, t in [0, 42)
  EXPECT_DOUBLE_EQ(g.front().t, 0.0);
  EXPECT_NEAR(g.back().t, 41.99, 1e-9);
  const double dt = 1.0 / cfg.gyro_rate;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  // world <- left at t = 0
  size_t i = 0;
  for (; i < g.size() && g[i].t < 2.0 - 1e-9; ++i) {
    EXPECT_NEAR(g[i].t, i * dt, 1e-12);
    q = q * quatExp(g[i].omega * dt);  // body-frame rate: q+ = q (x) Exp(omega dt)
  }
  ASSERT_EQ(i, 200u);
  const Eigen::Matrix3d R_true = sim.poseWorldLeft(2.0).linear();
  const double err = so3Log(q.toRotationMatrix().transpose() * R_true).norm();
  EXPECT_LT(err, 1e-6);
  EXPECT_GT(so3Log(R_true).norm(), 0.29);  // it did turn (0.3 rad)
}

TEST(GlobeGyro, NoiseBiasAndRandomWalkStatistics) {
  GlobeConfig cfg;
  cfg.gyro_noise = 0.002;
  cfg.gyro_bias = Eigen::Vector3d(0.001, -0.002, 0.003);
  const GlobeSimulator sim(cfg);
  const auto g = sim.gyro();
  const double N = g.size();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero(), m2 = Eigen::Vector3d::Zero();
  for (const auto& s : g) {
    const Eigen::Vector3d r = s.omega - sim.angularVelocity(s.t);
    mean += r / N;
    m2 += r.cwiseProduct(r) / N;
  }
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(mean[i], cfg.gyro_bias[i], 4.0 * cfg.gyro_noise / std::sqrt(N)) << "axis " << i;
    const double sd = std::sqrt(m2[i] - mean[i] * mean[i]);
    EXPECT_NEAR(sd, cfg.gyro_noise, 4.0 * cfg.gyro_noise / std::sqrt(2.0 * N)) << "axis " << i;
  }
  // Random walk only: increments between samples are N(0, walk^2 dt) per axis.
  cfg.gyro_noise = 0.0;
  cfg.gyro_bias.setZero();
  cfg.gyro_bias_walk = 1e-3;
  const GlobeSimulator walk(cfg);
  const auto w = walk.gyro();
  double s2 = 0.0;
  long n = 0;
  for (size_t i = 1; i < w.size(); ++i) {
    const Eigen::Vector3d d = w[i].omega - w[i - 1].omega;
    s2 += d.squaredNorm();
    n += 3;
  }
  const double expect = cfg.gyro_bias_walk * cfg.gyro_bias_walk / cfg.gyro_rate;
  EXPECT_NEAR(s2 / n / expect, 1.0, 4.0 * std::sqrt(2.0 / n));
}

// ============================================================================================ bad config
namespace {
struct BadCase {
  const char* what;
  void (*apply)(GlobeConfig&);
  const char* field;
  const char* value;  // as it must appear in the message
};
}  // namespace

TEST(GlobeConfigValidation, NamedErrorsWithTheValue) {
  EXPECT_NO_THROW(GlobeConfig().validate());
  const BadCase cases[] = {
      {"negative radius", [](GlobeConfig& c) { c.radius = -0.2; }, "globe.radius_mm", "-200"},
      {"camera on the sphere", [](GlobeConfig& c) { c.distance = 0.2; }, "globe.distance_mm", "200"},
      {"camera inside the sphere", [](GlobeConfig& c) { c.distance = 0.15; }, "globe.distance_mm", "150"},
      {"zero fps", [](GlobeConfig& c) { c.fps = 0.0; }, "globe.fps", "= 0"},
      {"NaN pixel sigma", [](GlobeConfig& c) { c.pixel_sigma = std::nan(""); }, "globe.pixel_sigma_px", "nan"},
      {"negative focal length", [](GlobeConfig& c) { c.rig.focal_length = -1.8e-3; }, "rig.focal_length_mm", "-1.8"},
      {"zero focal length", [](GlobeConfig& c) { c.rig.focal_length = 0.0; }, "rig.focal_length_mm", "= 0"},
      {"latitude at the pole", [](GlobeConfig& c) { c.latitude = 90.0 * kDeg; }, "globe.latitude_deg", "90"},
      {"no frames", [](GlobeConfig& c) { c.frames = 0; }, "globe.frames", "= 0"},
      {"no landmarks", [](GlobeConfig& c) { c.landmarks = 0; }, "globe.landmarks", "= 0"},
      {"infinite rate", [](GlobeConfig& c) { c.rate = INFINITY; }, "globe.rate_rad_s", "inf"},
      {"too many look-alikes", [](GlobeConfig& c) { c.lookalike_fraction = 0.7; }, "globe.lookalike_fraction", "0.7"},
      {"NaN gyro bias", [](GlobeConfig& c) { c.gyro_bias.y() = std::nan(""); }, "globe.gyro_bias_rad_s", "nan"},
      {"pixel size", [](GlobeConfig& c) { c.rig.pixel_size = -2.24e-6; }, "rig.pixel_size_um", "-2.24"},
      {"zero baseline", [](GlobeConfig& c) { c.rig.baseline.setZero(); }, "rig.baseline_mm", "[0, 0, 0]"},
      {"3 distortion coefficients",
       [](GlobeConfig& c) {
         c.rig.distortion = {0.1, 0.0, 0.0};
       },
       "rig.distortion", "[0.1, 0, 0]"},
  };
  for (const auto& bc : cases) {
    GlobeConfig cfg;
    bc.apply(cfg);
    try {
      cfg.validate();
      ADD_FAILURE() << bc.what << ": validate() did not throw";
    } catch (const SimConfigError& e) {
      EXPECT_EQ(e.field(), bc.field) << bc.what << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find(bc.value), std::string::npos) << bc.what << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find(bc.field), std::string::npos) << bc.what << ": " << e.what();
    }
    EXPECT_THROW(GlobeSimulator{cfg}, SimConfigError) << bc.what;
  }
}

TEST(GlobeConfigValidation, NothingVisibleNamesTheCulprit) {
  {
    GlobeConfig cfg;  // a 0.0057 deg cone: no landmark can face both cameras (15 deg apart) that closely
    cfg.max_incidence = 1e-4;
    EXPECT_NO_THROW(cfg.validate());
    try {
      GlobeSimulator sim(cfg);
      ADD_FAILURE() << "tiny max_incidence: no error";
    } catch (const SimConfigError& e) {
      EXPECT_EQ(e.field(), "globe.max_incidence_deg") << e.what();
      EXPECT_NE(std::string(e.what()).find("0.005729577951"), std::string::npos) << e.what();
    }
  }
  {
    GlobeConfig cfg;  // the right camera looks backwards
    cfg.rig.convergence = -170.0 * kDeg;
    EXPECT_NO_THROW(cfg.validate());
    try {
      GlobeSimulator sim(cfg);
      ADD_FAILURE() << "right camera looking away: no error";
    } catch (const SimConfigError& e) {
      EXPECT_EQ(e.field(), "rig.convergence_deg") << e.what();
      EXPECT_NE(std::string(e.what()).find("-170"), std::string::npos) << e.what();
    }
  }
  {
    GlobeConfig cfg;  // a 0.2 deg field of view over a sparse globe
    cfg.landmarks = 50;
    cfg.rig.focal_length = 0.5;
    try {
      GlobeSimulator sim(cfg);
      ADD_FAILURE() << "telephoto: no error";
    } catch (const SimConfigError& e) {
      EXPECT_EQ(e.field(), "rig.focal_length_mm") << e.what();
      EXPECT_NE(std::string(e.what()).find("500"), std::string::npos) << e.what();
    }
  }
}

// ============================================================================================ the whole run
TEST(GlobeRun, FullLoopStatistics) {
  const GlobeSimulator sim{GlobeConfig()};
  std::vector<double> visible, measured, ms_per_frame;
  const auto t_all = std::chrono::steady_clock::now();
  for (int k = 0; k < sim.frames(); ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto m = sim.measure(k);
    const auto t1 = std::chrono::steady_clock::now();
    ms_per_frame.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    measured.push_back(m.size());
    visible.push_back(sim.visible(k).size());
    EXPECT_GT(m.size(), 0u) << "frame " << k;
  }
  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_all).count();
  auto mm = [](const std::vector<double>& v) {
    return std::make_pair(*std::min_element(v.begin(), v.end()), *std::max_element(v.begin(), v.end()));
  };
  std::printf(
      "[ globe ] %d frames: visible landmarks per frame min %.0f / median %.0f / max %.0f; measured "
      "min %.0f / median %.0f / max %.0f\n",
      sim.frames(), mm(visible).first, median(visible), mm(visible).second, mm(measured).first, median(measured),
      mm(measured).second);
  std::printf("[ globe ] measure(): %.2f ms per frame (median), max %.2f ms; whole loop incl. visible() %.2f s\n",
              median(ms_per_frame), mm(ms_per_frame).second, total_s);
}
