// SPDX-License-Identifier: BSD-3-Clause
// The site scan end to end: a reduced hand-held sweep (make_dataset skin with skin.sweep: half resolution, 5 pairs
// over +-50 deg, hand jitter, calibration error and noise) measured by process_bag --site with the dataset's poses,
// checked against the generator's truth. Bars for this reduced sweep (half the pixels: about twice the height noise
// of the full-resolution sweep the benchmarks measure): every frame fused; every true plaque of at least 0.2 mm
// that some frame sees within 45 deg found exactly once, its top within max(20 um, 3 x its stated sigma), its PASI
// class right; no site plaque that no true plaque claims; >= 95 % of the skin some frame sees within 45 deg in both
// cameras has a fused height. And the bad inputs: no pose topic, a pose topic of the wrong type, a sweep whose pairs
// never overlap (exit status 5, each pair named, the results written). Then poses from the pairs' own features
// (--site-poses images) on a sweep with the full sweep's steps, and on pairs too far apart for them.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "site_truth.h"

namespace {

using skin3d_test::expectPlaquesMatchTheTruth;

const std::string kMakeDataset = SKIN3D_MAKE_DATASET_BIN;
const std::string kProcessBag = SKIN3D_PROCESS_BAG_BIN;

int run(const std::string& cmd) {
  std::printf("$ %s\n", cmd.c_str());
  std::fflush(stdout);
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

class SiteScan : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = ::testing::TempDir() + "skin3d_site_scan";
    bag_ = dir_ + "/sweep.bag";
    out_ = dir_ + "/results";
    ASSERT_EQ(run("rm -rf " + dir_ + " && mkdir -p " + dir_), 0);
    std::ofstream(dir_ + "/sweep.yaml") << "skin:\n  plaque_count: 6\n  resolution_scale: 0.5\n"
                                           "  sweep: {enabled: true, frames: 5, arc_deg: 100, fps: 2, plaque_span_deg: 70}\n";
    ASSERT_EQ(run(kMakeDataset + " skin --config " + dir_ + "/sweep.yaml --seed 11 --out " + bag_ + " --quiet"), 0);
    status_ = run(kProcessBag + " --site --site-poses ground_truth/pose --bag " + bag_ + " --out " + out_ + " --quiet");
  }
  static std::string dir_, bag_, out_;
  static int status_;
};
std::string SiteScan::dir_, SiteScan::bag_, SiteScan::out_;
int SiteScan::status_ = -1;

TEST_F(SiteScan, EveryPlaqueSeenWellIsMeasuredOnce) {
  ASSERT_EQ(status_, 0);
  const YAML::Node truth = YAML::LoadFile(dir_ + "/sweep.truth.yaml");
  const YAML::Node site = YAML::LoadFile(out_ + "/site.yaml");
  EXPECT_EQ(site["frames_fused"].as<int>(), 5);
  EXPECT_EQ(site["frames_left_out"].as<int>(), 0);
  EXPECT_EQ(site["surface"]["model"].as<std::string>(), "cylinder");
  // the frames agree where they overlap: with the generator's poses only the noise is left (under 10 um of rigid
  // disagreement at half resolution); a pose error, or points that are not skin, leave hundreds of um
  EXPECT_LT(site["seams"]["rigid_um"].as<double>(), 25.0);
  expectPlaquesMatchTheTruth(truth, site);
}

TEST_F(SiteScan, TheSkinTheFramesSeeIsFused) {
  ASSERT_EQ(status_, 0);
  // the coverage check of scripts/site_check.py, which reads the truth's coverage image and site_surface.ply
  const std::string js = dir_ + "/check.json";
  ASSERT_EQ(run("/usr/bin/python3 " + std::string(SKIN3D_SOURCE_DIR) + "/scripts/site_check.py " + bag_ + " " + out_ +
                " --json " + js),
            0);
  const YAML::Node r = YAML::LoadFile(js);  // JSON is YAML
  EXPECT_GE(r["coverage"].as<double>(), 0.95);
}

TEST_F(SiteScan, TheReportHasASitePage) {
  ASSERT_EQ(status_, 0);
  const std::string html = dir_ + "/report.html";
  ASSERT_EQ(run("PYTHONPATH=" + std::string(SKIN3D_SOURCE_DIR) + "/src /usr/bin/python3 " + std::string(SKIN3D_SOURCE_DIR) +
                "/scripts/report.py --out " + html + " " + out_),
            0);
  std::ifstream in(html);
  const std::string page((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find("site scan (5 pairs fused, 0 left out)"), std::string::npos);
  // every site plaque's top as site.yaml has it, and the sweep's truth beside it
  const YAML::Node site = YAML::LoadFile(out_ + "/site.yaml");
  for (const auto& p : site["plaques"]) {
    char top[32];
    std::snprintf(top, sizeof(top), "%.4f ± ", p["top_height_mm"].as<double>());
    EXPECT_NE(page.find(top), std::string::npos) << top;
  }
  EXPECT_NE(page.find("The sweep's truth: "), std::string::npos);
  EXPECT_NE(page.find("Coverage: pairs fused per cell"), std::string::npos);
}

TEST_F(SiteScan, WithoutPosesItSaysWhatIsMissing) {
  ASSERT_EQ(status_, 0);
  // the default pose topic (slam/odometry) is not in a simulated sweep: exit 1 naming it and --site-poses
  const std::string log = dir_ + "/noposes.log";
  EXPECT_EQ(run(kProcessBag + " --site --bag " + bag_ + " --out " + dir_ + "/noposes --quiet --frames 1 2> " + log), 1);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("slam/odometry"), std::string::npos) << text;
  EXPECT_NE(text.find("--site-poses"), std::string::npos) << text;
  // a topic that holds no pose
  EXPECT_EQ(run(kProcessBag + " --site --site-poses stereo/left/camera_info --bag " + bag_ + " --out " + dir_ +
                "/badposes --quiet --frames 1"),
            1);
}

TEST_F(SiteScan, ASweepThatNeverOverlapsSaysSoAndExitsFive) {
  ASSERT_EQ(status_, 0);
  // the same pairs with their poses moved apart: pair k half a metre further along world x than pair k - 1
  const std::string script = dir_ + "/apart.py", apart = dir_ + "/apart.bag", out = dir_ + "/apart";
  std::ofstream(script) << "import sys, rosbag\n"
                           "k = 0\n"
                           "with rosbag.Bag(sys.argv[2], 'w') as o:\n"
                           "    for topic, msg, t in rosbag.Bag(sys.argv[1]).read_messages():\n"
                           "        if topic.lstrip('/') == 'ground_truth/pose':\n"
                           "            msg.pose.position.x += 0.5 * k\n"
                           "            k += 1\n"
                           "        o.write(topic, msg, t)\n";
  ASSERT_EQ(run("/usr/bin/python3 " + script + " " + bag_ + " " + apart), 0);
  EXPECT_EQ(run(kProcessBag + " --site --site-poses ground_truth/pose --bag " + apart + " --out " + out + " --frames 3 --quiet"), 5);
  const YAML::Node site = YAML::LoadFile(out + "/site.yaml");  // written all the same
  EXPECT_EQ(site["frames_fused"].as<int>(), 1);
  EXPECT_EQ(site["frames_left_out"].as<int>(), 2);
  for (std::size_t k = 1; k < site["frames"].size(); ++k)
    EXPECT_NE(site["frames"][k]["left_out"].as<std::string>("").find("overlaps the fused site"), std::string::npos)
        << "pair " << k << " must be named with the reason";
}


// Poses from the pairs themselves (--site-poses images): a sweep with the hand's steps of the full sweep (9 deg
// between pairs; half resolution, 5 pairs over 36 deg, seed 13) measured as well as with the generator's poses:
// every pair placed and fused, the plaques' bars of EveryPlaqueSeenWellIsMeasuredOnce, seams at the noise. The
// placement itself: the registration fixes each pair to the site but leaves the cylinder's own freedoms (turning
// about its axis, sliding along it) to the odometry, so the site as a whole may sit a little off the truth's world
// (about 0.1 mm per pair): the skin each pair looks at within 1 mm RMS of where it truly is.
TEST(SiteScanFromImages, ASweepIsPlacedByItsOwnFeatures) {
  const std::string dir = ::testing::TempDir() + "skin3d_site_images", bag = dir + "/sweep.bag", out = dir + "/results";
  ASSERT_EQ(run("rm -rf " + dir + " && mkdir -p " + dir), 0);
  std::ofstream(dir + "/sweep.yaml") << "skin:\n  plaque_count: 4\n  resolution_scale: 0.5\n"
                                        "  sweep: {enabled: true, frames: 5, arc_deg: 36, fps: 4, plaque_span_deg: 25}\n";
  ASSERT_EQ(run(kMakeDataset + " skin --config " + dir + "/sweep.yaml --seed 13 --out " + bag + " --quiet"), 0);
  ASSERT_EQ(run(kProcessBag + " --site --site-poses images --bag " + bag + " --out " + out + " --quiet"), 0);
  const YAML::Node truth = YAML::LoadFile(dir + "/sweep.truth.yaml");
  const YAML::Node site = YAML::LoadFile(out + "/site.yaml");
  EXPECT_EQ(site["frames_fused"].as<int>(), 5);
  EXPECT_LT(site["seams"]["rigid_um"].as<double>(), 25.0);
  expectPlaquesMatchTheTruth(truth, site);
  const std::string js = dir + "/check.json";
  ASSERT_EQ(run("/usr/bin/python3 " + std::string(SKIN3D_SOURCE_DIR) + "/scripts/site_check.py " + bag + " " + out +
                " --json " + js),
            0);
  const YAML::Node r = YAML::LoadFile(js);
  ASSERT_TRUE(r["poses"].IsMap());
  EXPECT_EQ(r["poses"]["pairs"].as<int>(), 5);
  EXPECT_LT(r["poses"]["skin_rms_mm"].as<double>(), 1.0);
}

// Pairs 25 deg apart are too far apart for their features to match (the skin's texture changes with the view):
// each pair after the first is left out, named, and the run ends with status 5.
TEST_F(SiteScan, PairsTooFarApartForTheirFeaturesAreNamed) {
  ASSERT_EQ(status_, 0);
  const std::string out = dir_ + "/images_apart";
  EXPECT_EQ(run(kProcessBag + " --site --site-poses images --bag " + bag_ + " --out " + out + " --frames 2 --quiet"), 5);
  const YAML::Node site = YAML::LoadFile(out + "/site.yaml");
  ASSERT_EQ(site["frames"].size(), 2u);
  EXPECT_NE(site["frames"][1]["left_out"].as<std::string>("").find("no pose from the images"), std::string::npos)
      << site["frames"][1]["left_out"].as<std::string>("");
}

}  // namespace
