// SPDX-License-Identifier: BSD-3-Clause
// The skin scene: see include/skin3d/sim/skin.h for the model.
#include "skin3d/sim/skin.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "../common/text.h"

namespace skin3d {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
using common::num;

std::uint64_t hash64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
inline double unit(std::uint64_t h) { return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0); }
inline std::uint64_t cellHash(std::uint64_t seed, long long i, long long j, std::uint64_t salt) {
  return hash64(seed ^ hash64(static_cast<std::uint64_t>(i) * 0x8CB92BA72F3D8DD7ull ^
                              static_cast<std::uint64_t>(j) * 0xD6E8FEB86659FD93ull ^ salt));
}
inline double smooth01(double x) {
  const double t = std::clamp(x, 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}
inline double uniform(std::mt19937_64& rng, double a, double b) { return a + (b - a) * unit(rng()); }

/** Spots on a grid of `cell` m: in a fraction `p` of the cells a Gaussian spot (radius r0 ... r1, depth
 *  d0 ... d1) at a random place; returns the product of (1 - depth * exp(-d^2 / 2 r^2)) of the 3 x 3 cells around. */
double spots(std::uint64_t seed, std::uint64_t salt, double s, double t, double cell, double p, double r0, double r1,
             double d0, double d1) {
  const long long ci = static_cast<long long>(std::floor(s / cell)), cj = static_cast<long long>(std::floor(t / cell));
  double f = 1.0;
  for (long long i = ci - 1; i <= ci + 1; ++i)
    for (long long j = cj - 1; j <= cj + 1; ++j) {
      const std::uint64_t h = cellHash(seed, i, j, salt);
      if (unit(h) >= p) continue;
      const std::uint64_t h2 = hash64(h), h3 = hash64(h2), h4 = hash64(h3), h5 = hash64(h4);
      const double cx = (i + unit(h2)) * cell, cy = (j + unit(h3)) * cell;
      const double r = r0 + (r1 - r0) * unit(h4), depth = d0 + (d1 - d0) * unit(h5);
      const double d2 = (s - cx) * (s - cx) + (t - cy) * (t - cy);
      if (d2 < 16 * r * r) f *= 1.0 - depth * std::exp(-0.5 * d2 / (r * r));
    }
  return f;
}

}  // namespace

SkinScene::SkinScene(SkinGeometry g, std::uint64_t seed) : g_(std::move(g)), seed_(seed) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("SkinScene: " + what); };
  if (!(g_.semi_axis_y > 0) || !(g_.semi_axis_z > 0) || !std::isfinite(g_.semi_axis_y) || !std::isfinite(g_.semi_axis_z))
    bad("the limb's semi-axes must be > 0 (got " + num(g_.semi_axis_y) + ", " + num(g_.semi_axis_z) + " m)");
  if (!(g_.length > 0)) bad("the limb's length must be > 0");
  if (!(g_.contrast >= 0)) bad("contrast must be >= 0");
  const double rm = g_.meanRadius();
  for (std::size_t k = 0; k < g_.plaques.size(); ++k) {
    const SkinPlaque& p = g_.plaques[k];
    const std::string n = "plaques[" + std::to_string(k) + "]";
    if (!p.centre.allFinite()) bad(n + ".centre must be finite");
    if (!(p.radii.minCoeff() > 0) || !p.radii.allFinite()) bad(n + ".radii must be > 0");
    if (!(p.height > 0) || p.height > 0.01) bad(n + ".height must be in (0, 10] mm (got " + num(p.height * 1e3) + " mm)");
    if (!(p.ramp > 0) || p.ramp >= p.radii.minCoeff()) bad(n + ".ramp must be > 0 and smaller than the smaller radius");
    if (!(p.dome >= 0 && p.dome <= 1)) bad(n + ".dome must be in [0, 1]");
    if (!(p.irregularity >= 0 && p.irregularity < 0.5)) bad(n + ".irregularity must be in [0, 0.5)");
    if (std::fabs(p.centre.y() / rm) > 0.85 * kPi) bad(n + ".centre: more than 153 deg around the limb from the top");
    h_max_ = std::max(h_max_, p.height);
    std::mt19937_64 rng(hash64(seed ^ hash64(p.shape_seed + 77 * k)));
    Eigen::Vector3d amp, ph;
    double sum = 0;
    for (int m = 0; m < 3; ++m) {
      amp[m] = uniform(rng, 0.3, 1.0) / (m + 1);
      sum += amp[m];
      ph[m] = uniform(rng, 0, 2 * kPi);
    }
    harmonics_.push_back(amp * (p.irregularity / std::max(sum, 1e-12)));
    phases_.push_back(ph);
    const double reach = p.radii.maxCoeff() * (1 + p.irregularity) + 2e-3;
    boxes_.push_back({p.centre.x() - reach, p.centre.x() + reach, (p.centre.y() - reach) / rm, (p.centre.y() + reach) / rm});
  }
  double relief = 0;
  for (std::size_t k = 0; k < g_.ridges.size(); ++k) {
    const SkinRidge& r = g_.ridges[k];
    const std::string n = "ridges[" + std::to_string(k) + "]";
    if (!r.centre.allFinite() || !std::isfinite(r.orientation)) bad(n + ".centre and orientation must be finite");
    if (!(r.height > 0) || r.height > 0.01) bad(n + ".height must be in (0, 10] mm (got " + num(r.height * 1e3) + " mm)");
    if (!(r.width > 0) || r.width > 0.05) bad(n + ".width must be in (0, 50] mm");
    if (!(r.length > 0) || r.length > 1.0) bad(n + ".length must be in (0, 1000] mm");
    const double half = 0.5 * r.length + 4 * r.width;
    const double ds = std::fabs(std::cos(r.orientation)) * 0.5 * r.length + 4 * r.width;
    const double dt = std::fabs(std::sin(r.orientation)) * 0.5 * r.length + 4 * r.width;
    if (std::fabs(r.centre.y() / rm) + dt / rm > 0.49 * kPi || half <= 0)
      bad(n + ": reaches more than 88 deg around the limb from the top");
    relief_boxes_.push_back({r.centre.x() - ds, r.centre.x() + ds, (r.centre.y() - dt) / rm, (r.centre.y() + dt) / rm});
    relief += r.height;
  }
  h_max_ += relief;  // a plaque may sit on a ridge
}

double SkinScene::reliefAt(double s, double phi) const {
  double h = 0.0;
  const double t = g_.meanRadius() * phi;
  for (std::size_t k = 0; k < g_.ridges.size(); ++k) {
    const Box& b = relief_boxes_[k];
    if (s < b.s0 || s > b.s1 || phi < b.p0 || phi > b.p1) continue;
    const SkinRidge& r = g_.ridges[k];
    const double c = std::cos(r.orientation), sn = std::sin(r.orientation);
    const double du = s - r.centre.x(), dv = t - r.centre.y();
    const double along = c * du + sn * dv, across = -sn * du + c * dv;
    const double beyond = std::max(0.0, std::fabs(along) - 0.5 * r.length);  // the rounded ends
    const double d2 = across * across + beyond * beyond;
    h += r.height * std::exp(-0.5 * d2 / (r.width * r.width));
  }
  return h;
}

double SkinScene::profile(std::size_t k, double s, double phi) const {
  const SkinPlaque& p = g_.plaques[k];
  const double du = s - p.centre.x(), dv = g_.meanRadius() * phi - p.centre.y();
  const double c = std::cos(p.orientation), sn = std::sin(p.orientation);
  const double u = (c * du + sn * dv) / p.radii.x(), v = (-sn * du + c * dv) / p.radii.y();
  const double q0 = std::sqrt(u * u + v * v);
  const double psi = std::atan2(v, u);
  const Eigen::Vector3d& a = harmonics_[k];
  const Eigen::Vector3d& f = phases_[k];
  const double mod = 1.0 + a[0] * std::cos(2 * psi + f[0]) + a[1] * std::cos(3 * psi + f[1]) + a[2] * std::cos(4 * psi + f[2]);
  if (q0 >= mod) return 0.0;
  const double cp = std::cos(psi), sp = std::sin(psi);
  const double r_dir = std::sqrt(p.radii.x() * p.radii.x() * cp * cp + p.radii.y() * p.radii.y() * sp * sp);
  const double inside = (mod - q0) * r_dir;  // m, radial distance inside the outline
  const double q = q0 / mod;
  return p.height * smooth01(inside / p.ramp) * (1.0 - p.dome * q * q);
}

double SkinScene::heightAt(double s, double phi) const {
  double h = 0.0;
  plaqueAt(s, phi, &h);
  return h + (g_.ridges.empty() ? 0.0 : reliefAt(s, phi));
}

int SkinScene::plaqueAt(double s, double phi, double* height) const {
  int best = -1;
  double hb = 0.0;
  for (std::size_t k = 0; k < boxes_.size(); ++k) {
    const Box& b = boxes_[k];
    if (s < b.s0 || s > b.s1 || phi < b.p0 || phi > b.p1) continue;
    const double h = profile(k, s, phi);
    if (h > hb) {
      hb = h;
      best = static_cast<int>(k);
    }
  }
  if (height) *height = hb;
  return best;
}

Eigen::Vector2d SkinScene::surfaceCoordinates(const Eigen::Vector3d& x) const {
  return Eigen::Vector2d(x.x(), std::atan2(x.y() / g_.semi_axis_y, x.z() / g_.semi_axis_z));
}

Eigen::Vector3d SkinScene::surfacePoint(double s, double phi) const {
  const double a = g_.semi_axis_y, b = g_.semi_axis_z;
  const double r0 = std::hypot(a * std::sin(phi), b * std::cos(phi));
  const double k = 1.0 + heightAt(s, phi) / r0;
  return Eigen::Vector3d(s, k * a * std::sin(phi), k * b * std::cos(phi));
}

Eigen::Vector3d SkinScene::baseNormal(double phi) const {
  const double a = g_.semi_axis_y, b = g_.semi_axis_z;
  return Eigen::Vector3d(0.0, std::sin(phi) / a, std::cos(phi) / b).normalized();
}

double SkinScene::distanceToBase(const Eigen::Vector3d& x) const {
  const double a = g_.semi_axis_y, b = g_.semi_axis_z, py = x.y(), pz = x.z();
  double phi = std::atan2(py / a, pz / b);
  for (int it = 0; it < 30; ++it) {
    const double s = std::sin(phi), c = std::cos(phi);
    const double ey = a * s - py, ez = b * c - pz;
    const double f1 = ey * a * c - ez * b * s;
    const double f2 = a * a * c * c - ey * a * s + b * b * s * s - ez * b * c;
    if (!(std::fabs(f2) > 1e-300)) break;
    const double step = f1 / f2;
    phi -= std::clamp(step, -0.2, 0.2);
    if (std::fabs(step) < 1e-15) break;
  }
  const double d = std::hypot(a * std::sin(phi) - py, b * std::cos(phi) - pz);
  const double rho = std::hypot(py / a, pz / b);
  return rho >= 1.0 ? d : -d;
}

double SkinScene::G(const Eigen::Vector3d& x) const {
  const double a = g_.semi_axis_y, b = g_.semi_axis_z;
  const double ny = x.y() / a, nz = x.z() / b;
  const double rho = std::hypot(ny, nz);
  const double phi = std::atan2(ny, nz);
  const double r0 = std::hypot(a * std::sin(phi), b * std::cos(phi));
  return rho - 1.0 - heightAt(x.x(), phi) / r0;
}

bool SkinScene::intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Hit* hit) const {
  const double a = g_.semi_axis_y, b = g_.semi_axis_z;
  const double A = d.y() * d.y() / (a * a) + d.z() * d.z() / (b * b);
  if (!(A > 1e-18)) return false;  // parallel to the axis
  const double B = 2.0 * (o.y() * d.y() / (a * a) + o.z() * d.z() / (b * b));
  const double C0 = o.y() * o.y() / (a * a) + o.z() * o.z() / (b * b);
  auto enter = [&](double c, double* t0, double* t1) {
    const double disc = B * B - 4.0 * A * (C0 - c * c);
    if (disc < 0) return false;
    const double sq = std::sqrt(disc);
    *t0 = (-B - sq) / (2.0 * A);
    *t1 = (-B + sq) / (2.0 * A);
    return *t1 > 0;
  };
  const double c_out = 1.0 + 1.001 * h_max_ / std::min(a, b) + 1e-9;
  double to0, to1, tb0 = 0, tb1 = 0;
  if (!enter(c_out, &to0, &to1)) return false;
  to0 = std::max(to0, 0.0);
  const bool base = enter(1.0, &tb0, &tb1) && tb0 > 0;
  const double t_end = base ? tb0 : to1;
  auto finish = [&](double t, const Eigen::Vector3d& n) {
    const Eigen::Vector3d x = o + t * d;
    if (std::fabs(x.x()) > 0.5 * g_.length) return false;
    if (hit) {
      hit->distance = t;
      hit->point = x;
      hit->normal = n;
    }
    return true;
  };
  // near a plaque? (samples every 0.5 mm of the ray between the enclosing cylinder and the base)
  bool near = false;
  if (!boxes_.empty() || !relief_boxes_.empty()) {
    const int n = 1 + static_cast<int>(std::ceil((t_end - to0) / 0.5e-3));
    for (int i = 0; i <= n && !near; ++i) {
      const Eigen::Vector2d sc = surfaceCoordinates(o + (to0 + (t_end - to0) * i / n) * d);
      for (const std::vector<Box>* v : {&boxes_, &relief_boxes_})
        for (const Box& bx : *v)
          if (sc.x() >= bx.s0 && sc.x() <= bx.s1 && sc.y() >= bx.p0 && sc.y() <= bx.p1) near = true;
    }
  }
  if (!near) {
    if (!base) return false;
    const Eigen::Vector3d x = o + tb0 * d;
    return finish(tb0, baseNormal(surfaceCoordinates(x).y()));
  }
  // march to the first sign change of G, then bisect
  const double step = 0.1e-3;
  double t_prev = to0, t = to0;
  bool found = false;
  while (t < t_end) {
    t = std::min(t_end, t + step);
    if (G(o + t * d) <= 0) {
      found = true;
      break;
    }
    t_prev = t;
  }
  if (!found) {
    if (!base) return false;  // the march reached the base without a sign change (G = +0 there by rounding)
    const Eigen::Vector3d x = o + tb0 * d;
    return finish(tb0, baseNormal(surfaceCoordinates(x).y()));
  }
  double lo = t_prev, hi = t;
  for (int i = 0; i < 40 && hi - lo > 1e-10; ++i) {
    const double m = 0.5 * (lo + hi);
    (G(o + m * d) > 0 ? lo : hi) = m;
  }
  const double th = hi;
  const Eigen::Vector3d x = o + th * d;
  const double e = 1e-6;
  Eigen::Vector3d grad;
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d dx = Eigen::Vector3d::Zero();
    dx[k] = e;
    grad[k] = (G(x + dx) - G(x - dx)) / (2 * e);
  }
  if (!(grad.norm() > 0) || !grad.allFinite()) grad = baseNormal(surfaceCoordinates(x).y());
  return finish(th, grad.normalized());
}

float SkinScene::albedo(const Hit& hit) const {
  const Eigen::Vector2d sc = surfaceCoordinates(hit.point);
  const double s = sc.x(), t = g_.meanRadius() * sc.y(), c = g_.contrast;
  const std::uint64_t sd = seed_;
  const NoiseTexture mottle{8e-3, 3, 0.5, hash64(sd + 1)};
  const NoiseTexture fine{0.6e-3, 3, 0.6, hash64(sd + 2)};
  const NoiseTexture crease{1.5e-3, 2, 0.5, hash64(sd + 3)};
  const Eigen::Vector3d p(s, t, 0.123e-3);
  double v = 0.62;
  v *= 1.0 + c * 0.4 * (mottle.at(p) - 0.5);          // slow mottling, ~ 3 % std
  v *= 1.0 + c * 0.22 * (fine.at(p) - 0.5);            // micro-relief, ~ 2 % std
  const double r = std::fabs(crease.at(p) - 0.5);      // creases along the noise's mid-level lines
  v *= 1.0 - c * 0.05 * (1.0 - smooth01(r / 0.025));
  v *= spots(sd, 11, s, t, 0.5e-3, 0.4, 30e-6, 70e-6, 0.05 * c, 0.12 * c);   // pores
  v *= spots(sd, 12, s, t, 4e-3, 0.15, 0.4e-3, 1.2e-3, 0.03 * c, 0.07 * c);  // freckles
  double h = 0.0;
  const int k = plaqueAt(s, sc.y(), &h);
  if (k >= 0) {
    const double f = h / g_.plaques[static_cast<std::size_t>(k)].height;
    v *= 1.0 - 0.08 * std::min(1.0, 2.0 * f);  // erythema: a little darker
    if (g_.scale_texture && f > 0.5) {
      const NoiseTexture flakes{0.4e-3, 3, 0.6, hash64(sd + 4)};
      v *= 1.0 + c * 0.25 * smooth01((flakes.at(p) - 0.52) / 0.1) * smooth01((f - 0.5) / 0.3);  // silvery scale
    }
  }
  return static_cast<float>(std::clamp(v, 0.02, 0.98));
}

SkinPlaqueTruth SkinScene::plaqueTruth(std::size_t k, double step) const {
  if (k >= g_.plaques.size()) throw std::out_of_range("SkinScene::plaqueTruth: no plaque " + std::to_string(k));
  const SkinPlaque& p = g_.plaques[k];
  const double rm = g_.meanRadius(), a = g_.semi_axis_y, b = g_.semi_axis_z;
  const double reach = p.radii.maxCoeff() * (1 + p.irregularity) + step;
  SkinPlaqueTruth t;
  const double phic = p.centre.y() / rm;
  t.top_point = surfacePoint(p.centre.x(), phic);
  t.normal = baseNormal(phic);
  std::vector<std::pair<double, double>> cells;  // (distance, dA)
  // heights above the healthy skin around the plaque: a plaque on a ridge stands on the ridge's relief
  const bool relief = !g_.ridges.empty();
  double peak = distanceToBase(t.top_point) - (relief ? reliefAt(p.centre.x(), phic) : 0.0);
  Eigen::Vector3d cen = Eigen::Vector3d::Zero();
  const int n = static_cast<int>(std::ceil(reach / step));
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j) {
      const double s = p.centre.x() + i * step, phi = (p.centre.y() + j * step) / rm;
      if (profile(k, s, phi) <= 0) continue;
      const Eigen::Vector3d X = surfacePoint(s, phi);
      const double dist = distanceToBase(X) - (relief ? reliefAt(s, phi) : 0.0);
      const double dA = step * step / rm * std::hypot(a * std::cos(phi), b * std::sin(phi));
      cells.emplace_back(dist, dA);
      peak = std::max(peak, dist);
      t.footprint_area += dA;
      t.volume += dist * dA;
      cen += X * dA;
    }
  t.top_height = peak;
  for (const auto& [dist, dA] : cells) {
    if (dist >= 0.99 * peak) t.top_area += dA;
    if (dist >= 0.5 * peak) t.half_height_area += dA;
  }
  if (t.footprint_area > 0) {
    t.mean_height = t.volume / t.footprint_area;
    t.centroid = cen / t.footprint_area;
  }
  return t;
}

Eigen::Isometry3d skinRigPose(const SkinGeometry& g, double yaw, double tilt, double roll, double working_distance) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(kPi, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  const Eigen::Vector3d zaxis = R.col(2);  // from the rig towards the limb
  const Eigen::Vector2d u = Eigen::Vector2d(-zaxis.y(), -zaxis.z()).normalized();
  const double tc = 1.0 / std::hypot(u.x() / g.semi_axis_y, u.y() / g.semi_axis_z);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = Eigen::Vector3d(0.0, tc * u.x(), tc * u.y()) - working_distance * zaxis;
  return T;
}

SkinGeometry randomSkinGeometry(std::uint64_t seed, int count, double dome_max, double max_angle) {
  std::mt19937_64 rng(hash64(seed * 0x51ED27ull + 0x5EED));
  SkinGeometry g;
  g.semi_axis_y = uniform(rng, 0.030, 0.060);
  g.semi_axis_z = g.semi_axis_y * uniform(rng, 0.8, 1.0);
  const double rm = g.meanRadius();
  const double bounds[4] = {0.125e-3, 0.375e-3, 0.625e-3, 0.875e-3};
  for (int i = 0; i < count; ++i) {
    SkinPlaque p;
    for (int attempt = 0; attempt < 100; ++attempt) {
      p.height = i == 0 ? uniform(rng, 0.05e-3, 0.1e-3) : 0.1e-3 * std::exp(uniform(rng, 0.0, std::log(15.0)));
      bool clear = true;
      for (double bd : bounds) clear = clear && std::fabs(p.height - bd) >= 0.02e-3;
      if (clear) break;
    }
    p.ramp = uniform(rng, 0.5e-3, 1.5e-3);
    p.dome = dome_max > 0 ? uniform(rng, 0.0, dome_max) : 0.0;
    p.irregularity = uniform(rng, 0.05, 0.25);
    p.orientation = uniform(rng, 0, kPi);
    p.shape_seed = rng();
    bool placed = false;
    for (int attempt = 0; attempt < 500 && !placed; ++attempt) {
      p.radii = Eigen::Vector2d(uniform(rng, 4e-3, 9e-3), uniform(rng, 4e-3, 9e-3));
      p.centre = Eigen::Vector2d(uniform(rng, -0.04, 0.04), rm * uniform(rng, -1.0, 1.0) * max_angle);
      placed = true;
      for (const SkinPlaque& q : g.plaques) {
        const double need = (p.radii.maxCoeff() * (1 + p.irregularity) + q.radii.maxCoeff() * (1 + q.irregularity)) + 4e-3;
        if ((p.centre - q.centre).norm() < need) placed = false;
      }
    }
    if (!placed) throw std::runtime_error("randomSkinGeometry: cannot place " + std::to_string(count) + " plaques apart");
    g.plaques.push_back(p);
  }
  return g;
}

}  // namespace sim
}  // namespace skin3d
