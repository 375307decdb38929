/**
 * @file calibration.h
 * @brief Chessboard stereo calibration (OpenCV) into a ROS CameraInfo pair, with a report (thesis Table 4.1:
 * RMS reprojection error, baseline, angle between the optical axes) and a rectified preview.
 *
 * Pipeline: corners per image (findChessboardCorners on an image of at most ~1600 px, then cornerSubPix at full
 * resolution with a window scaled to the square size) -> calibrateCamera per camera -> stereoCalibrate (by
 * default refining both cameras jointly from the per-camera results; `fix_intrinsic` keeps them, as ROS
 * camera_calibration does) -> rectification with stereo::rectifyStereo():
 *  - a near-parallel rig (axes angle <= converged_threshold_rad) gets ROS's CALIB_ZERO_DISPARITY, alpha 0;
 *  - a strongly converged rig (the thesis' 54.4 deg one) gets flags 0 and the smallest alpha that keeps every
 *    board corner of every used view inside both rectified images (docs/design.md, "Known facts"); when alpha 0 does
 *    not, the rectified projections are fitted to those corners instead (see projection_fitted).
 *
 * Units: the core is SI. The board's square size is in metres, so the baseline, the right camera's
 * translation and P(0,3) = -fx' B of the right CameraInfo are in metres (as ROS expects); pixels are pixels.
 * Frames: the left optical frame is the reference (x right, y down, z forward), as in geometry::StereoRig.
 *
 * The camera_info YAML is the ROS camera_calibration format read by camera_calibration_parsers and
 * camera_info_manager (image_width, image_height, camera_name, camera_matrix, distortion_model,
 * distortion_coefficients, rectification_matrix, projection_matrix; matrices as {rows, cols, data}).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <functional>
#include <opencv2/core.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/geometry/camera.h"
#include "skin3d/geometry/stereo_rig.h"

namespace skin3d {
namespace stereo {

/** @brief Bad calibration input or file: names the field (option, file or YAML key) and the problem. */
class CalibrationError : public std::runtime_error {
 public:
  CalibrationError(const std::string& field, const std::string& message) : std::runtime_error(message), field_(field) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

/** @brief A chessboard: inner corners per row (cols) and per column (rows), square size in metres. */
struct ChessboardPattern {
  int cols = 9;
  int rows = 6;
  double square_m = 0.025;
  cv::Size size() const { return cv::Size(cols, rows); }
  int corners() const { return cols * rows; }
};

/**
 * @brief Parses "9x6" (inner corners, columns x rows; 'X' and '*' also accepted).
 * @throws CalibrationError (field "--pattern") unless both numbers are whole, >= 2 and <= 100.
 */
cv::Size parsePatternSize(const std::string& text);

/**
 * @brief Parses a length "25", "25mm", "2.5cm", "0.025m" into metres; a bare number is millimetres.
 * @throws CalibrationError (field `field`) unless it is a finite number > 0 with a known unit.
 */
double parseLengthToMetres(const std::string& text, const std::string& field = "--square");

/** @brief The board's inner corners in the board frame (z = 0), row by row, as findChessboardCorners orders them. */
std::vector<cv::Point3f> boardObjectPoints(const ChessboardPattern& pattern);

/**
 * @brief Finds the chessboard's inner corners with sub-pixel refinement.
 * @param image 8-bit grey or BGR image.
 * @param corners out: pattern.corners() points (pixel centres at integer coordinates), only when found.
 * @return false when the board (with exactly this number of inner corners) is not found.
 */
bool detectChessboard(const cv::Mat& image, const cv::Size& pattern, std::vector<cv::Point2f>* corners);

/** @brief One stereo pair of image files. */
struct ImagePair {
  std::string name;  //!< key shared by the two files (e.g. "01" for left01.jpg / right01.jpg)
  std::string left_path, right_path;
};

/** @brief A pair whose board was not usable, and why. */
struct SkippedPair {
  std::string name;
  std::string reason;  //!< e.g. "board not found in the right image"
};

/** @brief Corner lists of the pairs where the board was found in both images (same order in both). */
struct StereoCorners {
  cv::Size image_size;  //!< of every image, left and right
  std::vector<std::string> names;
  std::vector<std::vector<cv::Point2f>> left, right;
};

/**
 * @brief Reads every pair and detects the board in both images (left and right in parallel).
 *
 * The right corner list is reversed when it runs opposite to the left one (the 180 deg ambiguity of
 * findChessboardCorners), so that corner i is the same board corner in both images.
 * @param skipped out: pairs where the board was not found in one or both images.
 * @param progress optional: called once per pair, in order, with a one-line status.
 * @throws CalibrationError naming the file: unreadable image, or a size different from the first image's.
 */
StereoCorners detectStereoCorners(const std::vector<ImagePair>& pairs, const cv::Size& pattern,
                                  std::vector<SkippedPair>* skipped,
                                  const std::function<void(const std::string&)>& progress = {});

struct CalibrationOptions {
  /** Radial coefficients estimated (k1..k3: 1..3; ROS camera_calibration's --k-coefficients, whose default is 2
   *  too). The others are 0. k3 fits the corners slightly better but extrapolates badly where no corner was seen
   *  (image corners): on the rendered globe a simulated calibration with k3 left 2 mm of map RMS, with k1 k2 0.4 mm. */
  int k_coefficients = 2;
  /** Stereo step keeps the per-camera intrinsics (CALIB_FIX_INTRINSIC, as ROS does) instead of refining them. */
  bool fix_intrinsic = false;
  /** Axes angle above which the rig counts as strongly converged (flags 0, board-preserving alpha). */
  double converged_threshold_rad = 15.0 * 3.14159265358979323846 / 180.0;
  int min_pairs = 3;  //!< fewer usable pairs is an error
};

/** @brief Reprojection error of one used pair (RMS over its corners, px). */
struct PairError {
  std::string name;
  double left_px = 0.0, right_px = 0.0;
  double rms_px = 0.0;  //!< both cameras together
};

/** @brief Everything a stereo calibration produces. */
struct StereoCalibration {
  ChessboardPattern pattern;
  cv::Size image_size;
  /** The ROS CameraInfo pair: raw K and D (plumb_bob, 5), rectification R and projection P (metres). */
  geometry::CameraInfo left, right;
  geometry::StereoRig rig;  //!< raw (distorted) cameras and extrinsics, metres
  double rms_px = 0.0;      //!< stereoCalibrate's RMS reprojection error over both cameras and all pairs
  double left_mono_rms_px = 0.0, right_mono_rms_px = 0.0;  //!< calibrateCamera per camera
  double baseline_m = 0.0;                                 //!< distance between the optical centres
  double axes_angle_rad = 0.0;                             //!< angle between the optical axes
  std::vector<PairError> pairs;                            //!< per used pair
  // rectification
  bool converged = false;      //!< axes angle > options.converged_threshold_rad
  bool zero_disparity = true;  //!< CALIB_ZERO_DISPARITY (true) or flags 0
  double alpha = 0.0;          //!< stereoRectify's free scaling parameter used (meaningless if projection_fitted)
  /** Converged rig whose boards do not fit at alpha 0: stereoRectify's rotations are kept, but P (one focal length
   *  and row centre, a principal point per camera) is fitted so that every board corner is inside both images.
   *  (OpenCV's alpha > 0 with flags 0 shrinks or even negates the focal length when the principal point it picks
   *  lies outside the image, as it does for the 54.4 deg rig.) */
  bool projection_fitted = false;
  /** Used board corners in the left frame (m), from the board poses; the points of interest of a converged rig. */
  std::vector<Eigen::Vector3d> board_points;
  int board_points_inside = 0;     //!< how many of them lie inside both rectified images
  std::string rectification_note;  //!< how the rectification was chosen (human readable)
  // rows after rectification (detected corners through K, D, R, P)
  double rect_dv_median_px = 0.0, rect_dv_max_px = 0.0;
};

/**
 * @brief Calibrates the rig from corner lists (no images needed; tests feed synthetic corners).
 * @throws CalibrationError when fewer than options.min_pairs pairs, or lists of the wrong length.
 */
StereoCalibration calibrateStereo(const StereoCorners& corners, const ChessboardPattern& pattern,
                                  const CalibrationOptions& options = CalibrationOptions());

/**
 * @brief Side-by-side rectified preview (BGR) with horizontal epipolar lines: thin grey lines at regular rows,
 * and one coloured line per board row through the rectified corners (circles) in both images.
 * @param left_corners,right_corners raw corners of this pair (may be empty: lines only).
 * @param max_width the output is scaled down to at most this width.
 */
cv::Mat drawRectifiedPreview(const StereoCalibration& calib, const cv::Mat& left_raw, const cv::Mat& right_raw,
                             const std::vector<cv::Point2f>& left_corners,
                             const std::vector<cv::Point2f>& right_corners, int max_width = 1600);

/** @brief Rectified pixels (through K, D, R, P of `info`) of raw pixels: what image_proc's rectify produces. */
std::vector<cv::Point2f> rectifyPixels(const geometry::CameraInfo& info, const std::vector<cv::Point2f>& raw);

/** @brief camera_info in the ROS camera_calibration YAML format (numbers round-trip exactly). */
std::string cameraInfoYaml(const geometry::CameraInfo& info, const std::string& camera_name);

/**
 * @brief Parses a ROS camera_calibration YAML text.
 * @param camera_name optional out.
 * @throws CalibrationError naming the key: missing, wrong shape (3x3 K, 1xN D, 3x3 R, 3x4 P) or non-numeric.
 */
geometry::CameraInfo parseCameraInfoYaml(const std::string& text, std::string* camera_name = nullptr);

/** @brief Reads a camera_info YAML file; @throws CalibrationError (field = path) if unreadable or invalid. */
geometry::CameraInfo readCameraInfoYaml(const std::string& path, std::string* camera_name = nullptr);

/** @brief The report as YAML (lengths in mm, angles in degrees, errors in px; unit in every key name). */
std::string calibrationReportYaml(const StereoCalibration& calib, const std::vector<SkippedPair>& skipped);

/** @brief The human-readable report table (mm, degrees, px). */
std::string calibrationReportTable(const StereoCalibration& calib, const std::vector<SkippedPair>& skipped);

}  // namespace stereo
}  // namespace skin3d
