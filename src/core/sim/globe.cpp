// SPDX-License-Identifier: BSD-3-Clause
//
// The thesis' globe simulator (§6.2.3, ch. 7): see include/skin3d/sim/globe.h for the contract.
//
// Conventions chosen here (the header leaves them open):
//  - Globe frame G, at t = 0: the left optical centre is at c0 = distance (cos lat, 0, sin lat), i.e. on
//    longitude 0 (the x_G-z_G half plane with x_G > 0), latitude `latitude`.
//    e_r = c0 / |c0|, e_east = z_G x e_r = y_G, e_north = e_r x e_east.
//  - The lab "up" vector leans sideways (perpendicular to the line of sight, towards the west):
//        up = cos(tilt) z_G - sin(tilt) e_east,
//    so that angle(up, z_G) = tilt and the spin axis shows inclined in the image: its projection leans
//    towards image +x (right) by atan(tan(tilt) / cos(lat)) from the image's "up" (-y) direction
//    (25.1 deg for tilt 23 deg, latitude -25 deg), north pole up-right.
//  - Left optical frame: z_L = -e_r (looking at the centre), x_L = unit(z_L x up) (horizontal: x_L . up = 0,
//    no roll), y_L = z_L x x_L (points "down": y_L . up < 0).
//  - Spin: the globe turns by +rate about z_G relative to the rig (east-positive, like the Earth), so in G
//    the rig orbits by -rate t about z_G (westwards): T_G_L(t) = Rz(-rate t) T_G_L0. The world W is the left
//    optical frame at t = 0 and is fixed to the globe: T_W_L(t) = T_W_G Rz(-rate t) T_G_L0, T_W_G = T_G_L0^-1.
//  - Hence, in the rig frame, omega_L = -rate R_G_L0^T z_G and v_L = R_L_W dp_W/dt = -rate R_G_L0^T (z_G x c0)
//    = -rate distance cos(lat) R_G_L0^T e_east: both constant (the rig moves west: towards image -x, and +y by the
//    tilt).
//  - Rig (RigConfig::makeRig): K with fx = fy = focal_length / pixel_size, cx = (width - 1) / 2,
//    cy = (height - 1) / 2; in a rig frame at the baseline midpoint the left camera is turned +c/2 about y and
//    the right one -c/2 (design.h's convention), so R_left<-right = Ry(-c). `baseline` is the vector from the
//    left to the right optical centre in the midpoint (rig) frame, as in design.h; in the left optical frame
//    the right centre is Ry(-c/2) baseline (the two frames agree for c = 0).
//  - Randomness: a small portable generator (splitmix64-seeded xoshiro256**, Box-Muller normals), one stream
//    per purpose, keyed by a hash of (seed, purpose[, frame k, landmark id]): measure(k) is the same whatever
//    the call order, and a landmark's noise in frame k does not depend on which other landmarks are visible.

#include "../common/text.h"
#include "skin3d/sim/globe.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace skin3d {
namespace sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// ------------------------------------------------------------------------------------------- messages
using common::num;

std::string vec(const Eigen::Vector3d& v, double scale) {
  return "[" + num(v.x() * scale) + ", " + num(v.y() * scale) + ", " + num(v.z() * scale) + "]";
}

std::string list(const std::vector<double>& v) {
  std::string s = "[";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + num(v[i]);
  return s + "]";
}

[[noreturn]] void fail(const std::string& field, const std::string& value, const std::string& why) {
  throw SimConfigError(field, "field '" + field + "' = " + value + ": " + why);
}

/** Checks a (scaled) scalar: finite and `ok`. */
void check(bool ok, const std::string& field, double shown_value, const std::string& why) {
  if (!ok || !std::isfinite(shown_value)) fail(field, num(shown_value), why);
}

void validateRig(const RigConfig& r) {
  const double f_mm = r.focal_length * 1e3, pix_um = r.pixel_size * 1e6;
  check(r.focal_length > 0.0 && r.focal_length < 1.0, "rig.focal_length_mm", f_mm, "must be > 0 and < 1000 mm");
  check(r.pixel_size > 0.0 && r.pixel_size < 1e-3, "rig.pixel_size_um", pix_um, "must be > 0 and < 1000 um");
  check(r.width >= 1 && r.width <= 100000, "rig.width_px", r.width, "must be in [1, 100000]");
  check(r.height >= 1 && r.height <= 100000, "rig.height_px", r.height, "must be in [1, 100000]");
  if (!r.baseline.allFinite() || !(r.baseline.norm() > 1e-9) || !(r.baseline.norm() < 100.0))
    fail("rig.baseline_mm", vec(r.baseline, 1e3), "must be finite with a length in (0, 100 m)");
  check(std::abs(r.convergence) < kPi, "rig.convergence_deg", r.convergence / kDeg, "must be in (-180, 180)");
  if (!(r.distortion.empty() || r.distortion.size() == 4 || r.distortion.size() == 5))
    fail("rig.distortion", list(r.distortion), "plumb_bob takes 4 or 5 coefficients (k1 k2 p1 p2 [k3]), or none");
  for (double d : r.distortion)
    if (!std::isfinite(d)) fail("rig.distortion", list(r.distortion), "every coefficient must be finite");
}

// ------------------------------------------------------------------------------------------- randomness
inline std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

enum Stream : std::uint64_t { kLandmarks = 1, kDescriptors = 2, kLookalikes = 3, kMeasure = 4, kGyro = 5 };

std::uint64_t key(std::uint64_t seed, Stream stream, std::uint64_t a = 0, std::uint64_t b = 0) {
  std::uint64_t h = mix64(seed + 0x9e3779b97f4a7c15ULL);
  h = mix64(h ^ (static_cast<std::uint64_t>(stream) * 0xd1b54a32d192ed03ULL));
  h = mix64(h ^ (a + 0x632be59bd9b4e019ULL));
  h = mix64(h ^ (b + 0x8cb92ba72f3d8dd7ULL));
  return h;
}

/** xoshiro256** seeded by splitmix64; uniform doubles in (0, 1), normals by Box-Muller. Portable. */
class Rng {
 public:
  explicit Rng(std::uint64_t seed) {
    std::uint64_t x = seed;
    for (auto& si : s_) {
      x += 0x9e3779b97f4a7c15ULL;
      si = mix64(x);
    }
  }
  std::uint64_t next() {
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
  }
  double uniform() { return (static_cast<double>(next() >> 11) + 0.5) * 0x1.0p-53; }  // (0, 1)
  /** Uniform integer in [0, n). */
  std::uint64_t below(std::uint64_t n) { return static_cast<std::uint64_t>(uniform() * static_cast<double>(n)) % n; }
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double r = std::sqrt(-2.0 * std::log(uniform())), a = 2.0 * kPi * uniform();
    spare_ = r * std::sin(a);
    has_spare_ = true;
    return r * std::cos(a);
  }
  Eigen::Vector3d normal3() {
    const double x = normal(), y = normal(), z = normal();
    return Eigen::Vector3d(x, y, z);
  }

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::uint64_t s_[4];
  bool has_spare_ = false;
  double spare_ = 0.0;
};

/** Unit-norm float copy of d + sigma * N(0, I). */
std::vector<float> noisyDescriptor(const std::vector<float>& d, double sigma, Rng& rng) {
  std::vector<double> x(d.size());
  double n2 = 0.0;
  for (size_t i = 0; i < d.size(); ++i) {
    x[i] = d[i] + sigma * rng.normal();
    n2 += x[i] * x[i];
  }
  const double inv = n2 > 0.0 ? 1.0 / std::sqrt(n2) : 0.0;
  std::vector<float> out(d.size());
  for (size_t i = 0; i < d.size(); ++i) out[i] = static_cast<float>(x[i] * inv);
  return out;
}

// ------------------------------------------------------------------------------------------- visibility
/** What the cascade of visibility tests let through (for diagnostics of an impossible geometry). */
struct Counts {
  long front_left = 0;   // on the left camera's side of its tangent plane (s > 0)
  long front_both = 0;   // ... and of the right camera's
  long facing_both = 0;  // within max_incidence for both cameras
  long in_left = 0;      // ... in front of the left camera and inside its image
  long visible = 0;      // ... and in front of the right camera, inside its image
};

struct Candidate {
  int id;
  Eigen::Vector2d uv_left, uv_right;  // noise-free
};

/**
 * Landmarks visible to both cameras of the rig at pose T_W_L.
 *
 * Occlusion needs no test: on a sphere (convex), a surface point whose outward normal n has
 * n . (c - m) > 0 for a camera centre c outside the sphere is unoccluded, because the tangent plane
 * at m leaves the whole sphere on one side and the open segment from m to c on the other. The
 * incidence test (angle(n, c - m) <= max_incidence <= 90 deg) implies n . (c - m) > 0.
 */
std::vector<Candidate> findVisible(const GlobeConfig& c, const geometry::StereoRig& rig,
                                   const std::vector<Eigen::Vector3d>& landmarks, const Eigen::Vector3d& centre,
                                   const Eigen::Isometry3d& T_W_L, Counts* counts = nullptr) {
  const Eigen::Matrix3d R_L_W = T_W_L.linear().transpose();
  const Eigen::Vector3d c_left = T_W_L.translation();
  const Eigen::Vector3d c_right = T_W_L * rig.rightCentre();
  const double cos_max = std::cos(c.max_incidence), cos2 = cos_max * cos_max;
  const double inv_r = 1.0 / c.radius;
  // Cheap prune: n . (c - m) = n . (c - o) - r > 0 <=> (m - o) . (c - o) > r^2. One dot product each.
  const Eigen::Vector3d oL = c_left - centre, oR = c_right - centre;
  const double r2 = c.radius * c.radius;
  std::vector<Candidate> out;
  out.reserve(landmarks.size() / 8);
  for (size_t i = 0; i < landmarks.size(); ++i) {
    const Eigen::Vector3d a = landmarks[i] - centre;
    if (!(a.dot(oL) > r2)) continue;
    if (counts) ++counts->front_left;
    if (!(a.dot(oR) > r2)) continue;
    if (counts) ++counts->front_both;
    const Eigen::Vector3d n = a * inv_r;
    const Eigen::Vector3d dL = c_left - landmarks[i], dR = c_right - landmarks[i];
    const double sL = n.dot(dL), sR = n.dot(dR);  // > 0 here
    if (sL * sL < cos2 * dL.squaredNorm() || sR * sR < cos2 * dR.squaredNorm()) continue;
    if (counts) ++counts->facing_both;
    Candidate cand;
    cand.id = static_cast<int>(i);
    const Eigen::Vector3d X = R_L_W * (-dL);
    if (!(X.z() > 0.0)) continue;  // behind the left camera
    cand.uv_left = rig.left().project(X);
    if (!rig.left().inImage(cand.uv_left)) continue;
    if (counts) ++counts->in_left;
    const Eigen::Vector3d XR = rig.toRight(X);
    if (!(XR.z() > 0.0)) continue;  // behind the right camera
    cand.uv_right = rig.right().project(XR);
    if (!rig.right().inImage(cand.uv_right)) continue;
    if (counts) ++counts->visible;
    out.push_back(cand);
  }
  return out;
}

}  // namespace

// =========================================================================================== RigConfig
geometry::StereoRig RigConfig::makeRig() const {
  validateRig(*this);
  const double fpx = focal_length / pixel_size;
  Eigen::Matrix3d K;
  K << fpx, 0.0, 0.5 * (width - 1), 0.0, fpx, 0.5 * (height - 1), 0.0, 0.0, 1.0;
  try {
    const geometry::PinholeCamera cam(K, width, height, distortion);
    // Left turned +c/2, right -c/2 about y in the midpoint frame: R_left<-right = Ry(-c/2) Ry(-c/2); the
    // baseline is given in the midpoint frame, so the right centre in the left frame is Ry(-c/2) baseline.
    const Eigen::Matrix3d R_lr = Eigen::AngleAxisd(-convergence, Eigen::Vector3d::UnitY()).toRotationMatrix();
    const Eigen::Matrix3d R_left_rig = poseRigLeft().linear().transpose();
    return geometry::StereoRig::fromRightPose(cam, cam, R_lr, R_left_rig * baseline);
  } catch (const std::invalid_argument& e) {
    throw SimConfigError("rig", std::string("bad rig: ") + e.what());
  }
}

// =========================================================================================== GlobeConfig
void GlobeConfig::validate() const {
  check(radius > 0.0 && radius < 100.0, "globe.radius_mm", radius * 1e3, "must be > 0 (and < 100 m)");
  check(distance > 0.0 && distance < 1000.0, "globe.distance_mm", distance * 1e3, "must be > 0 (and < 1 km)");
  check(std::abs(latitude) < 0.5 * kPi, "globe.latitude_deg", latitude / kDeg, "must be in (-90, 90)");
  check(std::abs(tilt) < 0.5 * kPi, "globe.tilt_deg", tilt / kDeg, "must be in (-90, 90)");
  check(std::abs(rate) < 1e3, "globe.rate_rad_s", rate, "must be finite (|rate| < 1000 rad/s)");
  check(frames >= 1, "globe.frames", frames, "must be >= 1");
  check(fps > 0.0 && fps < 1e6, "globe.fps", fps, "must be > 0 (and < 1e6)");
  check(landmarks >= 1 && landmarks <= 1000000, "globe.landmarks", landmarks, "must be in [1, 1000000]");
  check(descriptor_size >= 2 && descriptor_size <= 4096, "globe.descriptor_size", descriptor_size,
        "must be in [2, 4096]");
  check(descriptor_noise >= 0.0 && descriptor_noise < 1e3, "globe.descriptor_noise", descriptor_noise,
        "must be >= 0 (per element of a unit-norm descriptor)");
  check(lookalike_fraction >= 0.0 && lookalike_fraction <= 0.5, "globe.lookalike_fraction", lookalike_fraction,
        "must be in [0, 0.5] (each look-alike copies its own original)");
  check(lookalike_distance > 0.0 && lookalike_distance <= 2.0, "globe.lookalike_distance", lookalike_distance,
        "must be in (0, 2] (distance between unit-norm descriptors)");
  check(pixel_sigma > 0.0 && pixel_sigma < 1e3, "globe.pixel_sigma_px", pixel_sigma, "must be > 0 (and < 1000 px)");
  check(max_incidence > 0.0 && max_incidence <= 0.5 * kPi, "globe.max_incidence_deg", max_incidence / kDeg,
        "must be in (0, 90]");
  check(gyro_rate > 0.0 && gyro_rate <= 1e5, "globe.gyro_rate_hz", gyro_rate, "must be in (0, 100000]");
  check(gyro_noise >= 0.0 && gyro_noise < 1e3, "globe.gyro_noise_rad_s", gyro_noise, "must be >= 0");
  if (!gyro_bias.allFinite() || !(gyro_bias.norm() < 1e3))
    fail("globe.gyro_bias_rad_s", vec(gyro_bias, 1.0), "must be finite (each |b| < 1000 rad/s)");
  check(gyro_bias_walk >= 0.0 && gyro_bias_walk < 1e3, "globe.gyro_bias_walk", gyro_bias_walk, "must be >= 0");
  validateRig(rig);
  // Sizes of what the simulator holds.
  const double gyro_samples = frames / fps * gyro_rate;
  check(gyro_samples <= 1e8, "globe.gyro_rate_hz", gyro_rate,
        "gives " + num(gyro_samples) + " gyroscope samples over the run (frames / fps); at most 1e8");
  // Geometry.
  if (!(distance > radius))
    fail("globe.distance_mm", num(distance * 1e3),
         "the camera must be outside the globe: distance must be > globe.radius_mm = " + num(radius * 1e3));
  const Eigen::Vector3d centre_L(0.0, 0.0, distance);  // the left camera looks at the centre
  const double right_to_centre = (rig.baseline - centre_L).norm();
  if (!(right_to_centre > radius))
    fail("rig.baseline_mm", vec(rig.baseline, 1e3),
         "puts the right camera inside the globe (" + num(right_to_centre * 1e3) + " mm from its centre, radius " +
             num(radius * 1e3) + " mm)");
}

// =========================================================================================== GlobeSimulator
GlobeSimulator::GlobeSimulator(const GlobeConfig& config) : config_(config) {
  config_.validate();
  rig_ = config_.rig.makeRig();
  const GlobeConfig& c = config_;

  // ---- geometry at t = 0 (see the conventions at the top of the file)
  const double phi = c.latitude, tau = c.tilt;
  const Eigen::Vector3d z_G = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d e_r(std::cos(phi), 0.0, std::sin(phi));
  const Eigen::Vector3d e_east = z_G.cross(e_r).normalized();  // (0, 1, 0)
  const Eigen::Vector3d up = std::cos(tau) * z_G - std::sin(tau) * e_east;
  const Eigen::Vector3d z_L = -e_r;
  const Eigen::Vector3d x_L = z_L.cross(up).normalized();  // |z_L x up| >= cos(lat) cos(tilt) > 0
  const Eigen::Vector3d y_L = z_L.cross(x_L);
  Eigen::Matrix3d R_G_L0;
  R_G_L0.col(0) = x_L;
  R_G_L0.col(1) = y_L;
  R_G_L0.col(2) = z_L;
  T_G_L0_ = Eigen::Isometry3d::Identity();
  T_G_L0_.linear() = R_G_L0;
  T_G_L0_.translation() = c.distance * e_r;
  T_W_G_ = T_G_L0_.inverse();

  // ---- landmarks: uniform on the sphere (isotropic Gaussian, normalised), fixed in G
  {
    Rng rng(key(c.seed, kLandmarks));
    landmarks_world_.resize(c.landmarks);
    for (int i = 0; i < c.landmarks; ++i) {
      Eigen::Vector3d g = rng.normal3();
      while (!(g.norm() > 1e-12)) g = rng.normal3();
      landmarks_world_[i] = T_W_G_ * (c.radius * g.normalized());
    }
  }
  // ---- descriptors: Gaussian, normalised
  {
    Rng rng(key(c.seed, kDescriptors));
    descriptors_.assign(c.landmarks, std::vector<float>());
    std::vector<double> x(c.descriptor_size);
    for (int i = 0; i < c.landmarks; ++i) {
      double n2 = 0.0;
      do {
        n2 = 0.0;
        for (auto& xi : x) {
          xi = rng.normal();
          n2 += xi * xi;
        }
      } while (!(n2 > 1e-24));
      const double inv = 1.0 / std::sqrt(n2);
      descriptors_[i].resize(c.descriptor_size);
      for (int j = 0; j < c.descriptor_size; ++j) descriptors_[i][j] = static_cast<float>(x[j] * inv);
    }
  }
  // ---- look-alikes: round(fraction * N) landmarks (the "copies") get a descriptor at exactly
  // lookalike_distance from that of their own original (a distinct, non-copy landmark). Unit vectors at
  // chord distance L make the angle 2 asin(L / 2): copy = cos(a) d + sin(a) u with u a random unit vector
  // orthogonal to d. So lookalike_fraction = number of look-alike pairs / landmarks.
  const int n_copies = static_cast<int>(std::lround(c.lookalike_fraction * c.landmarks));
  if (n_copies > 0) {
    Rng rng(key(c.seed, kLookalikes));
    std::vector<int> perm(c.landmarks);
    for (int i = 0; i < c.landmarks; ++i) perm[i] = i;
    for (int i = c.landmarks - 1; i > 0; --i) std::swap(perm[i], perm[rng.below(static_cast<std::uint64_t>(i) + 1)]);
    const double angle = 2.0 * std::asin(0.5 * c.lookalike_distance);
    const int D = c.descriptor_size;
    for (int j = 0; j < n_copies; ++j) {
      const int copy = perm[j], orig = perm[n_copies + j];  // n_copies <= N / 2: disjoint sets
      Eigen::VectorXd d(D), u(D);
      for (int e = 0; e < D; ++e) d[e] = descriptors_[orig][e];
      d.normalize();
      do {
        for (int e = 0; e < D; ++e) u[e] = rng.normal();
        u -= u.dot(d) * d;
      } while (!(u.norm() > 1e-9));
      u.normalize();
      const Eigen::VectorXd v = std::cos(angle) * d + std::sin(angle) * u;
      for (int e = 0; e < D; ++e) descriptors_[copy][e] = static_cast<float>(v[e]);
    }
  }

  // ---- is anything ever visible? Frames 0, 1/4, 1/2, 3/4 of the run.
  Counts counts;
  const int probes[4] = {0, c.frames / 4, c.frames / 2, (3 * c.frames) / 4};
  for (int k : probes) findVisible(c, rig_, landmarks_world_, sphereCentreWorld(), poseWorldLeft(stamp(k)), &counts);
  if (counts.visible == 0) {
    const std::string seen = " (frames 0, 1/4, 1/2, 3/4 of the run: " + std::to_string(counts.front_left) +
                             " landmark sightings on the left camera's side of the globe, " +
                             std::to_string(counts.front_both) + " on both cameras' side, " +
                             std::to_string(counts.facing_both) + " within max_incidence of both, " +
                             std::to_string(counts.in_left) + " of those in the left image, 0 in both)";
    if (counts.front_left == 0)
      fail("globe.landmarks", std::to_string(c.landmarks), "too few landmarks: none is ever visible" + seen);
    if (counts.front_both == 0)
      fail("rig.baseline_mm", vec(c.rig.baseline, 1e3),
           "the right camera never sees the side of the globe the left camera sees" + seen);
    if (counts.facing_both == 0)
      fail("globe.max_incidence_deg", num(c.max_incidence / kDeg),
           "no landmark ever faces both cameras within this angle" + seen);
    if (counts.in_left == 0)
      fail("rig.focal_length_mm", num(c.rig.focal_length * 1e3),
           "no landmark ever projects into the left image (field of view too narrow for the landmark density, or "
           "distortion)" +
               seen);
    if (c.rig.convergence != 0.0)
      fail("rig.convergence_deg", num(c.rig.convergence / kDeg),
           "the right camera never sees what the left one sees (it looks away)" + seen);
    fail("rig.baseline_mm", vec(c.rig.baseline, 1e3), "the right camera never sees what the left one sees" + seen);
  }
}

Eigen::Isometry3d GlobeSimulator::poseWorldLeft(double t) const {
  Eigen::Isometry3d Rz = Eigen::Isometry3d::Identity();
  Rz.linear() = Eigen::AngleAxisd(-config_.rate * t, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T_W_G_ * Rz * T_G_L0_;
}

Eigen::Vector3d GlobeSimulator::angularVelocity(double /*t*/) const {
  // R_W_L(t) = R_W_G Rz(-rate t) R_G_L0  =>  dR/dt = R_W_L [-rate R_G_L0^T z_G]x : constant in the rig frame.
  return -config_.rate * T_G_L0_.linear().transpose() * Eigen::Vector3d::UnitZ();
}

Eigen::Vector3d GlobeSimulator::linearVelocity(double /*t*/) const {
  // p_W(t) = R_W_G Rz(-rate t) c0 + t_W_G  =>  v_L = R_L_W dp/dt = R_G_L0^T (-rate z_G x c0).
  return T_G_L0_.linear().transpose() * (-config_.rate * Eigen::Vector3d::UnitZ().cross(T_G_L0_.translation()));
}

Eigen::Vector3d GlobeSimulator::sphereCentreWorld() const {
  return T_W_G_.translation();
}

std::vector<int> GlobeSimulator::visible(int k) const {
  const std::vector<Candidate> cands =
      findVisible(config_, rig_, landmarks_world_, sphereCentreWorld(), poseWorldLeft(stamp(k)));
  std::vector<int> ids;
  ids.reserve(cands.size());
  for (const auto& cand : cands) ids.push_back(cand.id);
  return ids;
}

std::vector<LandmarkMeasurement> GlobeSimulator::measure(int k) const {
  const GlobeConfig& c = config_;
  const std::vector<Candidate> cands =
      findVisible(c, rig_, landmarks_world_, sphereCentreWorld(), poseWorldLeft(stamp(k)));
  std::vector<LandmarkMeasurement> out;
  out.reserve(cands.size());
  for (const auto& cand : cands) {
    // One stream per (seed, frame, landmark), drawn in a fixed order: 4 pixel noises, the left-image
    // descriptor noise, the right-image descriptor noise.
    Rng rng(key(c.seed, kMeasure, static_cast<std::uint64_t>(static_cast<std::int64_t>(k)),
                static_cast<std::uint64_t>(cand.id)));
    LandmarkMeasurement m;
    m.id = cand.id;
    const double nl0 = rng.normal(), nl1 = rng.normal(), nr0 = rng.normal(), nr1 = rng.normal();
    m.uv_left = cand.uv_left + c.pixel_sigma * Eigen::Vector2d(nl0, nl1);
    m.uv_right = cand.uv_right + c.pixel_sigma * Eigen::Vector2d(nr0, nr1);
    const std::vector<float>& d = descriptors_[cand.id];
    m.descriptor = noisyDescriptor(d, c.descriptor_noise, rng);
    const std::vector<float> d_right = noisyDescriptor(d, c.descriptor_noise, rng);
    // A detector only reports what it sees: a feature pushed out of an image by the noise is lost.
    if (!rig_.left().inImage(m.uv_left) || !rig_.right().inImage(m.uv_right)) continue;
    const geometry::TriangulationResult tr = rig_.triangulate(m.uv_left, m.uv_right, c.pixel_sigma);
    if (!tr.ok || !tr.X.allFinite() || !tr.C.allFinite()) continue;
    m.position = tr.X;
    m.covariance = 0.5 * (tr.C + tr.C.transpose());
    // Match strength as a stereo matcher reports it: 1 - (distance between the left and the right image's
    // descriptor of the feature) / 2. Both are unit vectors, so the distance is in [0, 2]; it is clamped
    // into (0, 1]. Noise-free descriptors give 1; descriptor_noise sigma gives about 1 - sigma sqrt(D / 2).
    double dist2 = 0.0;
    for (size_t e = 0; e < d.size(); ++e) {
      const double diff = double(m.descriptor[e]) - double(d_right[e]);
      dist2 += diff * diff;
    }
    m.strength = static_cast<float>(std::clamp(1.0 - 0.5 * std::sqrt(dist2), 1e-6, 1.0));
    out.push_back(std::move(m));
  }
  return out;
}

std::vector<GyroSample> GlobeSimulator::gyro() const {
  const GlobeConfig& c = config_;
  const double T = c.frames / c.fps;  // samples at i / gyro_rate in [0, T)
  long n = static_cast<long>(std::ceil(T * c.gyro_rate));
  while (n > 0 && (n - 1) / c.gyro_rate >= T) --n;
  while (n / c.gyro_rate < T) ++n;
  std::vector<GyroSample> out(static_cast<size_t>(n));
  Rng rng(key(c.seed, kGyro));
  const double sqrt_dt = std::sqrt(1.0 / c.gyro_rate);
  Eigen::Vector3d bias = c.gyro_bias;
  for (long i = 0; i < n; ++i) {
    const double t = i / c.gyro_rate;
    const Eigen::Vector3d walk = rng.normal3(), noise = rng.normal3();  // always drawn: fixed stream layout
    if (i > 0) bias += c.gyro_bias_walk * sqrt_dt * walk;
    out[i].t = t;
    out[i].omega = angularVelocity(t) + bias + c.gyro_noise * noise;
  }
  return out;
}

}  // namespace sim
}  // namespace skin3d
