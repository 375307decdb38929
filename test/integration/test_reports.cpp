// SPDX-License-Identifier: BSD-3-Clause
// The plots and the one-page HTML report on real results directories. process_bag runs experiments 2
// and 3 on the 40-frame landmark globe and the induration on the quarter-resolution workpiece (both made at
// build time); then scripts/report.py, scripts/slam_report.py and scripts/skin3d_plots.py run on them, and
// test/scripts/check_report.py checks the page against the results files and the generator's truth.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

namespace {

const std::string kSource = SKIN3D_SOURCE_DIR;
const std::string kData = SKIN3D_TEST_DATA_DIR;
const std::string kProcess = SKIN3D_PROCESS_BAG_BIN;
const std::string kPy = "/usr/bin/python3 ";

std::string tmp(const std::string& name) { return ::testing::TempDir() + "skin3d_reports_" + name; }

int run(const std::string& cmd, std::string* output = nullptr) {
  const std::string log = tmp("log.txt");
  std::printf("$ %s\n", cmd.c_str());
  const int rc = std::system((cmd + " > " + log + " 2>&1").c_str());
  std::ifstream f(log);
  std::stringstream ss;
  ss << f.rdbuf();
  std::printf("%s", ss.str().c_str());
  if (output) *output = ss.str();
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

class Reports : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::string bag = kData + "/globe_landmarks_40.bag", cfg = kSource + "/config/slam_globe.yaml";
    ASSERT_EQ(run(kProcess + " --bag " + bag + " --out " + tmp("exp2") + " --config " + cfg), 0);
    ASSERT_EQ(run(kProcess + " --bag " + bag + " --out " + tmp("exp3") + " --config " + cfg + " --gyro"), 0);
    ASSERT_EQ(run(kProcess + " --induration --frames 2 --bag " + kData + "/workpiece_quarter.bag --out " +
                  tmp("induration") + " --config " + kSource + "/config/induration.yaml"),
              0);
  }
};

TEST_F(Reports, HtmlReportIsSelfContainedAndShowsTheRunsFigures) {
  const std::string html = tmp("report.html");
  std::remove(html.c_str());
  ASSERT_EQ(run(kPy + kSource + "/scripts/report.py --out " + html + " --title test " + tmp("exp2") + " " +
                tmp("exp3") + " " + tmp("induration")),
            0);
  EXPECT_EQ(run(kPy + kSource + "/test/scripts/check_report.py " + html + " " + tmp("exp2") + " " + tmp("exp3") + " " +
                tmp("induration")),
            0);
}

TEST_F(Reports, SlamReportPrintsTable72AndWritesThePlots) {
  std::string out;
  const std::string dir = tmp("plots");
  ASSERT_EQ(run(kPy + kSource + "/scripts/slam_report.py " + dir + " exp2=" + tmp("exp2") + " exp3=" + tmp("exp3"), &out), 0);
  EXPECT_NE(out.find("| exp2 | "), std::string::npos);
  EXPECT_NE(out.find("experiment 3 better than 2"), std::string::npos);
  for (const char* f : {"fig7_1_exp2.png", "fig7_1_exp3.png", "fig7_2.png", "fig7_4.png", "sphere_exp2.png"}) {
    const cv::Mat img = cv::imread(dir + "/" + f, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(img.empty()) << f;
    cv::Scalar mean, sd;
    cv::meanStdDev(img, mean, sd);
    EXPECT_GT(sd[0], 10.0) << f << " is blank";
  }
  // skin3d_plots.py on an induration directory: the height figure
  ASSERT_EQ(run(kPy + kSource + "/scripts/skin3d_plots.py " + tmp("induration") + " --out " + dir), 0);
  EXPECT_FALSE(cv::imread(dir + "/height_skin3d_reports_induration.png").empty());
}

TEST_F(Reports, BadDirectoryIsNamed) {
  std::string out;
  EXPECT_EQ(run(kPy + kSource + "/scripts/report.py --out " + tmp("bad.html") + " /nonexistent_dir", &out), 1);
  EXPECT_NE(out.find("/nonexistent_dir"), std::string::npos) << out;
  EXPECT_EQ(run(kPy + kSource + "/scripts/report.py " + tmp("exp2"), &out), 2);  // no --out
}

}  // namespace
