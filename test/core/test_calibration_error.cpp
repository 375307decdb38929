// SPDX-License-Identifier: BSD-3-Clause
// The calibration error of the rendered datasets (sim::perturbCalibration): the simulated chessboard calibration
// against the true rig it was made from, and the independent parameter errors it replaced as the default.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/dataset.h"
#include "skin3d/sim/globe.h"

using namespace skin3d;

namespace {

const double kWorkingDistance = 0.4;  // m: the globe's near surface (600 mm - 200 mm)

geometry::StereoRig trueRig() { return sim::RigConfig().makeRig(); }

// Depth error of the measured calibration at a left pixel (fraction of the image) at distance z, computed here
// from the true rig's projections (not from the perturbation's own summary).
double depthError(const geometry::StereoRig& truth, const geometry::StereoRig& measured, double fx, double fy, double z) {
  const Eigen::Vector2d uv(fx * truth.left().width(), fy * truth.left().height());
  const Eigen::Vector3d X = z * truth.left().unproject(uv);
  Eigen::Vector2d ul, ur;
  EXPECT_TRUE(truth.project(X, &ul, &ur));
  const geometry::TriangulationResult t = measured.triangulate(ul, ur, 0.5);
  EXPECT_TRUE(t.ok) << t.message;
  return t.X.z() - X.z();
}

}  // namespace

TEST(CalibrationError, ChessboardWithoutCornerNoiseRecoversTheRig) {
  sim::CalibrationPerturbation p;
  p.corner_sigma_px = 0.0;
  const geometry::StereoRig truth = trueRig();
  const sim::PerturbedCalibration c = sim::perturbCalibration(truth, p, 7, kWorkingDistance);
  EXPECT_LT(c.calibration_rms_px, 1e-3);
  EXPECT_NEAR(c.baseline_scale, 1.0, 1e-5);
  EXPECT_LT(c.rotation_error.norm(), 1e-6);
  EXPECT_LT(c.principal_left.norm(), 0.01);
  EXPECT_LT(c.principal_right.norm(), 0.01);
  for (double fx : {0.3, 0.5, 0.7})
    EXPECT_NEAR(depthError(truth, c.rig, fx, 0.5, kWorkingDistance), 0.0, 1e-6) << fx;
}

TEST(CalibrationError, ChessboardCalibrationIsRealisticAndDeterministic) {
  sim::CalibrationPerturbation p;  // defaults: 15 views, 0.14 px corner noise, k1 k2
  const geometry::StereoRig truth = trueRig();
  const sim::PerturbedCalibration a = sim::perturbCalibration(truth, p, 3, kWorkingDistance);
  const sim::PerturbedCalibration b = sim::perturbCalibration(truth, p, 3, kWorkingDistance);
  const sim::PerturbedCalibration c = sim::perturbCalibration(truth, p, 4, kWorkingDistance);
  EXPECT_EQ(a.rig.left().K(), b.rig.left().K());
  EXPECT_EQ(a.rig.t_rl(), b.rig.t_rl());
  EXPECT_NE(a.rig.left().K(), c.rig.left().K());
  // OpenCV's RMS is per corner over both coordinates: ~sqrt(2) x the per-coordinate noise, a little less for the
  // degrees of freedom the fit absorbs.
  EXPECT_GT(a.calibration_rms_px, 0.8 * std::sqrt(2.0) * p.corner_sigma_px);
  EXPECT_LT(a.calibration_rms_px, 1.1 * std::sqrt(2.0) * p.corner_sigma_px);
  // The summary's depth error is what the rig does to a point on the axis.
  EXPECT_NEAR(a.depth_error_m, depthError(truth, a.rig, truth.left().cx() / truth.left().width(),
                                          truth.left().cy() / truth.left().height(), kWorkingDistance), 1e-9);
  EXPECT_GE(std::abs(a.depth_error_max_m), std::abs(a.depth_error_m));
}

// The point of the chessboard model: a calibration against a metric board fits the disparities of boards at known
// distances, so its depth error at the working distance is far smaller than independent principal-point errors
// (sqrt(2) x 1.5 px of disparity, 4 mm at 400 mm) make it. Over 12 seeds, RMS at the image centre.
TEST(CalibrationError, ChessboardDepthErrorIsSmallerThanIndependentErrors) {
  const geometry::StereoRig truth = trueRig();
  sim::CalibrationPerturbation chess, indep;
  indep.model = sim::CalibrationErrorModel::Independent;
  double sum_c = 0.0, sum_i = 0.0;
  const int n = 12;
  for (int seed = 1; seed <= n; ++seed) {
    const double ec = depthError(truth, sim::perturbCalibration(truth, chess, seed, kWorkingDistance).rig, 0.5, 0.5,
                                 kWorkingDistance);
    const double ei = depthError(truth, sim::perturbCalibration(truth, indep, seed, kWorkingDistance).rig, 0.5, 0.5,
                                 kWorkingDistance);
    sum_c += ec * ec;
    sum_i += ei * ei;
  }
  const double rms_c = std::sqrt(sum_c / n), rms_i = std::sqrt(sum_i / n);
  std::printf("depth error at 400 mm, RMS over %d seeds: chessboard %.3f mm, independent %.3f mm\n", n, 1e3 * rms_c,
              1e3 * rms_i);
  // Expected from the parameters: independent ~ 1.9 mm/px x sqrt(2 x 1.5^2 + ...) px ~ 4 mm.
  EXPECT_GT(rms_i, 2e-3);
  EXPECT_LT(rms_c, 0.5 * rms_i);
  EXPECT_GT(rms_c, 0.0);
}

TEST(CalibrationError, DisabledGivesTheTruth) {
  sim::CalibrationPerturbation p;
  p.enabled = false;
  const geometry::StereoRig truth = trueRig();
  const sim::PerturbedCalibration c = sim::perturbCalibration(truth, p, 1, kWorkingDistance);
  EXPECT_EQ(c.rig.left().K(), truth.left().K());
  EXPECT_EQ(c.rig.t_rl(), truth.t_rl());
  EXPECT_EQ(c.depth_error_m, 0.0);
}

TEST(CalibrationError, ConfigKeysAndErrors) {
  sim::DatasetConfig c = sim::defaultDatasetConfig(sim::DatasetKind::GlobeImages);
  EXPECT_EQ(c.images.perturbation.model, sim::CalibrationErrorModel::Chessboard);
  sim::applyDatasetYaml(&c,
                        "images: {calibration_error: {model: independent, views: 20, corner_sigma_px: 0.3, "
                        "k_coefficients: 3, board: [7, 5], board_fill: 0.3, distance_rel: [0.8, 1.2], max_tilt_deg: 20}}",
                        "test");
  const auto& p = c.images.perturbation;
  EXPECT_EQ(p.model, sim::CalibrationErrorModel::Independent);
  EXPECT_EQ(p.views, 20);
  EXPECT_DOUBLE_EQ(p.corner_sigma_px, 0.3);
  EXPECT_EQ(p.k_coefficients, 3);
  EXPECT_EQ(p.board_cols, 7);
  EXPECT_EQ(p.board_rows, 5);
  EXPECT_DOUBLE_EQ(p.board_fill, 0.3);
  EXPECT_DOUBLE_EQ(p.min_distance_rel, 0.8);
  EXPECT_DOUBLE_EQ(p.max_distance_rel, 1.2);
  EXPECT_NEAR(p.max_tilt, 20.0 * M_PI / 180.0, 1e-12);
  const auto field = [](const std::string& yaml) {
    sim::DatasetConfig d = sim::defaultDatasetConfig(sim::DatasetKind::GlobeImages);
    try {
      sim::applyDatasetYaml(&d, yaml, "test");
    } catch (const sim::SimConfigError& e) {
      return e.field();
    }
    return std::string("no error");
  };
  EXPECT_EQ(field("images: {calibration_error: {model: magic}}"), "images.calibration_error.model");
  EXPECT_EQ(field("images: {calibration_error: {views: 2}}"), "images.calibration_error.views");
  EXPECT_EQ(field("images: {calibration_error: {board_fill: 0}}"), "images.calibration_error.board_fill");
  EXPECT_EQ(field("images: {calibration_error: {distance_rel: [1.5, 0.75]}}"), "images.calibration_error.distance_rel");
  EXPECT_EQ(field("images: {calibration_error: {k_coefficients: 4}}"), "images.calibration_error.k_coefficients");
}

TEST(CalibrationError, ABoardThatCannotFitIsAnError) {
  sim::CalibrationPerturbation p;
  p.board_fill = 1.0;        // the corner grid as wide as the image at the working distance...
  p.min_distance_rel = 0.5;  // ...and nearer: it never fits both images
  p.max_distance_rel = 0.6;
  EXPECT_THROW(sim::perturbCalibration(trueRig(), p, 1, kWorkingDistance), std::runtime_error);
}

// The frame the calibration defines (PerturbedCalibration::frame_*). A baseline error alone scales every
// triangulated point about the left centre, exactly: the fit must find that scale and no rotation or shift.
TEST(CalibrationError, MeasuredFrameOfABaselineErrorIsItsScale) {
  sim::CalibrationPerturbation p;
  p.model = sim::CalibrationErrorModel::Independent;
  p.baseline_rel = 0.003;
  p.rotation = p.principal_point = p.focal_rel = 0.0;
  const sim::PerturbedCalibration c = sim::perturbCalibration(trueRig(), p, 5, kWorkingDistance);
  ASSERT_GT(std::abs(c.baseline_scale - 1.0), 1e-4);  // the seed drew a real error
  EXPECT_NEAR(c.frame_scale, c.baseline_scale, 1e-9);
  EXPECT_LT(c.frame_rotation.norm(), 1e-9);
  EXPECT_LT(c.frame_translation.norm(), 1e-9);
  EXPECT_LT(c.frame_residual_rms_m, 1e-9);
  EXPECT_GT(c.frame_points, 100);
}

// A chessboard calibration's error is mostly rigid: the similarity explains most of the displacement of points
// the fit never saw (random points of the working volume, drawn here), and the rest is the reported residual.
TEST(CalibrationError, MeasuredFrameExplainsMostOfAChessboardCalibrationsError) {
  const geometry::StereoRig truth = trueRig();
  sim::CalibrationPerturbation p;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.15, 0.85), d(0.85, 1.15);
  for (int seed : {1, 2, 3}) {
    const sim::PerturbedCalibration c = sim::perturbCalibration(truth, p, seed, kWorkingDistance);
    const Eigen::Matrix3d sR = c.frame_scale * geometry::so3Exp(c.frame_rotation);
    double raw = 0.0, left = 0.0;
    int n = 0;
    while (n < 200) {
      const Eigen::Vector2d uv(u(rng) * truth.left().width(), u(rng) * truth.left().height());
      const Eigen::Vector3d X = d(rng) * kWorkingDistance * truth.left().unproject(uv);
      Eigen::Vector2d ul, ur;
      if (!truth.project(X, &ul, &ur) || !truth.right().inImage(ur)) continue;
      const geometry::TriangulationResult t = c.rig.triangulate(ul, ur, 0.5);
      ASSERT_TRUE(t.ok) << t.message;
      raw += (t.X - X).squaredNorm();
      left += (t.X - (sR * X + c.frame_translation)).squaredNorm();
      ++n;
    }
    raw = std::sqrt(raw / n);
    left = std::sqrt(left / n);
    std::printf("seed %d: displacement RMS %.3f mm, after the similarity %.3f mm (fit residual %.3f mm), rotation "
                "%.2f mrad, scale - 1 = %.1e\n",
                seed, 1e3 * raw, 1e3 * left, 1e3 * c.frame_residual_rms_m, 1e3 * c.frame_rotation.norm(),
                c.frame_scale - 1.0);
    EXPECT_LT(left, 0.5 * raw) << seed;
    EXPECT_LT(left, 2.0 * c.frame_residual_rms_m) << seed;
    EXPECT_GT(c.frame_rotation.norm(), 1e-4) << seed;  // 0.1 mrad: a chessboard calibration is never that good
  }
}
