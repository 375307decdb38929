/**
 * @file globe.h
 * @brief The thesis' globe simulator (§6.2.3, ch. 7): a stereo rig orbiting a textured sphere,
 * measuring its surface landmarks the way a real rig does.
 *
 * Geometry (SI units: metres, seconds, radians inside; the YAML speaks mm and degrees):
 *  - Globe frame G: centre at the origin, spin axis z_G. The globe turns about z_G at `rate`
 *    relative to the rig (equivalently the rig orbits it); the rig stays at latitude `latitude`
 *    (measured in G) and distance `distance` from the centre, its left optical axis pointing at the
 *    centre. The lab "up" direction is tilted by `tilt` from z_G; the left camera's image x axis is
 *    kept horizontal in the lab (no roll), so the tilt shows as an inclined spin axis in the images.
 *  - World frame W (the SLAM's origin, docs/design.md "world"): the left optical frame at t = 0.
 *    Ground-truth poses are T_W_L(t) (world <- left optical frame); the sphere centre in W is
 *    (0, 0, distance) at t = 0 by construction.
 *  - Landmarks: `landmarks` points uniformly distributed over the sphere (fixed in G, hence in W),
 *    each with a fixed unit-norm descriptor of `descriptor_size` floats.
 *
 * Measurement of frame k (time t_k = k / fps): every landmark visible to both cameras (in front of
 * both, its surface facing the rig within `max_incidence`, inside both images) is projected into
 * both cameras, pixel noise N(0, pixel_sigma^2) is added to each coordinate, and the pair is
 * triangulated with the core's MMSE triangulation (geometry/stereo_rig.h), giving the position in the
 * left optical frame with its own 3x3 covariance. The descriptor gets N(0, descriptor_noise^2) per
 * element (then renormalised). Optional look-alikes: a fraction of landmarks share a near-duplicate
 * of another landmark's descriptor (distance ~ lookalike_distance), to exercise data association.
 *
 * Gyroscope: z = omega_L(t) + bias + n, omega in the rig (left optical) frame, n ~ N(0, gyro_noise^2)
 * per sample, bias constant plus an optional random walk; samples at `gyro_rate` Hz.
 *
 * Deterministic: the same config (including seed) gives identical output.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "skin3d/geometry/stereo_rig.h"
#include "skin3d/sim/sim_error.h"

namespace skin3d {
namespace sim {

/** @brief A stereo rig described by its design numbers (metres, radians). */
struct RigConfig {
  double focal_length = 1.8e-3;   //!< m
  double pixel_size = 2.24e-6;    //!< m (effective, after binning)
  int width = 640;
  int height = 480;
  /** Left-to-right optical centre, m, in the rig frame (axes of an unturned camera; for convergence 0 this is
   *  the right optical centre in the left optical frame, e.g. (0.105, 0, 0.015) for the SLAM rig). */
  Eigen::Vector3d baseline = Eigen::Vector3d(0.105, 0.0, 0.015);
  double convergence = 0.0;       //!< angle between the optical axes, rad (each camera turned by half, about y)
  std::vector<double> distortion; //!< plumb_bob k1 k2 p1 p2 k3 for both cameras; empty = none

  /** @brief The rig (left optical frame as reference, metres). @throws SimConfigError. */
  geometry::StereoRig makeRig() const;

  /**
   * @brief Pose of the left optical frame in the rig frame (origin midway between the optical centres,
   * axes of an unturned camera): centre -baseline/2, turned by +convergence/2 about y (design.h convention).
   */
  Eigen::Isometry3d poseRigLeft() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.5 * convergence, Eigen::Vector3d::UnitY()).toRotationMatrix();
    T.translation() = -0.5 * baseline;
    return T;
  }
};

struct GlobeConfig {
  double radius = 0.200;          //!< m
  double distance = 0.600;        //!< m, rig (left optical centre) to globe centre
  double latitude = -0.436332313; //!< rad (-25 deg)
  double tilt = 0.401425728;      //!< rad (23 deg)
  double rate = 0.15;             //!< rad/s, spin of the globe relative to the rig
  int frames = 420;
  double fps = 10.0;
  int landmarks = 10000;
  int descriptor_size = 64;
  double descriptor_noise = 0.01; //!< per element, on unit-norm descriptors
  double lookalike_fraction = 0.0;
  double lookalike_distance = 0.05;  //!< descriptor distance of a look-alike from its original
  double pixel_sigma = 0.5;       //!< px
  double max_incidence = 1.3089969;  //!< rad (75 deg) between surface normal and the line of sight
  double gyro_rate = 100.0;       //!< Hz
  double gyro_noise = 0.002;      //!< rad/s per sample (1 sigma)
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  //!< rad/s
  double gyro_bias_walk = 0.0;    //!< rad/s per sqrt(s)
  std::uint64_t seed = 1;
  RigConfig rig;

  /** @throws SimConfigError naming the field ("globe.radius_mm", ...) for a bad value or geometry. */
  void validate() const;
};

/** @brief One stereo-triangulated landmark measurement (left optical frame, metres). */
struct LandmarkMeasurement {
  int id = -1;                             //!< ground-truth landmark index (never given to SLAM)
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  std::vector<float> descriptor;
  float strength = 0.0f;                   //!< match strength in (0, 1]: higher = more distinctive/closer
  Eigen::Vector2d uv_left = Eigen::Vector2d::Zero(), uv_right = Eigen::Vector2d::Zero();  //!< noisy pixels
};

struct GyroSample {
  double t = 0.0;
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();  //!< measured, rad/s, rig frame
};

class GlobeSimulator {
 public:
  /** @throws SimConfigError. */
  explicit GlobeSimulator(const GlobeConfig& config);

  const GlobeConfig& config() const { return config_; }
  const geometry::StereoRig& rig() const { return rig_; }
  int frames() const { return config_.frames; }
  double stamp(int k) const { return k / config_.fps; }

  /** @brief Ground-truth pose world <- left optical frame at time t. */
  Eigen::Isometry3d poseWorldLeft(double t) const;
  /** @brief True angular velocity of the rig in its own (left optical) frame, rad/s. */
  Eigen::Vector3d angularVelocity(double t) const;
  /** @brief True linear velocity of the rig in its own frame, m/s. */
  Eigen::Vector3d linearVelocity(double t) const;

  /** @brief Pose of the globe body frame G in the world (constant: the rig moves, the globe does not). */
  const Eigen::Isometry3d& poseWorldGlobe() const { return T_W_G_; }
  /** @brief Sphere centre in the world frame. */
  Eigen::Vector3d sphereCentreWorld() const;
  /** @brief Ground-truth landmark positions in the world frame. */
  const std::vector<Eigen::Vector3d>& landmarksWorld() const { return landmarks_world_; }
  /** @brief The landmarks' true (noise-free) descriptors. */
  const std::vector<std::vector<float>>& descriptors() const { return descriptors_; }

  /** @brief Landmarks visible to both cameras in frame k, noise-free pixels (ids only). */
  std::vector<int> visible(int k) const;
  /** @brief Noisy measurements of frame k (deterministic in (seed, k)). */
  std::vector<LandmarkMeasurement> measure(int k) const;
  /** @brief Gyroscope samples over [0, frames / fps) (deterministic in seed). */
  std::vector<GyroSample> gyro() const;

 private:
  GlobeConfig config_;
  geometry::StereoRig rig_;
  Eigen::Isometry3d T_W_G_ = Eigen::Isometry3d::Identity();  //!< world <- globe at t = 0
  Eigen::Isometry3d T_G_L0_ = Eigen::Isometry3d::Identity(); //!< globe <- left at t = 0
  std::vector<Eigen::Vector3d> landmarks_world_;
  std::vector<std::vector<float>> descriptors_;
};

}  // namespace sim
}  // namespace skin3d
