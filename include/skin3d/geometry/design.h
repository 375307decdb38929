/**
 * @file design.h
 * @brief Stereo design calculator (thesis §2.1-2.7, ch. 3, app. A): the
 * "Camera Geometry Visualiser" as a library.
 *
 * Units: this is a human-facing design tool, so every length is in
 * millimetres and every angle in degrees unless the name says otherwise.
 *
 * Frames: the rig frame has its origin at the midpoint of the two optical
 * centres and the axes of an unrotated camera (x right, y down, z forward).
 * The left optical centre is at -b/2, the right at +b/2 (b = baseline vector).
 * With a convergence angle alpha, the left camera is turned by +alpha/2 about
 * y (towards the right camera) and the right one by -alpha/2. The working
 * plane is z = working distance in the rig frame.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "skin3d/geometry/stereo_rig.h"

namespace skin3d {
namespace geometry {

/** @brief A bad design configuration: names the field and its value. */
class DesignConfigError : public std::runtime_error {
 public:
  DesignConfigError(const std::string& field, const std::string& message)
      : std::runtime_error(message), field_(field) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

/** @brief Inputs of the design calculator (config/part1_rig_design.yaml is a documented example). */
struct DesignConfig {
  std::string name;
  // sensor
  int width_px = 0;
  int height_px = 0;
  double pixel_size_mm = 0.0;
  /** Optional datasheet sensor size (the thesis rounds 4224 x 1.12 um to 4.8 mm). It feeds the thesis
   *  formulas (angles and fields of view, eq. 2.26/2.27) only; the camera model uses width_px * pixel. */
  double sensor_width_mm = std::numeric_limits<double>::quiet_NaN();
  double sensor_height_mm = std::numeric_limits<double>::quiet_NaN();  //!< optional
  // lens
  double focal_length_mm = 0.0;
  double f_number = 0.0;
  double coc_mm = std::numeric_limits<double>::quiet_NaN();  //!< circle of confusion; default 2 pixels
  // geometry
  Eigen::Vector3d baseline_mm = Eigen::Vector3d::Zero();  //!< right optical centre relative to the left
  double convergence_deg = 0.0;                           //!< angle between the optical axes (symmetric toe-in)
  bool per_camera_rotation = false;                       //!< use the two rotation vectors instead
  Eigen::Vector3d left_rotation_deg = Eigen::Vector3d::Zero();   //!< rotation vector, rig <- left camera
  Eigen::Vector3d right_rotation_deg = Eigen::Vector3d::Zero();  //!< rotation vector, rig <- right camera
  double working_distance_mm = std::numeric_limits<double>::quiet_NaN();  //!< default: the optimum
  // requirement
  double depth_resolution_mm = 0.0;
  double object_size_mm = 0.0;
  // analysis
  int grid_nx = 7;
  int grid_ny = 5;
  double pixel_sigma_px = 0.5;  //!< pixel localisation error for the uncertainty grid
};

/** @brief One point of the uncertainty grid (rig frame, mm). */
struct DesignGridPoint {
  Eigen::Vector3d X = Eigen::Vector3d::Zero();    //!< true point on the working plane
  Eigen::Vector2d uv_left = Eigen::Vector2d::Zero();
  Eigen::Vector2d uv_right = Eigen::Vector2d::Zero();
  Eigen::Vector3d X_est = Eigen::Vector3d::Zero();  //!< MMSE reconstruction of the noise-free pixels
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();    //!< mm^2, rig frame
  Eigen::Vector3d axes = Eigen::Vector3d::Zero();   //!< 1-sigma ellipsoid semi-axes, mm, largest first
  Eigen::Matrix3d axis_dirs = Eigen::Matrix3d::Identity();  //!< columns: unit directions of the axes
  double sigma_depth = 0.0;                         //!< 1-sigma along the rig z axis, mm
};

/** @brief Everything the calculator derives. */
struct DesignReport {
  DesignConfig config;
  // Image sensor metrics
  double sensor_width_mm = 0, sensor_height_mm = 0, sensor_diagonal_mm = 0, megapixels = 0;
  double focal_length_px = 0;
  // Lens metrics (angles of view)
  double aov_h_deg = 0, aov_v_deg = 0, aov_d_deg = 0;
  // Field of view at the working distance (eq. 2.2)
  double fov_w_mm = 0, fov_h_mm = 0, fov_d_mm = 0;
  // Depth of field
  double hyperfocal_mm = 0, near_mm = 0, far_mm = 0, depth_of_field_mm = 0;  // far, dof = inf beyond H
  // Stereo geometry
  double baseline_mm = 0;
  double working_distance_mm = 0;
  double optimum_working_distance_mm = 0;         //!< eq. 2.26: f * object / image width
  double depth_resolution_mm = 0;                 //!< eq. 2.25 at the working distance, per pixel of disparity
  double min_baseline_mm = 0;                     //!< eq. 2.27 (at the optimum working distance)
  double min_baseline_at_working_distance_mm = 0; //!< Z^2 * pixel / (f * dZ) at the working distance
  double recommended_convergence_deg = 0;         //!< eq. 2.24 at the working distance
  double optical_axes_angle_deg = 0;              //!< as configured
  // Camera poses in the rig frame
  Eigen::Matrix3d R_rig_left = Eigen::Matrix3d::Identity(), R_rig_right = Eigen::Matrix3d::Identity();
  Eigen::Vector3d c_left = Eigen::Vector3d::Zero(), c_right = Eigen::Vector3d::Zero();
  // Footprints on the working plane (rig x, y in mm; counter-clockwise)
  std::vector<Eigen::Vector2d> footprint_left, footprint_right, overlap;
  double footprint_left_area_mm2 = 0, footprint_right_area_mm2 = 0, overlap_area_mm2 = 0;
  Eigen::Vector2d overlap_min = Eigen::Vector2d::Zero(), overlap_max = Eigen::Vector2d::Zero();
  double overlap_fraction = 0;  //!< overlap area / left footprint area
  // Reconstruction uncertainty
  std::vector<DesignGridPoint> grid;
  double max_axis_mm = 0, mean_depth_sigma_mm = 0, max_depth_sigma_mm = 0;
  // Curves for the plots: (baseline mm, depth resolution mm) and (working distance mm, depth resolution mm)
  std::vector<std::pair<double, double>> resolution_vs_baseline, resolution_vs_distance;
};

/**
 * @brief Checks every field of a configuration.
 * @throws DesignConfigError naming the first bad field and its value.
 */
void validateDesignConfig(const DesignConfig& config);

/**
 * @brief Runs the calculator.
 * @throws DesignConfigError for a bad field or an impossible geometry (no overlap,
 *         a camera that does not see the working plane).
 */
DesignReport computeDesign(const DesignConfig& config);

/** @brief The stereo rig the design describes (left optical frame as reference, millimetres). */
StereoRig designRig(const DesignReport& report);

/**
 * @brief Parses a design YAML document (see config/part1_rig_design.yaml).
 * @param source text used in messages (e.g. the file name).
 * @throws DesignConfigError on unparsable YAML, a missing, unknown or bad field.
 */
DesignConfig parseDesignConfig(const std::string& yaml_text, const std::string& source = "config");

/** @brief Reads and parses a design YAML file; throws DesignConfigError if unreadable. */
DesignConfig loadDesignConfig(const std::string& path);

/** @brief The report as YAML text (mm, degrees). */
std::string designReportYaml(const DesignReport& report);

/** @brief The report as a readable table (mm, degrees). */
std::string designReportTable(const DesignReport& report);

// Polygon helpers (2D, counter-clockwise convex polygons).
/** @brief Signed area (positive for counter-clockwise). */
double polygonArea(const std::vector<Eigen::Vector2d>& poly);
/** @brief Intersection of two convex polygons (Sutherland-Hodgman); empty if disjoint. */
std::vector<Eigen::Vector2d> convexIntersection(const std::vector<Eigen::Vector2d>& subject,
                                                const std::vector<Eigen::Vector2d>& clip);
/** @brief True if p lies inside (or on) the convex counter-clockwise polygon. */
bool insideConvex(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p);

}  // namespace geometry
}  // namespace skin3d
