// SPDX-License-Identifier: BSD-3-Clause
// The induration measurement on synthetic organised clouds whose truth comes from the generator below:
// a pinhole camera looking at a tilted (optionally curved) skin surface with raised square plaques, points
// found by intersecting each pixel's ray with the true surface, then noise along the ray (seeded).
#include "skin3d/induration/induration.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

using namespace skin3d;
using induration::IndurationOptions;
using induration::measureInduration;

namespace {

struct Box {
  double u, v, half, height;  // centre (m, in-surface coordinates), half side (m), height (m)
};

struct Scene {
  Eigen::Vector3d origin = Eigen::Vector3d(0, 0, 0.25);  // surface point on the optical axis
  Eigen::Vector3d normal, e1, e2;                         // normal towards the camera
  double curvature = 0.0;                                 // 1/m: height offset 0.5 c (u^2 + v^2) along the normal
  std::vector<Box> boxes;
  double noise = 5e-6;                                    // m along the ray
  int width = 400, height = 300;
  double f = 700;
  std::uint64_t seed = 7;
  bool outliers = false;

  Scene() {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                              Eigen::AngleAxisd(-0.1, Eigen::Vector3d::UnitX()).toRotationMatrix();
    normal = R * Eigen::Vector3d(0, 0, -1);
    e1 = R * Eigen::Vector3d::UnitX();
    e2 = R * Eigen::Vector3d::UnitY();
  }
  double surface(double u, double v) const {  // height above the base plane (m)
    double h = 0.5 * curvature * (u * u + v * v);
    for (const auto& b : boxes)
      if (std::fabs(u - b.u) <= b.half && std::fabs(v - b.v) <= b.half) h += b.height;
    return h;
  }
  /** Ray-surface intersection by fixed-point iteration on the height (the surface is nearly flat). */
  stereo::DenseCloud cloud() const {
    stereo::DenseCloud c;
    c.xyz = cv::Mat(height, width, CV_32FC3, cv::Scalar::all(std::nan("")));
    c.sigma = cv::Mat(height, width, CV_32F, cv::Scalar(noise));
    c.ray = cv::Mat(height, width, CV_32FC3);
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> n(0.0, 1.0);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const Eigen::Vector3d r = Eigen::Vector3d((x - width / 2.0) / f, (y - height / 2.0) / f, 1).normalized();
        c.ray.at<cv::Vec3f>(y, x) = cv::Vec3f(r.x(), r.y(), r.z());
        double h = 0;
        Eigen::Vector3d X;
        for (int it = 0; it < 6; ++it) {
          // plane offset by h along the normal: n.(X - origin) = h
          const double t = (h + normal.dot(origin)) / normal.dot(r);
          X = t * r;
          const Eigen::Vector3d q = X - origin;
          h = surface(q.dot(e1), q.dot(e2));
        }
        X += r * (noise * n(rng));
        if (outliers && uni(rng) < 0.002) X += r * 0.01;  // gross mismatches, 10 mm along the ray
        c.xyz.at<cv::Vec3f>(y, x) = cv::Vec3f(X.x(), X.y(), X.z());
      }
    return c;
  }
};

double truthArea(const Box& b) { return 4 * b.half * b.half; }

}  // namespace

TEST(Induration, PasiClassesAreTheNearestCardStep) {
  const std::vector<double> b = IndurationOptions().pasi_boundaries;
  // documented: 0 below 0.125 mm, 1 to 0.375, 2 to 0.625, 3 to 0.875, 4 above
  EXPECT_EQ(induration::pasiClass(0.0, b), 0);
  EXPECT_EQ(induration::pasiClass(0.124e-3, b), 0);
  EXPECT_EQ(induration::pasiClass(0.126e-3, b), 1);
  EXPECT_EQ(induration::pasiClass(0.5e-3, b), 2);
  EXPECT_EQ(induration::pasiClass(0.7e-3, b), 3);
  EXPECT_EQ(induration::pasiClass(1.5e-3, b), 4);
  EXPECT_EQ(induration::pasiClass(-0.3e-3, b), 0);
}

TEST(Induration, PlaquesOnATiltedPlane) {
  Scene s;
  s.boxes = {{-0.02, -0.012, 0.006, 0.15e-3}, {0.0, 0.012, 0.007, 0.4e-3}, {0.02, -0.01, 0.005, 0.8e-3}};
  s.outliers = true;
  const auto r = measureInduration(s.cloud(), IndurationOptions());
  ASSERT_TRUE(r.reference_ok);
  for (const auto& c : r.reference.candidates) std::printf("candidate %s: %.2f um\n", c.first.c_str(), c.second * 1e6);
  EXPECT_EQ(r.reference.model, "plane") << "a plane is a plane";
  EXPECT_GT(r.outliers_removed, 0);
  EXPECT_LT(r.reference.rms, 3 * s.noise);
  EXPECT_GT(std::fabs(r.reference.normal.dot(s.normal)), 0.9999);
  ASSERT_EQ(r.plaques.size(), s.boxes.size());
  for (const auto& b : s.boxes) {
    const Eigen::Vector3d c = s.origin + b.u * s.e1 + b.v * s.e2 + b.height * s.normal;
    const induration::Plaque* best = nullptr;
    for (const auto& p : r.plaques)
      if ((p.centroid - c).norm() < 1e-3) best = &p;
    ASSERT_NE(best, nullptr) << "box of " << b.height * 1e3 << " mm not found";
    EXPECT_NEAR(best->mean_height, b.height, 3e-6);
    EXPECT_NEAR(best->area / truthArea(b), 1.0, 0.05);
    EXPECT_EQ(best->pasi_class, induration::pasiClass(b.height, IndurationOptions().pasi_boundaries));
    EXPECT_GE(best->max_height, best->mean_height);
    EXPECT_LT(best->std_height, 3 * s.noise);
    EXPECT_GT(best->mean_height_sigma, 0.0);
  }
  // labels mark the plaques, the height map is in metres
  EXPECT_EQ(r.labels.type(), CV_32S);
  EXPECT_EQ(r.height_map.type(), CV_32F);
  double maxl = 0;
  cv::minMaxLoc(r.labels, nullptr, &maxl);
  EXPECT_EQ(static_cast<int>(maxl), static_cast<int>(r.plaques.size()));
}

TEST(Induration, CurvedSkinNeedsTheQuadraticReference) {
  Scene s;
  s.curvature = 1.0 / 0.3;  // a 300 mm radius: forearm-like; 0.5 c u^2 = 0.6 mm at 20 mm from the centre
  s.boxes = {{0.008, 0.0, 0.006, 0.3e-3}};
  IndurationOptions o;
  o.reference_model = "quadratic";
  const auto r = measureInduration(s.cloud(), o);
  ASSERT_TRUE(r.reference_ok);
  ASSERT_EQ(r.plaques.size(), 1u) << "the curvature must not be taken for plaques";
  EXPECT_NEAR(r.plaques[0].mean_height, 0.3e-3, 0.01e-3);
  // with the plane model the curved skin itself stands out or the height is biased
  IndurationOptions plane;
  plane.reference_model = "plane";
  const auto rp = measureInduration(s.cloud(), plane);
  bool wrong = rp.plaques.size() != 1;
  if (!wrong) wrong = std::fabs(rp.plaques[0].mean_height - 0.3e-3) > 0.01e-3;
  EXPECT_TRUE(wrong) << "the test scene is not curved enough to tell the models apart";
  // the default (auto) sees that the skin is curved and measures against the quadric surface
  const auto ra = measureInduration(s.cloud(), IndurationOptions());
  ASSERT_TRUE(ra.reference_ok);
  for (const auto& c : ra.reference.candidates) std::printf("candidate %s: %.2f um\n", c.first.c_str(), c.second * 1e6);
  EXPECT_EQ(ra.reference.model, "quadric");
  ASSERT_EQ(ra.plaques.size(), 1u);
  EXPECT_NEAR(ra.plaques[0].mean_height, 0.3e-3, 0.01e-3);
}

TEST(Induration, NoHealthySkinLeftIsAWarning) {
  // four plaques of different heights, healthy skin around them
  Scene s;
  s.width = 300;
  s.height = 300;
  const double c = 0.02, h = 0.015;  // four 30 mm squares: about a third of the view
  s.boxes = {{-c, -c, h, 0.5e-3}, {c, -c, h, 1.0e-3}, {-c, c, h, 1.5e-3}, {c, c, h, 2.0e-3}};
  IndurationOptions o;
  o.min_reference_fraction = 0.8;  // demand more healthy skin than this view has
  const auto r = measureInduration(s.cloud(), o);
  bool named = false;
  for (const auto& w : r.warnings) named |= w.find("no healthy skin left") != std::string::npos;
  EXPECT_FALSE(r.reference_ok);
  EXPECT_TRUE(named);
  EXPECT_TRUE(r.plaques.empty());
  // with the default demand the same view is measured: the cross and rim are the reference
  const auto ok = measureInduration(s.cloud(), IndurationOptions());
  EXPECT_TRUE(ok.reference_ok);
  EXPECT_EQ(ok.plaques.size(), 4u);
}

TEST(Induration, EmptyAndTinyCloudsAreWarningsNotCrashes) {
  stereo::DenseCloud empty;
  auto r = measureInduration(empty, IndurationOptions());
  EXPECT_FALSE(r.reference_ok);
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("empty"), std::string::npos);

  Scene s;
  s.width = 20;
  s.height = 20;
  r = measureInduration(s.cloud(), IndurationOptions());
  EXPECT_FALSE(r.reference_ok);
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("too few"), std::string::npos);

  // a flat surface: a reference and no plaque, said so
  Scene flat;
  r = measureInduration(flat.cloud(), IndurationOptions());
  EXPECT_TRUE(r.reference_ok);
  EXPECT_TRUE(r.plaques.empty());
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings.back().find("no plaque"), std::string::npos);
}

TEST(Induration, BadOptionsNameTheOption) {
  IndurationOptions o;
  o.reference_model = "cubic";
  try {
    o.validate();
    FAIL();
  } catch (const induration::IndurationError& e) {
    EXPECT_NE(std::string(e.what()).find("reference_model"), std::string::npos);
  }
  o = IndurationOptions();
  o.pasi_boundaries = {0.5e-3, 0.25e-3, 0.75e-3, 1e-3};
  EXPECT_THROW(o.validate(), induration::IndurationError);
  o = IndurationOptions();
  o.edge_fraction = 1.5;
  EXPECT_THROW(o.validate(), induration::IndurationError);
}
