// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file test_dense_stereo.cpp
 * @brief Tests of skin3d::stereo::computeDisparity and the dense_stereo tool.
 *
 *  - Middlebury 2006 "Aloe" (real pair, ground-truth disparity from the dataset): bad-pixel rates (> 1 px,
 *    > 0.5 px) and RMS error of skin3d's matcher and of plain cv::StereoSGBM measured in the same run;
 *    skin3d must be no worse than SGBM at 1 px on the pixels it reports, and better at 1 px with the pixels it
 *    leaves unknown counted as bad.
 *  - Bad input (empty, mismatched, ROI outside, bad range, no texture, no overlap, saturation): an error or a
 *    warning naming the problem, never a crash.
 *  - Synthetic pair with known sub-pixel, spatially varying disparity (a plane d = d0 + a x + b y) rendered from
 *    an analytic band-limited texture (truth from the generator only): median error and the per-fraction bias
 *    (pixel locking), skin3d's "lk" refinement side by side with SGBM's own sub-pixel ("sgbm").
 *  - The dense_stereo tool end to end (Aloe, and the synthetic pair with a calibration for the cloud), and its
 *    exit codes on bad usage.
 */
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "../../src/core/stereo/dense_stereo_detail.h"

#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/calibration.h"
#include "skin3d/stereo/dense_stereo.h"

namespace {

using skin3d::stereo::computeDisparity;
using skin3d::stereo::DenseStereoError;
using skin3d::stereo::DenseStereoOptions;
using skin3d::stereo::DisparityMap;
using skin3d::stereo::DisparitySearch;
using skin3d::stereo::describeUnknown;
using skin3d::stereo::UnknownReason;
using skin3d::stereo::unknownReasonImage;

const std::string kAloeDir = std::string(SKIN3D_SHARED_DIR) + "/data/middlebury_aloe";

bool fileExists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

/** True when some warning contains one of the keywords (case-insensitive). */
bool warns(const DisparityMap& m, const std::vector<std::string>& keywords) {
  for (const std::string& w : m.warnings)
    for (const std::string& k : keywords)
      if (lower(w).find(k) != std::string::npos) return true;
  return false;
}

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const std::string& x : v) s += (s.empty() ? "" : " | ") + x;
  return s.empty() ? "(none)" : s;
}

/** Runs f, expects a DenseStereoError whose message contains one of the keywords. */
template <class F>
void expectError(F f, const std::vector<std::string>& keywords, const std::string& what) {
  try {
    f();
    ADD_FAILURE() << what << ": no DenseStereoError thrown";
  } catch (const DenseStereoError& e) {
    const std::string msg = lower(e.what());
    bool named = false;
    for (const std::string& k : keywords) named = named || msg.find(k) != std::string::npos;
    EXPECT_TRUE(named) << what << ": the message does not name the problem: '" << e.what() << "'";
  } catch (const std::exception& e) {
    ADD_FAILURE() << what << ": threw something other than DenseStereoError: " << e.what();
  }
}

DenseStereoOptions rangeOptions(double lo, double hi) {
  DenseStereoOptions o;
  o.min_disparity = lo;
  o.max_disparity = hi;
  return o;
}

/** Smoothed random noise texture, 8-bit, full contrast. */
cv::Mat noiseTexture(cv::Size size, unsigned seed, double blur_sigma = 1.2) {
  cv::Mat n(size, CV_32F);
  cv::RNG rng(seed);
  rng.fill(n, cv::RNG::NORMAL, 0.0, 1.0);
  cv::GaussianBlur(n, n, cv::Size(0, 0), blur_sigma);
  cv::normalize(n, n, 20, 235, cv::NORM_MINMAX);
  cv::Mat out;
  n.convertTo(out, CV_8U);
  return out;
}

// ------------------------------------------------------------------------------------------------ metrics

struct Metrics {
  double density = 0;       //!< (method known & GT known) / GT known
  double bad1_i = 0, bad05_i = 0, rms_i = 0;  //!< over GT-known pixels where the method gives a value
  double bad1_ii = 0, bad05_ii = 0;           //!< over all GT-known pixels, a missing value counts as bad
  long n_gt = 0, n_both = 0;
};

/** disparity: CV_32F, NaN unknown; gt: CV_8U, 0 unknown. */
Metrics evaluate(const cv::Mat& disparity, const cv::Mat& gt) {
  Metrics m;
  long bad1 = 0, bad05 = 0;
  double sse = 0;
  for (int y = 0; y < gt.rows; ++y) {
    const uint8_t* g = gt.ptr<uint8_t>(y);
    const float* d = disparity.ptr<float>(y);
    for (int x = 0; x < gt.cols; ++x) {
      if (g[x] == 0) continue;
      ++m.n_gt;
      if (!std::isfinite(d[x])) continue;
      ++m.n_both;
      const double e = std::abs(static_cast<double>(d[x]) - g[x]);
      bad1 += e > 1.0;
      bad05 += e > 0.5;
      sse += e * e;
    }
  }
  if (m.n_gt == 0) return m;
  m.density = static_cast<double>(m.n_both) / m.n_gt;
  if (m.n_both > 0) {
    m.bad1_i = static_cast<double>(bad1) / m.n_both;
    m.bad05_i = static_cast<double>(bad05) / m.n_both;
    m.rms_i = std::sqrt(sse / m.n_both);
  }
  const long missing = m.n_gt - m.n_both;
  m.bad1_ii = static_cast<double>(bad1 + missing) / m.n_gt;
  m.bad05_ii = static_cast<double>(bad05 + missing) / m.n_gt;
  return m;
}

/** StereoSGBM's CV_16S output (1/16 px) as CV_32F px, NaN where invalid (below minDisparity). */
cv::Mat sgbmToFloat(const cv::Mat& raw, int min_disparity) {
  cv::Mat out(raw.size(), CV_32F);
  for (int y = 0; y < raw.rows; ++y) {
    const int16_t* r = raw.ptr<int16_t>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < raw.cols; ++x)
      o[x] = r[x] < min_disparity * 16 ? std::numeric_limits<float>::quiet_NaN() : r[x] / 16.0f;
  }
  return out;
}

void printMetrics(const char* name, const Metrics& m) {
  std::printf("| %-28s | %6.1f %% | %6.2f %% | %6.2f %% | %6.3f | %6.2f %% | %6.2f %% |\n", name, 100 * m.density,
              100 * m.bad1_i, 100 * m.bad05_i, m.rms_i, 100 * m.bad1_ii, 100 * m.bad05_ii);
}

void recordMetrics(const std::string& prefix, const Metrics& m) {
  ::testing::Test::RecordProperty(prefix + "_density_pct", std::to_string(100 * m.density));
  ::testing::Test::RecordProperty(prefix + "_bad1_known_pct", std::to_string(100 * m.bad1_i));
  ::testing::Test::RecordProperty(prefix + "_bad05_known_pct", std::to_string(100 * m.bad05_i));
  ::testing::Test::RecordProperty(prefix + "_rms_known_px", std::to_string(m.rms_i));
  ::testing::Test::RecordProperty(prefix + "_bad1_all_pct", std::to_string(100 * m.bad1_ii));
  ::testing::Test::RecordProperty(prefix + "_bad05_all_pct", std::to_string(100 * m.bad05_ii));
}

struct Aloe {
  cv::Mat left, right, gt;  // colour, colour, CV_8U px (0 unknown)
};

bool loadAloe(Aloe* a) {
  if (!fileExists(kAloeDir + "/aloeL.jpg") || !fileExists(kAloeDir + "/aloeR.jpg") ||
      !fileExists(kAloeDir + "/aloeGT.png"))
    return false;
  a->left = cv::imread(kAloeDir + "/aloeL.jpg", cv::IMREAD_COLOR);
  a->right = cv::imread(kAloeDir + "/aloeR.jpg", cv::IMREAD_COLOR);
  a->gt = cv::imread(kAloeDir + "/aloeGT.png", cv::IMREAD_GRAYSCALE);
  return true;
}

// ------------------------------------------------------------------------------------------------ (a) Aloe

TEST(DenseStereoAloe, NoWorseThanPlainSgbmAtOnePixel) {
  Aloe a;
  if (!loadAloe(&a)) {
    GTEST_SKIP() << "Middlebury Aloe not found in " << kAloeDir << ": test skipped";
  }
  ASSERT_FALSE(a.left.empty()) << "cannot decode " << kAloeDir << "/aloeL.jpg";
  ASSERT_FALSE(a.right.empty()) << "cannot decode " << kAloeDir << "/aloeR.jpg";
  ASSERT_FALSE(a.gt.empty()) << "cannot decode " << kAloeDir << "/aloeGT.png";
  ASSERT_EQ(a.left.size(), a.right.size());
  ASSERT_EQ(a.left.size(), a.gt.size());
  cv::Mat gl, gr;
  cv::cvtColor(a.left, gl, cv::COLOR_BGR2GRAY);
  cv::cvtColor(a.right, gr, cv::COLOR_BGR2GRAY);

  // Plain OpenCV semi-global matching: HH, 320 disparities, block 5, P1 = 8 * 25, P2 = 32 * 25, rest default.
  const int block = 5;
  cv::Ptr<cv::StereoSGBM> sgbm = cv::StereoSGBM::create(0, 320, block, 8 * block * block, 32 * block * block);
  sgbm->setMode(cv::StereoSGBM::MODE_HH);
  const double t0 = static_cast<double>(cv::getTickCount());
  cv::Mat raw;
  sgbm->compute(gl, gr, raw);
  const double t_sgbm = (cv::getTickCount() - t0) / cv::getTickFrequency();
  const cv::Mat d_sgbm = sgbmToFloat(raw, 0);

  // skin3d, same range, default options otherwise, same grey input.
  DenseStereoOptions opt = rangeOptions(0, 320);
  const DisparityMap map = computeDisparity(gl, gr, opt);
  ASSERT_EQ(map.disparity.type(), CV_32F);
  ASSERT_EQ(map.disparity.size(), gl.size());

  const Metrics ms = evaluate(d_sgbm, a.gt), mk = evaluate(map.disparity, a.gt);
  std::printf("\nMiddlebury Aloe %dx%d, disparity 0..320, %ld known GT pixels (GT is integer: the 0.5 px rate "
              "includes its +-0.5 px quantisation)\n",
              gl.cols, gl.rows, mk.n_gt);
  std::printf("| %-28s | density | bad>1px (i) | bad>0.5px (i) | RMS px (i) | bad>1px (ii) | bad>0.5px (ii) |\n",
              "method");
  std::printf("|---|---:|---:|---:|---:|---:|---:|\n");
  printMetrics("cv::StereoSGBM HH", ms);
  printMetrics("skin3d computeDisparity", mk);
  std::printf("(i) GT-known pixels where the method gives a value; (ii) all GT-known pixels, missing = bad.\n");
  std::printf("time: StereoSGBM HH %.2f s; skin3d total %.2f s (prepare %.2f, sgbm %.2f, refine %.2f), coarse 1/%d\n",
              t_sgbm, map.timing.total, map.timing.prepare, map.timing.sgbm, map.timing.refine, map.coarse_scale);
  std::printf("skin3d warnings: %s\n", joined(map.warnings).c_str());
  recordMetrics("sgbm_hh", ms);
  recordMetrics("skin3d", mk);

  EXPECT_LE(mk.bad1_i, ms.bad1_i) << "skin3d's bad-pixel rate (> 1 px, pixels it reports) " << 100 * mk.bad1_i
                                  << " % is worse than plain StereoSGBM's " << 100 * ms.bad1_i << " %";
  // Counting the pixels a method leaves unknown as bad, skin3d must beat plain SGBM too (it answers
  // for about as many pixels, and precisely).
  EXPECT_LT(mk.bad1_ii, ms.bad1_ii) << "skin3d's bad-pixel rate (> 1 px, unknown = bad) " << 100 * mk.bad1_ii
                                    << " % is not below plain StereoSGBM's " << 100 * ms.bad1_ii << " %";
  // A matcher must not win (i) by reporting almost nothing: at least half of SGBM's density.
  EXPECT_GE(mk.density, 0.5 * ms.density) << "skin3d reports " << 100 * mk.density << " % of the GT pixels, SGBM "
                                          << 100 * ms.density << " %";
}

// ------------------------------------------------------------------------------------------------ (b) bad input

TEST(DenseStereoBadInput, ErrorsNameTheProblem) {
  const cv::Mat img = noiseTexture({200, 120}, 1);
  const DenseStereoOptions ok = rangeOptions(0, 32);
  expectError([&] { computeDisparity(cv::Mat(), img, ok); }, {"empty"}, "empty left image");
  expectError([&] { computeDisparity(img, cv::Mat(), ok); }, {"empty"}, "empty right image");
  const cv::Mat narrower = noiseTexture({190, 120}, 2);
  expectError([&] { computeDisparity(img, narrower, ok); }, {"size", "190", "mismatch", "differ"},
              "left/right size mismatch");
  cv::Mat colour;
  cv::cvtColor(img, colour, cv::COLOR_GRAY2BGR);
  expectError([&] { computeDisparity(img, colour, ok); }, {"type", "channel", "differ", "mismatch"},
              "grey left, colour right");

  DenseStereoOptions roi = ok;
  roi.roi = cv::Rect(300, 300, 50, 50);
  expectError([&] { computeDisparity(img, img, roi); }, {"roi", "region"}, "ROI outside the image");

  const double nan = std::numeric_limits<double>::quiet_NaN();
  expectError([&] { computeDisparity(img, img, DenseStereoOptions()); }, {"disparity", "range"},
              "range not set (NaN defaults)");
  expectError([&] { computeDisparity(img, img, rangeOptions(10, 10)); }, {"disparity", "range"}, "min == max");
  expectError([&] { computeDisparity(img, img, rangeOptions(20, 10)); }, {"disparity", "range"}, "min > max");
  expectError([&] { computeDisparity(img, img, rangeOptions(nan, 10)); }, {"disparity", "range"}, "min NaN");
  expectError([&] { computeDisparity(img, img, rangeOptions(0, nan)); }, {"disparity", "range"}, "max NaN");
  DenseStereoOptions levels = ok;
  levels.coarse_min_levels = 7;
  expectError([&] { computeDisparity(img, img, levels); }, {"coarse_min_levels"}, "coarse_min_levels 7");
}

// The semi-global search runs on a pair halved coarse_min_levels times even when it is narrower than
// coarse_max_width (skin's fine texture is about one pixel's noise); 0 lets a small pair be searched as it is.
TEST(DenseStereoCoarseLevel, TheSemiGlobalSearchRunsOnAHalvedPair) {
  const cv::Mat img = noiseTexture({200, 120}, 1);
  DenseStereoOptions o = rangeOptions(0, 32);
  EXPECT_EQ(computeDisparity(img, img, o).coarse_scale, 2);
  o.coarse_min_levels = 0;
  EXPECT_EQ(computeDisparity(img, img, o).coarse_scale, 1);
  o.coarse_min_levels = 2;
  EXPECT_EQ(computeDisparity(img, img, o).coarse_scale, 4);
}

TEST(DenseStereoBadInput, RoiPartlyOutsideIsClipped) {
  const cv::Mat img = noiseTexture({200, 120}, 3);
  DenseStereoOptions o = rangeOptions(0, 16);
  o.roi = cv::Rect(150, 60, 100, 100);  // partly outside the 200x120 image
  DisparityMap m;
  ASSERT_NO_THROW(m = computeDisparity(img, img, o));
  EXPECT_EQ(m.roi, cv::Rect(150, 60, 50, 60));
  // Outside the ROI the map is unknown.
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x)
      if (!m.roi.contains({x, y})) {
        ASSERT_TRUE(std::isnan(m.disparity.at<float>(y, x))) << "at " << x << "," << y;
      }
}

TEST(DenseStereoBadInput, NoTextureIsAllUnknownWithAWarning) {
  const cv::Mat grey(120, 200, CV_8U, cv::Scalar(128));
  DisparityMap m;
  ASSERT_NO_THROW(m = computeDisparity(grey, grey, rangeOptions(0, 32)));
  EXPECT_EQ(cv::countNonZero(m.disparity == m.disparity), 0) << "a uniform pair has known disparities";
  EXPECT_EQ(m.valid_fraction, 0.0);
  EXPECT_TRUE(warns(m, {"texture"})) << "warnings: " << joined(m.warnings);
}

TEST(DenseStereoBadInput, NoOverlapIsMostlyUnknown) {
  const cv::Mat l = noiseTexture({320, 240}, 11), r = noiseTexture({320, 240}, 12);  // unrelated textures
  DisparityMap m;
  ASSERT_NO_THROW(m = computeDisparity(l, r, rangeOptions(0, 48)));
  std::printf("unrelated pair: valid %.1f %%, warnings: %s\n", 100 * m.valid_fraction, joined(m.warnings).c_str());
  RecordProperty("unrelated_pair_valid_pct", std::to_string(100 * m.valid_fraction));
  EXPECT_LT(m.valid_fraction, 0.5) << "two unrelated textures should be mostly unknown";
  EXPECT_TRUE(m.valid_fraction < 0.1 || warns(m, {"overlap", "match", "valid", "unknown"}))
      << "valid " << m.valid_fraction << " without a warning; warnings: " << joined(m.warnings);
}

TEST(DenseStereoBadInput, SaturatedImagesWarn) {
  const cv::Mat white(120, 200, CV_8U, cv::Scalar(255));
  DisparityMap m;
  ASSERT_NO_THROW(m = computeDisparity(white, white, rangeOptions(0, 32)));
  EXPECT_TRUE(warns(m, {"saturat", "overexpos", "over-expos"})) << "warnings: " << joined(m.warnings);
  EXPECT_EQ(cv::countNonZero(m.disparity == m.disparity), 0) << "a saturated pair has known disparities";

  // 16-bit saturation too.
  const cv::Mat white16(120, 200, CV_16U, cv::Scalar(65535));
  ASSERT_NO_THROW(m = computeDisparity(white16, white16, rangeOptions(0, 32)));
  EXPECT_TRUE(warns(m, {"saturat", "overexpos", "over-expos"})) << "16-bit, warnings: " << joined(m.warnings);
}

// ------------------------------------------------------------------------------------------------ (c) synthetic

/**
 * Band-limited analytic texture T(x, y) = 128 + sum_k a_k sin(2 pi (fx_k x + fy_k y) + phi_k), frequencies 0.015 ...
 * 0.2 cycles/px in random directions, amplitude ~ 1/f (a natural-image spectrum), scaled to +-90 grey levels.
 */
struct AnalyticTexture {
  std::vector<double> fx, fy, phase, amp;
  explicit AnalyticTexture(unsigned seed, int n = 48) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    double sum = 0;
    for (int k = 0; k < n; ++k) {
      const double f = 0.015 * std::pow(0.2 / 0.015, u01(rng)), th = M_PI * u01(rng);
      fx.push_back(f * std::cos(th));
      fy.push_back(f * std::sin(th));
      phase.push_back(2 * M_PI * u01(rng));
      amp.push_back(1.0 / f);
      sum += 1.0 / f;
    }
    for (double& a : amp) a *= 90.0 * 2.2 / sum;  // sum of n random-phase sines: rms ~ sum / sqrt(2n)
  }
  double operator()(double x, double y) const {
    double v = 128;
    for (size_t k = 0; k < fx.size(); ++k) v += amp[k] * std::sin(2 * M_PI * (fx[k] * x + fy[k] * y) + phase[k]);
    return v;
  }
};

/** The generator's plane of disparities, in left pixels: d(x, y) = d0 + a x + b y (d = x_left - x_right). */
struct Plane {
  double d0 = 20.37, a = 0.0105, b = 0.0047;
  double operator()(double x, double y) const { return d0 + a * x + b * y; }
};

struct SyntheticPair {
  cv::Mat left, right, truth;  // CV_8U, CV_8U, CV_32F px
};

/** Left L(x, y) = T(x, y); right R(xr, y) = T(xl, y) with xl - d(xl, y) = xr, i.e. xl = (xr + d0 + b y) / (1 - a). */
SyntheticPair renderPlanePair(cv::Size size, const Plane& p, unsigned seed) {
  const AnalyticTexture tex(seed);
  SyntheticPair s;
  s.left.create(size, CV_8U);
  s.right.create(size, CV_8U);
  s.truth.create(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      s.left.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(tex(x, y));
      const double xl = (x + p.d0 + p.b * y) / (1.0 - p.a);
      s.right.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(tex(xl, y));
      s.truth.at<float>(y, x) = static_cast<float>(p(x, y));
    }
  return s;
}

/** An ideal rectified pair of `size`: fx = 1000 px, baseline 0.1 m, the right principal point `dc` px left of the left
 *  one (a converged rig rectified without zero-disparity alignment): Z = fx B / (d - dc). */
std::pair<skin3d::geometry::CameraInfo, skin3d::geometry::CameraInfo> rectifiedPair(cv::Size size, double dc) {
  skin3d::geometry::CameraInfo li, ri;
  for (auto* c : {&li, &ri}) {
    c->width = size.width;
    c->height = size.height;
    c->D = {0, 0, 0, 0, 0};
    c->K << 1000, 0, size.width / 2.0, 0, 1000, size.height / 2.0, 0, 0, 1;
    c->R.setIdentity();
    c->P.setZero();
    c->P.leftCols<3>() = c->K;
  }
  ri.P(0, 2) -= dc;
  ri.P(0, 3) = -1000 * 0.1;
  return {li, ri};
}

// The working range found from the images and the calibration alone: on planes at near and far disparities,
// with and without a principal-point offset (converged rigs), the range holds every true disparity and, in depth,
// is not wider than the generator's depths widened by the search's margin (10 %) and its 2 coarse pixels.
TEST(DisparitySearch, FindsTheRangeOfAnyRig) {
  struct Scene {
    double d0, a, dc;  // plane d = d0 + a x (px), principal-point offset
  };
  const cv::Size size(1280, 720);
  for (const Scene& sc : {Scene{25, 0.01, 0}, Scene{180, 0.03, 0}, Scene{-410, 0.02, -700}, Scene{520, -0.05, 300}}) {
    Plane plane;
    plane.d0 = sc.d0;
    plane.a = sc.a;
    plane.b = 0.002;
    const SyntheticPair pair = renderPlanePair(size, plane, 17);
    const auto [li, ri] = rectifiedPair(size, sc.dc);
    double t_lo, t_hi;
    cv::minMaxLoc(pair.truth, &t_lo, &t_hi);
    const DisparitySearch s = skin3d::stereo::searchDisparityRange(pair.left, pair.right, li, ri, DenseStereoOptions());
    std::printf("plane d %.0f ... %.0f px (dc %.0f): searched %.0f ... %.0f, found %.1f ... %.1f px; %s\n", t_lo, t_hi,
                sc.dc, s.searched_min, s.searched_max, s.min_disparity, s.max_disparity, s.note.c_str());
    EXPECT_TRUE(s.found) << s.note;
    EXPECT_LE(s.min_disparity, t_lo) << "d0 " << sc.d0;
    EXPECT_GE(s.max_disparity, t_hi) << "d0 " << sc.d0;
    const double fb = 100, z_near = fb / (t_hi - sc.dc), z_far = fb / (t_lo - sc.dc);
    const double slack = 2 * s.scale + 1;  // px: the search's 2 coarse pixels and its own 1-coarse-pixel error
    EXPECT_GE(s.min_disparity, fb / (1.1 * z_far) + sc.dc - slack - 0.01 * (t_hi - t_lo)) << "d0 " << sc.d0;
    EXPECT_LE(s.max_disparity, fb / (z_near / 1.1) + sc.dc + slack + 0.01 * (t_hi - t_lo)) << "d0 " << sc.d0;
    // the range found lets the matcher measure the plane
    DenseStereoOptions o;
    o.min_disparity = s.min_disparity;
    o.max_disparity = s.max_disparity;
    const DisparityMap m = computeDisparity(pair.left, pair.right, o);
    // where the right image holds the left one's point at all: 0 <= x - d(x) < w
    double shared = 0;
    for (int x = 0; x < size.width; ++x) shared += (x - plane(x, size.height / 2.0) >= 0 && x - plane(x, size.height / 2.0) < size.width);
    shared /= size.width;
    EXPECT_GT(m.valid_fraction, 0.8 * shared) << "d0 " << sc.d0 << ": " << describeUnknown(m);
  }
  // a pair with nothing to match: the whole searched range, with a note that says so
  const cv::Mat flat(size, CV_8U, cv::Scalar(120));
  const auto [li, ri] = rectifiedPair(size, 0);
  const DisparitySearch none = skin3d::stereo::searchDisparityRange(flat, flat, li, ri, DenseStereoOptions());
  EXPECT_FALSE(none.found);
  EXPECT_NE(none.note.find("searched"), std::string::npos) << none.note;
  EXPECT_EQ(none.min_disparity, none.searched_min);
  // images that cannot overlap: depth infinity beyond the image width
  const auto [la, ra] = rectifiedPair(size, 1250);
  const SyntheticPair any = renderPlanePair(size, Plane(), 3);
  EXPECT_THROW(skin3d::stereo::searchDisparityRange(any.left, any.right, la, ra, DenseStereoOptions()),
               DenseStereoError);
}

struct SubpixelFigures {
  double valid = 0, median_abs = 0, mean = 0, max_bin_bias = 0;
  std::vector<double> bin_mean;
  std::vector<long> bin_count;
};

/** Errors over the evaluation region (margin from the borders, right correspondence inside the image). */
SubpixelFigures subpixelFigures(const cv::Mat& d, const cv::Mat& truth, int bins = 10) {
  SubpixelFigures f;
  f.bin_mean.assign(bins, 0.0);
  f.bin_count.assign(bins, 0);
  std::vector<double> abs_err;
  const int margin = 16;
  long n = 0;
  double sum = 0;
  for (int y = margin; y < d.rows - margin; ++y)
    for (int x = margin; x < d.cols - margin; ++x) {
      const double t = truth.at<float>(y, x);
      if (x - t < margin) continue;  // the point is not (well) inside the right image
      ++n;
      const double v = d.at<float>(y, x);
      if (!std::isfinite(v)) continue;
      const double e = v - t;
      abs_err.push_back(std::abs(e));
      sum += e;
      const int bin = std::min(bins - 1, static_cast<int>((t - std::floor(t)) * bins));
      f.bin_mean[bin] += e;
      ++f.bin_count[bin];
    }
  if (abs_err.empty() || n == 0) return f;
  f.valid = static_cast<double>(abs_err.size()) / n;
  std::nth_element(abs_err.begin(), abs_err.begin() + abs_err.size() / 2, abs_err.end());
  f.median_abs = abs_err[abs_err.size() / 2];
  f.mean = sum / abs_err.size();
  for (int b = 0; b < bins; ++b) {
    if (f.bin_count[b] > 0) f.bin_mean[b] /= f.bin_count[b];
    f.max_bin_bias = std::max(f.max_bin_bias, std::abs(f.bin_mean[b]));
  }
  return f;
}

TEST(DenseStereoSynthetic, SubpixelPlaneWithoutPixelLocking) {
  const Plane plane;
  const cv::Size size(640, 480);
  const SyntheticPair s = renderPlanePair(size, plane, 7);
  // Range from the generator's plane (20.4 ... 29.4 px) with a margin.
  DenseStereoOptions lk = rangeOptions(10, 40);
  DenseStereoOptions sg = lk;
  sg.subpixel = "sgbm";
  const DisparityMap m_lk = computeDisparity(s.left, s.right, lk);
  const DisparityMap m_sg = computeDisparity(s.left, s.right, sg);
  const SubpixelFigures f_lk = subpixelFigures(m_lk.disparity, s.truth), f_sg = subpixelFigures(m_sg.disparity, s.truth);

  std::printf("\nSynthetic plane d = %.2f + %.4f x + %.4f y (%dx%d, analytic texture, 8-bit)\n", plane.d0, plane.a,
              plane.b, size.width, size.height);
  std::printf("| sub-pixel | valid | median |e| px | mean e px | max |bin mean| px |\n|---|---:|---:|---:|---:|\n");
  std::printf("| lk   | %5.1f %% | %.4f | %+.4f | %.4f |\n", 100 * f_lk.valid, f_lk.median_abs, f_lk.mean,
              f_lk.max_bin_bias);
  std::printf("| sgbm | %5.1f %% | %.4f | %+.4f | %.4f |\n", 100 * f_sg.valid, f_sg.median_abs, f_sg.mean,
              f_sg.max_bin_bias);
  std::printf("mean error per fractional-disparity bin (0.0-0.1, ..., 0.9-1.0):\n  lk  ");
  for (double b : f_lk.bin_mean) std::printf(" %+.3f", b);
  std::printf("\n  sgbm");
  for (double b : f_sg.bin_mean) std::printf(" %+.3f", b);
  std::printf("\nwarnings lk: %s; sgbm: %s\n", joined(m_lk.warnings).c_str(), joined(m_sg.warnings).c_str());
  RecordProperty("lk_median_abs_px", std::to_string(f_lk.median_abs));
  RecordProperty("lk_max_bin_bias_px", std::to_string(f_lk.max_bin_bias));
  RecordProperty("lk_valid_pct", std::to_string(100 * f_lk.valid));
  RecordProperty("sgbm_median_abs_px", std::to_string(f_sg.median_abs));
  RecordProperty("sgbm_max_bin_bias_px", std::to_string(f_sg.max_bin_bias));
  RecordProperty("sgbm_valid_pct", std::to_string(100 * f_sg.valid));

  // Pixels near the borders (excluded above): those without a correspondence (x - d_true < -0.5, the right
  // image's left edge) and those within 32 px of either image's border.
  for (const auto* mm : {&m_lk, &m_sg}) {
    long no_corr = 0, no_corr_known = 0, impossible = 0;
    std::vector<double> band;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double t = s.truth.at<float>(y, x), v = mm->disparity.at<float>(y, x);
        if (x - t < -0.5) {
          ++no_corr;
          no_corr_known += std::isfinite(v);
        }
        if (!std::isfinite(v)) continue;
        impossible += x - v < -0.5;
        const bool near_border = x < 32 || x >= size.width - 32 || x - t < 32 || y < 32 || y >= size.height - 32;
        if (near_border && x - t >= -0.5) band.push_back(std::abs(v - t));
      }
    std::sort(band.begin(), band.end());
    const char* name = mm == &m_lk ? "lk" : "sgbm";
    std::printf("%-4s: pixels without a correspondence reported: %ld of %ld; border band (32 px): %zu known, median "
                "|e| %.3f px, 90th percentile %.3f px\n",
                name, no_corr_known, no_corr, band.size(), band.empty() ? 0.0 : band[band.size() / 2],
                band.empty() ? 0.0 : band[band.size() * 9 / 10]);
    RecordProperty(std::string(name) + "_no_correspondence_reported", std::to_string(no_corr_known));
    // A disparity that points left of the right image was not measured.
    EXPECT_EQ(impossible, 0) << name << ": " << impossible << " known pixels with x - d < -0.5 (outside the right image)";
  }

  // An ideal, fully textured pair: nearly everything must be matched, and matched well.
  EXPECT_GT(f_lk.valid, 0.8);
  EXPECT_LT(f_lk.median_abs, 0.05);
  for (size_t b = 0; b < f_lk.bin_mean.size(); ++b) {
    EXPECT_GT(f_lk.bin_count[b], 1000) << "bin " << b << " barely populated (generator plane too flat?)";
    EXPECT_LT(std::abs(f_lk.bin_mean[b]), 0.03) << "pixel locking: mean error " << f_lk.bin_mean[b]
                                                << " px for true fractional disparity in [" << b / 10.0 << ", "
                                                << (b + 1) / 10.0 << ")";
  }
  // The sigma map is defined exactly where the disparity is, and is positive there.
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const float d = m_lk.disparity.at<float>(y, x), sd = m_lk.sigma.at<float>(y, x);
      ASSERT_EQ(std::isfinite(d), std::isfinite(sd)) << "at " << x << "," << y;
      if (std::isfinite(sd)) {
        ASSERT_GT(sd, 0.0f) << "at " << x << "," << y;
      }
    }
}

/** Sparse texture: Gaussian spots (sigma 1.5 px, random sign) on a flat grey, like freckles and pores on skin. */
struct SpotTexture {
  struct Spot {
    double x, y, a;
  };
  std::vector<std::vector<Spot>> rows;  // spots by their integer row
  explicit SpotTexture(cv::Size size, int n, unsigned seed) : rows(size.height + 20) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> ux(-200, size.width + 200), uy(-10, size.height + 10), ua(25, 45);
    for (int i = 0; i < n; ++i) {
      const Spot s{ux(rng), uy(rng), (rng() & 1 ? 1 : -1) * ua(rng)};
      rows[std::clamp(static_cast<int>(std::floor(s.y)) + 10, 0, size.height + 19)].push_back(s);
    }
  }
  double operator()(double x, double y) const {
    double v = 128;
    const int r = static_cast<int>(std::floor(y)) + 10;
    for (int k = std::max(0, r - 6); k <= std::min(static_cast<int>(rows.size()) - 1, r + 6); ++k)
      for (const Spot& s : rows[k]) {
        const double dx = x - s.x, dy = y - s.y;
        if (std::fabs(dx) < 7) v += s.a * std::exp(-(dx * dx + dy * dy) / (2 * 1.5 * 1.5));
      }
    return v;
  }
};

// The side of a limb: the disparity changes by 0.6 px per row, and the texture is sparse spots, so most windows
// hold their texture off-centre. A window's answer belongs to its texture's centroid; unless it is moved back
// along the slope to the window's centre, each window is off by slope x centroid offset (up to ~3 px here).
TEST(DenseStereoSynthetic, SteepSlantWithSparseSpotsIsUnbiased) {
  const cv::Size size(640, 200);
  const double d0 = 30, b = 0.6;  // d = d0 + b y: 30 ... 150 px
  const SpotTexture tex(size, 640 * 200 / 50, 11);
  cv::Mat left(size, CV_8U), right(size, CV_8U);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      left.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(tex(x, y));
      right.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(tex(x + d0 + b * y, y));  // x_l = x_r + d(y)
    }
  const DisparityMap m = computeDisparity(left, right, rangeOptions(20, 160));
  std::vector<double> err;
  long inside = 0;
  for (int y = 32; y < size.height - 32; ++y)
    for (int x = 32; x < size.width - 32; ++x) {
      const double t = d0 + b * y;
      if (x - t < 32) continue;
      ++inside;
      const float v = m.disparity.at<float>(y, x);
      if (std::isfinite(v)) err.push_back(std::fabs(v - t));
    }
  ASSERT_GT(inside, 10000);
  ASSERT_FALSE(err.empty());
  std::sort(err.begin(), err.end());
  const double med = err[err.size() / 2], p90 = err[err.size() * 9 / 10];
  std::printf("\nspots on a steep slant (dd/dy = %.1f): %.1f %% known, median |e| %.3f px, 90th percentile %.3f px\n%s\n",
              b, 100.0 * err.size() / inside, med, p90, describeUnknown(m).c_str());
  RecordProperty("median_abs_px", std::to_string(med));
  RecordProperty("p90_abs_px", std::to_string(p90));
  // Noise-free 8-bit images: the fit is limited by quantisation, a few hundredths of a pixel.
  EXPECT_LT(med, 0.05);
  EXPECT_LT(p90, 0.15);
  EXPECT_GT(err.size(), 0.8 * inside);
}

// Every pixel of the ROI has exactly one reason, known pixels none; the shares add up to 1.
TEST(DenseStereoSynthetic, UnknownReasonsAccountForEveryPixel) {
  const cv::Size size(320, 240);
  SyntheticPair s = renderPlanePair(size, Plane{}, 5);
  s.left(cv::Rect(180, 60, 100, 80)).setTo(128);  // a uniform patch in both views: nothing to fit there
  s.right(cv::Rect(150, 60, 100, 80)).setTo(128);
  DenseStereoOptions o = rangeOptions(10, 40);
  o.roi = cv::Rect(8, 4, 300, 230);
  const DisparityMap m = computeDisparity(s.left, s.right, o);
  ASSERT_EQ(m.unknown_reason.size(), size);
  ASSERT_EQ(m.unknown_share.size(), static_cast<size_t>(UnknownReason::kCount));
  double total = 0;
  for (double v : m.unknown_share) total += v;
  EXPECT_NEAR(total, 1.0, 1e-9);
  EXPECT_NEAR(m.unknown_share[0], m.valid_fraction, 1e-9);
  long mismatch = 0, outside_roi_wrong = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const uchar w = m.unknown_reason.at<uchar>(y, x);
      if (!o.roi.contains(cv::Point(x, y))) {
        outside_roi_wrong += w != 255;
        continue;
      }
      mismatch += (w == 0) != std::isfinite(m.disparity.at<float>(y, x));
    }
  EXPECT_EQ(mismatch, 0);
  EXPECT_EQ(outside_roi_wrong, 0);
  // the uniform patch is unknown for lack of texture (its core; the fit's window reaches texture at its rim)
  EXPECT_EQ(m.unknown_reason.at<uchar>(100, 240), static_cast<uchar>(UnknownReason::kTexture));
  const std::string d = describeUnknown(m);
  EXPECT_NE(d.find("texture"), std::string::npos) << d;
  const cv::Mat pic = unknownReasonImage(m, s.left);
  ASSERT_EQ(pic.size(), size);
  EXPECT_EQ(pic.type(), CV_8UC3);
}

// ------------------------------------------------------------------------------------------------ (d) the tool

struct RunResult {
  int code = -1;
  std::string out, err;
};

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string makeTempDir() {
  std::string tmpl = ::testing::TempDir() + "skin3d_dense_XXXXXX";
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  const char* d = ::mkdtemp(buf.data());
  return d ? std::string(d) : std::string();
}

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

/** Removes a temporary folder of a test unless the test failed (then it is kept for inspection). */
void cleanUp(const std::string& dir) {
  if (dir.empty()) return;
  if (::testing::Test::HasFailure()) {
    std::printf("kept %s for inspection\n", dir.c_str());
    return;
  }
  const int rc = std::system(("rm -rf " + quote(dir)).c_str());
  (void)rc;
}

RunResult runTool(const std::string& args, const std::string& tmp) {
  RunResult r;
  const std::string out = tmp + "/stdout.txt", err = tmp + "/stderr.txt";
  const std::string cmd = quote(SKIN3D_DENSE_STEREO_BIN) + " " + args + " >" + quote(out) + " 2>" + quote(err);
  const int status = std::system(cmd.c_str());
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

// The neighbour check (DenseStereoOptions::neighbour_check) on a field whose truth is known: fits on a slanted,
// curved surface with noise of sigma 0.05 px; row streaks of "disagreement" (the semi-global answer was off) where
// the fit is on the surface (SGBM wrong: must be kept) or 0.4-3 px off it (a wrong minimum: must stay unknown),
// and a block larger than the check's square where nothing vouches for the centre (must stay unknown).
TEST(DenseStereoNeighbourCheck, KeepsFitsOnTheSurfaceAndNotWrongMinima) {
  namespace dd = skin3d::stereo::dense_detail;
  using skin3d::stereo::UnknownReason;
  for (unsigned seed : {1u, 2u, 3u}) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> noise(0.f, 0.05f);
    std::uniform_int_distribution<int> len(3, 14), thick(1, 2), px(0, 239), py(0, 179);
    std::uniform_real_distribution<float> off(0.4f, 3.0f);
    const int rows = 180, cols = 240, radius = 11;
    auto truth = [](int x, int y) { return 60.f + 0.08f * x - 0.05f * y + 2e-4f * (x - 120) * (x - 120); };
    cv::Mat d(rows, cols, CV_32F), sigma(rows, cols, CV_32F, cv::Scalar(0.05f));
    cv::Mat valid(rows, cols, CV_8U, cv::Scalar(255)), reason(rows, cols, CV_8U, cv::Scalar(0));
    cv::Mat kind(rows, cols, CV_8U, cv::Scalar(0));  // 1: disagreement, fit right; 2: fit off the surface
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) d.at<float>(y, x) = truth(x, y) + noise(rng);
    const cv::Rect block(150, 100, 60, 50);
    int streaks = 0;
    while (cv::countNonZero(kind) < 0.15 * rows * cols) {
      const cv::Rect r = cv::Rect(px(rng), py(rng), len(rng), thick(rng)) & cv::Rect(0, 0, cols, rows);
      if ((r & block).area() > 0 || cv::countNonZero(kind(r)) > 0) continue;  // streaks do not overlap
      const bool wrong = (streaks++ % 2) == 1;
      const float shift = (wrong ? off(rng) : 0.f) * (rng() % 2 ? 1.f : -1.f);
      kind(r).setTo(wrong ? 2 : 1);
      d(r) += shift;
    }
    kind(block).setTo(1);  // on the surface, but nothing agreeing near its centre
    reason.setTo(static_cast<int>(UnknownReason::kDisagreement), kind > 0);
    valid.setTo(0, kind > 0);
    dd::keepFitsOnTheirNeighbours(d, sigma, valid, reason, radius);
    int right = 0, right_kept = 0, wrong = 0, wrong_kept = 0;
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) {
        // the block and its surroundings, where the block takes much of the square, are judged below
        const cv::Rect near_block(block.x - radius, block.y - radius, block.width + 2 * radius, block.height + 2 * radius);
        if (near_block.contains(cv::Point(x, y))) continue;
        const int k = kind.at<uchar>(y, x);
        const bool kept = valid.at<uchar>(y, x) != 0;
        EXPECT_EQ(kept, reason.at<uchar>(y, x) == 0) << "valid and reason disagree at " << x << "," << y;
        if (k == 1) { ++right; right_kept += kept; }
        if (k == 2) { ++wrong; wrong_kept += kept; }
      }
    const cv::Rect centre(block.x + radius, block.y + radius, block.width - 2 * radius, block.height - 2 * radius);
    const int centre_kept = cv::countNonZero(valid(centre));
    std::printf("seed %u: fits on the surface kept %d of %d, wrong minima kept %d of %d, block centre kept %d of %d\n",
                seed, right_kept, right, wrong_kept, wrong, centre_kept, centre.area());
    EXPECT_GT(right_kept, 0.95 * right) << "seed " << seed;
    EXPECT_EQ(wrong_kept, 0) << "seed " << seed;
    EXPECT_EQ(centre_kept, 0) << "seed " << seed;
    EXPECT_EQ(cv::countNonZero(valid(block)), cv::countNonZero(reason(block) == 0));
  }
  // a step of 3 px between two surfaces (an occlusion edge): fits on the step, halfway between the two sides (a window
  // straddling it, 1.5 px from either), must stay unknown, though they lie on the plane through both sides' fits
  std::mt19937 rng(4);
  std::normal_distribution<float> noise(0.f, 0.05f);
  const int rows = 60, cols = 80;
  cv::Mat d(rows, cols, CV_32F), sigma(rows, cols, CV_32F, cv::Scalar(0.05f));
  cv::Mat valid(rows, cols, CV_8U, cv::Scalar(255)), reason(rows, cols, CV_8U, cv::Scalar(0));
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) d.at<float>(y, x) = 30.f + (x < 40 ? 3.f : 0.f) + noise(rng);
  const cv::Rect step(39, 10, 2, 40);
  d(step).setTo(31.5f);
  reason(step).setTo(static_cast<int>(UnknownReason::kDisagreement));
  valid(step).setTo(0);
  const long kept = dd::keepFitsOnTheirNeighbours(d, sigma, valid, reason, 11);
  std::printf("fits on a 3 px step kept: %ld of %d\n", kept, step.area());
  EXPECT_EQ(kept, 0);
}

TEST(DenseStereoTool, AloeEndToEnd) {
  Aloe a;
  if (!loadAloe(&a)) {
    GTEST_SKIP() << "Middlebury Aloe not found in " << kAloeDir << ": test skipped";
  }
  const std::string tmp = makeTempDir();
  ASSERT_FALSE(tmp.empty()) << "cannot create a temporary folder";
  const std::string out = tmp + "/out";
  const RunResult r = runTool("--left " + quote(kAloeDir + "/aloeL.jpg") + " --right " + quote(kAloeDir + "/aloeR.jpg") +
                                  " --min-disparity 0 --max-disparity 320 --out " + quote(out),
                              tmp);
  ASSERT_EQ(r.code, 0) << "stdout:\n" << r.out << "\nstderr:\n" << r.err;
  std::printf("%s", r.out.c_str());
  EXPECT_NE(lower(r.out).find("valid"), std::string::npos) << "no valid fraction in the summary:\n" << r.out;
  EXPECT_NE(lower(r.out).find("calib"), std::string::npos) << "does not say that there is no cloud without --calib";
  EXPECT_FALSE(fileExists(out + "/cloud.ply")) << "a cloud without a calibration";
  EXPECT_TRUE(fileExists(out + "/disparity.png"));

  for (const char* name : {"disparity.tiff", "sigma.tiff"}) {
    const cv::Mat d = cv::imread(out + "/" + name, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(d.empty()) << "cannot read back " << name;
    EXPECT_EQ(d.type(), CV_32FC1) << name;
    EXPECT_EQ(d.size(), a.left.size()) << name;
  }
  const cv::Mat d = cv::imread(out + "/disparity.tiff", cv::IMREAD_UNCHANGED);
  long n_nan = 0, n_known = 0, n_out = 0, n_outside_right = 0;
  for (int y = 0; y < d.rows; ++y)
    for (int x = 0; x < d.cols; ++x) {
      const float v = d.at<float>(y, x);
      if (std::isnan(v)) {
        ++n_nan;
      } else {
        ++n_known;
        // The search covers 0 ... 320; the refinement may move a value by up to refine_max_shift (1.5 px by
        // default) past it, not more.
        n_out += !(v >= -1.5f && v <= 321.5f);
        n_outside_right += x - v < -0.5f;  // would match a point left of the right image: cannot be measured
      }
    }
  // The Aloe's leftmost columns (x < the scene's >= 43 px disparity) have no right correspondence.
  EXPECT_GT(n_nan, 0) << "no NaN in the disparity: unknown pixels must be NaN";
  EXPECT_GT(n_known, static_cast<long>(d.total() / 2)) << "less than half of the Aloe pixels known";
  EXPECT_EQ(n_out, 0) << "known disparities outside the searched range 0 ... 320 (+- 1.5 px)";
  EXPECT_EQ(n_outside_right, 0) << "known disparities d > x: the right pixel x - d lies outside the right image";
  // The file holds what the library computes (the tool adds nothing, loses nothing).
  Metrics m = evaluate(d, a.gt);
  std::printf("tool's disparity.tiff against the GT: bad > 1 px (i) %.2f %%, density %.1f %%\n", 100 * m.bad1_i,
              100 * m.density);
  cleanUp(tmp);
}

TEST(DenseStereoTool, BadUsage) {
  const std::string tmp = makeTempDir();
  ASSERT_FALSE(tmp.empty());
  const cv::Mat img = noiseTexture({160, 120}, 5);
  const std::string l = tmp + "/l.png", r = tmp + "/r.png", small = tmp + "/small.png", junk = tmp + "/junk.png";
  ASSERT_TRUE(cv::imwrite(l, img));
  ASSERT_TRUE(cv::imwrite(r, img));
  ASSERT_TRUE(cv::imwrite(small, noiseTexture({150, 120}, 6)));
  std::ofstream(junk) << "not an image";
  const std::string pair = "--left " + quote(l) + " --right " + quote(r) + " --out " + quote(tmp + "/o");

  RunResult h = runTool("--help", tmp);
  EXPECT_EQ(h.code, 0);
  for (const char* opt : {"--left", "--right", "--calib", "--out", "--min-disparity", "--max-disparity", "--z-range",
                          "--roi", "--mode", "--subpixel", "--block", "--help"})
    EXPECT_NE(h.out.find(opt), std::string::npos) << "--help does not document " << opt;

  struct Case {
    std::string args, must_name;
    int code;
  };
  const std::vector<Case> cases = {
      {"--bogus 3 " + pair + " --min-disparity 0 --max-disparity 16", "--bogus", 2},
      {pair + " --min-disparity 16 --max-disparity 4", "--min-disparity", 2},
      {pair + " --min-disparity 0 --max-disparity nan", "--max-disparity", 2},
      {pair + " --min-disparity 0", "--max-disparity", 2},
      {pair, "range", 2},
      {pair + " --min-disparity 0 --max-disparity 16 --roi 1,2,3", "--roi", 2},
      {pair + " --min-disparity 0 --max-disparity 16 --mode fast", "--mode", 2},
      {pair + " --min-disparity 0 --max-disparity 16 --subpixel quadratic", "--subpixel", 2},
      {pair + " --min-disparity 0 --max-disparity 16 --block 4", "--block", 2},
      {pair + " --z-range 0.2 0.3", "--calib", 2},
      {"--right " + quote(r) + " --min-disparity 0 --max-disparity 16", "--left", 2},
      {pair + " --min-disparity 0 --max-disparity 16 --left", "--left", 2},
      // Failures (exit 1): missing, unreadable, mismatched files, ROI outside the image, missing calibration.
      {"--left " + quote(tmp + "/none.png") + " --right " + quote(r) + " --min-disparity 0 --max-disparity 16",
       "none.png", 1},
      {"--left " + quote(junk) + " --right " + quote(r) + " --min-disparity 0 --max-disparity 16", "junk.png", 1},
      {"--left " + quote(l) + " --right " + quote(small) + " --min-disparity 0 --max-disparity 16", "size", 1},
      {pair + " --min-disparity 0 --max-disparity 16 --roi 500,500,10,10", "roi", 1},
      {pair + " --min-disparity 0 --max-disparity 16 --calib " + quote(tmp + "/nocalib"), "nocalib", 1},
  };
  for (const Case& c : cases) {
    const RunResult res = runTool(c.args, tmp);
    EXPECT_EQ(res.code, c.code) << "dense_stereo " << c.args << "\nstderr: " << res.err;
    EXPECT_NE(lower(res.err).find(lower(c.must_name)), std::string::npos)
        << "dense_stereo " << c.args << ": the message does not name '" << c.must_name << "':\n"
        << res.err;
  }
  cleanUp(tmp);
}

/** The tool with a calibration: the cloud of the synthetic plane lies at the generator's depths. */
TEST(DenseStereoTool, SyntheticPlaneCloud) {
  const std::string tmp = makeTempDir();
  ASSERT_FALSE(tmp.empty());
  const Plane plane;
  const cv::Size size(320, 240);
  const SyntheticPair s = renderPlanePair(size, plane, 9);
  ASSERT_TRUE(cv::imwrite(tmp + "/l.png", s.left));
  ASSERT_TRUE(cv::imwrite(tmp + "/r.png", s.right));
  // An ideal rectified pair: fx = 800 px, baseline 0.06 m, equal principal points: Z = fx B / d.
  const double fx = 800, B = 0.06;
  skin3d::geometry::CameraInfo li, ri;
  for (auto* c : {&li, &ri}) {
    c->width = size.width;
    c->height = size.height;
    c->D = {0, 0, 0, 0, 0};
    c->K << fx, 0, 160, 0, fx, 120, 0, 0, 1;
    c->R.setIdentity();
    c->P.setZero();
    c->P.leftCols<3>() = c->K;
  }
  ri.P(0, 3) = -fx * B;
  ASSERT_EQ(::mkdir((tmp + "/calib").c_str(), 0755), 0);
  std::ofstream(tmp + "/calib/left.yaml") << skin3d::stereo::cameraInfoYaml(li, "left");
  std::ofstream(tmp + "/calib/right.yaml") << skin3d::stereo::cameraInfoYaml(ri, "right");
  // Depths of the generator's plane: d in [d0, d0 + a w + b h].
  const double d_min = plane.d0, d_max = plane(size.width, size.height);
  const double z_near = fx * B / d_max, z_far = fx * B / d_min;
  const RunResult r = runTool("--left " + quote(tmp + "/l.png") + " --right " + quote(tmp + "/r.png") + " --calib " +
                                  quote(tmp + "/calib") + " --z-range " + std::to_string(0.8 * z_near) + " " +
                                  std::to_string(1.25 * z_far) + " --out " + quote(tmp + "/o"),
                              tmp);
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  const std::string ply = slurp(tmp + "/o/cloud.ply");
  ASSERT_FALSE(ply.empty()) << "no cloud.ply with --calib";
  const auto end = ply.find("end_header\n");
  ASSERT_NE(end, std::string::npos) << "cloud.ply has no PLY header";
  const std::string header = ply.substr(0, end);
  ASSERT_NE(header.find("format binary_little_endian 1.0"), std::string::npos) << header;
  const auto ev = header.find("element vertex ");
  ASSERT_NE(ev, std::string::npos) << header;
  const long n = std::stol(header.substr(ev + 15));
  EXPECT_GT(n, static_cast<long>(size.area() / 2)) << "too few points in the cloud";
  const size_t stride = 3 * sizeof(float) + 3;
  ASSERT_EQ(ply.size(), end + 11 + n * stride) << "cloud.ply size does not match its header";
  long off = 0;
  for (long i = 0; i < n; ++i) {
    float xyz[3];
    std::memcpy(xyz, ply.data() + end + 11 + i * stride, sizeof xyz);
    ASSERT_GT(xyz[2], 0.0f) << "point " << i << " behind the camera";
    // The pixel of the point (its viewing ray does not depend on the disparity), and the generator's depth
    // there: Z = fx B / d(u, v). 1 % of the depth is 0.2 px of disparity at d ~ 20 px.
    const double u = fx * xyz[0] / xyz[2] + 160, v = fx * xyz[1] / xyz[2] + 120;
    const double z_true = fx * B / plane(u, v);
    off += std::abs(xyz[2] / z_true - 1.0) > 0.01;
  }
  EXPECT_LT(off, n / 20) << off << " of " << n << " points more than 1 % off the generator's depth (" << z_near
                         << " ... " << z_far << " m)";
  cleanUp(tmp);
}

}  // namespace
