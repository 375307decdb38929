/**
 * @file render.h
 * @brief Ray-casting renderer of the simulated test objects (globe, workpiece) with camera realism.
 *
 * Exact ray casting per sample against the analytic geometry, s x s supersampling per pixel, an
 * albedo defined on the surface (so both views of a point agree) and view-independent shading
 * (Lambert with a fixed light direction in the world frame plus ambient), so that a surface point has
 * the same irradiance in both cameras. Realism (RealismOptions) then models what a real rig adds:
 * defocus blur, vignetting, per-camera gain/offset/gamma, shot + read noise and 8-bit quantisation.
 *
 * Units: metres and radians; images are cv::Mat.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "skin3d/geometry/camera.h"

namespace skin3d {
namespace sim {

/** @brief A ray hit: distance along the (unit) ray, world point, unit normal. */
struct Hit {
  double distance = 0.0;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
};

/** @brief Something the renderer can see. Implementations are immutable and thread-safe. */
class Scene {
 public:
  virtual ~Scene() = default;
  /** @brief Nearest hit with distance > 0 of the ray origin + s dir (dir unit, world frame). */
  virtual bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* hit) const = 0;
  /** @brief Albedo in [0, 1] of a surface point (world frame). */
  virtual float albedo(const Hit& hit) const = 0;
};

/**
 * @brief Band-limited procedural texture: fractal (fBm) gradient noise with `octaves` octaves,
 * lowest feature size `scale` (m), deterministic in `seed`. Values roughly in [0, 1].
 */
struct NoiseTexture {
  double scale = 0.05;
  int octaves = 6;
  double persistence = 0.55;
  std::uint64_t seed = 1;
  /** @brief Value at a 3D point (m). */
  double at(const Eigen::Vector3d& p) const;
};

/**
 * @brief A textured sphere (the globe): centre and radius in the world frame, albedo from a
 * precomputed equirectangular map of a globe-like procedural texture ("continents" from a
 * low-frequency noise threshold, detail at several scales), sampled bilinearly.
 * The map is built once in the constructor (texels of about `texel` metres at the equator).
 */
class SphereScene : public Scene {
 public:
  SphereScene(const Eigen::Vector3d& centre, double radius, std::uint64_t seed, double texel = 0.25e-3);
  bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* hit) const override;
  float albedo(const Hit& hit) const override;
  /** @brief Rotates the texture with the globe: world <- globe-body rotation at the time of rendering. */
  void setOrientation(const Eigen::Matrix3d& R_world_body) { R_world_body_ = R_world_body; }

 private:
  Eigen::Vector3d centre_;
  double radius_;
  Eigen::Matrix3d R_world_body_ = Eigen::Matrix3d::Identity();
  cv::Mat map_;  // CV_32F, equirectangular (longitude across, latitude down)
};

/** @brief One embossed plateau of the workpiece: an axis-aligned box on the plate (plate frame, m). */
struct Plateau {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  //!< x, y on the plate
  Eigen::Vector2d size = Eigen::Vector2d(0.015, 0.015);
  double height = 0.0001;                            //!< above the plate surface
};

/**
 * @brief The validation workpiece (thesis ch. 4, app. C): a flat plate (its top surface is z = 0 of the
 * plate frame, normal +z, extent `plate_size` centred at the origin) with embossed plateaus, covered by a
 * drawn random pattern (a 2D procedural texture in plate x, y, precomputed at `texel` resolution).
 * The plate frame is the world frame of the workpiece dataset.
 */
class WorkpieceScene : public Scene {
 public:
  WorkpieceScene(const Eigen::Vector2d& plate_size, std::vector<Plateau> plateaus, std::uint64_t seed,
                 double texel = 20e-6);
  bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* hit) const override;
  float albedo(const Hit& hit) const override;
  const std::vector<Plateau>& plateaus() const { return plateaus_; }
  /** @brief Height of the surface (z) at plate point (x, y): a plateau's height or 0. */
  double heightAt(const Eigen::Vector2d& xy) const;

 private:
  Eigen::Vector2d plate_size_;
  std::vector<Plateau> plateaus_;
  double texel_;
  cv::Mat map_;  // CV_32F over the plate
};

/** @brief What a real camera adds to the ideal image. Defaults: on ("realism"); ideal() turns them off. */
struct RealismOptions {
  double blur_sigma = 0.6;        //!< px, Gaussian defocus blur
  double vignetting = 0.25;       //!< relative fall-off at the image corner (0 = none), cos^4-like radial
  double gain = 1.0;              //!< multiplies the irradiance
  double offset = 0.0;            //!< added, in [0, 1] intensity units
  double gamma = 1.0;             //!< output = (gain * E + offset)^(1/gamma)
  double full_well = 8000.0;      //!< electrons at intensity 1 (shot noise variance = E * full_well); 0 = none
  double read_noise = 1.5;        //!< DN (of 255), Gaussian; 0 = none
  bool quantise = true;           //!< true: CV_8UC1 output; false: the clamped CV_32F image in [0, 1] (tests)
  static RealismOptions ideal();
};

struct RenderOptions {
  int supersample = 3;            //!< s x s samples per pixel (>= 1; realism wants >= 3)
  Eigen::Vector3d light_dir = Eigen::Vector3d(0.3, -0.5, -1.0).normalized();  //!< direction the light travels, world
  double ambient = 0.35;          //!< shading = ambient + (1 - ambient) * max(0, -n . light_dir)
  float background = 0.05f;       //!< albedo where a ray hits nothing
  int threads = 0;                //!< 0 = hardware concurrency
};

/**
 * @brief Ideal irradiance image (CV_32F, values ~[0, 1]) of the scene seen by `camera` (with its
 * distortion: pixel -> ray through camera.unproject) at pose T_world_cam (world <- camera optical frame).
 */
cv::Mat renderIrradiance(const Scene& scene, const geometry::PinholeCamera& camera,
                         const Eigen::Isometry3d& T_world_cam, const RenderOptions& options = RenderOptions());

/**
 * @brief Applies the realism chain to an irradiance image: blur, vignetting, gain/offset/gamma, shot and
 * read noise (random numbers from `seed`), then clamps to [0, 1] and quantises to CV_8UC1 (unless !quantise).
 */
cv::Mat applyRealism(const cv::Mat& irradiance, const RealismOptions& realism, std::uint64_t seed);

}  // namespace sim
}  // namespace skin3d
