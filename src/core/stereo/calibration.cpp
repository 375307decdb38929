// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/stereo/calibration.h"

#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <future>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "../common/text.h"
#include "skin3d/stereo/rectification.h"

namespace skin3d {
namespace stereo {

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

[[noreturn]] void fail(const std::string& field, const std::string& why) {
  throw CalibrationError(field, why);
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

/** Shortest text that reads back as exactly the same double. */
std::string exact(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

using common::fixed;

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out + "\"";
}

cv::Mat toGray8(const cv::Mat& image) {
  cv::Mat gray;
  if (image.channels() == 3)
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 4)
    cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  else
    gray = image;
  if (gray.depth() == CV_16U) {
    cv::Mat g8;
    gray.convertTo(g8, CV_8U, 1.0 / 256.0);
    return g8;
  }
  if (gray.depth() != CV_8U) {
    cv::Mat g8;
    cv::normalize(gray, g8, 0, 255, cv::NORM_MINMAX, CV_8U);
    return g8;
  }
  return gray;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  double med = v[m];
  if (v.size() % 2 == 0) med = 0.5 * (med + *std::max_element(v.begin(), v.begin() + m));
  return med;
}

cv::Mat infoK(const geometry::CameraInfo& info) {
  cv::Mat K;
  cv::eigen2cv(info.K, K);
  return K;
}

bool insideBoth(const RectifiedPair& p, const Eigen::Vector3d& X) {
  for (bool right : {false, true}) {
    const Eigen::Vector2d uv = projectRectified(p, X, right);
    const auto& info = right ? p.right : p.left;
    if (!uv.allFinite() || uv.x() < -0.5 || uv.y() < -0.5 || uv.x() > info.width - 0.5 || uv.y() > info.height - 0.5)
      return false;
  }
  return true;
}

}  // namespace

// ------------------------------------------------------------------------------------------------ parsing

cv::Size parsePatternSize(const std::string& text) {
  const std::string t = trim(text);
  const auto x = t.find_first_of("xX*");
  const auto bad = [&](const std::string& why) {
    fail("--pattern", "--pattern '" + text + "': " + why + " (expected inner corners COLSxROWS, e.g. 9x6)");
  };
  if (x == std::string::npos) bad("no 'x' between the two numbers");
  int v[2];
  const std::string parts[2] = {trim(t.substr(0, x)), trim(t.substr(x + 1))};
  for (int i = 0; i < 2; ++i) {
    const char* b = parts[i].data();
    const char* e = b + parts[i].size();
    const auto r = std::from_chars(b, e, v[i]);
    if (parts[i].empty() || r.ec != std::errc() || r.ptr != e) bad("'" + parts[i] + "' is not a whole number");
    if (v[i] < 2 || v[i] > 100) bad(std::to_string(v[i]) + " inner corners is out of range [2, 100]");
  }
  return cv::Size(v[0], v[1]);
}

double parseLengthToMetres(const std::string& text, const std::string& field) {
  const std::string t = trim(text);
  size_t end = 0;
  double v = 0.0;
  try {
    v = std::stod(t, &end);
  } catch (const std::exception&) {
    fail(field, field + " '" + text + "' is not a number (a length such as 25, 25mm, 2.5cm or 0.025m)");
  }
  const std::string unit = trim(t.substr(end));
  double scale = 0.0;
  if (unit.empty() || unit == "mm")
    scale = 1e-3;
  else if (unit == "cm")
    scale = 1e-2;
  else if (unit == "m")
    scale = 1.0;
  else
    fail(field, field + " '" + text + "': unknown unit '" + unit + "' (mm, cm or m; a bare number is mm)");
  if (!std::isfinite(v) || !(v > 0.0)) fail(field, field + " '" + text + "' must be a finite length > 0");
  return v * scale;
}

std::vector<cv::Point3f> boardObjectPoints(const ChessboardPattern& pattern) {
  std::vector<cv::Point3f> pts;
  pts.reserve(pattern.corners());
  for (int r = 0; r < pattern.rows; ++r)
    for (int c = 0; c < pattern.cols; ++c)
      pts.emplace_back(static_cast<float>(c * pattern.square_m), static_cast<float>(r * pattern.square_m), 0.0f);
  return pts;
}

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
 * Rectification of the calibrated rig (DESIGN.md: a strongly converged rig loses its scene with
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

// ------------------------------------------------------------------------------------------------ preview

cv::Mat drawRectifiedPreview(const StereoCalibration& calib, const cv::Mat& left_raw, const cv::Mat& right_raw,
                             const std::vector<cv::Point2f>& left_corners,
                             const std::vector<cv::Point2f>& right_corners, int max_width) {
  const cv::Size size(calib.left.width, calib.left.height);
  const auto rectified = [&](const geometry::CameraInfo& info, const cv::Mat& raw) {
    cv::Mat bgr;
    if (raw.channels() == 3 && raw.depth() == CV_8U)
      bgr = raw;
    else
      cv::cvtColor(toGray8(raw), bgr, cv::COLOR_GRAY2BGR);
    cv::Mat R, P, m1, m2, out;
    cv::eigen2cv(info.R, R);
    cv::eigen2cv(Eigen::Matrix3d(info.P.leftCols<3>()), P);
    cv::initUndistortRectifyMap(infoK(info), cv::Mat(info.D), R, P, size, CV_32FC1, m1, m2);
    cv::remap(bgr, out, m1, m2, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0, 0, 0));
    return out;
  };
  if (left_raw.empty() || right_raw.empty() || left_raw.size() != size || right_raw.size() != size)
    fail("preview",
         "preview: both raw images must be " + std::to_string(size.width) + "x" + std::to_string(size.height));
  const cv::Mat l = rectified(calib.left, left_raw), r = rectified(calib.right, right_raw);
  cv::Mat both;
  cv::hconcat(l, r, both);
  const double s = std::min(1.0, static_cast<double>(std::max(max_width, 64)) / both.cols);
  if (s < 1.0) cv::resize(both, both, cv::Size(), s, s, cv::INTER_AREA);
  const int W = both.cols, H = both.rows;
  const double off = size.width * s;  // x offset of the right image in the preview
  const int thick = std::max(1, static_cast<int>(std::lround(H / 500.0)));
  // Regular epipolar lines (rows).
  for (int k = 1; k < 16; ++k) {
    const int y = static_cast<int>(std::lround(k * H / 16.0));
    cv::line(both, cv::Point(0, y), cv::Point(W - 1, y), cv::Scalar(90, 170, 90), 1, cv::LINE_AA);
  }
  cv::line(both, cv::Point(static_cast<int>(off), 0), cv::Point(static_cast<int>(off), H - 1),
           cv::Scalar(255, 255, 255), thick);
  // Corners: all as small dots, one per board row (on a diagonal) with its own coloured line through both images.
  if (!left_corners.empty() && left_corners.size() == right_corners.size()) {
    const auto lr = rectifyPixels(calib.left, left_corners), rr = rectifyPixels(calib.right, right_corners);
    const int cols = calib.pattern.cols, rows = calib.pattern.rows;
    const cv::Scalar palette[] = {{0, 0, 255},   {0, 160, 255}, {0, 230, 230}, {0, 200, 0},
                                  {255, 160, 0}, {255, 0, 0},   {200, 0, 200}, {128, 128, 255}};
    const int rad = std::max(3, static_cast<int>(std::lround(H / 120.0)));
    for (size_t k = 0; k < lr.size(); ++k) {
      cv::circle(both, cv::Point2f(lr[k].x * s, lr[k].y * s), 1 + thick / 2, cv::Scalar(0, 255, 255), -1, cv::LINE_AA);
      cv::circle(both, cv::Point2f(rr[k].x * s + off, rr[k].y * s), 1 + thick / 2, cv::Scalar(0, 255, 255), -1,
                 cv::LINE_AA);
    }
    if (static_cast<int>(lr.size()) == cols * rows) {
      for (int row = 0; row < rows; ++row) {
        const int col = rows > 1 ? (row * (cols - 1)) / (rows - 1) : 0;
        const size_t k = static_cast<size_t>(row * cols + col);
        const cv::Scalar colour = palette[row % 8];
        const double y = 0.5 * (lr[k].y + rr[k].y) * s;
        cv::line(both, cv::Point2d(0, y), cv::Point2d(W - 1, y), colour, thick, cv::LINE_AA);
        cv::circle(both, cv::Point2f(lr[k].x * s, lr[k].y * s), rad, colour, thick + 1, cv::LINE_AA);
        cv::circle(both, cv::Point2f(rr[k].x * s + off, rr[k].y * s), rad, colour, thick + 1, cv::LINE_AA);
      }
    }
  }
  const double font = std::max(0.4, H / 900.0);
  const std::string mode = calib.zero_disparity ? "CALIB_ZERO_DISPARITY" : "flags 0";
  const std::string caption_l = "left rectified  (" + mode + ", " +
                                (calib.projection_fitted ? std::string("P fitted") : "alpha " + fixed(calib.alpha, 2)) +
                                ")";
  const std::string caption_r = "right rectified  (median |dv| " + fixed(calib.rect_dv_median_px, 2) + " px)";
  for (const auto& [text, x] : {std::make_pair(caption_l, 8.0), std::make_pair(caption_r, off + 8.0)}) {
    const cv::Point org(static_cast<int>(x), static_cast<int>(22 * font / 0.6));
    cv::putText(both, text, org, cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), 3 * thick + 1, cv::LINE_AA);
    cv::putText(both, text, org, cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(255, 255, 255), thick, cv::LINE_AA);
  }
  return both;
}

// ------------------------------------------------------------------------------------------------ YAML

std::string cameraInfoYaml(const geometry::CameraInfo& info, const std::string& camera_name) {
  const auto check = [](const auto& m, const char* field) {
    for (int i = 0; i < m.size(); ++i)
      if (!std::isfinite(m.data()[i]))
        fail(field, std::string("camera_info: ") + field + " has a non-finite entry; nothing to write");
  };
  check(info.K, "camera_matrix");
  check(info.R, "rectification_matrix");
  check(info.P, "projection_matrix");
  for (double d : info.D)
    if (!std::isfinite(d)) fail("distortion_coefficients", "camera_info: distortion_coefficients not finite");
  const auto matrix = [](const std::string& key, int rows, int cols, const auto& at) {
    std::ostringstream os;
    os << key << ":\n  rows: " << rows << "\n  cols: " << cols << "\n  data: [";
    for (int r = 0; r < rows; ++r)
      for (int c = 0; c < cols; ++c) os << (r + c ? ", " : "") << exact(at(r, c));
    os << "]\n";
    return os.str();
  };
  std::ostringstream os;
  os << "image_width: " << info.width << "\n"
     << "image_height: " << info.height << "\n"
     << "camera_name: " << (camera_name.empty() ? std::string("camera") : camera_name) << "\n"
     << matrix("camera_matrix", 3, 3, [&](int r, int c) { return info.K(r, c); })
     << "distortion_model: " << (info.distortion_model.empty() ? "plumb_bob" : info.distortion_model) << "\n"
     << matrix("distortion_coefficients", 1, static_cast<int>(info.D.size()), [&](int, int c) { return info.D[c]; })
     << matrix("rectification_matrix", 3, 3, [&](int r, int c) { return info.R(r, c); })
     << matrix("projection_matrix", 3, 4, [&](int r, int c) { return info.P(r, c); });
  return os.str();
}

geometry::CameraInfo parseCameraInfoYaml(const std::string& text, std::string* camera_name) {
  YAML::Node doc;
  try {
    doc = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    fail("yaml", std::string("camera_info: not valid YAML: ") + e.what());
  }
  if (!doc.IsMap()) fail("yaml", "camera_info: the top level must be a mapping (image_width: ..., camera_matrix: ...)");
  const auto integer = [&](const std::string& key) {
    const YAML::Node v = doc[key];
    if (!v.IsDefined() || v.IsNull()) fail(key, "camera_info: '" + key + "' is missing");
    try {
      const int i = v.as<int>();
      if (i <= 0) fail(key, "camera_info: '" + key + "' = " + std::to_string(i) + " must be > 0");
      return i;
    } catch (const YAML::Exception&) {
      fail(key, "camera_info: '" + key + "' = '" + (v.IsScalar() ? v.Scalar() : "(not a scalar)") +
                    "' is not a whole number");
    }
  };
  const auto matrix = [&](const std::string& key, int rows, int cols) {
    const YAML::Node m = doc[key];
    if (!m.IsDefined() || m.IsNull()) fail(key, "camera_info: '" + key + "' is missing");
    if (!m.IsMap()) fail(key, "camera_info: '" + key + "' must be a mapping {rows, cols, data}");
    int r = 0, c = 0;
    try {
      r = m["rows"].as<int>();
      c = m["cols"].as<int>();
    } catch (const YAML::Exception&) {
      fail(key, "camera_info: '" + key + ".rows' / '" + key + ".cols' missing or not whole numbers");
    }
    if (r != rows || (cols >= 0 && c != cols))
      fail(key, "camera_info: '" + key + "' is " + std::to_string(r) + "x" + std::to_string(c) + ", expected " +
                    std::to_string(rows) + "x" + (cols >= 0 ? std::to_string(cols) : std::string("N")));
    const YAML::Node d = m["data"];
    if (!d.IsSequence() || static_cast<int>(d.size()) != r * c)
      fail(key, "camera_info: '" + key + ".data' must be a list of rows*cols = " + std::to_string(r * c) + " numbers");
    std::vector<double> v;
    for (size_t i = 0; i < d.size(); ++i) {
      double x = 0.0;
      try {
        x = d[i].as<double>();
      } catch (const YAML::Exception&) {
        fail(key, "camera_info: '" + key + ".data[" + std::to_string(i) + "]' = '" +
                      (d[i].IsScalar() ? d[i].Scalar() : "?") + "' is not a number");
      }
      if (!std::isfinite(x)) fail(key, "camera_info: '" + key + ".data[" + std::to_string(i) + "]' is not finite");
      v.push_back(x);
    }
    return v;
  };
  geometry::CameraInfo info;
  info.width = integer("image_width");
  info.height = integer("image_height");
  if (camera_name) *camera_name = doc["camera_name"].IsScalar() ? doc["camera_name"].Scalar() : "";
  info.distortion_model = doc["distortion_model"].IsScalar() ? doc["distortion_model"].Scalar() : "plumb_bob";
  const auto K = matrix("camera_matrix", 3, 3);
  info.D = matrix("distortion_coefficients", 1, -1);
  const auto R = matrix("rectification_matrix", 3, 3);
  const auto P = matrix("projection_matrix", 3, 4);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      info.K(r, c) = K[r * 3 + c];
      info.R(r, c) = R[r * 3 + c];
    }
    for (int c = 0; c < 4; ++c) info.P(r, c) = P[r * 4 + c];
  }
  return info;
}

geometry::CameraInfo readCameraInfoYaml(const std::string& path, std::string* camera_name) {
  std::ifstream in(path);
  if (!in) fail(path, "camera_info: cannot open '" + path + "'");
  std::stringstream ss;
  ss << in.rdbuf();
  try {
    return parseCameraInfoYaml(ss.str(), camera_name);
  } catch (const CalibrationError& e) {
    fail(path, path + ": " + e.what());
  }
}

// ------------------------------------------------------------------------------------------------ report

namespace {
Eigen::Vector3d rotationVectorDeg(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle() * kRadToDeg;
}
std::string list(const std::vector<double>& v, int decimals = -1) {
  std::string s = "[";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + (decimals < 0 ? exact(v[i]) : fixed(v[i], decimals));
  return s + "]";
}
std::string vec(const Eigen::Vector3d& v, int decimals = -1) {
  return list({v.x(), v.y(), v.z()}, decimals);
}
}  // namespace

std::string calibrationReportYaml(const StereoCalibration& c, const std::vector<SkippedPair>& skipped) {
  std::ostringstream os;
  const auto& rig = c.rig;
  const Eigen::Matrix3d R_lr = rig.R_rl().transpose();
  const auto cam = [&](const char* name, const geometry::PinholeCamera& k, double mono) {
    os << name << ":\n"
       << "  fx_px: " << exact(k.fx()) << "\n  fy_px: " << exact(k.fy()) << "\n  cx_px: " << exact(k.cx())
       << "\n  cy_px: " << exact(k.cy()) << "\n  distortion_plumb_bob: " << list(k.D())
       << "\n  single_camera_rms_px: " << exact(mono) << "\n";
  };
  os << "# skin3d stereo calibration report (calibrate_stereo). Lengths mm, angles deg, errors px;\n"
     << "# frames: the left optical frame (x right, y down, z forward).\n"
     << "pattern: {cols: " << c.pattern.cols << ", rows: " << c.pattern.rows
     << ", square_mm: " << exact(c.pattern.square_m * 1e3) << "}\n"
     << "image_size_px: [" << c.image_size.width << ", " << c.image_size.height << "]\n"
     << "pairs_used: " << c.pairs.size() << "\n"
     << "pairs_skipped: " << skipped.size() << "\n"
     << "rms_reprojection_error_px: " << exact(c.rms_px) << "\n"
     << "baseline_mm: " << exact(c.baseline_m * 1e3) << "\n"
     << "optical_axes_angle_deg: " << exact(c.axes_angle_rad * kRadToDeg) << "\n"
     << "right_camera_centre_mm: " << vec(rig.rightCentre() * 1e3) << "\n"
     << "right_camera_rotation_vector_deg: " << vec(rotationVectorDeg(R_lr)) << "  # left <- right\n"
     << "R_right_left: "
     << list({rig.R_rl()(0, 0), rig.R_rl()(0, 1), rig.R_rl()(0, 2), rig.R_rl()(1, 0), rig.R_rl()(1, 1),
              rig.R_rl()(1, 2), rig.R_rl()(2, 0), rig.R_rl()(2, 1), rig.R_rl()(2, 2)})
     << "  # row-major, X_right = R X_left + t\n"
     << "t_right_left_mm: " << vec(rig.t_rl() * 1e3) << "\n";
  cam("left", rig.left(), c.left_mono_rms_px);
  cam("right", rig.right(), c.right_mono_rms_px);
  os << "rectification:\n"
     << "  converged_rig: " << (c.converged ? "true" : "false") << "\n"
     << "  flags: " << (c.zero_disparity ? "CALIB_ZERO_DISPARITY" : "0") << "\n"
     << "  alpha: " << (c.projection_fitted ? std::string("null  # not used: P fitted") : exact(c.alpha)) << "\n"
     << "  projection_fitted_to_board: " << (c.projection_fitted ? "true" : "false") << "\n"
     << "  board_corners_inside_both_images: " << c.board_points_inside << "\n"
     << "  board_corners: " << c.board_points.size() << "\n"
     << "  rectified_row_error_median_px: " << exact(c.rect_dv_median_px) << "\n"
     << "  rectified_row_error_max_px: " << exact(c.rect_dv_max_px) << "\n"
     << "  note: " << quoted(c.rectification_note) << "\n"
     << "per_pair:" << (c.pairs.empty() ? " []" : "") << "\n";
  for (const auto& p : c.pairs)
    os << "  - {name: " << quoted(p.name) << ", left_rms_px: " << exact(p.left_px)
       << ", right_rms_px: " << exact(p.right_px) << ", rms_px: " << exact(p.rms_px) << "}\n";
  os << "skipped:" << (skipped.empty() ? " []" : "") << "\n";
  for (const auto& s : skipped) os << "  - {name: " << quoted(s.name) << ", reason: " << quoted(s.reason) << "}\n";
  return os.str();
}

std::string calibrationReportTable(const StereoCalibration& c, const std::vector<SkippedPair>& skipped) {
  std::ostringstream os;
  const auto row = [&](const std::string& label, const std::string& value, const std::string& unit) {
    char buf[256];
    std::snprintf(buf, sizeof(buf), "  %-44s %22s  %s\n", label.c_str(), value.c_str(), unit.c_str());
    os << buf;
  };
  const auto& rig = c.rig;
  os << "Stereo calibration (" << c.pairs.size() << " pairs used, " << skipped.size() << " skipped; chessboard "
     << c.pattern.cols << "x" << c.pattern.rows << ", square " << fixed(c.pattern.square_m * 1e3, 3) << " mm; "
     << c.image_size.width << "x" << c.image_size.height << " px)\n";
  row("RMS reprojection error (stereo)", fixed(c.rms_px, 4), "px");
  row("RMS single camera left / right", fixed(c.left_mono_rms_px, 4) + " / " + fixed(c.right_mono_rms_px, 4), "px");
  row("baseline |b|", fixed(c.baseline_m * 1e3, 3), "mm");
  row("angle between the optical axes", fixed(c.axes_angle_rad * kRadToDeg, 3), "deg");
  const Eigen::Vector3d cr = rig.rightCentre() * 1e3;
  row("right optical centre (left frame) x y z", fixed(cr.x(), 2) + " " + fixed(cr.y(), 2) + " " + fixed(cr.z(), 2),
      "mm");
  for (const auto* cam : {&rig.left(), &rig.right()}) {
    const bool l = cam == &rig.left();
    row(std::string(l ? "left " : "right") + " fx fy", fixed(cam->fx(), 2) + " " + fixed(cam->fy(), 2), "px");
    row(std::string(l ? "left " : "right") + " cx cy", fixed(cam->cx(), 2) + " " + fixed(cam->cy(), 2), "px");
    row(std::string(l ? "left " : "right") + " k1 k2 p1 p2 k3",
        fixed(cam->D()[0], 4) + " " + fixed(cam->D()[1], 4) + " " + fixed(cam->D()[2], 4) + " " +
            fixed(cam->D()[3], 4) + " " + fixed(cam->D()[4], 4),
        "");
  }
  row("rectification flags / alpha",
      std::string(c.zero_disparity ? "ZERO_DISPARITY" : "0") + " / " +
          (c.projection_fitted ? std::string("P fitted") : fixed(c.alpha, 2)),
      "");
  row("board corners inside both rectified images",
      std::to_string(c.board_points_inside) + " / " + std::to_string(c.board_points.size()), "");
  row("rectified row error |dv| median / max", fixed(c.rect_dv_median_px, 3) + " / " + fixed(c.rect_dv_max_px, 3),
      "px");
  os << "  (" << c.rectification_note << ")\n";
  os << "Per pair RMS reprojection error (px)\n";
  char buf[256];
  std::snprintf(buf, sizeof(buf), "  %-20s %8s %8s %8s\n", "pair", "left", "right", "both");
  os << buf;
  for (const auto& p : c.pairs) {
    std::snprintf(buf, sizeof(buf), "  %-20s %8.4f %8.4f %8.4f\n", p.name.c_str(), p.left_px, p.right_px, p.rms_px);
    os << buf;
  }
  if (!skipped.empty()) {
    os << "Skipped pairs\n";
    for (const auto& s : skipped) os << "  " << s.name << ": " << s.reason << "\n";
  }
  return os.str();
}

}  // namespace stereo
}  // namespace skin3d
