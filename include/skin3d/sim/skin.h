/**
 * @file skin.h
 * @brief The skin scene: a limb with raised psoriatic plaques and low-contrast skin albedo (docs/design.md
 * "Datasets", kind `skin`), with its exact truth.
 *
 * Geometry, in the LIMB frame (the dataset's world frame): x along the limb axis, the cross-section an ellipse
 * in (y, z) with semi-axes a (y) and b (z), z towards the rig when the limb is not rolled. A base point is
 * B(s, phi) = (s, a sin phi, b cos phi), phi = 0 at the top; |s| <= length / 2 (the limb ends there: nothing is
 * seen beyond). A plaque raises the skin along the base point's radial direction (from the axis) by h(s, phi):
 *   X(s, phi) = (s, (1 + h / r0) a sin phi, (1 + h / r0) b cos phi),  r0 = |B - (s, 0, 0)|,
 * which for a circular limb is exactly along the normal; for an ellipse the height along the base normal differs
 * by a fraction of a percent, and the truth (SkinPlaque*) is the exact distance to the base surface, computed
 * numerically. Plaque outline in the surface coordinates (s, t = r_mean phi): an ellipse of semi-axes
 * `radii` turned by `orientation`, its radius modulated by harmonics 2 ... 4 (`irregularity`, seeded phases);
 * inside it the height rises over a border `ramp` wide with a smooth step (C1) to the top, which is flat
 * (dome 0) or domed (h = H (1 - dome q^2) at normalised radius q, so the peak H is at the centre).
 *
 * Ray casting: the first root of G(x) = rho(x) - 1 - h / r0 (rho the elliptic radius) along the ray between the
 * enclosing elliptic cylinder (1 + h_max / min(a, b)) and the base, marched in steps of 0.1 mm and bisected to
 * 1e-9 m; the base alone is hit analytically where no plaque is near. Normals of plaques by central differences.
 *
 * Albedo (surface coordinates, so both views agree), all from the seed: skin tone with slow mottling
 * (8 ... 2 mm), fine micro-relief (0.6 ... 0.15 mm), fine creases (ridges of a 1.5 mm noise), pores (0.5 mm
 * cells, 40 % of them with a dark dot 30 ... 70 um), soft freckles (4 mm cells, 15 %, 0.4 ... 1.2 mm); plaques
 * a little darker (erythema) with brighter flaky scale on their tops. `contrast` scales every modulation:
 * at 1 the fine contrast is a few grey levels (about 2.5 % of the tone), as real forearm skin in diffuse light.
 *
 * Not modelled: subsurface scattering (skin is treated as Lambertian), specular highlights, hair, limb taper
 * and soft-tissue deformation, motion, colour (one grey channel).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "skin3d/sim/render.h"

namespace skin3d {
namespace sim {

/** @brief One plaque, in the limb's surface coordinates (m, rad). */
struct SkinPlaque {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  //!< (s along the axis, t = r_mean phi around it), m
  Eigen::Vector2d radii = Eigen::Vector2d(0.007, 0.005);  //!< outline semi-axes, m
  double orientation = 0.0;   //!< rad, of the outline in (s, t)
  double height = 0.5e-3;     //!< m, peak height (flat top: the top's height)
  double ramp = 1.0e-3;       //!< m, width of the border over which the height rises
  double dome = 0.0;          //!< 0 flat top ... 1 fully domed
  double irregularity = 0.15; //!< relative amplitude of the outline's harmonics 2 ... 4
  std::uint64_t shape_seed = 1;
};

/** @brief Healthy relief on the limb, a ridge (a nose's bridge, a tendon, the raised side of a fold): a Gaussian
 *  cross-section of `height` and standard deviation `width` along a straight line of `length` (ends rounded over
 *  one width), in the limb's surface coordinates. Not a plaque: a reference fitted to the limb cannot follow it. */
struct SkinRidge {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  //!< (s along the axis, t = r_mean phi around it), m
  double orientation = 0.0;  //!< rad: direction of the ridge's line in (s, t); 0 = along the limb's axis
  double length = 0.04;      //!< m
  double width = 0.004;      //!< m, Gaussian sigma across
  double height = 2.0e-3;    //!< m, on its line
};

/** @brief The limb and its plaques. */
struct SkinGeometry {
  double semi_axis_y = 0.04, semi_axis_z = 0.04;  //!< m, cross-section (y across, z towards the rig)
  double length = 0.4;                            //!< m, along x (centred)
  std::vector<SkinPlaque> plaques;
  std::vector<SkinRidge> ridges;                  //!< healthy relief (plaques on a ridge sit on top of it)
  double contrast = 1.0;                          //!< scales every albedo modulation
  bool scale_texture = true;                      //!< flaky psoriatic scale on plaque tops
  double meanRadius() const { return 0.5 * (semi_axis_y + semi_axis_z); }
};

/** @brief Truth of one plaque (from the generator's geometry, integrated numerically on a fine grid). */
struct SkinPlaqueTruth {
  double top_height = 0;       //!< m, peak distance to the base surface along its normal (less the ridges' relief there)
  double mean_height = 0;      //!< m, mean distance over the footprint
  double footprint_area = 0;   //!< m^2 on the base surface where the height > 0
  double top_area = 0;         //!< m^2 where the height >= 99 % of the peak (flat top: the top face)
  /** m^2 where the height >= half the peak: the outline a measurement draws at half height (induration's
   *  edge_fraction 0.5), inside the footprint by about half the ramp */
  double half_height_area = 0;
  double volume = 0;           //!< m^3
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  //!< limb frame, area-weighted mean of the raised surface over the footprint
  Eigen::Vector3d top_point = Eigen::Vector3d::Zero(); //!< limb frame, the raised surface at the plaque centre
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();   //!< limb frame, base normal at the plaque centre
};

class SkinScene : public Scene {
 public:
  /** @throws std::invalid_argument naming a bad field. */
  SkinScene(SkinGeometry geometry, std::uint64_t seed);
  bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* hit) const override;
  float albedo(const Hit& hit) const override;

  const SkinGeometry& geometry() const { return g_; }
  /** @brief Height of the skin above the base at surface coordinates (s, phi), m: the ridges' relief plus the
   *  plaque there (0 on the bare limb). */
  double heightAt(double s, double phi) const;
  /** @brief The ridges' relief alone at (s, phi), m. */
  double reliefAt(double s, double phi) const;
  /** @brief Index of the plaque whose footprint holds (s, phi), or -1; its height there in *height if given. */
  int plaqueAt(double s, double phi, double* height = nullptr) const;
  /** @brief Surface coordinates (s, phi) of a limb-frame point (its elliptic angle). */
  Eigen::Vector2d surfaceCoordinates(const Eigen::Vector3d& x) const;
  /** @brief The raised surface point at (s, phi). */
  Eigen::Vector3d surfacePoint(double s, double phi) const;
  /** @brief Unit outward normal of the base ellipse at phi. */
  Eigen::Vector3d baseNormal(double phi) const;
  /** @brief Distance of a limb-frame point to the base surface (m, > 0 outside), exact (Newton on phi). */
  double distanceToBase(const Eigen::Vector3d& x) const;
  /** @brief Truth of plaque k, integrated on a grid of `step` m in (s, t). */
  SkinPlaqueTruth plaqueTruth(std::size_t k, double step = 25e-6) const;

 private:
  double profile(std::size_t k, double s, double phi) const;  // height of plaque k alone (0 outside)
  double G(const Eigen::Vector3d& x) const;                    // > 0 outside the skin
  SkinGeometry g_;
  std::uint64_t seed_;
  double h_max_ = 0;
  struct Box { double s0, s1, p0, p1; };
  std::vector<Box> boxes_;  // (s, phi) bounds of each plaque's footprint, with a margin
  std::vector<Box> relief_boxes_;  // and of each ridge (out to 4 widths)
  std::vector<Eigen::Vector3d> harmonics_;  // per plaque: amplitudes of harmonics 2, 3, 4
  std::vector<Eigen::Vector3d> phases_;
};

/**
 * @brief A random limb and plaques for a seed (the `skin` dataset's default): semi-axes 30 ... 60 mm with an
 * aspect (z / y) of 0.8 ... 1, `count` plaques with centres at |phi| <= max_angle (55 deg) around the top (so some sit on the slanted
 * sides) and |s| <= 40 mm, not overlapping, outline radii 4 ... 9 mm, heights log-uniform in [0.1, 1.5] mm
 * (the first in [0.05, 0.1]: one plaque below the detection bar) kept 0.02 mm away from the PASImeter class
 * boundaries (0.125, 0.375, 0.625, 0.875 mm: a class is then decidable within 10 um), ramps 0.5 ... 1.5 mm,
 * flat tops (dome_max > 0: domes up to it), irregularity 0.05 ... 0.25.
 */
/**
 * @brief Where the `skin` dataset puts the rig (its midpoint frame, in the limb frame): looking at the top of the limb
 * rolled by `roll` about its axis, the baseline along the limb turned by `yaw` about the rig axis, the rig axis
 * tilted by `tilt` along the limb, and meeting the skin at `working_distance` (m) from the rig's midpoint.
 */
Eigen::Isometry3d skinRigPose(const SkinGeometry& g, double yaw, double tilt, double roll, double working_distance);

SkinGeometry randomSkinGeometry(std::uint64_t seed, int count = 5, double dome_max = 0.0,
                                double max_angle = 55.0 * M_PI / 180.0);

}  // namespace sim
}  // namespace skin3d
