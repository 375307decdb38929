// SPDX-License-Identifier: BSD-3-Clause
//
// Tests of the ray-casting renderer (sim/render.h). Ground truth comes from geometry: closed-form ray
// intersections, ray marching against WorkpieceScene::heightAt, projections of known 3D points and edges
// with PinholeCamera::project, and the documented formulas of the realism chain.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <random>
#include <stdexcept>
#include <vector>

#include <opencv2/core.hpp>

#include "skin3d/sim/render.h"

namespace {

using skin3d::geometry::PinholeCamera;
using skin3d::sim::Hit;
using skin3d::sim::NoiseTexture;
using skin3d::sim::Plateau;
using skin3d::sim::RealismOptions;
using skin3d::sim::RenderOptions;
using skin3d::sim::Scene;
using skin3d::sim::SphereScene;
using skin3d::sim::WorkpieceScene;

constexpr double kPi = 3.14159265358979323846;

PinholeCamera makeCamera(double f, int w, int h, std::vector<double> D = {}) {
  Eigen::Matrix3d K;
  K << f, 0, 0.5 * (w - 1) + 3.25, 0, f * 1.001, 0.5 * (h - 1) - 2.5, 0, 0, 1;
  return PinholeCamera(K, w, h, std::move(D));
}

/** Camera looking straight down (-z of the world), image x along world +x, image y along world -y. */
Eigen::Isometry3d topDown(const Eigen::Vector3d& centre, double roll = 0.0) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  T.linear() = T.linear() * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = centre;
  return T;
}

/** Bilinear interpolation of a CV_32F image at a pixel position (pixel centres at integers). */
double bilinear(const cv::Mat& img, const Eigen::Vector2d& uv) {
  const int u0 = static_cast<int>(std::floor(uv.x())), v0 = static_cast<int>(std::floor(uv.y()));
  const double a = uv.x() - u0, b = uv.y() - v0;
  auto px = [&](int u, int v) { return static_cast<double>(img.at<float>(v, u)); };
  return (1 - b) * ((1 - a) * px(u0, v0) + a * px(u0 + 1, v0)) +
         b * ((1 - a) * px(u0, v0 + 1) + a * px(u0 + 1, v0 + 1));
}

bool insideMargin(const PinholeCamera& cam, const Eigen::Vector2d& uv, double m) {
  return uv.x() >= m && uv.y() >= m && uv.x() <= cam.width() - 1 - m && uv.y() <= cam.height() - 1 - m;
}

/** Independent closed form: nearest positive root of |o + t d - c| = r. */
bool sphereRoot(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& c, double r, double* t) {
  const double A = d.dot(d), B = 2 * d.dot(o - c), C = (o - c).squaredNorm() - r * r;
  const double disc = B * B - 4 * A * C;
  if (disc < 0) return false;
  const double t0 = (-B - std::sqrt(disc)) / (2 * A), t1 = (-B + std::sqrt(disc)) / (2 * A);
  *t = t0 > 0 ? t0 : t1;
  return *t > 0;
}

/** Delegates geometry to another scene, replaces the albedo (test hook for flat or analytic textures). */
class AlbedoOverride : public Scene {
 public:
  using Fn = std::function<float(const Hit&)>;
  AlbedoOverride(const Scene& inner, Fn fn) : inner_(inner), fn_(std::move(fn)) {}
  bool intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Hit* hit) const override {
    return inner_.intersect(o, d, hit);
  }
  float albedo(const Hit& hit) const override { return fn_(hit); }

 private:
  const Scene& inner_;
  Fn fn_;
};

// ============================================================================ (1) intersections

TEST(SimRender, SphereIntersectionMatchesClosedForm) {
  const Eigen::Vector3d c(0.1, -0.2, 0.6);
  const double r = 0.2;
  const SphereScene sphere(c, r, 3, 5e-3);
  Hit hit;
  // Straight at the centre: distance |c| - r, normal opposite to the ray.
  const Eigen::Vector3d o = Eigen::Vector3d::Zero();
  const Eigen::Vector3d d = c.normalized();
  ASSERT_TRUE(sphere.intersect(o, d, &hit));
  EXPECT_NEAR(hit.distance, c.norm() - r, 1e-12);
  EXPECT_LT((hit.normal + d).norm(), 1e-12);
  EXPECT_LT((hit.point - (c - r * d)).norm(), 1e-12);
  // Off-axis rays at angle theta from the centre direction: t = D cos(theta) - sqrt(r^2 - D^2 sin^2(theta)).
  const double D = c.norm();
  const Eigen::Vector3d perp = d.cross(Eigen::Vector3d::UnitX()).normalized();
  const double theta_max = std::asin(r / D);
  for (double f : {0.0, 0.3, 0.7, 0.99, 0.999999}) {
    const double th = f * theta_max;
    const Eigen::Vector3d di = (std::cos(th) * d + std::sin(th) * perp).normalized();
    ASSERT_TRUE(sphere.intersect(o, di, &hit)) << f;
    const double expect = D * std::cos(th) - std::sqrt(r * r - D * D * std::sin(th) * std::sin(th));
    EXPECT_NEAR(hit.distance, expect, 1e-9) << f;
    EXPECT_NEAR((hit.point - c).norm(), r, 1e-12);
    EXPECT_LT((hit.normal - (hit.point - c) / r).norm(), 1e-12);
  }
  // Grazing ray just outside the silhouette misses; pointing away misses.
  const double th = theta_max * (1 + 1e-6);
  EXPECT_FALSE(sphere.intersect(o, (std::cos(th) * d + std::sin(th) * perp).normalized(), &hit));
  EXPECT_FALSE(sphere.intersect(o, -d, &hit));
  // From inside (the centre): the far root, distance r.
  ASSERT_TRUE(sphere.intersect(c, Eigen::Vector3d::UnitY(), &hit));
  EXPECT_NEAR(hit.distance, r, 1e-12);
  // Random rays against the independent quadratic.
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n;
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d oi(0.3 * n(rng), 0.3 * n(rng), 0.3 * n(rng) - 0.2);
    const Eigen::Vector3d di = (c + Eigen::Vector3d(0.2 * n(rng), 0.2 * n(rng), 0.2 * n(rng)) - oi).normalized();
    double t;
    const bool expect = sphereRoot(oi, di, c, r, &t);
    ASSERT_EQ(sphere.intersect(oi, di, &hit), expect) << i;
    if (expect) {
      EXPECT_NEAR(hit.distance, t, 1e-10);
      ++hits;
    }
  }
  EXPECT_GT(hits, 500);
}

class WorkpieceGeometry : public ::testing::Test {
 protected:
  WorkpieceGeometry()
      : plate_(0.04, 0.03),
        p0_{Eigen::Vector2d(0.002, -0.003), Eigen::Vector2d(0.012, 0.008), 0.5e-3},
        p1_{Eigen::Vector2d(-0.011, 0.008), Eigen::Vector2d(0.006, 0.005), 0.1e-3},
        scene_(plate_, {p0_, p1_}, 9, 0.2e-3) {}
  Eigen::Vector2d plate_;
  Plateau p0_, p1_;
  WorkpieceScene scene_;
};

TEST_F(WorkpieceGeometry, ClosedFormHits) {
  Hit hit;
  const Eigen::Vector3d down(0, 0, -1);
  // Straight down onto a plateau top: z = height.
  ASSERT_TRUE(scene_.intersect(Eigen::Vector3d(0.004, -0.002, 0.1), down, &hit));
  EXPECT_NEAR(hit.point.z(), p0_.height, 1e-15);
  EXPECT_NEAR(hit.distance, 0.1 - p0_.height, 1e-15);
  EXPECT_EQ(hit.normal, Eigen::Vector3d::UnitZ());
  ASSERT_TRUE(scene_.intersect(Eigen::Vector3d(-0.011, 0.008, 0.05), down, &hit));
  EXPECT_NEAR(hit.point.z(), p1_.height, 1e-15);
  // Straight down onto the plate.
  ASSERT_TRUE(scene_.intersect(Eigen::Vector3d(0.015, 0.01, 0.1), down, &hit));
  EXPECT_NEAR(hit.point.z(), 0.0, 1e-15);
  EXPECT_NEAR(hit.distance, 0.1, 1e-15);
  // Outside the plate: miss (also obliquely onto z = 0 outside the extent).
  EXPECT_FALSE(scene_.intersect(Eigen::Vector3d(0.025, 0.0, 0.1), down, &hit));
  EXPECT_FALSE(scene_.intersect(Eigen::Vector3d(0.0, 0.0, 0.1), Eigen::Vector3d(0.3, 0.0, -0.1).normalized(), &hit));
  // Upwards or parallel above everything: miss.
  EXPECT_FALSE(scene_.intersect(Eigen::Vector3d(0.0, 0.0, 0.1), Eigen::Vector3d::UnitZ(), &hit));
  // Grazing: horizontal ray just above the plateau top misses; just below hits the wall.
  const double x0 = p0_.centre.x() - 0.5 * p0_.size.x();
  EXPECT_FALSE(scene_.intersect(Eigen::Vector3d(-0.019, p0_.centre.y(), p0_.height * (1 + 1e-9)),
                                Eigen::Vector3d::UnitX(), &hit));
  ASSERT_TRUE(scene_.intersect(Eigen::Vector3d(-0.019, p0_.centre.y(), p0_.height * (1 - 1e-9)),
                               Eigen::Vector3d::UnitX(), &hit));
  EXPECT_NEAR(hit.point.x(), x0, 1e-15);
  EXPECT_EQ(hit.normal, Eigen::Vector3d(-1, 0, 0));
  // Oblique rays aimed at the middle of each of the four walls: hit there with the outward normal.
  const double hx = 0.5 * p0_.size.x(), hy = 0.5 * p0_.size.y(), zc = 0.5 * p0_.height;
  const Eigen::Vector3d cen(p0_.centre.x(), p0_.centre.y(), zc);
  const Eigen::Vector3d walls[4] = {{-hx, 0, 0}, {hx, 0, 0}, {0, -hy, 0}, {0, hy, 0}};
  for (const auto& w : walls) {
    const Eigen::Vector3d target = cen + w + Eigen::Vector3d(0.3 * w.y(), 0.3 * w.x(), 0);  // off-centre along the wall
    const Eigen::Vector3d nrm = w.normalized();
    const Eigen::Vector3d dir = (-nrm * std::cos(0.4) - Eigen::Vector3d::UnitZ() * std::sin(0.4)).normalized();
    const Eigen::Vector3d origin = target - 0.005 * dir;
    ASSERT_TRUE(scene_.intersect(origin, dir, &hit)) << w.transpose();
    EXPECT_NEAR((hit.point - target).norm(), 0.0, 1e-12) << w.transpose();
    EXPECT_NEAR(hit.distance, 0.005, 1e-12);
    EXPECT_LT((hit.normal - nrm).norm(), 1e-15) << w.transpose() << " / " << hit.normal.transpose();
  }
  // heightAt.
  EXPECT_EQ(scene_.heightAt(Eigen::Vector2d(0.004, -0.002)), p0_.height);
  EXPECT_EQ(scene_.heightAt(Eigen::Vector2d(-0.011, 0.008)), p1_.height);
  EXPECT_EQ(scene_.heightAt(Eigen::Vector2d(0.015, 0.01)), 0.0);
  EXPECT_EQ(scene_.plateaus().size(), 2u);
}

TEST_F(WorkpieceGeometry, RandomRaysAgreeWithRayMarching) {
  // The first point along the ray where z <= heightAt(x, y) inside the plate, found by marching in 0.1 um
  // steps (from where the ray comes down to the highest plateau) and bisection: independent of the box /
  // plane intersection code.
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> U(-1, 1);
  int n_top = 0, n_wall = 0, n_plate = 0, n_miss = 0;
  const double h_max = std::max(p0_.height, p1_.height);
  auto below = [&](const Eigen::Vector3d& p) {
    return std::abs(p.x()) <= 0.5 * plate_.x() && std::abs(p.y()) <= 0.5 * plate_.y() &&
           p.z() <= scene_.heightAt(p.head<2>());
  };
  for (int i = 0; i < 3000; ++i) {
    // Rays from 1.5 mm above the plate at steep to grazing angles, aimed near the plateaus.
    const Eigen::Vector3d target(p0_.centre.x() + 0.009 * U(rng), p0_.centre.y() + 0.007 * U(rng), 0.0);
    const double elev = 0.05 + 1.45 * (0.5 + 0.5 * U(rng)), az = kPi * U(rng);
    const Eigen::Vector3d dir(-std::cos(elev) * std::cos(az), -std::cos(elev) * std::sin(az), -std::sin(elev));
    const Eigen::Vector3d origin = target - (0.0015 / std::sin(elev)) * dir;
    Hit hit;
    const bool got = scene_.intersect(origin, dir, &hit);
    double t_hit = -1;
    const double t0 = (origin.z() - h_max) / std::sin(elev) - 1e-7, t1 = origin.z() / std::sin(elev) + 1e-7;
    for (double t = t0; t < t1; t += 1e-7) {
      if (below(origin + t * dir)) {
        double a = t - 1e-7, b = t;
        for (int k = 0; k < 60; ++k) (below(origin + 0.5 * (a + b) * dir) ? b : a) = 0.5 * (a + b);
        t_hit = b;
        break;
      }
    }
    ASSERT_EQ(got, t_hit >= 0) << i;
    if (!got) {
      ++n_miss;
      continue;
    }
    EXPECT_NEAR(hit.distance, t_hit, 1e-9) << i;
    EXPECT_LT((hit.point - (origin + hit.distance * dir)).norm(), 1e-15);
    if (hit.normal.z() == 1.0) {
      EXPECT_NEAR(hit.point.z(), scene_.heightAt(hit.point.head<2>()), 1e-12) << i;
      (hit.point.z() > 0 ? n_top : n_plate)++;
    } else {
      ++n_wall;
      EXPECT_EQ(hit.normal.z(), 0.0);
      EXPECT_EQ(hit.normal.norm(), 1.0);
      EXPECT_LT(hit.normal.dot(dir), 0.0) << "a wall is seen from outside";
      EXPECT_GE(hit.point.z(), -1e-15);
      EXPECT_LE(hit.point.z(), p0_.height + 1e-15);
    }
  }
  EXPECT_GT(n_top, 300);
  EXPECT_GT(n_wall, 30);
  EXPECT_GT(n_plate, 300);
  EXPECT_LT(n_miss, 300);
  std::printf("marching: %d top, %d wall, %d plate, %d miss\n", n_top, n_wall, n_plate, n_miss);
}

TEST(SimRender, BadArgumentsThrow) {
  EXPECT_THROW(SphereScene(Eigen::Vector3d::Zero(), -1.0, 1), std::invalid_argument);
  EXPECT_THROW(SphereScene(Eigen::Vector3d::Zero(), 0.1, 1, 0.0), std::invalid_argument);
  EXPECT_THROW(WorkpieceScene(Eigen::Vector2d(0.0, 0.1), {}, 1), std::invalid_argument);
  Plateau bad;
  bad.height = -1e-4;
  EXPECT_THROW(WorkpieceScene(Eigen::Vector2d(0.01, 0.01), {bad}, 1, 1e-4), std::invalid_argument);
  NoiseTexture nt;
  nt.octaves = 0;
  EXPECT_THROW(nt.at(Eigen::Vector3d::Zero()), std::invalid_argument);
  const SphereScene s(Eigen::Vector3d(0, 0, 1), 0.1, 1, 5e-3);
  RenderOptions o;
  o.supersample = 0;
  EXPECT_THROW(renderIrradiance(s, makeCamera(100, 32, 24), Eigen::Isometry3d::Identity(), o), std::invalid_argument);
  EXPECT_THROW(renderIrradiance(s, PinholeCamera(), Eigen::Isometry3d::Identity()), std::invalid_argument);
  const cv::Mat img(8, 8, CV_32F, cv::Scalar(0.5));
  RealismOptions r = RealismOptions::ideal();
  r.vignetting = 1.0;
  EXPECT_THROW(applyRealism(img, r, 1), std::invalid_argument);
  r = RealismOptions::ideal();
  r.gamma = 0.0;
  EXPECT_THROW(applyRealism(img, r, 1), std::invalid_argument);
  EXPECT_THROW(applyRealism(cv::Mat(8, 8, CV_8U, cv::Scalar(1)), RealismOptions::ideal(), 1), std::invalid_argument);
}

// ============================================================================ rendering basics

TEST(SimRender, BackgroundWhereNothingIsHitAndShading) {
  const SphereScene sphere(Eigen::Vector3d(0, 0, 0.5), 0.1, 1, 5e-3);
  const PinholeCamera cam = makeCamera(200, 64, 48);
  RenderOptions o;
  o.background = 0.125f;
  Eigen::Isometry3d away = Eigen::Isometry3d::Identity();
  away.linear() = Eigen::AngleAxisd(kPi, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const cv::Mat img = renderIrradiance(sphere, cam, away, o);
  ASSERT_EQ(img.type(), CV_32FC1);
  ASSERT_EQ(img.cols, 64);
  ASSERT_EQ(img.rows, 48);
  double lo, hi;
  cv::minMaxLoc(img, &lo, &hi);
  EXPECT_FLOAT_EQ(lo, 0.125f);
  EXPECT_FLOAT_EQ(hi, 0.125f);
  // Shading: constant albedo 1, the light along the ray of the image centre: the centre pixel is
  // ambient + (1 - ambient) * cos(incidence), with the incidence from the closed-form hit.
  const AlbedoOverride white(sphere, [](const Hit&) { return 1.0f; });
  o.ambient = 0.2;
  o.supersample = 1;
  o.light_dir = Eigen::Vector3d(0.3, 0.1, 1.0).normalized();
  const cv::Mat lit = renderIrradiance(white, cam, Eigen::Isometry3d::Identity(), o);
  for (const Eigen::Vector2i& px : {Eigen::Vector2i(35, 21), Eigen::Vector2i(30, 30), Eigen::Vector2i(40, 15)}) {
    const Eigen::Vector3d ray = cam.unproject(px.cast<double>()).normalized();
    double t;
    ASSERT_TRUE(sphereRoot(Eigen::Vector3d::Zero(), ray, Eigen::Vector3d(0, 0, 0.5), 0.1, &t));
    const Eigen::Vector3d n = (t * ray - Eigen::Vector3d(0, 0, 0.5)) / 0.1;
    const double expect = 0.2 + 0.8 * std::max(0.0, -n.dot(o.light_dir));
    EXPECT_NEAR(lit.at<float>(px.y(), px.x()), expect, 1e-6);
  }
}

/** The plane z = 1 (world), seen from the origin; albedo = x or y of the hit point (test hook for rays). */
class RayProbe : public Scene {
 public:
  explicit RayProbe(int axis) : axis_(axis) {}
  bool intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Hit* hit) const override {
    if (d.z() <= 0) return false;
    hit->distance = (1.0 - o.z()) / d.z();
    hit->point = o + hit->distance * d;
    hit->normal = -Eigen::Vector3d::UnitZ();
    return true;
  }
  float albedo(const Hit& hit) const override { return static_cast<float>(hit.point[axis_]); }

 private:
  int axis_;
};

TEST(SimRender, SampleRaysAreCameraUnprojectOfTheSubPixelGrid) {
  // Pixel value = mean over the s x s sub-pixel grid (u + (i + 0.5)/s - 0.5, ...) of the ray's x (or y) at
  // z = 1, i.e. of camera.unproject: checks the sample positions, the pixel-centre convention and the
  // renderer's own (warm-started) undistortion against PinholeCamera::unproject, for a strongly distorted
  // camera and any number of threads.
  const PinholeCamera cam = makeCamera(300, 80, 60, {-0.3, 0.1, 0.002, -0.001, 0.01});
  RenderOptions o;
  o.ambient = 1.0;
  for (int s : {1, 3}) {
    for (int threads : {1, 2}) {
      o.supersample = s;
      o.threads = threads;
      for (int axis : {0, 1}) {
        const cv::Mat img = renderIrradiance(RayProbe(axis), cam, Eigen::Isometry3d::Identity(), o);
        double worst = 0;
        for (int v = 0; v < cam.height(); ++v) {
          for (int u = 0; u < cam.width(); ++u) {
            double mean = 0;
            for (int j = 0; j < s; ++j) {
              for (int i = 0; i < s; ++i) {
                const Eigen::Vector2d uv(u + (i + 0.5) / s - 0.5, v + (j + 0.5) / s - 0.5);
                mean += cam.unproject(uv)[axis] / (s * s);
              }
            }
            worst = std::max(worst, std::abs(img.at<float>(v, u) - mean));
          }
        }
        EXPECT_LT(worst, 1e-6) << "s " << s << " threads " << threads << " axis " << axis;
      }
    }
  }
}

class Throwing : public RayProbe {
 public:
  Throwing() : RayProbe(0) {}
  float albedo(const Hit& hit) const override {
    if (hit.point.x() > 0.1) throw std::runtime_error("boom");
    return 0.5f;
  }
};

TEST(SimRender, ExceptionInTheSceneReachesTheCaller) {
  RenderOptions o;
  o.threads = 2;
  EXPECT_THROW(renderIrradiance(Throwing(), makeCamera(100, 64, 48), Eigen::Isometry3d::Identity(), o),
               std::runtime_error);
}

// ============================================================================ (2) consistency between views

TEST(SimRender, SphereTextureIsOnTheSurfaceBothViewsAgree) {
  // Small globe, close parallel stereo pair with pixels (25 um) much finer than the texture, so a
  // surface point must have the same irradiance in both views (texture on the surface, shading
  // view-independent). The globe is turned (setOrientation) to exercise the body-frame lookup.
  const Eigen::Vector3d c(0.004, -0.003, 0.15);
  const double r = 0.05;
  SphereScene globe(c, r, 42);
  globe.setOrientation(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix());
  const PinholeCamera cam = makeCamera(4000, 640, 480);
  const Eigen::Isometry3d T_left = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_right = Eigen::Isometry3d::Identity();
  T_right.translation() = Eigen::Vector3d(0.005, 0.0, 0.0);
  RenderOptions o;
  o.light_dir = Eigen::Vector3d(0.3, -0.5, 1.0).normalized();  // lights the side facing the cameras
  const cv::Mat L = renderIrradiance(globe, cam, T_left, o);
  const cv::Mat R = renderIrradiance(globe, cam, T_right, o);

  std::vector<double> diff, shifted, values;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 15; ++j) {
      const Eigen::Vector2d uvL(20 + i * 30.3, 20 + j * 30.1);
      const Eigen::Vector3d ray = cam.unproject(uvL).normalized();
      double t;
      if (!sphereRoot(Eigen::Vector3d::Zero(), ray, c, r, &t)) continue;
      const Eigen::Vector3d X = t * ray;
      const Eigen::Vector3d cR = T_right.translation();
      if ((X - c).dot(cR - X) <= 0) continue;  // facing away from the right camera
      const Eigen::Vector2d uvR = cam.project(T_right.inverse() * X);
      if (!insideMargin(cam, uvR, 4) || !insideMargin(cam, uvL, 4)) continue;
      const double a = bilinear(L, uvL), b = bilinear(R, uvR);
      diff.push_back(std::abs(a - b));
      shifted.push_back(std::abs(a - bilinear(R, uvR + Eigen::Vector2d(3.0, -2.0))));
      values.push_back(a);
    }
  }
  ASSERT_GT(diff.size(), 100u);
  double mean = 0, mean_shift = 0, max = 0, vmean = 0, vvar = 0;
  for (std::size_t k = 0; k < diff.size(); ++k) {
    mean += diff[k] / diff.size();
    mean_shift += shifted[k] / diff.size();
    max = std::max(max, diff[k]);
    vmean += values[k] / diff.size();
  }
  for (double v : values) vvar += (v - vmean) * (v - vmean) / values.size();
  std::printf("views: %zu points, mean |diff| %.4g, max %.4g, wrong match %.4g, texture std %.3f\n", diff.size(), mean,
              max, mean_shift, std::sqrt(vvar));
  EXPECT_GT(std::sqrt(vvar), 0.03) << "the texture must vary, or the test proves nothing";
  EXPECT_LT(mean, 5e-4);
  EXPECT_LT(max, 3e-3);
  EXPECT_GT(mean_shift, 5 * mean) << "a 3.6 px wrong correspondence must be clearly worse";
}

TEST(SimRender, GlobeTextureTurnsWithTheGlobe) {
  // Turning the globe by R about its centre and moving the camera around the centre by the same R must give
  // the same image (no shading: ambient 1); a texture fixed in the world would not.
  const Eigen::Vector3d c(0.01, 0.02, 0.3);
  SphereScene globe(c, 0.1, 5, 0.5e-3);
  const PinholeCamera cam = makeCamera(500, 160, 120);
  RenderOptions o;
  o.ambient = 1.0;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.9, Eigen::Vector3d(0.2, 1.0, 0.3).normalized()).toRotationMatrix();
  const cv::Mat a = renderIrradiance(globe, cam, Eigen::Isometry3d::Identity(), o);
  globe.setOrientation(R);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = c - R * c;
  const cv::Mat b = renderIrradiance(globe, cam, T, o);
  const cv::Mat moved_camera_only = renderIrradiance(SphereScene(c, 0.1, 5, 0.5e-3), cam, T, o);
  EXPECT_LT(cv::norm(a, b, cv::NORM_INF), 1e-4);
  EXPECT_GT(cv::norm(a, moved_camera_only, cv::NORM_L1) / a.total(), 0.02);
}

// ============================================================================ (3) edge position

TEST(SimRender, PlateauEdgeAndWallLandWhereTheirProjectionSays) {
  // A plateau edge seen from above, slightly rolled so the edge crosses the sample grid at all
  // phases. Albedo override: 1 on one kind of face, 0 elsewhere, ambient 1 (no shading), so a row's
  // sum measures the face's extent with sub-pixel accuracy (area sampling by the s x s samples).
  const Plateau p{Eigen::Vector2d(0.002, 0.001), Eigen::Vector2d(0.010, 0.008), 0.7e-3};
  const WorkpieceScene wp(Eigen::Vector2d(0.04, 0.03), {p}, 3, 0.1e-3);
  const double x0 = p.centre.x() - 0.5 * p.size.x();
  const PinholeCamera cam = makeCamera(2000, 640, 480);
  const Eigen::Isometry3d T = topDown(Eigen::Vector3d(x0 - 0.004, p.centre.y(), 0.03), 0.05);
  const Eigen::Isometry3d T_cw = T.inverse();
  RenderOptions o;
  o.supersample = 8;
  o.ambient = 1.0;
  o.background = 0.0f;
  const AlbedoOverride top(wp, [](const Hit& h) { return h.normal.z() > 0.5 && h.point.z() > 0 ? 1.0f : 0.0f; });
  const AlbedoOverride wall(wp, [](const Hit& h) { return std::abs(h.normal.z()) < 0.5 ? 1.0f : 0.0f; });
  const cv::Mat It = renderIrradiance(top, cam, T, o);
  const cv::Mat Iw = renderIrradiance(wall, cam, T, o);

  // Projected edge lines: top edge (x0, y, h) and foot of the wall (x0, y, 0).
  auto lineU = [&](double z, double v) {
    const Eigen::Vector2d a = cam.project(T_cw * Eigen::Vector3d(x0, p.centre.y() - 0.003, z));
    const Eigen::Vector2d b = cam.project(T_cw * Eigen::Vector3d(x0, p.centre.y() + 0.003, z));
    return a.x() + (v - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
  };
  double err_sum = 0, err_max = 0, werr_sum = 0, werr_max = 0;
  int rows = 0;
  for (int v = 60; v < 420; ++v) {
    const double e_top = lineU(p.height, v), e_foot = lineU(0.0, v);
    ASSERT_GT(e_top - e_foot, 5.0);  // the wall faces the camera: a band of > 5 px
    const int ua = static_cast<int>(e_foot) - 6, ub = static_cast<int>(e_top) + 6;
    ASSERT_GT(ua, 0);
    ASSERT_LT(ub, cam.width());
    double not_top = 0, wall_px = 0;
    for (int u = ua; u <= ub; ++u) {
      not_top += 1.0 - It.at<float>(v, u);
      wall_px += Iw.at<float>(v, u);
    }
    const double measured_edge = ua - 0.5 + not_top;
    const double err = measured_edge - e_top, werr = wall_px - (e_top - e_foot);
    err_sum += err;
    werr_sum += werr;
    err_max = std::max(err_max, std::abs(err));
    werr_max = std::max(werr_max, std::abs(werr));
    ++rows;
  }
  std::printf("edge: mean %.4f max %.4f px; wall width: mean %.4f max %.4f px\n", err_sum / rows, err_max,
              werr_sum / rows, werr_max);
  EXPECT_LT(std::abs(err_sum / rows), 0.01) << "mean edge position error, px";
  EXPECT_LT(err_max, 1.0 / 16 + 0.01) << "per-row edge error, px (s = 8 quantisation)";
  EXPECT_LT(std::abs(werr_sum / rows), 0.01) << "mean wall width error, px";
  EXPECT_LT(werr_max, 2.0 / 16 + 0.01);
}

// ============================================================================ (4) determinism

TEST(SimRender, DeterministicInSeed) {
  NoiseTexture a{0.01, 5, 0.5, 7}, b = a;
  b.seed = 8;
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> U(-0.1, 0.1);
  double sum = 0, sum2 = 0, diff = 0, lo = 1, hi = 0;
  const int N = 20000;
  for (int i = 0; i < N; ++i) {
    const Eigen::Vector3d q(U(rng), U(rng), U(rng));
    const double va = a.at(q);
    EXPECT_EQ(va, a.at(q));
    diff += std::abs(va - b.at(q)) / N;
    sum += va / N;
    sum2 += va * va / N;
    lo = std::min(lo, va);
    hi = std::max(hi, va);
  }
  EXPECT_GT(diff, 0.03);
  EXPECT_NEAR(sum, 0.5, 0.03);
  EXPECT_GT(std::sqrt(sum2 - sum * sum), 0.05);
  EXPECT_GE(lo, 0.0);
  EXPECT_LE(hi, 1.0);

  const PinholeCamera cam = makeCamera(500, 160, 120);
  RenderOptions one, two;
  one.threads = 1;
  two.threads = 2;
  {
    const SphereScene s1(Eigen::Vector3d(0, 0, 0.3), 0.1, 11, 1e-3), s2(Eigen::Vector3d(0, 0, 0.3), 0.1, 11, 1e-3),
        s3(Eigen::Vector3d(0, 0, 0.3), 0.1, 12, 1e-3);
    const cv::Mat i1 = renderIrradiance(s1, cam, Eigen::Isometry3d::Identity(), one);
    const cv::Mat i2 = renderIrradiance(s2, cam, Eigen::Isometry3d::Identity(), two);
    const cv::Mat i3 = renderIrradiance(s3, cam, Eigen::Isometry3d::Identity(), two);
    EXPECT_EQ(cv::norm(i1, i2, cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(i1, i3, cv::NORM_L1) / i1.total(), 0.02);
  }
  {
    const std::vector<Plateau> pl{Plateau()};
    const WorkpieceScene w1(Eigen::Vector2d(0.03, 0.02), pl, 5, 50e-6), w2(Eigen::Vector2d(0.03, 0.02), pl, 5, 50e-6),
        w3(Eigen::Vector2d(0.03, 0.02), pl, 6, 50e-6);
    const Eigen::Isometry3d T = topDown(Eigen::Vector3d(0.001, 0.0, 0.05));
    const cv::Mat i1 = renderIrradiance(w1, cam, T, one);
    const cv::Mat i2 = renderIrradiance(w2, cam, T, two);
    const cv::Mat i3 = renderIrradiance(w3, cam, T, two);
    EXPECT_EQ(cv::norm(i1, i2, cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(i1, i3, cv::NORM_L1) / i1.total(), 0.02);
    const RealismOptions real;
    const cv::Mat r1 = applyRealism(i1, real, 99), r2 = applyRealism(i1, real, 99), r3 = applyRealism(i1, real, 100);
    ASSERT_EQ(r1.type(), CV_8UC1);
    EXPECT_EQ(cv::norm(r1, r2, cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(r1, r3, cv::NORM_INF), 0.0);
  }
}

// ============================================================================ (5) realism

TEST(SimRender, IdealRealismOnlyQuantises) {
  const RealismOptions id = RealismOptions::ideal();
  EXPECT_EQ(id.blur_sigma, 0.0);
  EXPECT_EQ(id.vignetting, 0.0);
  EXPECT_EQ(id.gain, 1.0);
  EXPECT_EQ(id.offset, 0.0);
  EXPECT_EQ(id.gamma, 1.0);
  EXPECT_LE(id.full_well, 0.0);
  EXPECT_EQ(id.read_noise, 0.0);
  cv::Mat E(97, 131, CV_32F);
  cv::RNG(3).fill(E, cv::RNG::UNIFORM, -0.1, 1.1);
  const cv::Mat out = applyRealism(E, id, 1);
  ASSERT_EQ(out.type(), CV_8UC1);
  int worst = 0;
  for (int v = 0; v < E.rows; ++v) {
    for (int u = 0; u < E.cols; ++u) {
      const double e = std::clamp(static_cast<double>(E.at<float>(v, u)), 0.0, 1.0);
      worst = std::max(worst,
                       std::abs(static_cast<int>(out.at<std::uint8_t>(v, u)) - static_cast<int>(std::lround(255 * e))));
    }
  }
  EXPECT_LE(worst, 1);
}

TEST(SimRender, NoiseMatchesShotAndReadModel) {
  struct Case {
    double E, full_well, read;
  };
  for (const Case& k : {Case{0.5, 8000, 1.5}, Case{0.2, 1000, 0.0}, Case{0.7, 0.0, 3.0}}) {
    const cv::Mat flat(400, 500, CV_32F, cv::Scalar(k.E));
    RealismOptions r = RealismOptions::ideal();
    r.full_well = k.full_well;
    r.read_noise = k.read;
    const double var = (k.full_well > 0 ? k.E / k.full_well : 0.0) + std::pow(k.read / 255.0, 2);
    r.quantise = false;
    cv::Scalar mean, sd;
    cv::meanStdDev(applyRealism(flat, r, 4), mean, sd);
    EXPECT_NEAR(sd[0], std::sqrt(var), 0.1 * std::sqrt(var)) << k.E << " " << k.full_well << " " << k.read;
    EXPECT_NEAR(mean[0], k.E, 4 * std::sqrt(var / flat.total()));
    // Quantised: in DN, plus the uniform quantisation noise (1/12 DN^2).
    r.quantise = true;
    cv::meanStdDev(applyRealism(flat, r, 4), mean, sd);
    const double dn = std::sqrt(var * 255 * 255 + 1.0 / 12);
    EXPECT_NEAR(sd[0], dn, 0.1 * dn);
  }
}

TEST(SimRender, VignettingGainOffsetGammaAndBlurAsDocumented) {
  // Vignetting: V(r) = (1 + a (r/r_c)^2)^-2, a = (1 - vignetting)^-1/2 - 1, centre ((w-1)/2, (h-1)/2).
  const int w = 641, h = 481;
  const cv::Mat flat(h, w, CV_32F, cv::Scalar(0.8));
  RealismOptions r = RealismOptions::ideal();
  r.quantise = false;
  r.vignetting = 0.25;
  const cv::Mat vig = applyRealism(flat, r, 1);
  const double a = 1 / std::sqrt(0.75) - 1;
  EXPECT_NEAR(vig.at<float>(240, 320), 0.8, 1e-6);
  EXPECT_NEAR(vig.at<float>(0, 0) / 0.8, 0.75, 1e-5);
  EXPECT_NEAR(vig.at<float>(480, 640) / 0.8, 0.75, 1e-5);
  EXPECT_NEAR(vig.at<float>(120, 160) / 0.8, std::pow(1 + a * 0.25, -2), 1e-5);  // half way along the diagonal
  const double rx = 320.0 / std::hypot(320.0, 240.0);                            // edge middle (0, 240)
  EXPECT_NEAR(vig.at<float>(240, 0) / 0.8, std::pow(1 + a * rx * rx, -2), 1e-5);
  for (int u = 1; u <= 320; ++u) EXPECT_LE(vig.at<float>(240, u - 1), vig.at<float>(240, u));

  // Response: y = (gain E + offset)^(1/gamma), clamped to [0, 1].
  cv::Mat ramp(1, 101, CV_32F);
  for (int u = 0; u < 101; ++u) ramp.at<float>(0, u) = u / 100.0f;
  r = RealismOptions::ideal();
  r.gain = 1.3;
  r.offset = 0.05;
  r.gamma = 2.2;
  r.quantise = false;
  const cv::Mat yf = applyRealism(ramp, r, 1);
  r.quantise = true;
  const cv::Mat y8 = applyRealism(ramp, r, 1);
  for (int u = 0; u < 101; ++u) {
    const double expect = std::min(1.0, std::pow(1.3 * u / 100.0 + 0.05, 1 / 2.2));
    EXPECT_NEAR(yf.at<float>(0, u), expect, 1e-6) << u;
    EXPECT_NEAR(y8.at<std::uint8_t>(0, u), 255 * expect, 0.5 + 1e-4) << u;
  }

  // Blur: an impulse spreads into a Gaussian of variance sigma^2 per axis, sum preserved.
  cv::Mat impulse(61, 61, CV_32F, cv::Scalar(0));
  impulse.at<float>(30, 30) = 1.0f;
  r = RealismOptions::ideal();
  r.quantise = false;
  r.blur_sigma = 1.5;
  const cv::Mat bl = applyRealism(impulse, r, 1);
  double s = 0, mx = 0, mxx = 0;
  for (int v = 0; v < 61; ++v) {
    for (int u = 0; u < 61; ++u) {
      const double val = bl.at<float>(v, u);
      s += val;
      mx += val * (u - 30);
      mxx += val * (u - 30) * (u - 30);
    }
  }
  EXPECT_NEAR(s, 1.0, 1e-4);
  EXPECT_NEAR(mx, 0.0, 1e-6);
  EXPECT_NEAR(std::sqrt(mxx / s), 1.5, 0.03);
}

// ============================================================================ (6) distortion

TEST(SimRender, DistortedCameraSeesTheSameSurfacePointAtItsProjection) {
  // A smooth analytic texture (features of ~10 mm, pixels of ~0.7 mm) on the globe's geometry: the
  // distorted and the undistorted camera at the same pose must give the same irradiance at their
  // respective projections of a surface point. The distortion moves corner pixels by tens of pixels.
  const Eigen::Vector3d c(0.0, 0.0, 0.35);
  const double r = 0.2;
  const SphereScene sphere(c, r, 1, 5e-3);
  const AlbedoOverride smooth(sphere, [](const Hit& h) {
    const Eigen::Vector3d& p = h.point;
    return static_cast<float>(0.5 + 0.3 * std::sin(2 * kPi * p.x() / 0.02) * std::cos(2 * kPi * p.y() / 0.017) +
                              0.1 * std::sin(2 * kPi * p.z() / 0.013));
  });
  const PinholeCamera ideal = makeCamera(450, 640, 480);
  const PinholeCamera dist(ideal.K(), 640, 480, {-0.25, 0.08, 0.001, -0.0005, 0.0});
  RenderOptions o;
  o.light_dir = Eigen::Vector3d(0.2, 0.3, 1.0).normalized();
  const cv::Mat Ii = renderIrradiance(smooth, ideal, Eigen::Isometry3d::Identity(), o);
  const cv::Mat Id = renderIrradiance(smooth, dist, Eigen::Isometry3d::Identity(), o);
  double max = 0, mean = 0, wrong = 0, max_shift = 0;
  int n = 0;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N;
  while (n < 400) {
    // Surface points facing the camera (at the origin).
    const Eigen::Vector3d dir = (Eigen::Vector3d(0, 0, -1) + 0.6 * Eigen::Vector3d(N(rng), N(rng), 0)).normalized();
    const Eigen::Vector3d X = c + r * dir;
    if (dir.dot(-X) <= 0.5 * X.norm()) continue;  // incidence < 60 deg: no silhouette pixels
    const Eigen::Vector2d ui = ideal.project(X), ud = dist.project(X);
    if (!insideMargin(ideal, ui, 3) || !insideMargin(dist, ud, 3)) continue;
    const double a = bilinear(Ii, ui), b = bilinear(Id, ud);
    max = std::max(max, std::abs(a - b));
    mean += std::abs(a - b);
    wrong += std::abs(a - bilinear(Id, ui));  // ignoring the distortion
    max_shift = std::max(max_shift, (ui - ud).norm());
    ++n;
  }
  mean /= n;
  wrong /= n;
  std::printf("distortion: max %.4g mean %.4g wrong %.4g shift %.1f px\n", max, mean, wrong, max_shift);
  EXPECT_GT(max_shift, 15.0) << "the distortion must matter for this test to mean something";
  EXPECT_LT(max, 5e-3);
  EXPECT_LT(mean, 1e-3);
  EXPECT_GT(wrong, 10 * mean);
}

}  // namespace
