// SPDX-License-Identifier: BSD-3-Clause
// The site scan's fusion (site/site_fusion.h): its residual's Jacobian, the body surface's coordinates, and an orbit
// around a rendered limb (geometry from the simulator's SkinScene, truth from its plaqueTruth) fused and measured.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/induration/induration.h"
#include "skin3d/sim/skin.h"
#include "skin3d/site/site_fusion.h"
#include "site_test_scene.h"

using namespace skin3d;  // NOLINT(build/namespaces)

namespace {

constexpr double kDeg = M_PI / 180.0;

/** An orbit of views around a limb: clouds cast through the scene (the truth's geometry), noise along the rays. */
struct Orbit {
  sim::SkinScene scene;
  int width = 480, height = 360;
  double f = 1400;                 // px: 0.18 mm pixels at 250 mm
  double baseline = 0.1;           // m, the right camera's centre along x (for the incidence of both cameras)
  double distance = 0.25;          // m from the skin
  double noise = 10e-6;            // m along the ray
  explicit Orbit(const sim::SkinGeometry& g) : scene(g, 7) {}
  /** the left camera's pose in the limb frame, looking at the limb from angle a around its axis */
  Eigen::Isometry3d pose(double a) const {
    const Eigen::Vector3d out(0, std::sin(a), std::cos(a));  // from the axis towards the camera
    const double r = scene.geometry().meanRadius();
    Eigen::Matrix3d R;
    const Eigen::Vector3d z = -out, x = Eigen::Vector3d::UnitX(), y = z.cross(x);
    R.col(0) = x;
    R.col(1) = y;
    R.col(2) = z;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = R;
    T.translation() = (r + distance) * out;
    return T;
  }
  geometry::DenseCloud cloud(const Eigen::Isometry3d& T_W_C, std::uint64_t seed) const {
    return site_test::castCloud(scene, T_W_C, width, height, f, baseline, noise, seed);
  }
};

sim::SkinGeometry limbWithThreePlaques() {
  sim::SkinGeometry g;
  g.semi_axis_y = 0.045;
  g.semi_axis_z = 0.040;
  const double rm = g.meanRadius();
  const double heights[3] = {0.3e-3, 0.6e-3, 1.0e-3}, angles[3] = {-65 * kDeg, 0.0, 70 * kDeg};
  for (int k = 0; k < 3; ++k) {
    sim::SkinPlaque p;
    p.centre = Eigen::Vector2d(0.004 * (k - 1), rm * angles[k]);
    p.radii = Eigen::Vector2d(0.007, 0.0055);
    p.height = heights[k];
    p.ramp = 0.8e-3;
    p.irregularity = 0.1;
    p.shape_seed = 11 + k;
    g.plaques.push_back(p);
  }
  return g;
}

}  // namespace

TEST(SiteFusion, PointToPlaneJacobianMatchesNumericalDifferences) {
  const Eigen::Vector3d X(0.03, -0.02, 0.25), P(0.031, -0.018, 0.2495), n = Eigen::Vector3d(0.2, -0.3, 0.9).normalized();
  Eigen::Matrix<double, 1, 6> J;
  site::pointToPlane(X, P, n, &J);
  const double h = 1e-7;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d[k] = h;
    auto moved = [&](double s) {
      return Eigen::Vector3d(geometry::so3Exp(s * d.head<3>()) * X + s * d.tail<3>());
    };
    const double num = (site::pointToPlane(moved(1), P, n, nullptr) - site::pointToPlane(moved(-1), P, n, nullptr)) / (2 * h);
    EXPECT_NEAR(J[k], num, 1e-7) << "column " << k;
  }
}

TEST(SiteFusion, SurfaceCoordinatesRoundTrip) {
  site::SiteSurface c;
  c.model = "cylinder";
  c.origin = Eigen::Vector3d(0.01, 0.02, 0.3);
  c.axis = Eigen::Vector3d(1, 0.2, 0.1).normalized();
  c.e1 = c.axis.cross(Eigen::Vector3d::UnitZ()).normalized();
  c.e2 = c.axis.cross(c.e1);
  c.radius = 0.04;
  site::SiteSurface p = c;
  p.model = "plane";
  for (const auto* s : {&c, &p})
    for (const Eigen::Vector3d& X : {Eigen::Vector3d(0.02, 0.05, 0.31), Eigen::Vector3d(-0.03, -0.01, 0.27)}) {
      EXPECT_LT((s->toWorld(s->toSurface(X)) - X).norm(), 1e-12) << s->model;
    }
}

TEST(SiteFusion, AnOrbitIsFusedAndEachPlaqueMeasuredOnce) {
  const Orbit orbit(limbWithThreePlaques());
  induration::IndurationOptions io;
  site::SiteFusion fusion(site::SiteOptions(), io);
  // world = the first view's camera frame; poses given with errors a SLAM would leave (the registration removes them)
  const double angles[] = {-50, -33, -17, 0, 17, 33, 50};
  const Eigen::Isometry3d T_limb_C0 = orbit.pose(angles[0] * kDeg), T_C0_limb = T_limb_C0.inverse();
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n01(0, 1);
  for (int k = 0; k < 7; ++k) {
    const Eigen::Isometry3d T_limb_C = orbit.pose(angles[k] * kDeg);
    const geometry::DenseCloud cloud = orbit.cloud(T_limb_C, 100 + k);
    const induration::IndurationResult own = induration::measureInduration(cloud, io);
    Eigen::Isometry3d given = T_C0_limb * T_limb_C;
    if (k > 0) {
      Eigen::Isometry3d err = Eigen::Isometry3d::Identity();
      err.linear() = geometry::so3Exp(Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * 1e-3);
      err.translation() = Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * 0.2e-3;
      given = given * err;
    }
    const site::SiteFrame& f = fusion.add(cloud, own, given, k * 0.25);
    ASSERT_TRUE(f.fused) << "frame " << k << ": " << f.reason;
    if (k > 0) {
      EXPECT_LT(f.seam_excess, 5e-6) << "frame " << k << " disagrees with the site after registration (" << f.seam_rms * 1e6
                                      << " um RMS, " << f.seam_noise * 1e6 << " um from the noise)";
    }
  }
  const site::SiteResult r = fusion.measure();
  EXPECT_EQ(r.surface.model, "cylinder");
  for (const auto& w : r.warnings) std::printf("warning: %s\n", w.c_str());
  std::printf("body %s scatter %.1f um; unrolled %s rms %.1f um, threshold %.3f mm, smoothing %.1f px\n", r.body_model.c_str(), r.body_rms * 1e6,
              r.flat.reference.model.c_str(), r.flat.reference.rms * 1e6, r.flat.detection_threshold * 1e3, r.flat.smoothing_px);
  ASSERT_EQ(r.plaques.size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    const sim::SkinPlaqueTruth t = orbit.scene.plaqueTruth(k);
    const Eigen::Vector3d c = T_C0_limb * t.centroid;
    const site::SitePlaque* m = nullptr;
    for (const auto& p : r.plaques)
      if ((p.centroid - c).norm() < 3e-3) m = &p;
    ASSERT_NE(m, nullptr) << "plaque " << k << " not found where it is";
    EXPECT_NEAR(m->top_height, t.top_height, 10e-6) << "plaque " << k;
    // the outline is drawn at half height (induration's edge_fraction 0.5): its area is the truth's at half height
    EXPECT_NEAR(m->area, t.half_height_area, 0.05 * t.half_height_area) << "plaque " << k;
    EXPECT_NEAR(m->volume, t.volume, 0.10 * t.volume) << "plaque " << k;
    EXPECT_GE(m->views, 1) << "plaque " << k;
  }
  // the live view: the whole turn of the limb in coarse cells, what was seen on the limb's surface, what was not empty
  const site::SitePreview pv = fusion.preview(40000);
  EXPECT_EQ(pv.model, "cylinder");
  EXPECT_EQ(pv.frames_fused, 7);
  ASSERT_FALSE(pv.height.empty());
  EXPECT_LE(pv.height.total(), 40000u * 1.1);
  int known = 0, unseen = 0;
  for (int j = 0; j < pv.height.rows; ++j)
    for (int i = 0; i < pv.height.cols; ++i) {
      const cv::Vec3f X = pv.world_xyz.at<cv::Vec3f>(j, i);
      if (!std::isfinite(pv.height.at<float>(j, i))) {
        EXPECT_EQ(pv.frames.at<uchar>(j, i), 0);
        ++unseen;
        continue;
      }
      ++known;
      EXPECT_GE(pv.frames.at<uchar>(j, i), 1);
      const Eigen::Vector3d L = T_limb_C0 * Eigen::Vector3d(X[0], X[1], X[2]);  // on the limb: between its semi-axes
      EXPECT_GT(std::hypot(L.y(), L.z()), 0.040 - 0.5e-3);
      EXPECT_LT(std::hypot(L.y(), L.z()), 0.045 + 1.5e-3);
    }
  EXPECT_GT(known, 0);
  EXPECT_GT(unseen, known / 4) << "the views cover about 220 deg of the turn: the back of the limb is not covered";
  for (std::size_t k = 0; k < 3; ++k) {  // each plaque stands out of the preview by about its height
    const sim::SkinPlaqueTruth t = orbit.scene.plaqueTruth(k);
    const Eigen::Vector3d c = T_C0_limb * t.centroid;
    float top = -1;
    for (int j = 0; j < pv.height.rows; ++j)
      for (int i = 0; i < pv.height.cols; ++i) {
        const cv::Vec3f X = pv.world_xyz.at<cv::Vec3f>(j, i);
        if (std::isfinite(X[0]) && (Eigen::Vector3d(X[0], X[1], X[2]) - c).norm() < 3e-3) top = std::max(top, pv.height.at<float>(j, i));
      }
    EXPECT_NEAR(top, t.top_height, 0.2 * t.top_height) << "plaque " << k << " in the preview";
  }
}

// The registration settles: a frame given 1 mrad and 0.2 mm off (each axis) is placed on the skin fused before,
// along the body's normal within half the samples' noise (10 um along the rays), and stops before its iteration
// limit. A limb is nearly a cylinder: sliding along and turning about its axis are held only by the skin's relief,
// the directions where undamped Gauss-Newton steps swing back and forth (they had run to the limit every time).
TEST(SiteFusion, TheRegistrationPlacesAFrameOnTheSkinFusedBefore) {
  const Orbit orbit(limbWithThreePlaques());
  induration::IndurationOptions io;
  const Eigen::Isometry3d T_limb_C0 = orbit.pose(-8 * kDeg), T_C0_limb = T_limb_C0.inverse();
  std::mt19937_64 rng(17);
  std::normal_distribution<double> n01(0, 1);
  for (int trial = 0; trial < 3; ++trial) {
    site::SiteFusion fusion(site::SiteOptions(), io);
    const geometry::DenseCloud c0 = orbit.cloud(T_limb_C0, 300 + trial);
    ASSERT_TRUE(fusion.add(c0, induration::measureInduration(c0, io), Eigen::Isometry3d::Identity(), 0).fused);
    const Eigen::Isometry3d truth = T_C0_limb * orbit.pose(10 * kDeg);
    const geometry::DenseCloud c1 = orbit.cloud(T_limb_C0 * truth, 400 + trial);
    Eigen::Isometry3d err = Eigen::Isometry3d::Identity();
    err.linear() = geometry::so3Exp(Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * 1e-3);
    err.translation() = Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * 0.2e-3;
    const site::SiteFrame& f = fusion.add(c1, induration::measureInduration(c1, io), truth * err, 0.25);
    ASSERT_TRUE(f.fused) << f.reason;
    double s2 = 0, g2 = 0, h2 = 0;
    long n = 0;
    for (int v = 0; v < c1.xyz.rows; v += 4)
      for (int u = 0; u < c1.xyz.cols; u += 4) {
        const cv::Vec3f p = c1.xyz.at<cv::Vec3f>(v, u);
        if (!std::isfinite(p[0])) continue;
        const Eigen::Vector3d X(p[0], p[1], p[2]);
        const Eigen::Vector3d e = f.pose * X - truth * X, L = T_limb_C0 * truth * X;
        const Eigen::Vector3d nrm = T_C0_limb.linear() * Eigen::Vector3d(0, L.y(), L.z()).normalized();
        s2 += e.squaredNorm();
        h2 += std::pow(e.dot(nrm), 2);
        g2 += (truth * err * X - truth * X).squaredNorm();
        ++n;
      }
    ASSERT_GT(n, 1000);
    const double placed = std::sqrt(s2 / n), given = std::sqrt(g2 / n);
    std::printf("trial %d: skin placed %.1f um RMS from the truth (given %.1f um), along the normal %.1f um, %d iterations\n", trial, placed * 1e6,
                given * 1e6, std::sqrt(h2 / n) * 1e6, f.registration_iterations);
    // along the body's normal (what the fused heights feel) far below one sample's noise; along the skin (held only by
    // its relief) under half a fusion cell (the pixel footprint, 0.18 mm)
    EXPECT_LT(std::sqrt(h2 / n), 0.5 * orbit.noise) << "trial " << trial;
    EXPECT_LT(placed, 0.1e-3) << "trial " << trial;
    EXPECT_LT(f.registration_iterations, site::SiteOptions().register_iterations) << "trial " << trial;
  }
}

TEST(SiteFusion, AFrameThatDoesNotOverlapIsLeftOutAndNamed) {
  const Orbit orbit(limbWithThreePlaques());
  induration::IndurationOptions io;
  site::SiteFusion fusion(site::SiteOptions(), io);
  const Eigen::Isometry3d T0 = orbit.pose(0);
  const geometry::DenseCloud c0 = orbit.cloud(T0, 1);
  ASSERT_TRUE(fusion.add(c0, induration::measureInduration(c0, io), Eigen::Isometry3d::Identity(), 0).fused);
  // the next view said to be 60 mm along the limb: nothing of it falls on the fused site
  const geometry::DenseCloud c1 = orbit.cloud(T0, 2);
  Eigen::Isometry3d far = Eigen::Isometry3d::Identity();
  far.translation() = T0.inverse().linear() * Eigen::Vector3d(0.3, 0, 0);
  const site::SiteFrame& f = fusion.add(c1, induration::measureInduration(c1, io), far, 0.25);
  EXPECT_FALSE(f.fused);
  EXPECT_NE(f.reason.find("overlaps the fused site"), std::string::npos) << f.reason;
  // an empty cloud
  const site::SiteFrame& e = fusion.add(geometry::DenseCloud(), induration::IndurationResult(), Eigen::Isometry3d::Identity(), 0.5);
  EXPECT_FALSE(e.fused);
  EXPECT_FALSE(e.reason.empty());
  const site::SiteResult r = fusion.measure();
  EXPECT_EQ(r.frames_fused, 1);
  EXPECT_EQ(r.frames_left_out, 2);
}

TEST(SiteOptions, ConfigFileListsExactlyTheKeysWithTheCodeDefaults) {
  const std::string path = std::string(SKIN3D_SOURCE_DIR) + "/config/site.yaml";
  // the file applied over options that differ from the defaults in every key gives the defaults back
  site::SiteOptions from_file;
  from_file.cell = 1e-3;
  from_file.max_incidence_deg = 50;
  from_file.register_frames = false;
  from_file.register_stride = 7;
  from_file.register_iterations = 3;
  from_file.min_overlap = 0.5;
  from_file.max_correction = 1e-3;
  from_file.seam_block = 4e-3;
  from_file.pose_graph = !site::SiteOptions().pose_graph;
  const site::SiteOptions defaults;
  for (const auto& k : site::siteOptionKeys())
    ASSERT_NE(site::getSiteOption(from_file, k), site::getSiteOption(defaults, k)) << "the test must change " << k;
  ASSERT_NO_THROW(site::applySiteOptions(&from_file, path));
  for (const auto& k : site::siteOptionKeys())
    EXPECT_EQ(site::getSiteOption(from_file, k), site::getSiteOption(defaults, k)) << "key " << k;
  std::ifstream f(path);
  std::vector<std::string> file_keys;
  std::string line;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#' || line[0] == ' ') continue;
    file_keys.push_back(line.substr(0, line.find(':')));
  }
  EXPECT_EQ(file_keys, site::siteOptionKeys());
  // a bad key or value is named
  site::SiteOptions o;
  try {
    site::setSiteOption(&o, "site_cel_mm", "1");
    ADD_FAILURE() << "an unknown key was taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("site_cel_mm"), std::string::npos) << e.what();
  }
  EXPECT_THROW(site::setSiteOption(&o, "site_register", "yes"), std::invalid_argument);
  EXPECT_THROW(site::setSiteOption(&o, "site_min_overlap", "-1"), std::invalid_argument);
}
