// SPDX-License-Identifier: BSD-3-Clause
// The skin scene (make_dataset skin): geometry, ray casting and the truth it reports, against closed forms.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "skin3d/sim/skin.h"

using skin3d::sim::Hit;
using skin3d::sim::SkinGeometry;
using skin3d::sim::SkinPlaque;
using skin3d::sim::SkinScene;

namespace {

SkinGeometry circularLimb(double dome = 0.0) {
  SkinGeometry g;
  g.semi_axis_y = g.semi_axis_z = 0.04;
  SkinPlaque p;
  p.centre = Eigen::Vector2d(0.01, 0.0);  // on the top
  p.radii = Eigen::Vector2d(0.006, 0.005);
  p.height = 0.6e-3;
  p.ramp = 1e-3;
  p.dome = dome;
  p.irregularity = 0.0;
  g.plaques.push_back(p);
  SkinPlaque side = p;  // 45 deg around the limb
  side.centre = Eigen::Vector2d(-0.02, 0.04 * M_PI / 4);
  side.height = 0.2e-3;
  g.plaques.push_back(side);
  return g;
}

/** A scene of `g` must be refused with an error that names `field`. */
void expectRefusedNaming(const SkinGeometry& g, const std::string& field) {
  try {
    SkinScene s(g, 1);
    ADD_FAILURE() << "accepted; expected an error naming " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

}  // namespace

TEST(SimSkin, RaysHitTheLimbAndThePlaquesWhereTheyAre) {
  const SkinScene scene(circularLimb(), 7);
  Hit hit;
  // straight down onto the top, away from the plaques: the base at z = R
  ASSERT_TRUE(scene.intersect(Eigen::Vector3d(0.1, 0.0, 0.3), Eigen::Vector3d(0, 0, -1), &hit));
  EXPECT_NEAR(hit.point.z(), 0.04, 1e-9);
  EXPECT_NEAR(hit.normal.z(), 1.0, 1e-9);
  // onto the flat top of the first plaque: R + H, normal still radial
  ASSERT_TRUE(scene.intersect(Eigen::Vector3d(0.01, 0.0, 0.3), Eigen::Vector3d(0, 0, -1), &hit));
  EXPECT_NEAR(hit.point.z(), 0.04 + 0.6e-3, 1e-8);
  EXPECT_NEAR(hit.normal.z(), 1.0, 1e-4);
  // along the radius at 45 deg onto the side plaque: R + 0.2 mm from the axis
  const Eigen::Vector3d dir(0.0, -std::sin(M_PI / 4), -std::cos(M_PI / 4));
  ASSERT_TRUE(scene.intersect(Eigen::Vector3d(-0.02, 0.0, 0.0) - 0.3 * dir, dir, &hit));
  EXPECT_NEAR(std::hypot(hit.point.y(), hit.point.z()), 0.04 + 0.2e-3, 1e-8);
  // beside the limb: nothing
  EXPECT_FALSE(scene.intersect(Eigen::Vector3d(0.0, 0.05, 0.3), Eigen::Vector3d(0, 0, -1), &hit));
  // beyond its end: nothing
  EXPECT_FALSE(scene.intersect(Eigen::Vector3d(0.3, 0.0, 0.3), Eigen::Vector3d(0, 0, -1), &hit));
}

TEST(SimSkin, TruthOfAFlatTopPlaqueOnACircularLimb) {
  const SkinScene scene(circularLimb(), 7);
  const auto t = scene.plaqueTruth(0, 20e-6);
  EXPECT_NEAR(t.top_height, 0.6e-3, 1e-9);  // radial = normal on a circle
  // footprint: the outline ellipse (pi a b) on the cylinder (its arc length is t); top: shrunk by the ramp
  EXPECT_NEAR(t.footprint_area / (M_PI * 0.006 * 0.005), 1.0, 0.01);
  EXPECT_LT(t.top_area, t.footprint_area);
  EXPECT_NEAR(t.top_area / (M_PI * 0.005 * 0.004), 1.0, 0.03);
  EXPECT_LT(t.mean_height, t.top_height);
  EXPECT_GT(t.mean_height, 0.5 * t.top_height);
  EXPECT_NEAR(t.volume, t.mean_height * t.footprint_area, 1e-15);
  EXPECT_NEAR(t.top_point.z(), 0.04 + 0.6e-3, 1e-9);
  EXPECT_NEAR(t.centroid.x(), 0.01, 1e-5);
  // a dome puts the peak at the centre, the mean lower than a flat top's
  const SkinScene domed(circularLimb(0.5), 7);
  const auto d = domed.plaqueTruth(0, 20e-6);
  EXPECT_NEAR(d.top_height, 0.6e-3, 1e-9);
  EXPECT_LT(d.mean_height, t.mean_height);
}

TEST(SimSkin, DistanceToAnEllipticBaseIsExact) {
  SkinGeometry g;
  g.semi_axis_y = 0.05;
  g.semi_axis_z = 0.035;
  const SkinScene scene(g, 1);
  for (double phi : {-1.2, -0.5, 0.0, 0.3, 1.0}) {
    const Eigen::Vector3d base(0.0, 0.05 * std::sin(phi), 0.035 * std::cos(phi));
    for (double delta : {-0.5e-3, 0.0, 0.3e-3, 1.5e-3})
      EXPECT_NEAR(scene.distanceToBase(base + delta * scene.baseNormal(phi)), delta, 1e-10) << phi << " " << delta;
  }
}

TEST(SimSkin, RandomScenesAreDeterministicAndCoverTheRange) {
  const SkinGeometry a = skin3d::sim::randomSkinGeometry(3), b = skin3d::sim::randomSkinGeometry(3);
  ASSERT_EQ(a.plaques.size(), 5u);
  EXPECT_EQ(a.semi_axis_y, b.semi_axis_y);
  for (std::size_t i = 0; i < a.plaques.size(); ++i) EXPECT_EQ(a.plaques[i].height, b.plaques[i].height);
  int below = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const SkinGeometry g = skin3d::sim::randomSkinGeometry(seed);
    EXPECT_GE(g.semi_axis_y, 0.03);
    EXPECT_LE(g.semi_axis_y, 0.06);
    for (const auto& p : g.plaques) {
      EXPECT_GE(p.height, 0.05e-3);
      EXPECT_LE(p.height, 1.5e-3);
      for (double bd : {0.125e-3, 0.375e-3, 0.625e-3, 0.875e-3}) EXPECT_GE(std::fabs(p.height - bd), 0.02e-3 - 1e-12);
      below += p.height < 0.1e-3;
      EXPECT_LE(std::fabs(p.centre.y() / g.meanRadius()), 55.0 * M_PI / 180.0 + 1e-12);
    }
    SkinScene scene(g, seed);  // valid
  }
  EXPECT_EQ(below, 20) << "one plaque below the 0.1 mm bar per scene";
}

TEST(SimSkin, BadGeometryIsNamed) {
  SkinGeometry g = circularLimb();
  g.plaques[0].ramp = 0.01;  // wider than the plaque
  expectRefusedNaming(g, "plaques[0].ramp");
}

TEST(SimSkin, ARidgeIsHealthyReliefUnderThePlaquesOnIt) {
  // a ridge along the axis over the top of the limb (a nose's bridge), 2 mm high, sigma 3 mm, 60 mm long, with the
  // first plaque (at s = 10 mm on the top) on its crest
  SkinGeometry g = circularLimb();
  skin3d::sim::SkinRidge r;
  r.centre = Eigen::Vector2d(0.0, 0.0);
  r.length = 0.06;
  r.width = 0.003;
  r.height = 2e-3;
  g.ridges.push_back(r);
  const SkinScene scene(g, 7);
  // the relief: the full height on its line, exp(-1/2) one width across, rounded ends beyond +-30 mm
  EXPECT_NEAR(scene.reliefAt(-0.02, 0.0), 2e-3, 1e-12);
  EXPECT_NEAR(scene.reliefAt(-0.02, 0.003 / 0.04), 2e-3 * std::exp(-0.5), 1e-12);
  EXPECT_NEAR(scene.reliefAt(0.033, 0.0), 2e-3 * std::exp(-0.5), 1e-12);
  // a ray straight down onto the ridge away from the plaques meets R + 2 mm; onto the plaque on it R + 2.6 mm
  Hit hit;
  ASSERT_TRUE(scene.intersect(Eigen::Vector3d(-0.02, 0.0, 0.3), Eigen::Vector3d(0, 0, -1), &hit));
  EXPECT_NEAR(hit.point.z(), 0.04 + 2e-3, 1e-8);
  ASSERT_TRUE(scene.intersect(Eigen::Vector3d(0.01, 0.0, 0.3), Eigen::Vector3d(0, 0, -1), &hit));
  EXPECT_NEAR(hit.point.z(), 0.04 + 2.6e-3, 1e-8);
  // the plaque's truth is its height above the skin around it (the ridge's relief taken off), not above the limb
  const auto t = scene.plaqueTruth(0, 20e-6);
  const auto bare = SkinScene(circularLimb(), 7).plaqueTruth(0, 20e-6);
  EXPECT_NEAR(t.top_height, 0.6e-3, 1e-6);
  EXPECT_NEAR(t.mean_height, bare.mean_height, 2e-6);
  EXPECT_NEAR(t.footprint_area, bare.footprint_area, 1e-9);
  // the side plaque, far from the ridge (45 deg around: 31 mm = 10 widths), keeps its truth exactly
  EXPECT_NEAR(scene.plaqueTruth(1, 20e-6).top_height, SkinScene(circularLimb(), 7).plaqueTruth(1, 20e-6).top_height, 1e-12);
  // a bad ridge is named
  g.ridges[0].height = 0;
  expectRefusedNaming(g, "ridges[0].height");
}
