// SPDX-License-Identifier: BSD-3-Clause
// Induration accuracy: the rendered workpiece at full resolution (4224x3136, the dataset's realism on:
// perturbed calibration, blur, photometric differences, noise; 3 exposures) made by the real dataset tool,
// measured by the real offline path (process_bag --induration), compared with the generator's truth file.
// Bars: every plateau 0.1-0.7 mm found in every frame, height within +-0.02 mm (target 0.01), the PASI class
// of the true height, area within 5 %, no other plaque; repeatability (std over the frames) reported.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace {

const std::string kMakeDataset = SKIN3D_MAKE_DATASET_BIN;
const std::string kProcessBag = SKIN3D_PROCESS_BAG_BIN;
const std::string kSource = SKIN3D_SOURCE_DIR;

int run(const std::string& cmd) {
  std::printf("$ %s\n", cmd.c_str());
  std::fflush(stdout);
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// The PASImeter classes as documented in induration.h / config/induration.yaml: the card steps are
// k * 0.25 mm, a height belongs to the nearest step (boundaries half-way between the steps).
int documentedPasiClass(double height_mm) {
  const double b[] = {0.125, 0.375, 0.625, 0.875};
  int k = 0;
  for (double x : b)
    if (height_mm >= x) ++k;
  return k;
}

struct Truth {
  double height_mm, area_mm2;
  Eigen::Vector3d centroid_m;
};

TEST(IndurationAccuracy, FullResolutionWorkpieceWithRealism) {
  const std::string dir = ::testing::TempDir() + "skin3d_induration_acc";
  const std::string bag = dir + "/workpiece.bag", out = dir + "/results";
  ASSERT_EQ(run("mkdir -p " + dir), 0);
  // the dataset's defaults: full resolution, realism on, 3 exposures
  ASSERT_EQ(run(kMakeDataset + " workpiece --out " + bag + " --quiet"), 0);
  ASSERT_EQ(run(kProcessBag + " --induration --bag " + bag + " --out " + out + " --config " + kSource +
                "/config/induration.yaml"),
            0);

  const YAML::Node truth = YAML::LoadFile(dir + "/workpiece.truth.yaml");
  std::vector<Truth> plateaus;
  for (const auto& p : truth["plateaus"]) {
    const auto c = p["centroid_left_m"];
    plateaus.push_back({p["height_mm"].as<double>(), p["area_mm2"].as<double>(),
                        Eigen::Vector3d(c[0].as<double>(), c[1].as<double>(), c[2].as<double>())});
  }
  ASSERT_EQ(plateaus.size(), 7u);

  const YAML::Node result = YAML::LoadFile(out + "/induration.yaml");
  const YAML::Node frames = result["frames"];
  ASSERT_EQ(frames.size(), 3u) << "one record per exposure";
  std::vector<std::vector<double>> heights(plateaus.size()), areas(plateaus.size());
  double worst_h = 0, worst_a = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const YAML::Node plaques = frames[f]["plaques"];
    std::vector<bool> used(plaques.size(), false);
    for (std::size_t i = 0; i < plateaus.size(); ++i) {
      int best = -1;
      double best_d = 3e-3;  // a plaque within 3 mm of the plateau's true top-face centroid
      for (std::size_t j = 0; j < plaques.size(); ++j) {
        const auto c = plaques[j]["centroid_m"];
        const double d = (Eigen::Vector3d(c[0].as<double>(), c[1].as<double>(), c[2].as<double>()) - plateaus[i].centroid_m).norm();
        if (d < best_d) {
          best_d = d;
          best = static_cast<int>(j);
        }
      }
      ASSERT_GE(best, 0) << "frame " << f << ": the " << plateaus[i].height_mm << " mm plateau was not found";
      used[best] = true;
      const YAML::Node p = plaques[best];
      const double h = p["top_height_mm"].as<double>(), a = p["area_mm2"].as<double>();
      heights[i].push_back(h);
      areas[i].push_back(a);
      worst_h = std::max(worst_h, std::fabs(h - plateaus[i].height_mm));
      worst_a = std::max(worst_a, std::fabs(a / plateaus[i].area_mm2 - 1));
      std::printf("frame %zu plateau %.1f mm: measured top %.4f mm (error %+.4f; interior mean %.4f), area %.1f mm^2 (%+.1f %%), PASI %d, "
                  "centroid off by %.2f mm\n",
                  f, plateaus[i].height_mm, h, h - plateaus[i].height_mm, p["mean_height_mm"].as<double>(), a, 100 * (a / plateaus[i].area_mm2 - 1),
                  p["pasi_class"].as<int>(), 1e3 * best_d);
      EXPECT_NEAR(h, plateaus[i].height_mm, 0.02) << "frame " << f;
      EXPECT_EQ(p["pasi_class"].as<int>(), documentedPasiClass(plateaus[i].height_mm)) << "frame " << f;
      EXPECT_NEAR(a / plateaus[i].area_mm2, 1.0, 0.05) << "frame " << f;
    }
    for (std::size_t j = 0; j < plaques.size(); ++j)
      EXPECT_TRUE(used[j]) << "frame " << f << ": plaque " << plaques[j]["id"].as<int>() << " ("
                           << plaques[j]["mean_height_mm"].as<double>() << " mm, " << plaques[j]["area_mm2"].as<double>()
                           << " mm^2) is not a plateau";
  }
  // repeatability over the exposures
  double worst_std = 0;
  for (std::size_t i = 0; i < plateaus.size(); ++i) {
    double m = 0, s = 0;
    for (double h : heights[i]) m += h;
    m /= heights[i].size();
    for (double h : heights[i]) s += (h - m) * (h - m);
    s = std::sqrt(s / (heights[i].size() - 1));
    worst_std = std::max(worst_std, s);
    std::printf("plateau %.1f mm: mean over %zu frames %.4f mm, std %.4f mm\n", plateaus[i].height_mm, heights[i].size(), m, s);
  }
  std::printf("worst height error %.4f mm, worst area error %.2f %%, worst repeatability std %.4f mm\n", worst_h,
              100 * worst_a, worst_std);
  ::testing::Test::RecordProperty("worst_height_error_um", static_cast<int>(std::round(1e3 * worst_h)));
  ::testing::Test::RecordProperty("worst_area_error_permille", static_cast<int>(std::round(1e3 * worst_a)));
  ::testing::Test::RecordProperty("worst_repeatability_std_um", static_cast<int>(std::round(1e3 * worst_std)));
  // the report files of docs/design.md
  for (const char* f : {"induration.yaml", "height_map.png", "surface.ply"})
    EXPECT_EQ(run(std::string("test -s ") + out + "/" + f), 0) << f;
}

}  // namespace
