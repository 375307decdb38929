// SPDX-License-Identifier: BSD-3-Clause
// Chessboard stereo calibration: real images (OpenCV's sample pairs) against OpenCV's own calibration of the
// same corners, a synthetic strongly converged rig against its ground truth, the ROS camera_info YAML, and the
// calibrate_stereo command line end to end.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/stereo/calibration.h"

using namespace skin3d;

namespace {

constexpr double kDeg = M_PI / 180.0;

const std::string kRealDir = std::string(SKIN3D_SHARED_DIR) + "/data/chessboard_stereo";
const char* const kRealKeys[] = {"01", "02", "03", "04", "05", "06", "07", "08", "09", "11", "12", "13", "14"};

bool isFile(const std::string& p) {
  struct stat st;
  return stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

bool haveRealImages() {
  return isFile(kRealDir + "/left01.jpg") && isFile(kRealDir + "/right14.jpg");
}

std::vector<stereo::ImagePair> realPairs() {
  std::vector<stereo::ImagePair> pairs;
  for (const char* k : kRealKeys)
    pairs.push_back({k, kRealDir + "/left" + k + ".jpg", kRealDir + "/right" + k + ".jpg"});
  return pairs;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : (v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]));
}

/** |dv| of corresponding corners after rectification with OpenCV's undistortPoints and the CameraInfo's K D R P. */
std::vector<double> rectifiedRowErrors(const geometry::CameraInfo& l, const geometry::CameraInfo& r,
                                       const std::vector<std::vector<cv::Point2f>>& left,
                                       const std::vector<std::vector<cv::Point2f>>& right) {
  const auto rect = [](const geometry::CameraInfo& info, const std::vector<cv::Point2f>& raw) {
    cv::Mat K(3, 3, CV_64F), R(3, 3, CV_64F), P(3, 4, CV_64F);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) {
        if (j < 3) K.at<double>(i, j) = info.K(i, j), R.at<double>(i, j) = info.R(i, j);
        P.at<double>(i, j) = info.P(i, j);
      }
    std::vector<cv::Point2f> out;
    cv::undistortPoints(raw, out, K, cv::Mat(info.D), R, P);
    return out;
  };
  std::vector<double> dv;
  for (size_t i = 0; i < left.size(); ++i) {
    const auto a = rect(l, left[i]), b = rect(r, right[i]);
    for (size_t k = 0; k < a.size(); ++k) dv.push_back(std::abs(a[k].y - b[k].y));
  }
  return dv;
}

std::string run(const std::string& cmd, int* status) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) {
    *status = -1;
    return out;
  }
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int rc = pclose(p);
  *status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  return out;
}

/** A fresh folder under /tmp, removed with everything in it at the end of the scope. */
struct TempDir {
  std::string path;
  TempDir() {
    char tmpl[] = "/tmp/skin3d_calib_XXXXXX";
    const char* d = mkdtemp(tmpl);
    path = d ? d : "";
  }
  ~TempDir() {
    std::error_code ec;
    if (!path.empty()) std::filesystem::remove_all(path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
};

void copyFile(const std::string& from, const std::string& to) {
  std::ifstream in(from, std::ios::binary);
  std::ofstream out(to, std::ios::binary);
  out << in.rdbuf();
}

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

// ------------------------------------------------------------------------------------------------ parsing

TEST(Calibration, ParsesPatternAndSquare) {
  EXPECT_EQ(stereo::parsePatternSize("9x6"), cv::Size(9, 6));
  EXPECT_EQ(stereo::parsePatternSize(" 7X5 "), cv::Size(7, 5));
  for (const char* bad : {"9", "9x", "x6", "9x6x2", "1x6", "9.5x6", "axb", "-9x6", "101x6"}) {
    try {
      stereo::parsePatternSize(bad);
      ADD_FAILURE() << "accepted --pattern '" << bad << "'";
    } catch (const stereo::CalibrationError& e) {
      EXPECT_EQ(e.field(), "--pattern");
      EXPECT_NE(std::string(e.what()).find("--pattern"), std::string::npos) << e.what();
    }
  }
  EXPECT_DOUBLE_EQ(stereo::parseLengthToMetres("25"), 0.025);
  EXPECT_DOUBLE_EQ(stereo::parseLengthToMetres("25mm"), 0.025);
  EXPECT_DOUBLE_EQ(stereo::parseLengthToMetres("2.5cm"), 0.025);
  EXPECT_DOUBLE_EQ(stereo::parseLengthToMetres("0.025m"), 0.025);
  for (const char* bad : {"-1", "0", "abc", "", "nan", "inf", "25 furlongs", "25in"})
    EXPECT_THROW(stereo::parseLengthToMetres(bad), stereo::CalibrationError) << bad;
}

// ------------------------------------------------------------------------------------------------ real images

TEST(CalibrationReal, MatchesOpenCvStereoCalibrateAndAlignsRows) {
  if (!haveRealImages()) GTEST_SKIP() << "no chessboard images at " << kRealDir << " (the shared data folder)";
  std::vector<stereo::SkippedPair> skipped;
  const auto corners = stereo::detectStereoCorners(realPairs(), cv::Size(9, 6), &skipped);
  for (const auto& s : skipped) std::cout << "  skipped " << s.name << ": " << s.reason << "\n";
  EXPECT_EQ(corners.names.size() + skipped.size(), 13u);
  ASSERT_GE(corners.names.size(), 10u);
  EXPECT_EQ(corners.image_size, cv::Size(640, 480));

  stereo::ChessboardPattern pattern;  // 9x6; the source gives no square size: 1 mm (baseline in squares)
  pattern.square_m = 1e-3;
  const auto calib = stereo::calibrateStereo(corners, pattern);

  // Reference: OpenCV directly on the same corners, standard settings as ROS camera_calibration uses them:
  // cv::calibrateCamera per camera (k1 k2 p1 p2: CALIB_FIX_K3, ROS's default --k-coefficients 2, also skin3d's
  // default), then cv::stereoCalibrate with CALIB_FIX_INTRINSIC.
  const std::vector<std::vector<cv::Point3f>> obj(corners.names.size(), stereo::boardObjectPoints(pattern));
  cv::Mat K1, D1, K2, D2, R, T, E, F;
  std::vector<cv::Mat> rv, tv;
  cv::calibrateCamera(obj, corners.left, corners.image_size, K1, D1, rv, tv, cv::CALIB_FIX_K3);
  cv::calibrateCamera(obj, corners.right, corners.image_size, K2, D2, rv, tv, cv::CALIB_FIX_K3);
  const double ref_rms = cv::stereoCalibrate(obj, corners.left, corners.right, K1, D1, K2, D2, corners.image_size, R, T,
                                             E, F, cv::CALIB_FIX_INTRINSIC);
  const double ref_baseline = cv::norm(T);
  const double ref_angle = std::acos(std::min(1.0, R.at<double>(2, 2)));  // angle between the optical axes
  std::cout << "  RMS reprojection error: skin3d " << calib.rms_px << " px, OpenCV (FIX_INTRINSIC) " << ref_rms
            << " px\n  baseline " << calib.baseline_m * 1e3 << " mm (OpenCV " << ref_baseline * 1e3
            << "), angle between the optical axes " << calib.axes_angle_rad / kDeg << " deg (OpenCV "
            << ref_angle / kDeg << ")\n";
  EXPECT_NEAR(calib.rms_px, ref_rms, 0.10 * ref_rms);
  EXPECT_LT(calib.rms_px, 0.5);
  EXPECT_NEAR(calib.baseline_m, ref_baseline, 0.02 * ref_baseline);
  EXPECT_NEAR(calib.axes_angle_rad, ref_angle, 0.3 * kDeg);
  EXPECT_FALSE(calib.converged);
  EXPECT_TRUE(calib.zero_disparity);  // a parallel rig is rectified as ROS does

  // Per-pair errors combine into the overall RMS (stereoCalibrate: sqrt of the mean squared error per camera point).
  double sum = 0.0;
  for (const auto& p : calib.pairs) sum += p.left_px * p.left_px + p.right_px * p.right_px;
  EXPECT_NEAR(std::sqrt(sum / (2.0 * calib.pairs.size())), calib.rms_px, 1e-6);

  // Rows after rectification, on corners found independently of skin3d (OpenCV's findChessboardCorners and
  // cornerSubPix with a fixed 5x5 window), through K D R P of the produced CameraInfo.
  std::vector<std::vector<cv::Point2f>> il, ir;
  double corner_diff_max = 0.0;
  std::vector<double> corner_diff;
  for (size_t i = 0; i < corners.names.size(); ++i) {
    std::vector<cv::Point2f> c[2];
    for (int s = 0; s < 2; ++s) {
      const cv::Mat g =
          cv::imread(kRealDir + (s ? "/right" : "/left") + corners.names[i] + ".jpg", cv::IMREAD_GRAYSCALE);
      ASSERT_TRUE(cv::findChessboardCorners(g, cv::Size(9, 6), c[s],
                                            cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
      cv::cornerSubPix(g, c[s], cv::Size(5, 5), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 0.01));
      const auto& mine = s ? corners.right[i] : corners.left[i];
      if (cv::norm(c[s].front() - mine.front()) > cv::norm(c[s].back() - mine.front()))
        std::reverse(c[s].begin(), c[s].end());  // the detector's 180-degree ambiguity
      for (size_t k = 0; k < c[s].size(); ++k) {
        corner_diff.push_back(cv::norm(c[s][k] - mine[k]));
        corner_diff_max = std::max(corner_diff_max, corner_diff.back());
      }
    }
    il.push_back(c[0]);
    ir.push_back(c[1]);
  }
  std::cout << "  corners vs OpenCV's own (5x5 window): median " << median(corner_diff) << " px, max "
            << corner_diff_max << " px\n";
  EXPECT_LT(median(corner_diff), 0.1);
  EXPECT_LT(corner_diff_max, 1.0);
  const auto dv = rectifiedRowErrors(calib.left, calib.right, il, ir);
  std::cout << "  rectified |dv| of independently detected corners: median " << median(dv) << " px, max "
            << *std::max_element(dv.begin(), dv.end()) << " px\n";
  EXPECT_LT(median(dv), 0.5);
  EXPECT_NEAR(calib.rect_dv_median_px, median(dv), 0.1);
  RecordProperty("rms_px", std::to_string(calib.rms_px));
  RecordProperty("opencv_rms_px", std::to_string(ref_rms));
  RecordProperty("baseline_squares", std::to_string(calib.baseline_m * 1e3));
  RecordProperty("axes_angle_deg", std::to_string(calib.axes_angle_rad / kDeg));
}

// ------------------------------------------------------------------------------------------------ synthetic

namespace {

struct SyntheticRig {
  geometry::StereoRig rig;
  std::vector<std::vector<Eigen::Vector3d>> boards;                // board corners in the left frame, per view
  std::vector<std::pair<Eigen::Matrix3d, Eigen::Vector3d>> poses;  // X_left = R p_board + t, per view
};

// The thesis' Part I rig (f 2625 px at 4224x3136, 210 mm, 54.4 deg) at a quarter of the resolution, with a mild
// lens distortion, and boards of 9x6 inner corners (15 mm squares) around the working distance of 245 mm, every
// inner corner at least margin_px from the border of both images.
SyntheticRig convergedRig(const stereo::ChessboardPattern& pattern, int views, std::mt19937* rng,
                          double margin_px = 10.0) {
  Eigen::Matrix3d K;
  K << 2625.0 / 4, 0, 527.5, 0, 2625.0 / 4, 391.5, 0, 0, 1;
  const geometry::PinholeCamera cl(K, 1056, 784, {-0.06, 0.04, 0.0004, -0.0003, 0.0});
  Eigen::Matrix3d K2 = K;
  K2(0, 0) *= 1.004;
  K2(1, 1) *= 1.004;
  K2(0, 2) += 6.0;
  K2(1, 2) -= 4.0;
  const geometry::PinholeCamera cr(K2, 1056, 784, {-0.05, 0.03, -0.0002, 0.0005, 0.0});
  const double a = 54.4 * kDeg;
  const Eigen::Vector3d c_r = geometry::so3Exp(Eigen::Vector3d(0, -0.5 * a, 0)) * Eigen::Vector3d(0.21, 0, 0);
  SyntheticRig s{geometry::StereoRig::fromRightPose(cl, cr, geometry::so3Exp(Eigen::Vector3d(0, -a, 0)), c_r), {}, {}};
  // Rig frame: origin at the midpoint of the optical centres, z along the bisector.
  const Eigen::Matrix3d R_rig_left = geometry::so3Exp(Eigen::Vector3d(0, 0.5 * a, 0));
  const Eigen::Vector3d c_left(-0.105, 0, 0);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto obj = stereo::boardObjectPoints(pattern);
  const Eigen::Vector3d centre_board(0.5 * (pattern.cols - 1) * pattern.square_m,
                                     0.5 * (pattern.rows - 1) * pattern.square_m, 0.0);
  int tries = 0;
  while (static_cast<int>(s.boards.size()) < views && ++tries < 100000) {
    const Eigen::Matrix3d R_rig_board =
        geometry::so3Exp(Eigen::Vector3d(30 * kDeg * u(*rng), 30 * kDeg * u(*rng), 25 * kDeg * u(*rng)));
    const Eigen::Vector3d centre(0.03 * u(*rng), 0.025 * u(*rng), 0.245 + 0.03 * u(*rng));
    const Eigen::Matrix3d R = R_rig_left.transpose() * R_rig_board;
    const Eigen::Vector3d t = R_rig_left.transpose() * (centre - R_rig_board * centre_board - c_left);
    std::vector<Eigen::Vector3d> pts;
    bool ok = true;
    for (const auto& p : obj) {
      const Eigen::Vector3d X = R * Eigen::Vector3d(p.x, p.y, p.z) + t;
      Eigen::Vector2d ul, ur;
      ok = ok && s.rig.project(X, &ul, &ur);
      for (const auto& uv : {ul, ur})
        ok = ok && uv.x() > margin_px && uv.y() > margin_px && uv.x() < 1055 - margin_px && uv.y() < 783 - margin_px;
      pts.push_back(X);
    }
    if (!ok) continue;
    s.boards.push_back(pts);
    s.poses.emplace_back(R, t);
  }
  return s;
}

/** Where every raw pixel of a distorted camera lies in its ideal pinhole image (computed once per camera). */
struct DistortionMap {
  cv::Mat x, y;
};
DistortionMap distortionMap(const geometry::PinholeCamera& cam, int pad) {
  const int W = cam.width(), H = cam.height();
  std::vector<cv::Point2f> raw, ideal;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) raw.emplace_back(static_cast<float>(x), static_cast<float>(y));
  cv::Mat K(3, 3, CV_64F);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) K.at<double>(i, j) = cam.K()(i, j);
  cv::undistortPoints(raw, ideal, K, cv::Mat(cam.D()), cv::noArray(), K,
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 1e-6));
  DistortionMap m{cv::Mat(H, W, CV_32F), cv::Mat(H, W, CV_32F)};
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      m.x.at<float>(y, x) = ideal[y * W + x].x + pad;
      m.y.at<float>(y, x) = ideal[y * W + x].y + pad;
    }
  return m;
}

/**
 * Renders a view of the board (squares of pattern.square_m, one white square of margin around the 10x7 squares,
 * on a grey background) through a distorted camera: 2x2 samples per pixel of the ideal pinhole image (padded by
 * `pad` px), then the lens distortion by remapping every raw pixel to its ideal position; mild blur and noise.
 */
cv::Mat renderBoard(const geometry::PinholeCamera& cam, const DistortionMap& map, int pad, const Eigen::Matrix3d& R,
                    const Eigen::Vector3d& t, const stereo::ChessboardPattern& pattern, std::mt19937* rng) {
  const int W = cam.width(), H = cam.height(), S = 2;
  const Eigen::Matrix3d A = R.transpose() * cam.K().inverse();  // board-frame direction of pixel (u, v, 1)
  const Eigen::Vector3d o = R.transpose() * t;
  const double sq = pattern.square_m;
  cv::Mat ideal(H + 2 * pad, W + 2 * pad, CV_32F);
  for (int y = 0; y < ideal.rows; ++y)
    for (int x = 0; x < ideal.cols; ++x) {
      double sum = 0.0;
      for (int i = 0; i < S; ++i)
        for (int j = 0; j < S; ++j) {
          const double u = x - pad + (j + 0.5) / S - 0.5, v = y - pad + (i + 0.5) / S - 0.5;
          const Eigen::Vector3d d = A.col(0) * u + A.col(1) * v + A.col(2);
          const double lambda = o.z() / d.z();
          double value = 0.35;  // background
          if (lambda > 0.0) {
            const double cx = std::floor((lambda * d.x() - o.x()) / sq), cy = std::floor((lambda * d.y() - o.y()) / sq);
            if (cx >= -1 && cx <= pattern.cols - 1 && cy >= -1 && cy <= pattern.rows - 1)
              value = (static_cast<long>(cx + cy) % 2 == 0) ? 0.05 : 0.95;
            else if (cx >= -2 && cx <= pattern.cols && cy >= -2 && cy <= pattern.rows)
              value = 0.95;  // white margin
          }
          sum += value;
        }
      ideal.at<float>(y, x) = static_cast<float>(255.0 * sum / (S * S));
    }
  cv::Mat img, noise(H, W, CV_32F);
  cv::remap(ideal, img, map.x, map.y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(90));
  cv::GaussianBlur(img, img, cv::Size(0, 0), 0.7);
  cv::RNG cv_rng((*rng)());
  cv_rng.fill(noise, cv::RNG::NORMAL, 0.0, 2.0);
  img += noise;
  cv::Mat out;
  img.convertTo(out, CV_8U);
  return out;
}

}  // namespace

TEST(CalibrationSynthetic, ConvergedRigRecoversBaselineAndAngleAndKeepsTheBoardInside) {
  std::mt19937 rng(4);
  stereo::ChessboardPattern pattern;
  pattern.square_m = 0.015;
  const auto truth = convergedRig(pattern, 16, &rng);
  ASSERT_EQ(truth.boards.size(), 16u);
  std::normal_distribution<double> noise(0.0, 0.2);
  stereo::StereoCorners corners;
  corners.image_size = cv::Size(1056, 784);
  std::vector<std::vector<cv::Point2f>> exact_l, exact_r;
  for (size_t v = 0; v < truth.boards.size(); ++v) {
    corners.names.push_back("view" + std::to_string(v));
    std::vector<cv::Point2f> l, r, el, er;
    for (const auto& X : truth.boards[v]) {
      Eigen::Vector2d ul, ur;
      truth.rig.project(X, &ul, &ur);
      el.emplace_back(ul.x(), ul.y());
      er.emplace_back(ur.x(), ur.y());
      l.emplace_back(ul.x() + noise(rng), ul.y() + noise(rng));
      r.emplace_back(ur.x() + noise(rng), ur.y() + noise(rng));
    }
    corners.left.push_back(l);
    corners.right.push_back(r);
    exact_l.push_back(el);
    exact_r.push_back(er);
  }
  const auto calib = stereo::calibrateStereo(corners, pattern);
  std::cout << "  synthetic 54.4 deg rig: baseline " << calib.baseline_m * 1e3 << " mm (210), angle "
            << calib.axes_angle_rad / kDeg << " deg (54.4), RMS " << calib.rms_px << " px, fx " << calib.rig.left().fx()
            << " (656.25), rectified f " << calib.left.P(0, 0) << (calib.projection_fitted ? " (P fitted)" : "")
            << ", inside " << calib.board_points_inside << "/" << calib.board_points.size() << "\n";
  EXPECT_NEAR(calib.baseline_m, 0.210, 0.01 * 0.210);
  EXPECT_NEAR(calib.axes_angle_rad / kDeg, 54.4, 0.3);
  EXPECT_NEAR(calib.rig.left().fx(), 656.25, 0.01 * 656.25);
  EXPECT_NEAR(calib.rig.right().fx(), 656.25 * 1.004, 0.01 * 656.25);
  // 0.2 px per coordinate is 0.28 px per point; the fit absorbs a little of it.
  EXPECT_GT(calib.rms_px, 0.2);
  EXPECT_LT(calib.rms_px, 0.32);
  EXPECT_TRUE(calib.converged);
  EXPECT_FALSE(calib.zero_disparity);  // docs/design.md: CALIB_ZERO_DISPARITY would move the board out of the images
  EXPECT_EQ(calib.board_points_inside, static_cast<int>(calib.board_points.size()));
  // A usable rectified resolution (OpenCV's alpha > 0 with flags 0 shrinks the focal length to a few px here).
  EXPECT_GT(calib.left.P(0, 0), 0.5 * 656.25) << calib.rectification_note;

  // The true (noise-free) corners through the estimated rectification: inside both images, rows aligned.
  const auto dv = rectifiedRowErrors(calib.left, calib.right, exact_l, exact_r);
  EXPECT_LT(median(dv), 0.2);
  EXPECT_LT(*std::max_element(dv.begin(), dv.end()), 0.8);
  for (size_t v = 0; v < exact_l.size(); ++v)
    for (int s = 0; s < 2; ++s) {
      const auto pts = stereo::rectifyPixels(s ? calib.right : calib.left, s ? exact_r[v] : exact_l[v]);
      for (const auto& p : pts) {
        EXPECT_GE(p.x, 0.0f);
        EXPECT_GE(p.y, 0.0f);
        EXPECT_LE(p.x, 1055.0f);
        EXPECT_LE(p.y, 783.0f);
      }
    }
  // The rig rebuilt from the CameraInfo pair (what a ROS consumer does) has the estimated geometry.
  const auto back = geometry::StereoRig::fromCameraInfo(calib.left, calib.right);
  EXPECT_NEAR(back.baseline(), calib.baseline_m, 1e-9);
  EXPECT_NEAR(back.opticalAxesAngle(), calib.axes_angle_rad, 1e-9);
}

TEST(CalibrationSynthetic, TooFewPairsAndBadCornerListsAreErrors) {
  std::mt19937 rng(5);
  stereo::ChessboardPattern pattern;
  pattern.square_m = 0.015;
  const auto truth = convergedRig(pattern, 2, &rng);
  stereo::StereoCorners corners;
  corners.image_size = cv::Size(1056, 784);
  for (size_t v = 0; v < truth.boards.size(); ++v) {
    corners.names.push_back("v" + std::to_string(v));
    std::vector<cv::Point2f> l, r;
    for (const auto& X : truth.boards[v]) {
      Eigen::Vector2d ul, ur;
      truth.rig.project(X, &ul, &ur);
      l.emplace_back(ul.x(), ul.y());
      r.emplace_back(ur.x(), ur.y());
    }
    corners.left.push_back(l);
    corners.right.push_back(r);
  }
  try {
    stereo::calibrateStereo(corners, pattern);
    ADD_FAILURE() << "2 pairs accepted";
  } catch (const stereo::CalibrationError& e) {
    EXPECT_EQ(e.field(), "pairs");
  }
  corners.names.push_back("v2");
  corners.left.push_back(corners.left[0]);
  corners.right.push_back(std::vector<cv::Point2f>(corners.right[0].begin(), corners.right[0].end() - 1));
  try {
    stereo::calibrateStereo(corners, pattern);
    ADD_FAILURE() << "a list of 53 corners accepted";
  } catch (const stereo::CalibrationError& e) {
    EXPECT_EQ(e.field(), "corners");
    EXPECT_NE(std::string(e.what()).find("v2"), std::string::npos) << e.what();
  }
}

// ------------------------------------------------------------------------------------------------ YAML

namespace {
/** Independent reading of the ROS layout: top-level keys, and rows / cols / number of data entries per matrix. */
struct RosYamlShape {
  std::map<std::string, std::string> scalars;
  std::map<std::string, std::array<int, 3>> matrices;  // rows, cols, data count
};
RosYamlShape rosShape(const std::string& text) {
  RosYamlShape s;
  std::istringstream in(text);
  std::string line, current;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = line.substr(0, colon);
    std::string value = line.substr(colon + 1);
    value.erase(0, value.find_first_not_of(' '));
    if (line[0] != ' ') {
      current = key;
      if (value.empty())
        s.matrices[key] = {-1, -1, -1};
      else
        s.scalars[key] = value;
    } else if (key == "  rows") {
      s.matrices[current][0] = std::stoi(value);
    } else if (key == "  cols") {
      s.matrices[current][1] = std::stoi(value);
    } else if (key == "  data") {
      const int commas = static_cast<int>(std::count(value.begin(), value.end(), ','));
      s.matrices[current][2] = value == "[]" ? 0 : commas + 1;
    }
  }
  return s;
}
}  // namespace

TEST(CalibrationYaml, RoundTripIsExactAndTheLayoutIsRos) {
  geometry::CameraInfo info;
  info.width = 4224;
  info.height = 3136;
  info.K << 2625.123456789012, 0, 2111.5 + 1.0 / 3.0, 0, 2624.9, 1567.25, 0, 0, 1;
  info.D = {-0.123456789, 1e-17, 3.0e-4, -2.5e-5, 0.1 / 3.0};
  info.R = geometry::so3Exp(Eigen::Vector3d(0.01, -0.47, 0.003));
  info.P << 2600.5, 0, 1900.25, -2600.5 * 0.2101234, 0, 2600.5, 1500.75, 0, 0, 0, 1, 0;
  const std::string text = stereo::cameraInfoYaml(info, "stereo/right");
  std::string name;
  const auto back = stereo::parseCameraInfoYaml(text, &name);
  EXPECT_EQ(name, "stereo/right");
  EXPECT_EQ(back.width, 4224);
  EXPECT_EQ(back.height, 3136);
  EXPECT_EQ(back.distortion_model, "plumb_bob");
  EXPECT_EQ(back.D, info.D);  // bit-exact
  EXPECT_EQ(back.K, info.K);
  EXPECT_EQ(back.R, info.R);
  EXPECT_EQ(back.P, info.P);

  const auto shape = rosShape(text);
  EXPECT_EQ(shape.scalars.at("image_width"), "4224");
  EXPECT_EQ(shape.scalars.at("image_height"), "3136");
  EXPECT_EQ(shape.scalars.at("camera_name"), "stereo/right");
  EXPECT_EQ(shape.scalars.at("distortion_model"), "plumb_bob");
  const std::array<int, 3> k33{3, 3, 9}, d15{1, 5, 5}, p34{3, 4, 12};
  EXPECT_EQ(shape.matrices.at("camera_matrix"), k33);
  EXPECT_EQ(shape.matrices.at("distortion_coefficients"), d15);
  EXPECT_EQ(shape.matrices.at("rectification_matrix"), k33);
  EXPECT_EQ(shape.matrices.at("projection_matrix"), p34);
  EXPECT_EQ(shape.scalars.size() + shape.matrices.size(), 8u);

  // Files: write, read back.
  const TempDir tmp;
  const std::string dir = tmp.path, path = dir + "/right.yaml";
  std::ofstream(path) << text;
  EXPECT_EQ(stereo::readCameraInfoYaml(path).P, info.P);

  // Broken files name the key.
  const auto expectField = [](const std::string& t, const std::string& field) {
    try {
      stereo::parseCameraInfoYaml(t);
      ADD_FAILURE() << "accepted a file with a bad " << field;
    } catch (const stereo::CalibrationError& e) {
      EXPECT_EQ(e.field(), field) << e.what();
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  std::string t = text;
  expectField(t.substr(0, t.find("projection_matrix")), "projection_matrix");
  t = text;
  t.replace(t.find("rows: 3"), 7, "rows: 2");
  expectField(t, "camera_matrix");
  t = text;
  t.replace(t.find("image_width: 4224"), 17, "image_width: wide");
  expectField(t, "image_width");
  t = text;
  t.replace(t.find("-0.123456789"), 12, "oops");
  expectField(t, "distortion_coefficients");
  EXPECT_THROW(stereo::readCameraInfoYaml(dir + "/missing.yaml"), stereo::CalibrationError);
}

// ------------------------------------------------------------------------------------------------ command line

TEST(CalibrateStereoCli, RealImagesEndToEnd) {
  if (!haveRealImages()) GTEST_SKIP() << "no chessboard images at " << kRealDir << " (the shared data folder)";
  const TempDir tmp;
  const std::string bin = SKIN3D_CALIBRATE_STEREO_BIN, out = tmp.path + "/out";
  int status = -1;
  const std::string log = run(bin + " --images " + kRealDir + " --pattern 9x6 --square 1 --out " + out, &status);
  ASSERT_EQ(status, 0) << log;
  for (const char* needle : {"RMS reprojection error", "baseline", "angle between the optical axes", "[13/13] 14"})
    EXPECT_NE(log.find(needle), std::string::npos) << needle << "\n" << log;
  std::string left_name, right_name;
  const auto l = stereo::readCameraInfoYaml(out + "/left.yaml", &left_name);
  const auto r = stereo::readCameraInfoYaml(out + "/right.yaml", &right_name);
  EXPECT_EQ(left_name, "left");
  EXPECT_EQ(right_name, "right");
  EXPECT_EQ(l.width, 640);
  EXPECT_EQ(r.height, 480);
  // Right camera to the right of the left one; the baseline of the YAML (metres) is the report's (mm).
  EXPECT_LT(r.P(0, 3), 0.0);
  const double baseline_mm = -r.P(0, 3) / r.P(0, 0) * 1e3;
  const std::string report = readFile(out + "/report.yaml");
  const auto pos = report.find("baseline_mm: ");
  ASSERT_NE(pos, std::string::npos) << report;
  EXPECT_NEAR(std::stod(report.substr(pos + 13)), baseline_mm, 1e-6 * baseline_mm);
  for (const char* key : {"rms_reprojection_error_px:", "optical_axes_angle_deg:", "per_pair:", "skipped: []",
                          "flags: CALIB_ZERO_DISPARITY", "alpha: 0"})
    EXPECT_NE(report.find(key), std::string::npos) << key << "\n" << report;
  const cv::Mat preview = cv::imread(out + "/rectified_preview.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(preview.empty());
  EXPECT_EQ(preview.cols, 1280);
  EXPECT_EQ(preview.rows, 480);
  cv::Scalar mean, stddev;
  cv::meanStdDev(preview, mean, stddev);
  EXPECT_GT(stddev[0], 30.0);  // an image, not a blank
}

TEST(CalibrateStereoCli, SkipsAndListsPairsWithoutBoardAndUnpairedFiles) {
  if (!haveRealImages()) GTEST_SKIP() << "no chessboard images at " << kRealDir << " (the shared data folder)";
  const TempDir tmp;
  const std::string dir = tmp.path, bin = SKIN3D_CALIBRATE_STEREO_BIN;
  // Four real pairs under other names, a pair of blank frames, a left image without a partner and a text file.
  const char* keys[] = {"01", "04", "07", "11"};
  mkdir((dir + "/cam0").c_str(), 0755);
  mkdir((dir + "/cam1").c_str(), 0755);
  for (const char* k : keys) {
    copyFile(kRealDir + "/left" + k + ".jpg", dir + "/cam0/" + k + ".jpg");
    copyFile(kRealDir + "/right" + k + ".jpg", dir + "/cam1/" + k + ".jpg");
  }
  const cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(128));
  cv::imwrite(dir + "/cam0/99.jpg", blank);
  cv::imwrite(dir + "/cam1/99.jpg", blank);
  cv::imwrite(dir + "/cam0/50.jpg", blank);
  std::ofstream(dir + "/cam1/notes.txt") << "not an image";
  int status = -1;
  const std::string base = bin + " --images " + dir + " --left-glob 'cam0/*.jpg' --right-glob 'cam1/*.jpg' ";
  std::string log = run(base + "--pattern 9x6 --square 25mm --out " + dir + "/out", &status);
  ASSERT_EQ(status, 0) << log;
  EXPECT_NE(log.find("99: board not found in the left and the right image"), std::string::npos) << log;
  EXPECT_NE(log.find("cam0/50.jpg"), std::string::npos) << log;  // unpaired, listed
  EXPECT_NE(log.find("4 pairs used, 1 skipped"), std::string::npos) << log;
  const std::string report = readFile(dir + "/out/report.yaml");
  EXPECT_NE(report.find("pairs_skipped: 1"), std::string::npos) << report;
  EXPECT_NE(report.find("{name: \"99\", reason: \"board not found in the left and the right image\"}"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("square_mm: 25"), std::string::npos) << report;

  // Fewer than 3 usable pairs: exit 1 with the skipped pairs listed.
  log = run(base + "--pattern 7x7 --square 25mm --out " + dir + "/out77", &status);
  EXPECT_EQ(status, 1) << log;
  EXPECT_NE(log.find("only 0 of 5 pairs"), std::string::npos) << log;
  for (const char* k : {"01", "04", "07", "11", "99"})
    EXPECT_NE(log.find(std::string("  ") + k + ": board not found"), std::string::npos) << k << "\n" << log;
}

TEST(CalibrateStereoCli, BadInputAndCommandLine) {
  const TempDir tmp;
  const std::string dir = tmp.path, bin = SKIN3D_CALIBRATE_STEREO_BIN;
  mkdir((dir + "/empty").c_str(), 0755);
  int status = -1;
  std::string log = run(bin + " --images " + dir + "/empty --pattern 9x6 --square 1 --out " + dir + "/o", &status);
  EXPECT_EQ(status, 1) << log;
  EXPECT_NE(log.find("no image pairs"), std::string::npos) << log;

  log = run(bin + " --images " + dir + "/nonexistent --pattern 9x6 --square 1 --out " + dir + "/o", &status);
  EXPECT_EQ(status, 1) << log;
  EXPECT_NE(log.find("--images"), std::string::npos) << log;

  // Bad --pattern / --square values: exit 1, the option named.
  for (const auto& [args, field] : {std::make_pair(std::string("--pattern 9x6 --square -1"), "--square"),
                                    std::make_pair(std::string("--pattern 9x6 --square abc"), "--square"),
                                    std::make_pair(std::string("--pattern 9 --square 1"), "--pattern"),
                                    std::make_pair(std::string("--pattern 1x6 --square 1"), "--pattern")}) {
    log = run(bin + " --images " + dir + "/empty " + args + " --out " + dir + "/o", &status);
    EXPECT_EQ(status, 1) << args << "\n" << log;
    EXPECT_NE(log.find(field), std::string::npos) << args << "\n" << log;
  }

  // Images: unreadable, different sizes, too few pairs.
  const cv::Mat a(480, 640, CV_8UC1, cv::Scalar(100)), b(240, 320, CV_8UC1, cv::Scalar(100));
  mkdir((dir + "/sizes").c_str(), 0755);
  cv::imwrite(dir + "/sizes/left1.png", a);
  cv::imwrite(dir + "/sizes/right1.png", b);
  log = run(bin + " --images " + dir + "/sizes --pattern 9x6 --square 1 --out " + dir + "/o", &status);
  EXPECT_EQ(status, 1) << log;
  EXPECT_NE(log.find("right1.png' is 320x240"), std::string::npos) << log;
  mkdir((dir + "/broken").c_str(), 0755);
  cv::imwrite(dir + "/broken/left1.png", a);
  std::ofstream(dir + "/broken/right1.png") << "this is not a PNG";
  log = run(bin + " --images " + dir + "/broken --pattern 9x6 --square 1 --out " + dir + "/o", &status);
  EXPECT_EQ(status, 1) << log;
  EXPECT_NE(log.find("cannot read image '" + dir + "/broken/right1.png'"), std::string::npos) << log;
  if (haveRealImages()) {
    mkdir((dir + "/two").c_str(), 0755);
    for (const char* k : {"01", "02"})
      for (const char* s : {"left", "right"}) copyFile(kRealDir + "/" + s + k + ".jpg", dir + "/two/" + s + k + ".jpg");
    log = run(bin + " --images " + dir + "/two --pattern 9x6 --square 1 --out " + dir + "/o", &status);
    EXPECT_EQ(status, 1) << log;
    EXPECT_NE(log.find("only 2 of 2 pairs; at least 3"), std::string::npos) << log;

    // An --out that cannot be created (below a regular file, even for root): exit 3.
    std::ofstream(dir + "/a_file") << "x";
    log =
        run(bin + " --images " + kRealDir + " --pattern 9x6 --square 1 --quiet --out " + dir + "/a_file/out", &status);
    EXPECT_EQ(status, 3) << log;
    EXPECT_NE(log.find("a_file/out"), std::string::npos) << log;
  }

  // Command line: exit 2.
  for (const std::string args : {"", "--bogus", "--images", "--images x --pattern 9x6 --square 1",
                                 "--images x --pattern 9x6 --square 1 --out y --left-glob left",
                                 "--images x --pattern 9x6 --square 1 --out y --k-coefficients 7"}) {
    log = run(bin + " " + args, &status);
    EXPECT_EQ(status, 2) << "'" << args << "'\n" << log;
    EXPECT_NE(log.find("usage:"), std::string::npos) << log;
  }
  log = run(bin + " --help", &status);
  EXPECT_EQ(status, 0);
  EXPECT_NE(log.find("--left-glob"), std::string::npos);
}

TEST(CalibrateStereoCli, RenderedConvergedRigEndToEnd) {
  // Images of the 54.4 deg rig rendered from the ground truth, through the command line.
  std::mt19937 rng(7);
  stereo::ChessboardPattern pattern;
  pattern.square_m = 0.015;
  const auto truth = convergedRig(pattern, 12, &rng, 60.0);
  ASSERT_EQ(truth.poses.size(), 12u);
  const TempDir tmp;
  const std::string dir = tmp.path, bin = SKIN3D_CALIBRATE_STEREO_BIN;
  const int pad = 60;
  const DistortionMap map_l = distortionMap(truth.rig.left(), pad), map_r = distortionMap(truth.rig.right(), pad);
  std::vector<std::vector<cv::Point2f>> exact_l, exact_r;
  for (size_t v = 0; v < truth.poses.size(); ++v) {
    const auto& [R, t] = truth.poses[v];
    const Eigen::Matrix3d R_r = truth.rig.R_rl() * R;
    const Eigen::Vector3d t_r = truth.rig.R_rl() * t + truth.rig.t_rl();
    char name[32];
    std::snprintf(name, sizeof(name), "%02zu.png", v + 1);
    cv::imwrite(dir + "/left" + name, renderBoard(truth.rig.left(), map_l, pad, R, t, pattern, &rng));
    cv::imwrite(dir + "/right" + name, renderBoard(truth.rig.right(), map_r, pad, R_r, t_r, pattern, &rng));
    std::vector<cv::Point2f> el, er;
    for (const auto& X : truth.boards[v]) {
      Eigen::Vector2d ul, ur;
      truth.rig.project(X, &ul, &ur);
      el.emplace_back(ul.x(), ul.y());
      er.emplace_back(ur.x(), ur.y());
    }
    exact_l.push_back(el);
    exact_r.push_back(er);
  }
  int status = -1;
  const std::string log = run(bin + " --images " + dir + " --pattern 9x6 --square 15mm --out " + dir + "/out", &status);
  ASSERT_EQ(status, 0) << log;
  std::cout << log.substr(log.find("Stereo calibration"), 700) << "...\n";
  const std::string report = readFile(dir + "/out/report.yaml");
  const auto number = [&](const std::string& key) {
    const auto pos = report.find(key + ": ");
    return pos == std::string::npos ? std::nan("") : std::stod(report.substr(pos + key.size() + 2));
  };
  EXPECT_EQ(number("pairs_used"), 12.0) << log;
  EXPECT_NEAR(number("baseline_mm"), 210.0, 2.1);
  EXPECT_NEAR(number("optical_axes_angle_deg"), 54.4, 0.3);
  EXPECT_LT(number("rms_reprojection_error_px"), 0.3);
  EXPECT_NE(report.find("converged_rig: true"), std::string::npos) << report;
  EXPECT_NE(report.find("flags: 0"), std::string::npos) << report;
  EXPECT_EQ(number("  board_corners_inside_both_images"), number("  board_corners"));
  // The YAML pair a ROS node would load: true corners rectified through it are inside both images, rows aligned.
  const auto l = stereo::readCameraInfoYaml(dir + "/out/left.yaml");
  const auto r = stereo::readCameraInfoYaml(dir + "/out/right.yaml");
  const auto dv = rectifiedRowErrors(l, r, exact_l, exact_r);
  EXPECT_LT(median(dv), 0.3);
  EXPECT_LT(*std::max_element(dv.begin(), dv.end()), 1.0);
  int outside = 0;
  for (size_t v = 0; v < exact_l.size(); ++v)
    for (const auto& [info, pts] : {std::make_pair(&l, &exact_l[v]), std::make_pair(&r, &exact_r[v])})
      for (const auto& p : stereo::rectifyPixels(*info, *pts))
        outside += (p.x < 0 || p.y < 0 || p.x > 1055 || p.y > 783) ? 1 : 0;
  EXPECT_EQ(outside, 0);
  const cv::Mat preview = cv::imread(dir + "/out/rectified_preview.png");
  ASSERT_FALSE(preview.empty());
  EXPECT_EQ(preview.cols, 1600);
}
