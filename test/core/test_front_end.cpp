// SPDX-License-Identifier: BSD-3-Clause
// The stereo front end as one object (stereo/front_end.h): its options table agrees with config/frontend.yaml,
// refuses bad keys and values by name, and one frame through FrontEnd is the stages run one by one; a pair whose
// sizes disagree with the calibration is refused with the reason.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <opencv2/imgproc.hpp>
#include <random>

#include "skin3d/stereo/front_end.h"

using namespace skin3d;

namespace {

const double kF = 500.0, kB = 0.1, kShift = 20.0;  // Z = f B / d = 2.5 m

geometry::CameraInfo info(int w, int h, double tx) {
  geometry::CameraInfo c;
  c.width = w;
  c.height = h;
  c.D = {0, 0, 0, 0, 0};
  c.K << kF, 0, (w - 1) / 2.0, 0, kF, (h - 1) / 2.0, 0, 0, 1;
  c.P << kF, 0, (w - 1) / 2.0, tx, 0, kF, (h - 1) / 2.0, 0, 0, 0, 1, 0;
  return c;
}

// A textured fronto-parallel scene: the right view is the left one shifted by kShift pixels.
std::pair<cv::Mat, cv::Mat> texturedPair(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  cv::Mat big(h, w + 40, CV_8U);
  std::uniform_int_distribution<int> u(0, 255);
  for (int v = 0; v < big.rows; ++v)
    for (int x = 0; x < big.cols; ++x) big.at<uint8_t>(v, x) = static_cast<uint8_t>(u(rng));
  cv::GaussianBlur(big, big, cv::Size(0, 0), 2.0);
  cv::normalize(big, big, 0, 255, cv::NORM_MINMAX);
  const cv::Mat left = big(cv::Rect(0, 0, w, h)).clone();  // column c: u_left = c, u_right = c - kShift
  const cv::Mat right = big(cv::Rect(static_cast<int>(kShift), 0, w, h)).clone();
  return {left, right};
}

}  // namespace

TEST(FrontEnd, ConfigFileListsEveryKeyWithTheCodeDefault) {
  const std::string path = std::string(SKIN3D_SOURCE_DIR) + "/config/frontend.yaml";
  stereo::FrontEndOptions from_file;
  from_file.features.type = stereo::FeatureType::ORB;  // the file must set it back
  stereo::applyFrontEndOptions(&from_file, path);
  const stereo::FrontEndOptions defaults;
  for (const auto& k : stereo::frontEndOptionKeys())
    EXPECT_EQ(stereo::getFrontEndOption(from_file, k), stereo::getFrontEndOption(defaults, k)) << "key " << k;
  std::ifstream f(path);
  const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  for (const auto& k : stereo::frontEndOptionKeys()) EXPECT_NE(text.find("\n" + k + ":"), std::string::npos) << k;
  EXPECT_EQ(stereo::getFrontEndOption(defaults, "feature_type"), "akaze");
}

TEST(FrontEnd, BadKeysAndValuesAreRefusedByName) {
  stereo::FrontEndOptions o;
  try {
    stereo::setFrontEndOption(&o, "no_such_key", "1");
    FAIL() << "accepted an unknown key";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_key"), std::string::npos) << e.what();
  }
  EXPECT_THROW(stereo::setFrontEndOption(&o, "feature_type", "sift"), std::invalid_argument);
  EXPECT_THROW(stereo::setFrontEndOption(&o, "ratio", "abc"), std::invalid_argument);
  stereo::setFrontEndOption(&o, "min_depth", "2");
  stereo::setFrontEndOption(&o, "max_depth", "1");
  try {
    o.validate();
    FAIL() << "max_depth < min_depth accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("max_depth"), std::string::npos) << e.what();
  }
  stereo::FrontEndOptions n;
  n.max_landmarks = -1;
  EXPECT_THROW(stereo::FrontEnd{n}, std::invalid_argument);
}

TEST(FrontEnd, OneFrameIsTheStagesRunOneByOne) {
  const int w = 320, h = 240;
  const auto pair = texturedPair(w, h, 7);
  const geometry::CameraInfo li = info(w, h, 0.0), ri = info(w, h, -kF * kB);
  stereo::FrontEndOptions o;
  stereo::FrontEnd fe(o);
  const stereo::FrontEndFrame f = fe.process(pair.first, pair.second, li, ri);
  ASSERT_GT(f.landmarks.size(), 20u);
  // the stages by hand: rectification (identity here), matching, triangulation
  stereo::FeatureOptions fo = o.features;
  fo.disparity_offset = li.P(0, 2) - ri.P(0, 2);
  const stereo::StereoFeatureMatcher matcher(fo);
  const stereo::Rectifier rl(li), rr(ri);
  const auto matches = matcher.process(rl(pair.first), rr(pair.second));
  const auto lms = stereo::triangulateMatches(li, ri, matches, o.triangulate);
  ASSERT_EQ(lms.size(), f.landmarks.size());
  for (size_t i = 0; i < lms.size(); ++i) {
    EXPECT_EQ(lms[i].position, f.landmarks[i].position);
    EXPECT_EQ(lms[i].covariance, f.landmarks[i].covariance);
  }
  // and the depth the geometry gives
  double zsum = 0;
  for (const auto& l : f.landmarks) zsum += l.position.z();
  EXPECT_NEAR(zsum / f.landmarks.size(), kF * kB / kShift, 0.05);
  // max_landmarks keeps the strongest
  o.max_landmarks = 10;
  stereo::FrontEnd few(o);
  EXPECT_LE(few.process(pair.first, pair.second, li, ri).landmarks.size(), 10u);
}

TEST(FrontEnd, ASizeThatIsNotTheCalibrationsIsRefusedWithTheReason) {
  const auto pair = texturedPair(320, 240, 3);
  stereo::FrontEnd fe{stereo::FrontEndOptions()};
  try {
    fe.process(pair.first, pair.second, info(640, 480, 0.0), info(640, 480, -50.0));
    FAIL() << "accepted a 320x240 image for a 640x480 calibration";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("320x240"), std::string::npos) << e.what();
  }
}
