// SPDX-License-Identifier: BSD-3-Clause
//
// Tests of the stereo front end's feature detection and left-right matching (stereo/features.h).
// Ground truth comes from geometry, never from our own output:
//  - synthetic rectified pairs: a procedural texture and the same texture shifted by a known (sub-pixel)
//    disparity with cv::warpAffine, so every correct match has u_l - u_r = d on the same row;
//  - hand-made keypoints and descriptors with closed-form distances for the matching rules;
//  - a real pair with ground-truth disparity (Middlebury Aloe, in ../shared when present);
//  - a rendered globe pair (core ray caster, parallel SLAM rig, rectified with the core's rectifyStereo
//    and OpenCV's remap): the depth fx B / d of every match against the sphere hit of its left ray.
// Set SKIN3D_TEST_DEBUG_DIR to a directory to get the globe pair's drawStereoMatches image there.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/sim/dataset.h"
#include "skin3d/sim/globe.h"
#include "skin3d/sim/render.h"
#include "skin3d/stereo/features.h"
#include "skin3d/stereo/rectification.h"

namespace {

using skin3d::stereo::FeatureOptions;
using skin3d::stereo::FeatureType;
using skin3d::stereo::ImageFeatures;
using skin3d::stereo::MatchStats;
using skin3d::stereo::StereoFeatureMatcher;
using skin3d::stereo::StereoMatch;

const FeatureType kAllTypes[] = {FeatureType::KAZE, FeatureType::AKAZE, FeatureType::ORB};

/** Band-limited random texture (sum of bicubically upsampled white noise at several scales), 8-bit. */
cv::Mat proceduralTexture(int width, int height, std::uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat acc(height, width, CV_32F, cv::Scalar(0));
  double amplitude = 1.0;
  for (int cell : {48, 24, 12, 6, 3}) {
    cv::Mat coarse(height / cell + 4, width / cell + 4, CV_32F);
    rng.fill(coarse, cv::RNG::UNIFORM, 0.0, 1.0);
    cv::Mat fine;
    cv::resize(coarse, fine, cv::Size(coarse.cols * cell, coarse.rows * cell), 0, 0, cv::INTER_CUBIC);
    acc += amplitude * fine(cv::Rect(cell, cell, width, height));
    amplitude *= 0.9;
  }
  cv::Mat out;
  cv::normalize(acc, acc, 20, 235, cv::NORM_MINMAX);
  acc.convertTo(out, CV_8U);
  return out;
}

/** Adds Gaussian noise (sigma in DN) to an 8-bit image, deterministic in seed. */
cv::Mat addNoise(const cv::Mat& img, double sigma, std::uint64_t seed) {
  if (sigma <= 0) return img.clone();
  cv::RNG rng(seed);
  cv::Mat noise(img.size(), CV_32F), f;
  rng.fill(noise, cv::RNG::NORMAL, 0.0, sigma);
  img.convertTo(f, CV_32F);
  f += noise;
  cv::Mat out;
  f.convertTo(out, CV_8U);  // saturates
  return out;
}

/** right(u, v) = big(u + pad + shift, v): what a right camera sees of a plane at disparity `shift`. */
struct SyntheticPair {
  cv::Mat left, right;
};
SyntheticPair shiftedPair(const cv::Mat& big, int pad, int width, double shift, std::uint64_t noise_seed,
                          double noise_sigma = 1.5) {
  const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, shift, 0, 1, 0);
  cv::Mat moved;
  cv::warpAffine(big, moved, M, big.size(), cv::INTER_CUBIC | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT);
  const cv::Rect roi(pad, 0, width, big.rows);
  return {addNoise(big(roi), noise_sigma, noise_seed), addNoise(moved(roi), noise_sigma, noise_seed + 1)};
}

SyntheticPair texturePair(double shift, std::uint64_t seed = 7) {
  const int pad = 80, width = 640, height = 480;
  return shiftedPair(proceduralTexture(width + 2 * pad, height, seed), pad, width, shift, seed * 10);
}

struct DisparityErrors {
  std::vector<double> abs_err;  // |(u_l - u_r) - disparity_offset - d_true|
  int max_row_violations = 0;
  double median() const {
    std::vector<double> e = abs_err;
    if (e.empty()) return 1e9;
    std::nth_element(e.begin(), e.begin() + e.size() / 2, e.end());
    return e[e.size() / 2];
  }
  double fractionBelow(double t) const {
    if (abs_err.empty()) return 0.0;
    return static_cast<double>(std::count_if(abs_err.begin(), abs_err.end(), [t](double e) { return e < t; })) /
           abs_err.size();
  }
};

DisparityErrors disparityErrors(const std::vector<StereoMatch>& matches, double offset, double d_true,
                                double max_row_diff) {
  DisparityErrors out;
  for (const auto& m : matches) {
    out.abs_err.push_back(std::abs((m.left.x() - m.right.x()) - offset - d_true));
    if (std::abs(m.left.y() - m.right.y()) > max_row_diff) ++out.max_row_violations;
  }
  return out;
}

/** Hand-made features: keypoints at given positions and CV_32F descriptors given row by row. */
ImageFeatures makeFeatures(const std::vector<cv::Point2f>& pts, const std::vector<std::vector<float>>& desc) {
  ImageFeatures f;
  for (const auto& p : pts) f.keypoints.emplace_back(p, 10.0f, -1.0f, 1.0f);
  f.descriptors = cv::Mat(static_cast<int>(desc.size()), static_cast<int>(desc[0].size()), CV_32F);
  for (size_t i = 0; i < desc.size(); ++i)
    for (size_t j = 0; j < desc[i].size(); ++j)
      f.descriptors.at<float>(static_cast<int>(i), static_cast<int>(j)) = desc[i][j];
  return f;
}

FeatureOptions options(FeatureType type) {
  FeatureOptions o;
  o.type = type;
  return o;
}

}  // namespace

// ================================================================================ names and options

TEST(FeatureTypes, NamesRoundTripAndUnknownNamesAreListed) {
  for (FeatureType t : kAllTypes) EXPECT_EQ(skin3d::stereo::parseFeatureType(featureTypeName(t)), t);
  EXPECT_EQ(skin3d::stereo::parseFeatureType("KAZE"), FeatureType::KAZE);
  try {
    skin3d::stereo::parseFeatureType("sift");
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("sift"), std::string::npos) << msg;
    for (const char* known : {"kaze", "akaze", "orb"}) EXPECT_NE(msg.find(known), std::string::npos) << msg;
  }
}

TEST(FeatureOptions, DefaultsAreValid) {
  EXPECT_NO_THROW(FeatureOptions().validate());
  for (FeatureType t : kAllTypes) EXPECT_NO_THROW(StereoFeatureMatcher{options(t)});
}

TEST(FeatureOptions, BadValuesThrowNamingTheFieldAndValue) {
  struct Case {
    std::function<void(FeatureOptions&)> set;
    std::string field, value;
  };
  const double nan = std::nan("");
  const std::vector<Case> cases = {
      {[](FeatureOptions& o) { o.ratio = 1.5; }, "ratio", "1.5"},
      {[](FeatureOptions& o) { o.ratio = 0.0; }, "ratio", "0"},
      {[nan](FeatureOptions& o) { o.ratio = nan; }, "ratio", "nan"},
      {[](FeatureOptions& o) { o.threshold = -0.001; }, "threshold", "-0.001"},
      {[](FeatureOptions& o) { o.threshold = 0.0; }, "threshold", "0"},
      {[](FeatureOptions& o) { o.threshold = INFINITY; }, "threshold", "inf"},
      {[](FeatureOptions& o) { o.max_features = -1; }, "max_features", "-1"},
      {[](FeatureOptions& o) { o.max_row_diff = -0.5; }, "max_row_diff", "-0.5"},
      {[nan](FeatureOptions& o) { o.max_row_diff = nan; }, "max_row_diff", "nan"},
      {[nan](FeatureOptions& o) { o.min_disparity = nan; }, "min_disparity", "nan"},
      {[](FeatureOptions& o) {
         o.min_disparity = 10;
         o.max_disparity = 5;
       },
       "max_disparity", "5"},
      {[nan](FeatureOptions& o) { o.max_disparity = nan; }, "max_disparity", "nan"},
      {[](FeatureOptions& o) { o.disparity_offset = INFINITY; }, "disparity_offset", "inf"},
      {[](FeatureOptions& o) {
         o.type = FeatureType::ORB;
         o.threshold = 300;
       },
       "threshold", "300"},
      {[](FeatureOptions& o) { o.type = static_cast<FeatureType>(7); }, "type", "7"},
      {[](FeatureOptions& o) { o.border_margin = -1; }, "border_margin", "-1"},
      {[nan](FeatureOptions& o) { o.border_margin = nan; }, "border_margin", "nan"},
  };
  for (const auto& c : cases) {
    FeatureOptions o;
    c.set(o);
    try {
      o.validate();
      ADD_FAILURE() << c.field << " = " << c.value << " accepted";
    } catch (const std::invalid_argument& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.field + " = " + c.value), std::string::npos) << msg;
    }
    EXPECT_THROW(StereoFeatureMatcher{o}, std::invalid_argument) << c.field;
  }
}

// ================================================================ matching rules on hand-made features

TEST(StereoMatching, RowDisparityWindowRatioAndStrengthFollowTheDefinition) {
  FeatureOptions o;
  o.ratio = 0.8;
  o.max_row_diff = 1.5;
  o.min_disparity = 5;
  o.max_disparity = 60;
  o.disparity_offset = 10;  // geometric d = u_l - u_r - 10
  o.cross_check = false;
  const StereoFeatureMatcher m(o);
  // One left feature at (200, 100), descriptor e0 = (1, 0, 0, 0).
  const ImageFeatures left = makeFeatures({{200, 100}}, {{1, 0, 0, 0}});
  // Right candidates (geometric disparity, row offset):
  //  0: d = 30, dv = 0.4, distance 0.1   <- the match
  //  1: d = 40, dv = -1.2, distance 0.5  <- the second best: ratio 0.2, strength 0.8
  //  2: d = 30, dv = 1.6 (outside the row band), distance 0
  //  3: d = 2   (below min_disparity),  distance 0
  //  4: d = 70  (above max_disparity),  distance 0
  //  5: d = -20 (a right feature right of the left one), distance 0
  const ImageFeatures right =
      makeFeatures({{160, 100.4f}, {150, 98.8f}, {160, 101.6f}, {188, 100}, {120, 100}, {210, 100}},
                   {{1, 0.1f, 0, 0}, {1, 0, 0.5f, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}});
  MatchStats st;
  const auto matches = m.match(left, right, &st);
  ASSERT_EQ(matches.size(), 1u);
  EXPECT_DOUBLE_EQ(matches[0].right.x(), 160.0);
  EXPECT_FLOAT_EQ(static_cast<float>(matches[0].right.y()), 100.4f);
  EXPECT_NEAR(matches[0].strength, 1.0 - 0.1 / 0.5, 1e-6);
  EXPECT_EQ(matches[0].descriptor, (std::vector<float>{1, 0, 0, 0}));
  EXPECT_FLOAT_EQ(matches[0].size, 10.0f);
  EXPECT_EQ(st.left_features, 1);
  EXPECT_EQ(st.right_features, 6);
  EXPECT_EQ(st.candidates, 1);
  EXPECT_EQ(st.matches, 1);

  // The ratio test: a second candidate at distance 0.11 (0.1 / 0.11 > 0.8) makes it ambiguous.
  ImageFeatures right2 = makeFeatures({{160, 100.4f}, {150, 98.8f}}, {{1, 0.1f, 0, 0}, {1, 0, 0.11f, 0}});
  EXPECT_TRUE(m.match(left, right2, &st).empty());
  EXPECT_EQ(st.candidates, 1);
  EXPECT_EQ(st.ratio_rejected, 1);
  // ratio = 1 switches it off; the strength is the (small) margin 1 - 0.1 / 0.11.
  FeatureOptions o1 = o;
  o1.ratio = 1.0;
  const auto loose = StereoFeatureMatcher(o1).match(left, right2);
  ASSERT_EQ(loose.size(), 1u);
  EXPECT_NEAR(loose[0].strength, 1.0 - 0.1 / 0.11, 1e-5);
  EXPECT_GT(loose[0].strength, 0.0f);

  // A single candidate: strength 1.
  const ImageFeatures single = makeFeatures({{150, 99}}, {{0, 1, 0, 0}});
  const auto one = m.match(left, single);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_FLOAT_EQ(one[0].strength, 1.0f);

  // Nothing in the window: no candidate at all.
  const ImageFeatures none = makeFeatures({{160, 110}}, {{1, 0, 0, 0}});
  EXPECT_TRUE(m.match(left, none, &st).empty());
  EXPECT_EQ(st.candidates, 0);
}

TEST(StereoMatching, CrossCheckKeepsOnlyMutualBestMatches) {
  FeatureOptions o;
  o.cross_check = true;
  o.ratio = 1.0;
  // Left 0 and left 1 both prefer right 0; right 0 prefers left 1, so left 0 fails the cross-check.
  const ImageFeatures left = makeFeatures({{300, 50}, {320, 50}}, {{1, 0, 0}, {1, 0.05f, 0}});
  const ImageFeatures right = makeFeatures({{280, 50}, {200, 50}}, {{1, 0.06f, 0}, {0, 1, 0}});
  MatchStats st;
  const auto matches = StereoFeatureMatcher(o).match(left, right, &st);
  ASSERT_EQ(matches.size(), 1u);
  EXPECT_DOUBLE_EQ(matches[0].left.x(), 320.0);
  EXPECT_DOUBLE_EQ(matches[0].right.x(), 280.0);
  EXPECT_EQ(st.cross_rejected, 1);
  o.cross_check = false;
  EXPECT_EQ(StereoFeatureMatcher(o).match(left, right).size(), 2u);

  // The cross-check looks back only inside the window: a left feature that would be a better match of
  // right 0 but lies 3 rows away does not take it away.
  o.cross_check = true;
  const ImageFeatures left2 = makeFeatures({{300, 50}, {320, 53}}, {{1, 0, 0}, {1, 0.06f, 0}});
  EXPECT_EQ(StereoFeatureMatcher(o).match(left2, right).size(), 1u);
}

// A match whose keypoint is nearer its image's border than the larger keypoint diameter is dropped (on the rendered
// globe a left feature whose true partner lay 2.9 px from the right image's edge, where the detector sees nothing,
// took the only candidate 5.7 px away, with strength 1).
TEST(StereoMatching, MatchesNearTheImageBorderAreDropped) {
  FeatureOptions o;
  ImageFeatures left = makeFeatures({{300, 50}, {212, 100}, {400, 474}, {500, 200}}, {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}});
  ImageFeatures right = makeFeatures({{280, 50}, {8, 100}, {380, 474}, {480, 200}}, {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}});
  right.keypoints[3].size = 25.0f;  // the larger diameter counts: 480 is 159 px from the right edge, 200 px rows: kept
  left.image_size = right.image_size = cv::Size(640, 480);
  MatchStats st;
  auto matches = StereoFeatureMatcher(o).match(left, right, &st);
  ASSERT_EQ(matches.size(), 2u);  // right x = 8 < 10 (diameter) and left y = 474 > 479 - 10 are dropped
  EXPECT_DOUBLE_EQ(matches[0].left.x(), 300.0);
  EXPECT_DOUBLE_EQ(matches[1].left.x(), 500.0);
  EXPECT_EQ(st.border_rejected, 2);
  right.keypoints[3].size = 50.0f;  // 50 px margin: y = 200 and x = 480 are still inside it, kept
  EXPECT_EQ(StereoFeatureMatcher(o).match(left, right).size(), 2u);
  right.keypoints[3].size = 210.0f;  // y = 200 < 210: cut
  EXPECT_EQ(StereoFeatureMatcher(o).match(left, right).size(), 1u);
  o.border_margin = 0.0;  // off
  EXPECT_EQ(StereoFeatureMatcher(o).match(left, right).size(), 4u);
  o.border_margin = 1.0;
  left.image_size = right.image_size = cv::Size();  // unknown image size (hand-made features): nothing to test
  EXPECT_EQ(StereoFeatureMatcher(o).match(left, right).size(), 4u);
}

TEST(StereoMatching, BinaryDescriptorsUseHammingAndExpandToBits) {
  FeatureOptions o;
  o.cross_check = false;
  ImageFeatures left, right;
  left.keypoints = {cv::KeyPoint(100, 20, 7)};
  right.keypoints = {cv::KeyPoint(80, 20, 7), cv::KeyPoint(70, 20, 7)};
  left.descriptors = (cv::Mat_<uchar>(1, 2) << 0x05, 0x80);  // bits 0, 2 and 15
  right.descriptors = (cv::Mat_<uchar>(2, 2) << 0x04, 0x80,  // Hamming 1
                       0xFA, 0x7F);                          // Hamming 16
  const auto matches = StereoFeatureMatcher(o).match(left, right);
  ASSERT_EQ(matches.size(), 1u);
  EXPECT_DOUBLE_EQ(matches[0].right.x(), 80.0);
  EXPECT_NEAR(matches[0].strength, 1.0 - 1.0 / 16.0, 1e-6);
  std::vector<float> bits(16, 0.0f);
  bits[0] = bits[2] = bits[15] = 1.0f;
  EXPECT_EQ(matches[0].descriptor, bits);
}

TEST(StereoMatching, InconsistentFeaturesThrowAndEmptyOnesGiveNothing) {
  const StereoFeatureMatcher m{FeatureOptions()};
  const ImageFeatures f = makeFeatures({{10, 10}}, {{1, 0}});
  ImageFeatures binary;
  binary.keypoints = f.keypoints;
  binary.descriptors = cv::Mat(1, 2, CV_8U, cv::Scalar(1));
  EXPECT_THROW(m.match(f, binary), std::invalid_argument);
  ImageFeatures broken = f;
  broken.descriptors = cv::Mat();
  EXPECT_THROW(m.match(f, broken), std::invalid_argument);
  MatchStats st;
  EXPECT_TRUE(m.match(ImageFeatures(), f, &st).empty());
  EXPECT_EQ(st.right_features, 1);
  EXPECT_EQ(st.matches, 0);
  EXPECT_TRUE(m.match(f, ImageFeatures()).empty());
}

// ======================================================================= synthetic shifted texture

// (1) A textured plane at a known sub-pixel disparity: matches on the same row, disparity d.
TEST(SyntheticPair, KazeRecoversAKnownSubpixelDisparity) {
  const double d = 23.4;
  const SyntheticPair p = texturePair(d);
  const FeatureOptions o;
  MatchStats st;
  const auto matches = StereoFeatureMatcher(o).process(p.left, p.right, &st);
  EXPECT_GE(matches.size(), 300u) << st.left_features << " / " << st.right_features << " features";
  const DisparityErrors e = disparityErrors(matches, 0.0, d, o.max_row_diff);
  EXPECT_EQ(e.max_row_violations, 0);
  EXPECT_LT(e.median(), 0.3);
  EXPECT_GE(e.fractionBelow(1.0), 0.95);
  for (const auto& m : matches) {
    EXPECT_GT(m.strength, 0.0f);
    EXPECT_LE(m.strength, 1.0f);
    EXPECT_EQ(m.descriptor.size(), 64u);
  }
}

// (1) The principal-point offset: the right image shifted by d + 10 with disparity_offset = 10 gives d.
TEST(SyntheticPair, DisparityOffsetIsRemovedFromTheGeometricDisparity) {
  const double d = 17.6, offset = 10.0;
  const SyntheticPair p = texturePair(d + offset, 11);
  FeatureOptions o;
  o.disparity_offset = offset;
  o.min_disparity = d - 3;
  o.max_disparity = d + 3;
  const auto matches = StereoFeatureMatcher(o).process(p.left, p.right);
  EXPECT_GE(matches.size(), 300u);
  const DisparityErrors e = disparityErrors(matches, offset, d, o.max_row_diff);
  EXPECT_EQ(e.max_row_violations, 0);
  EXPECT_LT(e.median(), 0.3);
  EXPECT_GE(e.fractionBelow(1.0), 0.95);
  // Without the offset the same window [d - 3, d + 3] does not contain the raw disparity d + 10.
  o.disparity_offset = 0.0;
  EXPECT_LE(StereoFeatureMatcher(o).process(p.left, p.right).size(), matches.size() / 20);
}

// (3) The disparity window excludes what lies outside it. With the true disparity outside the window the few
// matches left are wrong ones: a left feature with a single candidate in the window is accepted (strength 1,
// header), and only the cross-check guards it.
TEST(SyntheticPair, DisparityWindowExcludesMatchesOutsideIt) {
  const double d = 23.4;
  const SyntheticPair p = texturePair(d, 5);
  const StereoFeatureMatcher base{FeatureOptions()};
  const ImageFeatures fl = base.detect(p.left), fr = base.detect(p.right);
  const size_t all = base.match(fl, fr).size();
  ASSERT_GE(all, 300u);
  struct Window {
    double lo, hi;
    bool contains_d;
  };
  for (const Window w : {Window{30, 1e9, false}, Window{0.5, 20, false}, Window{20, 30, true}, Window{23, 24, true}}) {
    FeatureOptions o;
    o.min_disparity = w.lo;
    o.max_disparity = w.hi;
    const auto matches = StereoFeatureMatcher(o).match(fl, fr);
    for (const auto& m : matches) {
      const double disp = m.left.x() - m.right.x();
      EXPECT_GE(disp, w.lo);
      EXPECT_LE(disp, w.hi);
    }
    if (w.contains_d) {
      EXPECT_GE(matches.size(), all * 9 / 10) << "[" << w.lo << ", " << w.hi << "]";
    } else {
      EXPECT_LE(matches.size(), all / 5) << "[" << w.lo << ", " << w.hi << "]";
    }
  }
}

// (2) A repeated pattern (identical tiles along the rows): the ratio test and the cross-check refuse to
// choose between look-alikes; without them nearly every feature "matches" something. KAZE's nonlinear
// diffusion runs over the whole image, so within ~130 px of a border a tile's features differ from their
// interior copies; the look-alikes are exact copies in the interior, where the counts are taken.
TEST(SyntheticPair, RatioTestAndCrossCheckRejectARepeatedPattern) {
  const int tile_w = 64, width = 640, height = 480, pad = 2 * tile_w;
  const cv::Mat tile = proceduralTexture(tile_w, height, 3);
  cv::Mat big;
  cv::repeat(tile, 1, (width + 2 * pad) / tile_w, big);
  // Noise-free: the tiles are exact copies in both images (and the shift keeps the period).
  const SyntheticPair p = shiftedPair(big, pad, width, 2 * tile_w + 20, 99, 0.0);
  FeatureOptions strict;  // ratio 0.8, cross-check
  FeatureOptions ratio_only = strict, cross_only = strict, loose = strict;
  ratio_only.cross_check = false;
  cross_only.ratio = 1.0;
  loose.ratio = 1.0;
  loose.cross_check = false;
  const StereoFeatureMatcher m(strict);
  const ImageFeatures fl = m.detect(p.left), fr = m.detect(p.right);
  const auto interior = [](const std::vector<StereoMatch>& matches) {
    return std::count_if(matches.begin(), matches.end(),
                         [](const StereoMatch& x) { return x.left.x() > 150 && x.left.x() < 490; });
  };
  MatchStats st;
  const auto n_loose = interior(StereoFeatureMatcher(loose).match(fl, fr, &st));
  EXPECT_GE(n_loose, 300);
  EXPECT_LE(interior(m.match(fl, fr, &st)) * 50, n_loose);
  EXPECT_GT(st.ratio_rejected, n_loose);
  // Each alone: a few more survive, where the only exact copy in the window is interior and the others
  // are border-affected.
  EXPECT_LE(interior(StereoFeatureMatcher(ratio_only).match(fl, fr)) * 20, n_loose);
  EXPECT_LE(interior(StereoFeatureMatcher(cross_only).match(fl, fr)) * 20, n_loose);

  // Control: the same pipeline on a non-repeating texture keeps most of its loose matches.
  const SyntheticPair q = texturePair(20, 3);
  const size_t q_loose = StereoFeatureMatcher(loose).process(q.left, q.right).size();
  EXPECT_GE(m.process(q.left, q.right).size() * 2, q_loose);
}

// (4) Every feature type detects, describes as documented and matches the known disparity.
TEST(SyntheticPair, EveryFeatureTypeWorks) {
  const double d = 21.0;
  const SyntheticPair p = texturePair(d, 13);
  for (FeatureType t : kAllTypes) {
    SCOPED_TRACE(featureTypeName(t));
    const StereoFeatureMatcher m(options(t));
    const ImageFeatures f = m.detect(p.left);
    ASSERT_GT(f.keypoints.size(), 100u);
    EXPECT_LE(f.keypoints.size(), 3000u);
    ASSERT_EQ(f.descriptors.rows, static_cast<int>(f.keypoints.size()));
    size_t bits = 0;
    switch (t) {
      case FeatureType::KAZE:
        EXPECT_EQ(f.descriptors.type(), CV_32FC1);
        EXPECT_EQ(f.descriptors.cols, 64);
        bits = 64;
        break;
      case FeatureType::AKAZE:  // binary MLDB, 486 bits in 61 bytes
        EXPECT_EQ(f.descriptors.type(), CV_8UC1);
        EXPECT_EQ(f.descriptors.cols, 61);
        bits = 488;
        break;
      case FeatureType::ORB:  // rBRIEF, 256 bits
        EXPECT_EQ(f.descriptors.type(), CV_8UC1);
        EXPECT_EQ(f.descriptors.cols, 32);
        bits = 256;
        break;
    }
    for (size_t i = 1; i < f.keypoints.size(); ++i) ASSERT_GE(f.keypoints[i - 1].response, f.keypoints[i].response);
    const auto matches = m.process(p.left, p.right);
    EXPECT_GE(matches.size(), 200u);
    const DisparityErrors e = disparityErrors(matches, 0.0, d, 1.5);
    EXPECT_EQ(e.max_row_violations, 0);
    if (t != FeatureType::ORB) {  // sub-pixel refined keypoints
      EXPECT_LT(e.median(), 0.3);
      EXPECT_GE(e.fractionBelow(1.0), 0.95);
    } else {
      // ORB keypoints are integer pixels of pyramid level `octave` (scale 1.2^octave), not refined: each
      // image's position is quantised to +-0.5 scale, so the disparity error lies within scale (+0.5 px of
      // interpolation and noise); its median is ~0.29 scale for two uniform quantisation errors.
      std::vector<double> normalised;
      int within = 0;
      for (size_t i = 0; i < matches.size(); ++i) {
        const double scale = std::pow(1.2, matches[i].octave);
        normalised.push_back(e.abs_err[i] / scale);
        if (e.abs_err[i] <= scale + 0.5) ++within;
      }
      std::nth_element(normalised.begin(), normalised.begin() + normalised.size() / 2, normalised.end());
      EXPECT_LT(normalised[normalised.size() / 2], 0.4);
      EXPECT_GE(within, 0.95 * matches.size());
    }
    for (const auto& mm : matches) {
      ASSERT_EQ(mm.descriptor.size(), bits);
      if (t == FeatureType::KAZE) continue;
      for (float b : mm.descriptor) ASSERT_TRUE(b == 0.0f || b == 1.0f);
    }
  }
}

TEST(SyntheticPair, MaxFeaturesKeepsTheStrongest) {
  const cv::Mat img = texturePair(0, 17).left;
  for (FeatureType t : kAllTypes) {
    SCOPED_TRACE(featureTypeName(t));
    FeatureOptions all = options(t);
    all.max_features = 0;
    const ImageFeatures f_all = StereoFeatureMatcher(all).detect(img);
    const int n = static_cast<int>(f_all.keypoints.size()) / 4;
    ASSERT_GT(n, 20);
    FeatureOptions few = all;
    few.max_features = n;
    const ImageFeatures f = StereoFeatureMatcher(few).detect(img);
    ASSERT_EQ(static_cast<int>(f.keypoints.size()), n);
    if (t == FeatureType::ORB) continue;  // ORB distributes its quota over the pyramid levels itself
    // Same detector, same keypoints: the kept ones are the n strongest of all, with their descriptors.
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(f.keypoints[i].pt, f_all.keypoints[i].pt);
      EXPECT_EQ(cv::norm(f.descriptors.row(i), f_all.descriptors.row(i), cv::NORM_L1), 0.0);
    }
    EXPECT_GE(f.keypoints[n - 1].response, f_all.keypoints[n].response);
  }
}

TEST(SyntheticPair, OrbThresholdAboveOneIsTheFastThreshold) {
  const cv::Mat img = texturePair(0, 19).left;
  FeatureOptions o = options(FeatureType::ORB);
  o.max_features = 0;
  o.threshold = 5;
  const size_t low = StereoFeatureMatcher(o).detect(img).keypoints.size();
  o.threshold = 40;
  const size_t high = StereoFeatureMatcher(o).detect(img).keypoints.size();
  EXPECT_LT(high * 2, low) << high << " vs " << low;
}

TEST(SyntheticPair, ProcessEqualsDetectAndMatch) {
  const SyntheticPair p = texturePair(12.5, 23);
  for (FeatureType t : kAllTypes) {
    const StereoFeatureMatcher m(options(t));
    MatchStats a, b;
    const auto via_process = m.process(p.left, p.right, &a);
    const auto via_parts = m.match(m.detect(p.left), m.detect(p.right), &b);
    ASSERT_EQ(via_process.size(), via_parts.size()) << featureTypeName(t);
    for (size_t i = 0; i < via_parts.size(); ++i) {
      EXPECT_EQ(via_process[i].left, via_parts[i].left);
      EXPECT_EQ(via_process[i].right, via_parts[i].right);
    }
    EXPECT_EQ(a.ratio_rejected, b.ratio_rejected);
    EXPECT_EQ(a.cross_rejected, b.cross_rejected);
  }
}

// ======================================================================================= bad input

TEST(BadInput, EmptyBlackAndTexturelessImagesGiveNoFeatures) {
  const cv::Mat textured = texturePair(0, 29).left;
  for (FeatureType t : kAllTypes) {
    SCOPED_TRACE(featureTypeName(t));
    const StereoFeatureMatcher m(options(t));
    for (const cv::Mat& img : {cv::Mat(), cv::Mat(480, 640, CV_8U, cv::Scalar(0)),
                               cv::Mat(480, 640, CV_8U, cv::Scalar(128)), cv::Mat(3, 3, CV_8U, cv::Scalar(200))}) {
      const ImageFeatures f = m.detect(img);
      EXPECT_TRUE(f.keypoints.empty());
      EXPECT_EQ(f.descriptors.rows, 0);
    }
    MatchStats st;
    EXPECT_TRUE(m.process(cv::Mat(), cv::Mat(), &st).empty());
    EXPECT_TRUE(m.process(textured, cv::Mat(480, 640, CV_8U, cv::Scalar(0)), &st).empty());
    EXPECT_GT(st.left_features, 0);
    EXPECT_EQ(st.right_features, 0);
    // Tiny images: no crash.
    cv::Mat tiny(12, 9, CV_8U);
    cv::randu(tiny, 0, 255);
    EXPECT_NO_THROW(m.process(tiny, tiny));
  }
}

TEST(BadInput, MismatchedSizesAndColourDoNotCrash) {
  const SyntheticPair p = texturePair(15, 31);
  cv::Mat small, colour;
  cv::resize(p.right, small, cv::Size(320, 240));
  cv::cvtColor(p.right, colour, cv::COLOR_GRAY2BGR);
  for (FeatureType t : kAllTypes) {
    const StereoFeatureMatcher m(options(t));
    EXPECT_NO_THROW(m.process(p.left, small)) << featureTypeName(t);
    EXPECT_NO_THROW(m.process(small, p.left)) << featureTypeName(t);
  }
  const StereoFeatureMatcher m{FeatureOptions()};
  // A BGR image is converted to grey: the same keypoints as the grey image.
  const ImageFeatures grey = m.detect(p.right), bgr = m.detect(colour);
  ASSERT_EQ(grey.keypoints.size(), bgr.keypoints.size());
  for (size_t i = 0; i < grey.keypoints.size(); ++i) EXPECT_EQ(grey.keypoints[i].pt, bgr.keypoints[i].pt);
  EXPECT_THROW(m.detect(cv::Mat(10, 10, CV_32F, cv::Scalar(0.5))), std::invalid_argument);
  EXPECT_THROW(m.detect(cv::Mat(10, 10, CV_8UC2, cv::Scalar(0))), std::invalid_argument);
  EXPECT_NO_THROW(skin3d::stereo::drawStereoMatches(p.left, small, m.process(p.left, small)));
}

// =========================================================================================== drawing

TEST(DrawStereoMatches, SideBySideWithLinesColouredByStrength) {
  const cv::Mat l(100, 120, CV_8U, cv::Scalar(0)), r(80, 90, CV_8U, cv::Scalar(0));
  StereoMatch strong, weak;
  strong.left = Eigen::Vector2d(60, 40);
  strong.right = Eigen::Vector2d(30, 40);
  strong.strength = 1.0f;
  weak.left = Eigen::Vector2d(60, 70);
  weak.right = Eigen::Vector2d(30, 70);
  weak.strength = 0.05f;
  const cv::Mat img = skin3d::stereo::drawStereoMatches(l, r, {strong, weak});
  ASSERT_EQ(img.type(), CV_8UC3);
  ASSERT_EQ(img.rows, 100);
  ASSERT_EQ(img.cols, 210);
  // Mid-points of the two lines (left x 60 -> right x 120 + 30): BGR, green for strong, red for weak.
  const cv::Vec3b s = img.at<cv::Vec3b>(40, 105), w = img.at<cv::Vec3b>(70, 105);
  EXPECT_GT(s[1], 200);
  EXPECT_LT(s[2], 50);
  EXPECT_GT(w[2], 200);
  EXPECT_LT(w[1], 50);
  // Circles around the end points; the centre itself is not covered.
  EXPECT_GT(img.at<cv::Vec3b>(37, 60)[1], 100);
  EXPECT_GT(img.at<cv::Vec3b>(43, 150)[1], 100);
  EXPECT_TRUE(skin3d::stereo::drawStereoMatches(cv::Mat(), cv::Mat(), {}).empty());
}

// ========================================================================== real pair (Middlebury)

TEST(MiddleburyAloe, MatchesAgreeWithTheGroundTruthDisparity) {
  const std::string dir = std::string(SKIN3D_SHARED_DIR) + "/data/middlebury_aloe/";
  const cv::Mat L = cv::imread(dir + "aloeL.jpg", cv::IMREAD_GRAYSCALE),
                R = cv::imread(dir + "aloeR.jpg", cv::IMREAD_GRAYSCALE);
  const cv::Mat gt = cv::imread(dir + "aloeGT.png", cv::IMREAD_UNCHANGED);
  if (L.empty() || R.empty() || gt.empty()) GTEST_SKIP() << "Middlebury Aloe not found in " << dir;
  ASSERT_EQ(gt.type(), CV_8UC1);
  MatchStats st;
  const auto matches = StereoFeatureMatcher(FeatureOptions()).process(L, R, &st);
  int known = 0, good = 0;
  for (const auto& m : matches) {
    const int u = static_cast<int>(std::lround(m.left.x())), v = static_cast<int>(std::lround(m.left.y()));
    const int d_true = gt.at<uchar>(v, u);
    if (d_true == 0) continue;  // unknown
    ++known;
    // Integer ground truth: within 1 px of it (plus its 0.5 px rounding).
    if (std::abs((m.left.x() - m.right.x()) - d_true) <= 1.5) ++good;
  }
  // Real images: occlusion boundaries, where the integer ground truth belongs to one side, and a few
  // mismatches on the repetitive background cloth.
  EXPECT_GE(known, 500) << matches.size() << " matches";
  EXPECT_GE(good, 0.85 * known) << good << " of " << known;
}

// ======================================================== rendered globe: rectification + matching

namespace {

/** A rendered, rectified globe pair seen by the parallel SLAM rig (built once for all the tests). */
struct GlobePair {
  skin3d::stereo::RectifiedPair rect;
  Eigen::Vector3d centre_left = Eigen::Vector3d(0, 0, 0.6);  // sphere centre, raw left optical frame
  double radius = 0.2;
  cv::Mat left, right;  // rectified, 8-bit

  static const GlobePair& get() {
    static const GlobePair pair = make();
    return pair;
  }

 private:
  static cv::Mat rectify(const skin3d::geometry::CameraInfo& c, const cv::Mat& raw) {
    cv::Mat K, R, P, map1, map2, out;
    const Eigen::Matrix3d P3 = c.P.leftCols<3>();
    cv::eigen2cv(c.K, K);
    cv::eigen2cv(c.R, R);
    cv::eigen2cv(P3, P);
    cv::initUndistortRectifyMap(K, cv::Mat(c.D), R, P, raw.size(), CV_32FC1, map1, map2);
    cv::remap(raw, out, map1, map2, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    return out;
  }

  static GlobePair make() {
    using namespace skin3d;
    GlobePair g;
    const geometry::StereoRig rig = sim::RigConfig().makeRig();
    // The globe 600 mm in front of the left camera, as in the globe-images dataset at t = 0 (world = left
    // optical frame); texels of 0.5 mm (about a pixel at the globe's front) keep the texture quick to build.
    const sim::SphereScene scene(g.centre_left, g.radius, 1, 0.5e-3);
    sim::RenderOptions ro;
    ro.light_dir = Eigen::Vector3d(0.3, std::sin(0.5), std::cos(0.5)).normalized();  // lamp on the rig
    const Eigen::Isometry3d T_L_R(Eigen::Translation3d(rig.rightCentre()) * Eigen::Quaterniond(rig.R_rl().transpose()));
    const cv::Mat irr_l = sim::renderIrradiance(scene, rig.left(), Eigen::Isometry3d::Identity(), ro);
    const cv::Mat irr_r = sim::renderIrradiance(scene, rig.right(), T_L_R, ro);
    const sim::ImageConfig images = sim::defaultDatasetConfig(sim::DatasetKind::GlobeImages).images;
    g.rect = stereo::rectifyStereo(rig);
    g.left = rectify(g.rect.left, sim::applyRealism(irr_l, images.left, 101));
    g.right = rectify(g.rect.right, sim::applyRealism(irr_r, images.right, 102));
    return g;
  }
};

}  // namespace

// (6) The whole chain (render -> rectify -> detect -> match) against the renderer's geometry: the depth
// of every match from its rectified disparity, Z = fx B / d, against the depth where the left pixel's ray
// meets the sphere.
TEST(RenderedGlobe, MatchedDepthAgreesWithTheSphere) {
  const GlobePair& g = GlobePair::get();
  const Eigen::Matrix<double, 3, 4>& Pl = g.rect.left.P;
  const Eigen::Matrix<double, 3, 4>& Pr = g.rect.right.P;
  const double fx = Pl(0, 0), fy = Pl(1, 1), cx = Pl(0, 2), cy = Pl(1, 2);
  const double B = -Pr(0, 3) / Pr(0, 0);
  const double offset = Pl(0, 2) - Pr(0, 2);
  const Eigen::Vector3d c = g.rect.left.R * g.centre_left;  // sphere centre in the rectified left frame
  for (FeatureType t : {FeatureType::KAZE, FeatureType::AKAZE}) {
    SCOPED_TRACE(featureTypeName(t));
    FeatureOptions o = options(t);
    o.disparity_offset = offset;
    MatchStats st;
    const auto matches = StereoFeatureMatcher(o).process(g.left, g.right, &st);
    if (t == FeatureType::KAZE) {
      EXPECT_GE(matches.size(), 200u);
      if (const char* dir = std::getenv("SKIN3D_TEST_DEBUG_DIR"))
        cv::imwrite(std::string(dir) + "/globe_matches_kaze.png",
                    skin3d::stereo::drawStereoMatches(g.left, g.right, matches));
    } else {
      EXPECT_GE(matches.size(), 100u);
    }
    // The depth error of a match in disparity units: |Z - Z_true| fx B / Z_true^2 (depth noise per px).
    std::vector<double> err_px;
    int misses = 0;
    for (const auto& m : matches) {
      const double d = (m.left.x() - m.right.x()) - offset;
      ASSERT_GT(d, 0.0);
      const double Z = fx * B / d;
      const Eigen::Vector3d ray((m.left.x() - cx) / fx, (m.left.y() - cy) / fy, 1.0);
      const double a = ray.squaredNorm(), b = -2.0 * ray.dot(c), cc = c.squaredNorm() - g.radius * g.radius;
      const double disc = b * b - 4 * a * cc;
      if (disc < 0) {
        ++misses;
        continue;
      }
      const double Z_true = (-b - std::sqrt(disc)) / (2 * a);  // ray z = 1: the parameter is the depth
      err_px.push_back(std::abs(Z - Z_true) * fx * B / (Z_true * Z_true));
    }
    EXPECT_LE(misses, static_cast<int>(matches.size()) / 50);
    ASSERT_FALSE(err_px.empty());
    std::sort(err_px.begin(), err_px.end());
    const double median = err_px[err_px.size() / 2];
    const double within =
        static_cast<double>(std::lower_bound(err_px.begin(), err_px.end(), 2.0) - err_px.begin()) / err_px.size();
    // A feature is localised to a few tenths of a pixel in each image: the disparity error's median stays
    // below 0.5 px and 90 % of the matches lie within 2 px (gross mismatches would be tens of px off).
    EXPECT_LT(median, 0.5) << matches.size() << " matches";
    EXPECT_GE(within, 0.9) << matches.size() << " matches";
  }
}
