/**
 * @file dataset.h
 * @brief Configuration of the simulated datasets (DESIGN.md "Datasets") and the calibration
 * perturbation that makes a rendered dataset as imperfect as a real stereo calibration.
 *
 * Kinds: globe-landmarks (thesis' landmark-level globe simulator), globe-images (the same scene
 * rendered), workpiece (the validation workpiece seen by the Part I rig). Defaults reproduce the
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

namespace skin3d {
namespace sim {

enum class DatasetKind { GlobeLandmarks, GlobeImages, Workpiece };

/** @throws SimConfigError("kind", ...) listing the known kinds. */
DatasetKind parseDatasetKind(const std::string& name);
std::string datasetKindName(DatasetKind kind);

/** @brief How far the calibration written to the bag is off the truth (1 sigma each). */
struct CalibrationPerturbation {
  bool enabled = true;
  double baseline_rel = 0.003;        //!< relative baseline length error
  double rotation = 0.05 * M_PI / 180.0;  //!< rad, RMS magnitude of the relative rotation error
  double principal_point = 1.5;       //!< px, per coordinate and camera
  double focal_rel = 0.0015;          //!< relative focal length error per camera
};

/** @brief What a perturbation drew, and the rig the bag's camera_info describes. */
struct PerturbedCalibration {
  geometry::StereoRig rig;            //!< the calibration as "measured"
  double baseline_scale = 1.0;
  Eigen::Vector3d rotation_error = Eigen::Vector3d::Zero();  //!< rad, rotation vector applied to R_rl
  Eigen::Vector2d principal_left = Eigen::Vector2d::Zero(), principal_right = Eigen::Vector2d::Zero();  //!< px
  double focal_scale_left = 1.0, focal_scale_right = 1.0;
};

/** @brief Draws a calibration error for `truth` (deterministic in seed). Disabled: returns the truth. */
PerturbedCalibration perturbCalibration(const geometry::StereoRig& truth, const CalibrationPerturbation& p,
                                        std::uint64_t seed);

struct ImageConfig {
  bool ideal = false;                 //!< no realism, exact calibration (debugging)
  int supersample = 3;
  RealismOptions left, right;         //!< per-camera photometry; shared blur/vignetting/noise
  CalibrationPerturbation perturbation;
  double light_elevation = 0.5;       //!< rad; light from above-left of the rig (globe), fixed to the rig
};

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
  RigConfig scaledRig() const;
  void validate() const;
};

struct DatasetConfig {
  DatasetKind kind = DatasetKind::GlobeLandmarks;
  std::uint64_t seed = 1;
  GlobeConfig globe;
  WorkpieceConfig workpiece;
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
