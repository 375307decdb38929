// SPDX-License-Identifier: BSD-3-Clause
// Stereo design calculator: the thesis' worked example, geometric checks that
// do not reuse the calculator's formulas, and every kind of bad input.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <sys/wait.h>

#include "skin3d/geometry/design.h"

using namespace skin3d::geometry;

namespace {

const char* kThesisExample = R"(
name: thesis worked example (§3.2)
sensor: {width_px: 4224, height_px: 3136, pixel_size_um: 1.12, width_mm: 4.8, height_mm: 3.7}
lens: {focal_length_mm: 2.94, f_number: 2.0}
geometry: {baseline_mm: [210, 0, 0], convergence_deg: 54.4}
requirement: {depth_resolution_mm: 0.1, object_size_mm: 400}
)";

const char* kParallel = R"(
sensor: {width_px: 640, height_px: 480, pixel_size_um: 2.24}
lens: {focal_length_mm: 1.8, f_number: 2.0}
geometry: {baseline_mm: [105, 0, 0], working_distance_mm: 400}
requirement: {depth_resolution_mm: 1.0, object_size_mm: 400}
analysis: {grid: [5, 3], pixel_sigma_px: 0.5}
)";

// Replaces the first occurrence of `from` in the text.
std::string edit(std::string text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  if (pos != std::string::npos) text.replace(pos, from.size(), to);
  return text;
}

// Expects a DesignConfigError naming `field` and mentioning `value`, from parsing and computing.
void expectError(const std::string& yaml, const std::string& field, const std::string& value) {
  try {
    computeDesign(parseDesignConfig(yaml, "test.yaml"));
    FAIL() << "expected an error about " << field;
  } catch (const DesignConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(value), std::string::npos) << e.what();
  }
}

std::string run(const std::string& cmd, int* status) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  char buf[512];
  while (p && fgets(buf, sizeof buf, p)) out += buf;
  const int rc = p ? pclose(p) : -1;
  *status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  return out;
}

}  // namespace

TEST(Design, ReproducesTheThesisWorkedExample) {
  const DesignReport r = computeDesign(parseDesignConfig(kThesisExample));
  // Thesis §3.2: b_min = 2.94 x (1.12e-3 / 0.1) x (400 / 4.8)^2 = 228.667 mm; working distance 245 mm.
  EXPECT_NEAR(r.min_baseline_mm, 228.667, 0.001);
  EXPECT_NEAR(r.optimum_working_distance_mm, 245.0, 0.001);
  EXPECT_NEAR(r.working_distance_mm, 245.0, 0.001);  // the default
  // At the minimum baseline the depth resolution at that distance is exactly the requirement.
  EXPECT_NEAR(r.min_baseline_at_working_distance_mm, r.min_baseline_mm, 1e-9);
  EXPECT_NEAR(r.optical_axes_angle_deg, 54.4, 1e-9);
}

TEST(Design, ShippedConfigsWork) {
  const DesignReport p1 = computeDesign(loadDesignConfig(SKIN3D_SOURCE_DIR "/config/part1_rig_design.yaml"));
  EXPECT_NEAR(p1.min_baseline_mm, 228.667, 0.001);
  EXPECT_GT(p1.overlap_area_mm2, 0.0);
  EXPECT_GE(p1.grid.size(), 10u);
  const DesignReport slam = computeDesign(loadDesignConfig(SKIN3D_SOURCE_DIR "/config/slam_rig_design.yaml"));
  // docs/design.md: with 2.24 um pixels the two views overlap by about two thirds at 400 mm, fx ~ 804 px, 43 deg.
  EXPECT_NEAR(slam.focal_length_px, 803.6, 0.1);
  EXPECT_NEAR(slam.aov_h_deg, 43.4, 0.1);
  EXPECT_GT(slam.overlap_fraction, 0.55);
  EXPECT_LT(slam.overlap_fraction, 0.75);
}

TEST(Design, ParallelRigFootprintsFollowFromThePinholeModel) {
  const DesignReport r = computeDesign(parseDesignConfig(kParallel));
  // Each footprint is the image rectangle scaled by Z/f: 640 x 480 px * 2.24 um * 400 / 1.8.
  const double w = 640 * 2.24e-3 * 400 / 1.8, h = 480 * 2.24e-3 * 400 / 1.8;
  EXPECT_NEAR(r.footprint_left_area_mm2, w * h, 1e-6 * w * h);
  EXPECT_NEAR(r.footprint_right_area_mm2, w * h, 1e-6 * w * h);
  // Two such rectangles shifted by the 105 mm baseline overlap in (w - 105) x h, centred between the cameras.
  EXPECT_NEAR(r.overlap_area_mm2, (w - 105.0) * h, 1e-6 * w * h);
  EXPECT_NEAR(r.overlap_max.x() - r.overlap_min.x(), w - 105.0, 1e-6);
  EXPECT_NEAR(r.overlap_max.x() + r.overlap_min.x(), 0.0, 1e-6);
  // Depth of field brackets the working distance.
  EXPECT_LT(r.near_mm, 400.0);
  EXPECT_GT(r.far_mm, 400.0);
}

TEST(Design, UncertaintyGridAgreesWithDisparityNoise) {
  const DesignReport r = computeDesign(parseDesignConfig(kParallel));
  ASSERT_EQ(r.grid.size(), 15u);
  const double f_px = 1.8 / 2.24e-3;
  for (const auto& g : r.grid) {
    EXPECT_LT((g.X_est - g.X).norm(), 1e-6);
    EXPECT_TRUE(insideConvex(r.overlap, g.X.head<2>()));
    // Depth noise of a parallel rig: Z^2 / (f b) * sqrt(2) sigma, to first order; off-axis points a bit more.
    const double expected = 400.0 * 400.0 / (f_px * 105.0) * std::sqrt(2.0) * 0.5;
    EXPECT_GT(g.sigma_depth, 0.99 * expected);
    EXPECT_LT(g.sigma_depth, 1.15 * expected);
    EXPECT_GE(g.axes[0], g.axes[1]);
    EXPECT_GE(g.axes[1], g.axes[2]);
  }
}

TEST(Design, ConvergedRigOverlapIsSymmetric) {
  const DesignReport r = computeDesign(parseDesignConfig(kThesisExample));
  EXPECT_NEAR(r.overlap_max.x() + r.overlap_min.x(), 0.0, 1e-6);
  EXPECT_NEAR(r.footprint_left_area_mm2, r.footprint_right_area_mm2, 1e-6 * r.footprint_left_area_mm2);
  // The same rig given as per-camera rotation vectors is the same design.
  const std::string rotations = edit(kThesisExample, "convergence_deg: 54.4",
                                     "left_rotation_deg: [0, 27.2, 0], right_rotation_deg: [0, -27.2, 0]");
  const DesignReport q = computeDesign(parseDesignConfig(rotations));
  EXPECT_NEAR(q.overlap_area_mm2, r.overlap_area_mm2, 1e-6 * r.overlap_area_mm2);
}

TEST(Design, PolygonHelpers) {
  const std::vector<Eigen::Vector2d> a = {{0, 0}, {2, 0}, {2, 2}, {0, 2}}, b = {{1, 1}, {3, 1}, {3, 3}, {1, 3}};
  EXPECT_DOUBLE_EQ(polygonArea(a), 4.0);
  EXPECT_NEAR(polygonArea(convexIntersection(a, b)), 1.0, 1e-12);
  const std::vector<Eigen::Vector2d> far = {{5, 5}, {6, 5}, {6, 6}, {5, 6}};
  EXPECT_TRUE(convexIntersection(a, far).empty());
  EXPECT_TRUE(insideConvex(a, Eigen::Vector2d(1, 1)));
  EXPECT_FALSE(insideConvex(a, Eigen::Vector2d(3, 1)));
}

TEST(Design, BadInputNamesTheField) {
  const std::string y = kThesisExample;
  expectError(edit(y, "focal_length_mm: 2.94, ", ""), "lens.focal_length_mm", "missing");
  expectError(edit(y, "focal_length_mm: 2.94", "focal_length_mm: -2.94"), "lens.focal_length_mm", "-2.94");
  expectError(edit(y, "focal_length_mm: 2.94", "focal_length_mm: 0"), "lens.focal_length_mm", "0");
  expectError(edit(y, "pixel_size_um: 1.12", "pixel_size_um: 0"), "sensor.pixel_size_um", "0");
  expectError(edit(y, "pixel_size_um: 1.12", "pixel_size_um: .nan"), "sensor.pixel_size_um", ".nan");
  expectError(edit(y, "pixel_size_um: 1.12", "pixel_size_um: abc"), "sensor.pixel_size_um", "abc");
  expectError(edit(y, "width_px: 4224", "width_px: -5"), "sensor.width_px", "-5");
  expectError(edit(y, "f_number: 2.0", "f_nmuber: 2.0"), "lens.f_nmuber", "unknown");
  expectError(edit(y, "baseline_mm: [210, 0, 0]", "baseline_mm: [210, 0]"), "geometry.baseline_mm", "3 numbers");
  expectError(edit(y, "baseline_mm: [210, 0, 0]", "baseline_mm: [0, 0, 0]"), "geometry.baseline_mm", "[0, 0, 0]");
  expectError(edit(y, "depth_resolution_mm: 0.1", "depth_resolution_mm: -1"), "requirement.depth_resolution_mm", "-1");
  expectError(edit(y, "convergence_deg: 54.4", "convergence_deg: 200"), "geometry.convergence_deg", "200");
  expectError(edit(y, "sensor:", "sensors:"), "sensors", "unknown");
  expectError(edit(y, "requirement: {depth_resolution_mm: 0.1, object_size_mm: 400}", ""), "requirement", "missing");
  // Impossible geometries: no overlap (parallel cameras 210 mm apart looking at a plane 20 mm away) ...
  expectError(edit(y, "convergence_deg: 54.4}", "convergence_deg: 0, working_distance_mm: 20}"), "geometry",
              "do not overlap");
  // ... and cameras turned so far that the working plane is behind part of their view.
  expectError(edit(y, "convergence_deg: 54.4", "convergence_deg: 150"), "geometry", "does not meet the working plane");
  // Unparsable YAML says where.
  try {
    parseDesignConfig("sensor: {width_px: [1, 2\nlens: x", "broken.yaml");
    FAIL();
  } catch (const DesignConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("broken.yaml"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("line"), std::string::npos) << e.what();
  }
  EXPECT_THROW(parseDesignConfig("", "empty.yaml"), DesignConfigError);
  EXPECT_THROW(loadDesignConfig("/nonexistent/design.yaml"), DesignConfigError);
}

TEST(Design, ReportYamlParsesAndHoldsTheFigures) {
  const DesignReport r = computeDesign(parseDesignConfig(kThesisExample));
  const std::string yaml = designReportYaml(r);
  EXPECT_NE(yaml.find("min_baseline_mm: 228.666"), std::string::npos) << yaml.substr(0, 2000);
  EXPECT_NE(designReportTable(r).find("228.667"), std::string::npos);
}

TEST(StereoDesignTool, ExitCodesAndMessages) {
  const std::string bin = SKIN3D_STEREO_DESIGN_BIN;
  const std::string dir = ::testing::TempDir() + "skin3d_design_cli";
  int status = 0;
  std::string out = run(bin + " --config " SKIN3D_SOURCE_DIR "/config/part1_rig_design.yaml --out " + dir + " --no-plots", &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("228.667"), std::string::npos) << out;
  EXPECT_TRUE(std::ifstream(dir + "/report.yaml").good());

  const std::string bad = dir + "/bad.yaml";
  std::ofstream(bad) << edit(kThesisExample, "focal_length_mm: 2.94", "focal_length_mm: -1");
  out = run(bin + " --config " + bad, &status);
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("lens.focal_length_mm"), std::string::npos) << out;
  EXPECT_NE(out.find("-1"), std::string::npos) << out;

  // With plots: the four PNGs of scripts/plot_design.py (thesis Fig. 3.1, 3.2) are written and not empty.
  const std::string pdir = dir + "/plots";
  out = run(bin + " --config " SKIN3D_SOURCE_DIR "/config/slam_rig_design.yaml --quiet --out " + pdir, &status);
  EXPECT_EQ(status, 0) << out;
  for (const char* png : {"depth_resolution.png", "fields_of_view.png", "projected_grid.png",
                          "reconstruction_uncertainty.png"}) {
    std::ifstream f(pdir + "/" + png, std::ios::binary | std::ios::ate);
    EXPECT_TRUE(f.good()) << png;
    EXPECT_GT(static_cast<long>(f.tellg()), 20000L) << png;
  }

  out = run(bin + " --config /nonexistent.yaml", &status);
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("cannot read"), std::string::npos) << out;
  out = run(bin, &status);
  EXPECT_EQ(status, 2) << out;
  out = run(bin + " --bogus", &status);
  EXPECT_EQ(status, 2) << out;
}
