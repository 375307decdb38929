// SPDX-License-Identifier: BSD-3-Clause
// Stereo calibration maths: chessboard corners, OpenCV's calibration and the choice of rectification
// (text parsing, preview, camera_info YAML and the report: calibration_io.cpp).
#include "skin3d/stereo/calibration.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <future>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration_detail.h"
#include "skin3d/stereo/rectification.h"

namespace skin3d {
namespace stereo {

using namespace calib_detail;  // NOLINT(build/namespaces): the private helpers of this file pair

// ------------------------------------------------------------------------------------------------ corners

bool detectChessboard(const cv::Mat& image, const cv::Size& pattern, std::vector<cv::Point2f>* corners) {
  if (image.empty()) return false;
  const cv::Mat gray = toGray8(image);
  // Detection on an image of at most kDetectSide px (findChessboardCorners slows down sharply with size, and
  // the quads are found as well at this scale); refinement at full resolution.
  constexpr int kDetectSide = 1600;
  const int side = std::max(gray.cols, gray.rows);
  double scale = 1.0;
  cv::Mat small = gray;
  if (side > kDetectSide) {
    scale = static_cast<double>(kDetectSide) / side;
    cv::resize(gray, small, cv::Size(), scale, scale, cv::INTER_AREA);
  }
  std::vector<cv::Point2f> c;
  const int flags = cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK;
  if (!cv::findChessboardCorners(small, pattern, c, flags)) return false;
  if (static_cast<int>(c.size()) != pattern.area()) return false;
  if (scale != 1.0)
    for (auto& p : c)
      p = cv::Point2f(static_cast<float>((p.x + 0.5) / scale - 0.5), static_cast<float>((p.y + 0.5) / scale - 0.5));
  // Refinement window: half-size 0.3 of the smallest corner spacing, 3..60 px. On OpenCV's sample pairs the
  // refined corners are stable for 0.2..0.35 (< 0.5 px apart), while 0.4 already pulls outer corners by up to
  // 4 px towards the board's edge and the sample's fixed 11 px doubles the RMS error (0.45 vs 0.20 px). The
  // same pairs upscaled to 4224 px (blurred edges) need the large windows: a 25 px cap gives 1.72 px, 60 px 1.43.
  double spacing = 1e9;
  for (int r = 0; r < pattern.height; ++r)
    for (int k = 0; k < pattern.width; ++k) {
      const cv::Point2f& p = c[r * pattern.width + k];
      if (k + 1 < pattern.width) spacing = std::min(spacing, cv::norm(c[r * pattern.width + k + 1] - p));
      if (r + 1 < pattern.height) spacing = std::min(spacing, cv::norm(c[(r + 1) * pattern.width + k] - p));
    }
  const int half = std::max(3, std::min(60, static_cast<int>(std::lround(0.3 * spacing))));
  cv::cornerSubPix(gray, c, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 50, 1e-3));
  *corners = std::move(c);
  return true;
}

StereoCorners detectStereoCorners(const std::vector<ImagePair>& pairs, const cv::Size& pattern,
                                  std::vector<SkippedPair>* skipped,
                                  const std::function<void(const std::string&)>& progress) {
  struct View {
    cv::Size size;
    bool found = false;
    std::vector<cv::Point2f> corners;
  };
  const auto process = [&pattern](const std::string& path) {
    const cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (img.empty()) fail(path, "cannot read image '" + path + "' (missing, unreadable or not an image)");
    View v;
    v.size = img.size();
    v.found = detectChessboard(img, pattern, &v.corners);
    return v;
  };
  StereoCorners out;
  std::string first_path;
  const auto checkSize = [&](const cv::Size& s, const std::string& path) {
    if (first_path.empty()) {
      out.image_size = s;
      first_path = path;
    } else if (s != out.image_size) {
      fail(path, "image '" + path + "' is " + std::to_string(s.width) + "x" + std::to_string(s.height) + " but '" +
                     first_path + "' is " + std::to_string(out.image_size.width) + "x" +
                     std::to_string(out.image_size.height) + ": all images must have the same size");
    }
  };
  for (size_t i = 0; i < pairs.size(); ++i) {
    const ImagePair& p = pairs[i];
    // Left and right in parallel (the machines have two cores); get() rethrows the right image's error.
    auto right_job = std::async(std::launch::async, process, p.right_path);
    View l;
    try {
      l = process(p.left_path);
    } catch (...) {
      right_job.wait();
      throw;
    }
    View r = right_job.get();
    checkSize(l.size, p.left_path);
    checkSize(r.size, p.right_path);
    std::ostringstream line;
    line << "[" << (i + 1) << "/" << pairs.size() << "] " << p.name << ": ";
    if (l.found && r.found) {
      // findChessboardCorners may start at either end of the board: make corner i the same board corner in both.
      const cv::Point2f dl = l.corners.back() - l.corners.front(), dr = r.corners.back() - r.corners.front();
      const bool flipped = dl.dot(dr) < 0.0f;
      if (flipped) std::reverse(r.corners.begin(), r.corners.end());
      out.names.push_back(p.name);
      out.left.push_back(std::move(l.corners));
      out.right.push_back(std::move(r.corners));
      line << "board found in both images" << (flipped ? " (right corner order reversed to match the left)" : "");
    } else {
      const std::string reason = !l.found && !r.found ? "board not found in the left and the right image"
                                 : !l.found           ? "board not found in the left image"
                                                      : "board not found in the right image";
      if (skipped) skipped->push_back({p.name, reason});
      line << reason << " -> skipped";
    }
    if (progress) progress(line.str());
  }
  return out;
}

// ------------------------------------------------------------------------------------------------ calibration

std::vector<cv::Point2f> rectifyPixels(const geometry::CameraInfo& info, const std::vector<cv::Point2f>& raw) {
  std::vector<cv::Point2f> out;
  if (raw.empty()) return out;
  cv::Mat R, P;
  cv::eigen2cv(info.R, R);
  cv::eigen2cv(Eigen::Matrix3d(info.P.leftCols<3>()), P);
  cv::undistortPoints(raw, out, infoK(info), cv::Mat(info.D), R, P);
  return out;
}

namespace {

/** The calibration's inputs checked: as many corner lists as names, a board, enough pairs, full corner lists. */
void checkCalibrationInput(const StereoCorners& corners, const ChessboardPattern& pattern, const CalibrationOptions& options) {
  const size_t n = corners.names.size();
  if (corners.left.size() != n || corners.right.size() != n)
    fail("corners", "calibration: " + std::to_string(n) + " pair names but " + std::to_string(corners.left.size()) +
                        " left and " + std::to_string(corners.right.size()) + " right corner lists");
  if (pattern.cols < 2 || pattern.rows < 2)
    fail("pattern", "calibration: the pattern needs at least 2x2 inner corners");
  if (!(pattern.square_m > 0.0) || !std::isfinite(pattern.square_m))
    fail("square", "calibration: square size " + common::num(pattern.square_m) + " m must be finite and > 0");
  if (corners.image_size.width <= 0 || corners.image_size.height <= 0)
    fail("image_size", "calibration: image size " + std::to_string(corners.image_size.width) + "x" +
                           std::to_string(corners.image_size.height) + " must be positive");
  if (options.k_coefficients < 0 || options.k_coefficients > 3)
    fail("k_coefficients", "calibration: k_coefficients " + std::to_string(options.k_coefficients) +
                               " must be 0..3 (radial terms k1..k3)");
  if (static_cast<int>(n) < std::max(options.min_pairs, 1))
    fail("pairs", "calibration: the board was found in both images of only " + std::to_string(n) +
                      " pair(s); at least " + std::to_string(options.min_pairs) + " are needed");
  for (size_t i = 0; i < n; ++i)
    for (const auto* list : {&corners.left[i], &corners.right[i]})
      if (static_cast<int>(list->size()) != pattern.corners())
        fail("corners", "calibration: pair '" + corners.names[i] + "' has " + std::to_string(list->size()) +
                            " corners in one image, the " + std::to_string(pattern.cols) + "x" +
                            std::to_string(pattern.rows) + " board has " + std::to_string(pattern.corners()));

}

/**
 * Rectification of the calibrated rig (docs/design.md: a strongly converged rig loses its scene with
 * CALIB_ZERO_DISPARITY): as ROS camera_calibration for a near-parallel rig; for a converged one, alpha 0 when it
 * keeps every board corner inside, else a rectified projection fitted to keep them (out.rectification_note says
 * which, out.projection_fitted whether fitted).
 */
RectifiedPair chooseRectification(StereoCalibration& out, const CalibrationOptions& options) {
  out.converged = out.axes_angle_rad > options.converged_threshold_rad;
  RectifiedPair rect;
  if (!out.converged) {
    rect = rectifyStereo(out.rig);
    out.rectification_note = "near-parallel rig (axes angle " + fixed(out.axes_angle_rad * kRadToDeg, 2) +
                             " deg <= " + fixed(options.converged_threshold_rad * kRadToDeg, 1) +
                             " deg): CALIB_ZERO_DISPARITY, alpha 0 (as ROS camera_calibration)";
  } else {
    const std::string head =
        "strongly converged rig (axes angle " + fixed(out.axes_angle_rad * kRadToDeg, 2) + " deg): ";
    bool at_alpha0 = false;
    try {
      rect = rectifyStereo(out.rig, out.board_points);
      at_alpha0 = rect.alpha == 0.0;
    } catch (const std::runtime_error&) {
      // No alpha keeps every corner inside: the rotations are all that is needed from here on.
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (const auto& X : out.board_points) centroid += X;
      centroid /= static_cast<double>(out.board_points.size());
      try {
        rect = rectifyStereo(out.rig, {centroid});
      } catch (const std::runtime_error&) {
        rect = rectifyStereo(out.rig);
      }
    }
    if (at_alpha0) {
      out.rectification_note = head + "flags 0, alpha 0 keeps all " + std::to_string(out.board_points.size()) +
                               " board corners inside both rectified images";
    } else {
      RectifiedPair fitted = rect;
      // Focal length at most the raw cameras' (mean of fx, fy of both): no zoom beyond the raw resolution.
      const double f_raw =
          0.25 * (out.rig.left().fx() + out.rig.left().fy() + out.rig.right().fx() + out.rig.right().fy());
      if (fitRectifiedProjection(&fitted, out.board_points, f_raw, 2.0)) {
        rect = fitted;
        out.projection_fitted = true;
        out.rectification_note =
            head +
            "flags 0; alpha 0 loses board corners and OpenCV's alpha > 0 degenerates for this rig, so the "
            "rectified P (focal " +
            fixed(rect.left.P(0, 0), 1) + " px, at most the raw one; a cx per camera) is fitted to keep all " +
            std::to_string(out.board_points.size()) + " board corners inside both images";
      } else {
        out.rectification_note = head + (rect.zero_disparity ? "CALIB_ZERO_DISPARITY" : "flags 0") + ", alpha " +
                                 fixed(rect.alpha, 2) +
                                 "; some board corners are not in front of both rectified cameras";
      }
    }
  }
  return rect;
}

}  // namespace

StereoCalibration calibrateStereo(const StereoCorners& corners, const ChessboardPattern& pattern,
                                  const CalibrationOptions& options) {
  checkCalibrationInput(corners, pattern, options);
  const size_t n = corners.names.size();
  StereoCalibration out;
  out.pattern = pattern;
  out.image_size = corners.image_size;
  const cv::Size size = corners.image_size;
  const std::vector<std::vector<cv::Point3f>> object(n, boardObjectPoints(pattern));

  int dist_flags = 0;
  if (options.k_coefficients < 3) dist_flags |= cv::CALIB_FIX_K3;
  if (options.k_coefficients < 2) dist_flags |= cv::CALIB_FIX_K2;
  if (options.k_coefficients < 1) dist_flags |= cv::CALIB_FIX_K1;

  cv::Mat K1, D1 = cv::Mat::zeros(5, 1, CV_64F), K2, D2 = cv::Mat::zeros(5, 1, CV_64F);
  std::vector<cv::Mat> rv, tv;
  out.left_mono_rms_px = cv::calibrateCamera(object, corners.left, size, K1, D1, rv, tv, dist_flags);
  out.right_mono_rms_px = cv::calibrateCamera(object, corners.right, size, K2, D2, rv, tv, dist_flags);

  const int stereo_flags =
      dist_flags | (options.fix_intrinsic ? cv::CALIB_FIX_INTRINSIC : cv::CALIB_USE_INTRINSIC_GUESS);
  cv::Mat R, T, E, F, per_view;
  out.rms_px =
      cv::stereoCalibrate(object, corners.left, corners.right, K1, D1, K2, D2, size, R, T, E, F, per_view, stereo_flags,
                          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-7));
  if (!std::isfinite(out.rms_px) || !cv::checkRange(K1) || !cv::checkRange(K2) || !cv::checkRange(R) ||
      !cv::checkRange(T))
    fail("corners", "calibration: the stereo calibration diverged (non-finite result); check the corner lists");

  Eigen::Matrix3d eK1, eK2, eR;
  Eigen::Vector3d eT;
  cv::cv2eigen(K1, eK1);
  cv::cv2eigen(K2, eK2);
  cv::cv2eigen(R, eR);
  cv::cv2eigen(T, eT);
  const auto dvec = [](const cv::Mat& D) {
    std::vector<double> d(5, 0.0);
    for (int i = 0; i < std::min<int>(5, static_cast<int>(D.total())); ++i) d[i] = D.at<double>(i);
    return d;
  };
  out.rig = geometry::StereoRig(geometry::PinholeCamera(eK1, size.width, size.height, dvec(D1)),
                                geometry::PinholeCamera(eK2, size.width, size.height, dvec(D2)), eR, eT);
  out.baseline_m = out.rig.baseline();
  out.axes_angle_rad = out.rig.opticalAxesAngle();
  for (size_t i = 0; i < n; ++i) {
    PairError e;
    e.name = corners.names[i];
    e.left_px = per_view.at<double>(static_cast<int>(i), 0);
    e.right_px = per_view.at<double>(static_cast<int>(i), 1);
    e.rms_px = std::sqrt(0.5 * (e.left_px * e.left_px + e.right_px * e.right_px));
    out.pairs.push_back(e);
  }

  // Board corners in the left frame from each view's board pose (final left intrinsics).
  for (size_t i = 0; i < n; ++i) {
    cv::Mat rvec, tvec;
    cv::solvePnP(object[i], corners.left[i], K1, D1, rvec, tvec);
    cv::Mat Rb;
    cv::Rodrigues(rvec, Rb);
    Eigen::Matrix3d eRb;
    Eigen::Vector3d etb;
    cv::cv2eigen(Rb, eRb);
    cv::cv2eigen(tvec, etb);
    for (const auto& X : object[i]) out.board_points.push_back(eRb * Eigen::Vector3d(X.x, X.y, X.z) + etb);
  }

  const RectifiedPair rect = chooseRectification(out, options);
  out.zero_disparity = rect.zero_disparity;
  out.alpha = rect.alpha;
  out.left = rect.left;
  out.right = rect.right;
  for (const auto& X : out.board_points) out.board_points_inside += insideBoth(rect, X) ? 1 : 0;

  std::vector<double> dv;
  for (size_t i = 0; i < n; ++i) {
    const auto l = rectifyPixels(out.left, corners.left[i]);
    const auto r = rectifyPixels(out.right, corners.right[i]);
    for (size_t k = 0; k < l.size(); ++k) dv.push_back(std::abs(static_cast<double>(l[k].y) - r[k].y));
  }
  out.rect_dv_median_px = median(dv);
  out.rect_dv_max_px = dv.empty() ? 0.0 : *std::max_element(dv.begin(), dv.end());
  return out;
}

}  // namespace stereo
}  // namespace skin3d
