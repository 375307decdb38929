// SPDX-License-Identifier: BSD-3-Clause
// Issue 7: rviz under Xvfb with each of the project's rviz configs, through scripts/rviz_screenshot, on the
// datasets the other tests build. A screenshot must show the scene: it is compared with a screenshot of rviz
// on the same config with no data (the empty window), and that difference must stand well above the
// difference between two empty windows (fps counter, cursor: the noise floor, measured in the same run).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

namespace {

const std::string kSource = SKIN3D_SOURCE_DIR;
const std::string kScript = kSource + "/scripts/rviz_screenshot";

std::string shot(const std::string& name, const std::string& args, int wait_s) {
  const std::string out = ::testing::TempDir() + "skin3d_rviz_" + name + ".png";
  std::remove(out.c_str());
  const std::string cmd = kScript + " --out " + out + " --wait " + std::to_string(wait_s) + " " + args;
  std::printf("$ %s\n", cmd.c_str());
  std::fflush(stdout);
  const int rc = std::system(cmd.c_str());
  EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 0) << cmd;
  return out;
}

/** Share of the pixels whose colour differs by more than 40 (of 255) in some channel. */
double changed(const std::string& a, const std::string& b) {
  const cv::Mat x = cv::imread(a), y = cv::imread(b);
  if (x.empty() || y.empty() || x.size() != y.size()) {
    ADD_FAILURE() << "cannot compare " << a << " and " << b;
    return 0;
  }
  cv::Mat d, m;
  cv::absdiff(x, y, d);
  cv::Mat ch[3];
  cv::split(d, ch);
  m = cv::max(cv::max(ch[0], ch[1]), ch[2]) > 40;
  return cv::countNonZero(m) / static_cast<double>(m.total());
}

/** The screenshot is not a blank screen (a dead rviz leaves the X root window black). */
void expectNotBlank(const std::string& path) {
  const cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty()) << path;
  cv::Scalar mean, sd;
  cv::meanStdDev(img, mean, sd);
  EXPECT_GT(sd[0], 10.0) << path << " is blank";
}

struct Case {
  const char* name;
  const char* config;  // rviz/...
  std::string launch;  // launch file + args
  int wait_s;
};

TEST(RvizScreenshots, EachConfigShowsItsScene) {
  const std::string data = SKIN3D_TEST_DATA_DIR;
  const Case cases[] = {
      {"design", "stereo_design.rviz", "stereo_design.launch", 20},
      {"globe", "slam.rviz",
       "replay_globe.launch bag:=" + data + "/globe_landmarks_40.bag results:=" + ::testing::TempDir() +
           "skin3d_rviz_globe required_player:=false rate:=0.5",
       30},
      {"workpiece", "workpiece.rviz",
       "replay_workpiece.launch bag:=" + data + "/workpiece_quarter.bag results:= rate:=0.5", 50},
  };
  // noise floor: two empty windows of the same config
  const std::string e1 = shot("empty_a", "--empty " + kSource + "/rviz/workpiece.rviz", 12);
  const std::string e2 = shot("empty_b", "--empty " + kSource + "/rviz/workpiece.rviz", 12);
  const double floor = changed(e1, e2);
  std::printf("two empty windows differ in %.3f %% of the pixels\n", 100 * floor);
  for (const auto& c : cases) {
    const std::string empty = shot(std::string(c.name) + "_empty", "--empty " + kSource + "/rviz/" + c.config, 12);
    const std::string scene = shot(c.name, c.launch, c.wait_s);
    expectNotBlank(scene);
    const double diff = changed(scene, empty);
    std::printf("%s (%s): the scene differs from the empty window in %.2f %% of the pixels -> %s\n", c.name, c.config,
                100 * diff, scene.c_str());
    ::testing::Test::RecordProperty(std::string(c.name) + "_changed_permille", static_cast<int>(1000 * diff));
    EXPECT_GT(diff, 0.005) << c.name << ": the screenshot looks like the empty window (" << scene << ")";
    EXPECT_GT(diff, 5 * floor) << c.name << ": not above the empty-window noise";
  }
}

}  // namespace
