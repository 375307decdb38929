/**
 * @file skin_sweep.h
 * @brief A hand-held sweep of the rig around a limb (the `skin` dataset with `skin.sweep.enabled`, docs/design.md
 * "Datasets"): the rig's path, its gyroscope and the frames' stamps, all from the seed.
 *
 * The rig moves on an arc about the limb's axis: at time t it looks at the limb as the single-view `skin` dataset
 * does with the limb rolled by roll0 + a(t), a(t) running linearly from -arc / 2 (first frame) to +arc / 2 (last
 * frame), its axis meeting the skin at the working distance. A hand is not a turntable: on top of the arc the rig
 * is moved by a smooth jitter, two sinusoids per axis (0.3 ... 1.5 Hz, seeded phases) scaled so that the rotation
 * jitter has an RMS of `jitter_rot` per axis and the translation jitter `jitter` per axis (in the rig frame, about
 * the rig's midpoint). The gyroscope measures the left optical frame's angular velocity (central differences of
 * the path, 1e-5 s) plus a constant bias and white noise per sample, as the globe's gyro does.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "skin3d/sim/globe.h"
#include "skin3d/sim/skin.h"

namespace skin3d {
namespace sim {

/** @brief The sweep's motion and sensors (config/datasets/skin_sweep.yaml documents every field). */
struct SkinSweepConfig {
  bool enabled = false;
  int frames = 17;                            //!< stereo pairs over the arc
  double arc = 140.0 * M_PI / 180.0;          //!< rad, the arc about the limb's axis (+-arc/2)
  double fps = 4.0;                           //!< pairs per second
  double jitter = 2.0e-3;                     //!< m, RMS of the hand's translation jitter per axis
  double jitter_rot = 1.5 * M_PI / 180.0;     //!< rad, RMS of its rotation jitter per axis
  double plaque_span = 95.0 * M_PI / 180.0;   //!< rad, random plaques lie at |angle around the limb| <= this
  double gyro_rate = 200.0;                   //!< Hz
  double gyro_noise = 0.005;                  //!< rad/s per sample (1 sigma)
  Eigen::Vector3d gyro_bias = Eigen::Vector3d(0.004, -0.006, 0.003);  //!< rad/s, constant
  void validate() const;                      //!< throws SimConfigError naming the field
};

class SkinSweepPath {
 public:
  /**
   * @param g the limb; yaw, tilt, roll0 the single-view pose angles (skin.h) at the middle of the arc
   * @param T_rig_left the left optical frame in the rig frame (RigConfig::poseRigLeft)
   */
  SkinSweepPath(const SkinGeometry& g, const SkinSweepConfig& c, double working_distance, double yaw, double tilt,
                double roll0, const Eigen::Isometry3d& T_rig_left, std::uint64_t seed);
  double frameTime(int k) const { return k / c_.fps; }   //!< s after the first frame
  double duration() const { return (c_.frames - 1) / c_.fps; }
  /** @brief The rig's pose in the limb frame at t (jitter included). */
  Eigen::Isometry3d poseWorldRig(double t) const;
  /** @brief The left optical frame's pose in the limb frame at t. */
  Eigen::Isometry3d poseWorldLeft(double t) const { return poseWorldRig(t) * T_rig_left_; }
  /** @brief True angular velocity of the left optical frame, in that frame (rad/s). */
  Eigen::Vector3d angularVelocity(double t) const;
  /** @brief Gyro samples at i / gyro_rate over [0, duration + 1 / fps), bias and noise added (seeded). */
  std::vector<GyroSample> gyro(std::uint64_t seed) const;

 private:
  Eigen::Isometry3d arcPose(double a) const;  // the rig on the arc at angle a, no jitter
  SkinGeometry g_;
  SkinSweepConfig c_;
  double wd_, yaw_, tilt_, roll0_;
  Eigen::Isometry3d T_rig_left_;
  Eigen::Matrix<double, 6, 2> freq_, phase_, amp_;  // per axis (rx ry rz tx ty tz), two sinusoids
};

}  // namespace sim
}  // namespace skin3d
