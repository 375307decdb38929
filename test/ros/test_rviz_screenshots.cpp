// SPDX-License-Identifier: BSD-3-Clause
// rviz under Xvfb with each of the project's rviz configs, through scripts/rviz_screenshot, on the
// datasets the other tests build. A screenshot must show the scene: it is compared with a screenshot of rviz
// on the same config with no data (the empty window), region by region: the 3D view must change well above
// the difference between two empty windows there (the noise floor, measured in the same run), and where a
// config's image panels must show images (rviz docks them on the left, with the Displays panel), most of that
// dock must change ("No Image" -> the image). Between two empty windows the dock differs too: rviz stacks the
// image panels in a random order. rviz/rig.rviz runs through launch/rig.launch on 10 rendered globe frames in
// place of the cameras, rviz/site.rviz through launch/replay_sweep.launch on the reduced sweep. Every case prints
// the figures (whole screen, left dock, 3D view).
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

/** The screenshots run the nodelets of this build tree unless SKIN3D_BUILD_DIR says otherwise. */
const bool kBuildDirSet = ::setenv("SKIN3D_BUILD_DIR", SKIN3D_BUILD_DIR, 0) == 0;

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

/** Share of the pixels whose colour differs by more than 40 (of 255) in some channel; within `part` (fractions
 *  of the width and height: x, y, w, h) when given. */
double changed(const std::string& a, const std::string& b, const cv::Rect2d& part = cv::Rect2d(0, 0, 1, 1)) {
  const cv::Mat x = cv::imread(a), y = cv::imread(b);
  if (x.empty() || y.empty() || x.size() != y.size()) {
    ADD_FAILURE() << "cannot compare " << a << " and " << b;
    return 0;
  }
  const cv::Rect r(cvRound(part.x * x.cols), cvRound(part.y * x.rows), cvRound(part.width * x.cols),
                   cvRound(part.height * x.rows));
  cv::Mat d, m;
  cv::absdiff(x(r), y(r), d);
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
  bool images;  // the image panels must show images
};

// Regions of the 1280x800 screen (fractions): rviz docks the Displays and image panels on the left (0 ... 342 px),
// the 3D view is the rest below the toolbar, left of the (hidden) right dock.
const cv::Rect2d kLeftDock(0.0, 0.08, 0.26, 0.84);
const cv::Rect2d kView3d(0.30, 0.08, 0.68, 0.88);
// The 3D view must change in more than this share of its pixels (1200 px: more than the TF axes alone).
const double kMinView3d = 0.002;
// The dock of a config whose panels show images changes in more than this share (empty ones: a few %).
const double kMinDockImages = 0.25;

TEST(RvizScreenshots, EachConfigShowsItsScene) {
  const std::string data = SKIN3D_TEST_DATA_DIR;
  const Case cases[] = {
      {"design", "stereo_design.rviz", "stereo_design.launch", 20, false},
      {"globe", "slam.rviz",
       "replay_globe.launch bag:=" + data + "/globe_landmarks_40.bag results:=" + ::testing::TempDir() +
           "skin3d_rviz_globe required_player:=false rate:=0.5",
       30, false},
      // 2 frames 20 s apart (after rosbag's 2 s delay): the rectified image is not latched, and rviz must have
      // subscribed before a frame comes, which a loaded machine can delay by many seconds. required_player:=false:
      // the launch runs on after the bag has been measured, until the screenshot is taken
      {"workpiece", "workpiece.rviz",
       "replay_workpiece.launch bag:=" + data + "/workpiece_quarter.bag results:= rate:=0.025 required_player:=false",
       50, true},
      // 10 frames over 20 s (after rosbag's 2 s delay): rviz is up long before the last image
      {"rig", "rig.rviz", "rig.launch bag:=" + data + "/globe_images_10.bag rate:=0.05", 30, true},
      // the reduced sweep (5 half-resolution pairs): the site so far and its coverage image, both latched, appear
      // once the first pair is fused (some seconds per pair); the launch runs on until the screenshot
      {"site", "site.rviz", "replay_sweep.launch bag:=" + data + "/skin_sweep_half.bag results:= required_player:=false",
       45, true},
  };
  ASSERT_TRUE(kBuildDirSet);
  std::printf("build tree: %s\n", std::getenv("SKIN3D_BUILD_DIR"));
  // noise floor: two empty windows of the same config (two image panels: their order varies); the second is the
  // workpiece case's own empty window
  const std::string e1 = shot("empty_a", "--empty " + kSource + "/rviz/workpiece.rviz", 8);
  const std::string e2 = shot("workpiece_empty", "--empty " + kSource + "/rviz/workpiece.rviz", 8);
  expectNotBlank(e1);
  expectNotBlank(e2);
  const double floor = changed(e1, e2), floor_dock = changed(e1, e2, kLeftDock), floor_view = changed(e1, e2, kView3d);
  std::printf("two empty windows differ in %.3f %% of the pixels (left dock %.2f %%, 3D view %.3f %%)\n", 100 * floor,
              100 * floor_dock, 100 * floor_view);
  for (const auto& c : cases) {
    const std::string empty = std::string(c.name) == "workpiece"
                                  ? e2
                                  : shot(std::string(c.name) + "_empty", "--empty " + kSource + "/rviz/" + c.config, 8);
    const std::string scene = shot(c.name, c.launch, c.wait_s);
    expectNotBlank(empty);
    expectNotBlank(scene);
    const double diff = changed(scene, empty);
    const double dock = changed(scene, empty, kLeftDock), view = changed(scene, empty, kView3d);
    std::printf(
        "%s (%s): the scene differs from the empty window in %.2f %% of the pixels (left dock %.1f %%, 3D view "
        "%.2f %%) -> %s\n",
        c.name, c.config, 100 * diff, 100 * dock, 100 * view, scene.c_str());
    ::testing::Test::RecordProperty(std::string(c.name) + "_changed_permille", static_cast<int>(1000 * diff));
    ::testing::Test::RecordProperty(std::string(c.name) + "_view3d_changed_permille", static_cast<int>(1000 * view));
    EXPECT_GT(view, kMinView3d) << c.name << ": the 3D view looks like the empty window's (" << scene << ")";
    EXPECT_GT(view, 5 * floor_view) << c.name << ": the 3D view does not stand above the empty-window noise";
    if (c.images) {  // "No Image" panels turned into images
      EXPECT_GT(dock, kMinDockImages) << c.name << ": the image panels do not show images (" << scene << ")";
      EXPECT_GT(dock, 5 * floor_dock) << c.name << ": the image panels do not stand above the empty-window noise";
    }
  }
}

}  // namespace
