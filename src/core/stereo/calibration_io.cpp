// SPDX-License-Identifier: BSD-3-Clause
// Stereo calibration I/O: pattern and length text, the rectified preview image, camera_info YAML (ROS
// camera_calibration_parsers' format) and the calibration report (the maths: calibration.cpp).
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "calibration_detail.h"
#include "skin3d/stereo/calibration.h"

namespace skin3d {
namespace stereo {

using namespace calib_detail;  // NOLINT(build/namespaces): the private helpers of this file pair

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
