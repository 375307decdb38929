// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/sim/skin_sweep.h"

#include <cmath>
#include <random>
#include <string>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/sim_error.h"

namespace skin3d {
namespace sim {

namespace {
constexpr double kDeg = M_PI / 180.0;
void bad(const std::string& field, double v, const std::string& why) {
  throw SimConfigError(field, "field '" + field + "' = " + std::to_string(v) + ": " + why);
}
double uniform01(std::mt19937_64& r) { return static_cast<double>(r() >> 11) * (1.0 / 9007199254740992.0); }
}  // namespace

void SkinSweepConfig::validate() const {
  if (!enabled) return;
  if (frames < 2 || frames > 200) bad("skin.sweep.frames", frames, "must be in 2..200");
  if (!(arc > 0) || arc > 300 * kDeg) bad("skin.sweep.arc_deg", arc / kDeg, "must be in (0, 300]");
  if (!(fps > 0) || !std::isfinite(fps)) bad("skin.sweep.fps", fps, "must be > 0");
  if (!(jitter >= 0) || jitter > 0.02) bad("skin.sweep.jitter_mm", jitter * 1e3, "must be in [0, 20]");
  if (!(jitter_rot >= 0) || jitter_rot > 10 * kDeg) bad("skin.sweep.jitter_deg", jitter_rot / kDeg, "must be in [0, 10]");
  if (!(plaque_span > 0) || plaque_span > 180 * kDeg) bad("skin.sweep.plaque_span_deg", plaque_span / kDeg, "must be in (0, 180]");
  if (!(gyro_rate > 0) || gyro_rate > 1e4) bad("skin.sweep.gyro.rate_hz", gyro_rate, "must be in (0, 10000]");
  if (!(gyro_noise >= 0) || gyro_noise > 10) bad("skin.sweep.gyro.noise_rad_s", gyro_noise, "must be in [0, 10]");
  if (!gyro_bias.allFinite() || gyro_bias.norm() > 10) bad("skin.sweep.gyro.bias_rad_s", gyro_bias.norm(), "must be finite, |b| <= 10");
}

SkinSweepPath::SkinSweepPath(const SkinGeometry& g, const SkinSweepConfig& c, double working_distance, double yaw,
                             double tilt, double roll0, const Eigen::Isometry3d& T_rig_left, std::uint64_t seed)
    : g_(g), c_(c), wd_(working_distance), yaw_(yaw), tilt_(tilt), roll0_(roll0), T_rig_left_(T_rig_left) {
  std::mt19937_64 rng(seed * 0x2545F4914F6CDD1Dull + 0x5EEEull);
  for (int a = 0; a < 6; ++a)
    for (int j = 0; j < 2; ++j) {
      freq_(a, j) = 0.3 + 1.2 * uniform01(rng);
      phase_(a, j) = 2 * M_PI * uniform01(rng);
      amp_(a, j) = a < 3 ? c.jitter_rot : c.jitter;  // two sinusoids of amplitude A: RMS A
    }
}

Eigen::Isometry3d SkinSweepPath::arcPose(double a) const {
  return skinRigPose(g_, yaw_, tilt_, roll0_ + a, wd_);  // the single-view skin dataset's rig, the limb rolled by a
}

Eigen::Isometry3d SkinSweepPath::poseWorldRig(double t) const {
  const double span = duration();
  const double a = span > 0 ? c_.arc * (t / span - 0.5) : 0.0;
  Eigen::Matrix<double, 6, 1> j;
  for (int i = 0; i < 6; ++i)
    j[i] = amp_(i, 0) * std::sin(2 * M_PI * freq_(i, 0) * t + phase_(i, 0)) +
           amp_(i, 1) * std::sin(2 * M_PI * freq_(i, 1) * t + phase_(i, 1));
  Eigen::Isometry3d J = Eigen::Isometry3d::Identity();
  J.linear() = geometry::so3Exp(j.head<3>());
  J.translation() = j.tail<3>();
  return arcPose(a) * J;
}

Eigen::Vector3d SkinSweepPath::angularVelocity(double t) const {
  constexpr double h = 1e-5;
  const Eigen::Matrix3d R0 = poseWorldLeft(t - h).linear(), R1 = poseWorldLeft(t + h).linear();
  return geometry::so3Log(R0.transpose() * R1) / (2 * h);  // body rates: R(t + dt) = R(t) Exp(w dt)
}

std::vector<GyroSample> SkinSweepPath::gyro(std::uint64_t seed) const {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 0x6E70ull);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double T = duration() + 1.0 / c_.fps;
  std::vector<GyroSample> out;
  for (long i = 0; i / c_.gyro_rate < T; ++i) {
    GyroSample s;
    s.t = i / c_.gyro_rate;
    s.omega = angularVelocity(s.t) + c_.gyro_bias + c_.gyro_noise * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    out.push_back(s);
  }
  return out;
}

}  // namespace sim
}  // namespace skin3d
