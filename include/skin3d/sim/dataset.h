/**
 * @file dataset.h
 * @brief Configuration of the simulated datasets (docs/design.md "Datasets") and the calibration
 * perturbation that makes a rendered dataset as imperfect as a real stereo calibration.
 *
 * Kinds: globe-landmarks (thesis' landmark-level globe simulator), globe-images (the same scene
 * rendered), workpiece (the validation workpiece seen by the Part I rig), skin (a limb with plaques seen by
 * the Part I rig: skin.h). Defaults reproduce the
 * thesis' parameters; a YAML file (config/datasets/globe.yaml, workpiece.yaml document every field)
 * overrides them.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "skin3d/geometry/stereo_rig.h"
#include "skin3d/sim/globe.h"
#include "skin3d/sim/render.h"
#include "skin3d/sim/sim_error.h"
#include "skin3d/sim/skin.h"
#include "skin3d/sim/skin_sweep.h"

namespace skin3d {
namespace sim {

enum class DatasetKind { GlobeLandmarks, GlobeImages, Workpiece, Skin };

/** @throws SimConfigError("kind", ...) listing the known kinds. */
DatasetKind parseDatasetKind(const std::string& name);
std::string datasetKindName(DatasetKind kind);

/** @brief How the calibration written to the bag is drawn. */
enum class CalibrationErrorModel {
  /** A stereo calibration is simulated (the default): a chessboard is placed at `views` random poses around the
   *  working distance, its corners are projected with the true rig, `corner_sigma_px` Gaussian noise is added and
   *  the core's calibrateStereo (the calibrate_stereo tool's algorithm) estimates the rig. Its errors are therefore
   *  correlated the way a real calibration's are: the principal points may be off by a pixel each, but the
   *  disparity a board at a known distance produces is fitted, so the depth error stays small. */
  Chessboard,
  /** Each parameter is drawn independently (the datasets' model before the simulated chessboard calibration): principal points, focal lengths,
   *  baseline and relative rotation. Independent principal-point errors shift the disparity by
   *  sqrt(2) * principal_point_px, which a calibration against a metric board would not leave. */
  Independent,
};

/** @brief How far the calibration written to the bag is off the truth. */
struct CalibrationPerturbation {
  bool enabled = true;
  CalibrationErrorModel model = CalibrationErrorModel::Chessboard;
  // --- Independent model (1 sigma each)
  double baseline_rel = 0.003;        //!< relative baseline length error
  double rotation = 0.05 * M_PI / 180.0;  //!< rad, RMS magnitude of the relative rotation error
  double principal_point = 1.5;       //!< px, per coordinate and camera
  double focal_rel = 0.0015;          //!< relative focal length error per camera
  // --- Chessboard model
  int views = 15;                     //!< board poses (pairs) used by the simulated calibration
  /** Corner localisation noise, px per coordinate (1 sigma). 0.14 px gives the simulated calibration an RMS
   *  reprojection error of ~0.2 px (OpenCV's RMS is per corner, both coordinates: sqrt(2) sigma), what
   *  calibrate_stereo reaches on 13 real chessboard pairs (0.197 px; the shared test data, SKIN3D_SHARED_DIR). */
  double corner_sigma_px = 0.14;
  int board_cols = 9, board_rows = 6;  //!< inner corners, as the real board
  /** Radial distortion coefficients the calibration estimates (calibrate_stereo's --k-coefficients). */
  int k_coefficients = 2;
  /** Size of the board: its corner grid spans this fraction of the left image's width at the working distance. */
  double board_fill = 0.4;
  /** Board distances, uniform in [min, max] x working distance. */
  double min_distance_rel = 0.75, max_distance_rel = 1.5;
  double max_tilt = 30.0 * M_PI / 180.0;  //!< rad, board tilt about its x and y axes (uniform in +-)
};

/** @brief Name of a model ("chessboard", "independent"); parse throws SimConfigError listing the known ones. */
std::string calibrationErrorModelName(CalibrationErrorModel m);
CalibrationErrorModel parseCalibrationErrorModel(const std::string& name);

/** @brief What a perturbation drew, and the rig the bag's camera_info describes. */
struct PerturbedCalibration {
  geometry::StereoRig rig;            //!< the calibration as "measured"
  double baseline_scale = 1.0;
  Eigen::Vector3d rotation_error = Eigen::Vector3d::Zero();  //!< rad, rotation vector applied to R_rl
  Eigen::Vector2d principal_left = Eigen::Vector2d::Zero(), principal_right = Eigen::Vector2d::Zero();  //!< px
  double focal_scale_left = 1.0, focal_scale_right = 1.0;
  /** Error of the depth triangulated with the measured calibration from the true pixels of a point on the left
   *  optical axis at the working distance (m; > 0: too far). What the calibration error does to a landmark. */
  double depth_error_m = 0.0;
  /** The largest such error over a 9 x 9 grid of the left image (points at the working distance the right camera
   *  sees too), m. */
  double depth_error_max_m = 0.0;
  /** The similarity that best maps true CCS points to the points this calibration triangulates from their true
   *  pixels, X_measured ~ frame_scale Exp(frame_rotation) X + frame_translation (least squares, Umeyama, over the
   *  working volume: a 9 x 9 grid of the left image at 0.8, 0.9, ..., 1.2 x the working distance, points both
   *  cameras see). Its rigid part is the frame the calibration defines: no image can tell it from the true
   *  optical frame, so a SLAM world fixed by the first camera frame is this frame, and the poses the SLAM
   *  estimates are E T_true E^-1 with E = (Exp(frame_rotation), frame_translation) (scripts/slam_nees.py
   *  --calibrated-frame). The scale is a metric error, not a frame: it is reported, not folded in. */
  Eigen::Vector3d frame_rotation = Eigen::Vector3d::Zero();     //!< rad, rotation vector
  Eigen::Vector3d frame_translation = Eigen::Vector3d::Zero();  //!< m
  double frame_scale = 1.0;
  double frame_residual_rms_m = 0.0;  //!< RMS of what the similarity does not explain (m): the non-rigid part
  int frame_points = 0;               //!< grid points the fit used
  // Chessboard model only
  double calibration_rms_px = 0.0;    //!< the simulated calibration's RMS reprojection error
  double board_square_m = 0.0;
};

/**
 * @brief Draws a calibration error for `truth` (deterministic in seed). Disabled: returns the truth.
 * @param working_distance m, where the rig is used (the board poses of the Chessboard model, depth_error_m).
 * @throws std::runtime_error if the Chessboard model cannot place its board in both images.
 */
PerturbedCalibration perturbCalibration(const geometry::StereoRig& truth, const CalibrationPerturbation& p,
                                        std::uint64_t seed, double working_distance);

struct ImageConfig {
  bool ideal = false;                 //!< no realism, exact calibration (debugging)
  int supersample = 3;
  RealismOptions left, right;         //!< per-camera photometry; shared blur/vignetting/noise
  CalibrationPerturbation perturbation;
  double light_elevation = 0.5;       //!< rad; light from above-left of the rig (globe), fixed to the rig
};

/** @brief `rig` with fewer, larger pixels over the same field of view (resolution_scale in (0, 1]). */
RigConfig scaleRig(const RigConfig& rig, double resolution_scale);

struct WorkpieceConfig {
  Eigen::Vector2d plate_size = Eigen::Vector2d(0.12, 0.09);  //!< m
  std::vector<Plateau> plateaus;      //!< default: 0.1 ... 0.7 mm, 15 x 15 mm, in a 4 + 3 grid
  RigConfig rig;                      //!< default: the Part I rig (f 2.94 mm, 1.12 um, 4224x3136, 210 mm, 54.4 deg)
  double working_distance = 0.245;    //!< m, rig midpoint to the plate along the rig axis
  double tilt = 5.0 * M_PI / 180.0;   //!< rad, the plate's tilt about the rig x axis (a hand never holds it square)
  double resolution_scale = 1.0;      //!< < 1: fewer, larger pixels over the same field of view (fast tests)
  int frames = 3;                     //!< repeated exposures of the same view (noise differs)
  double fps = 2.0;
  double texel = 20e-6;               //!< m, pattern resolution
  /** @brief The rig at resolution_scale. */
  RigConfig scaledRig() const { return scaleRig(rig, resolution_scale); }
  void validate() const;
};

/** @brief The skin dataset (config/datasets/skin.yaml documents every field). */
struct SkinConfig {
  bool random = true;                 //!< draw the limb, its plaques and its pose from the seed (randomSkinGeometry)
  int plaque_count = 5;               //!< random: plaques drawn
  double dome_max = 0.0;              //!< random: plaque tops domed up to this (0 = flat tops)
  SkinGeometry geometry;              //!< used when !random (plaques in surface coordinates)
  double yaw = 0.0;                   //!< rad, the limb axis turned about the rig axis (0: along the baseline)
  double tilt = 0.0;                  //!< rad, the limb axis tilted towards / away from the rig
  double roll = 0.0;                  //!< rad, the limb turned about its own axis
  double max_yaw = 30.0 * M_PI / 180.0, max_tilt = 8.0 * M_PI / 180.0, max_roll = 15.0 * M_PI / 180.0;  //!< random: +- ranges
  RigConfig rig;                      //!< default: the Part I rig
  double working_distance = 0.245;    //!< m, rig midpoint to the skin along the rig axis
  double resolution_scale = 1.0;
  int frames = 2;
  double fps = 2.0;
  double contrast = 1.0;              //!< skin albedo modulation (1: a few grey levels)
  bool scale_texture = true;          //!< psoriatic scale on plaque tops
  /** A hand-held sweep around the limb (skin_sweep.h) instead of a still rig: `frames` / `fps` above are then
   *  the sweep's, and the truth is in the first left optical frame (`world`). */
  SkinSweepConfig sweep;
  RigConfig scaledRig() const { return scaleRig(rig, resolution_scale); }
  /** @brief The scene's geometry and pose for a seed (random or as configured). */
  SkinGeometry geometryFor(std::uint64_t seed, double* yaw, double* tilt, double* roll) const;
  void validate() const;
};

struct DatasetConfig {
  DatasetKind kind = DatasetKind::GlobeLandmarks;
  std::uint64_t seed = 1;
  GlobeConfig globe;
  WorkpieceConfig workpiece;
  SkinConfig skin;
  ImageConfig images;
  std::string source;                 //!< where overrides came from (for the truth file)
};

/** @brief The thesis' defaults for a kind (landmark globe: pixel noise only, exact calibration). */
DatasetConfig defaultDatasetConfig(DatasetKind kind);

/**
 * @brief Applies a YAML document's overrides (mm, degrees, um as the field names say).
 * @throws SimConfigError naming the field for unparsable YAML, unknown fields or bad values.
 */
void applyDatasetYaml(DatasetConfig* config, const std::string& yaml_text, const std::string& source);

/** @brief Switches realism off and the calibration error off (--ideal). */
void makeIdeal(DatasetConfig* config);

/** @brief Validates the whole configuration; throws SimConfigError. */
void validateDatasetConfig(const DatasetConfig& config);

}  // namespace sim
}  // namespace skin3d
