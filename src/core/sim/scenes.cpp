// SPDX-License-Identifier: BSD-3-Clause
//
// The simulated test objects: the textured globe (SphereScene) and the validation workpiece
// (WorkpieceScene). Exact analytic ray intersection in double precision; albedo from a texture map that
// is precomputed (multithreaded) in the constructor and sampled bilinearly, so that the hot loop of the
// renderer does no noise evaluation.
//
// Globe map: equirectangular in the globe BODY frame, W x H = W x W/2 texels with W = 2 ceil(pi r / texel)
// (texel ~ `texel` m along the equator) capped at 8192 x 4096. Texel (row i, column j) is centred at
// latitude pi/2 - (i + 0.5) pi / H (north up) and longitude -pi + (j + 0.5) 2 pi / W. Bilinear lookup
// wraps in longitude and clamps in latitude (within half a texel of a pole the value is that of the
// nearest texel row: a blemish of < 1 texel at the poles). The texture is evaluated at the 3D surface
// point (body frame), so it is seamless and undistorted. Content (GlobeTexture): "continents" where a
// low-frequency fBm (150 ... 19 mm, perturbed by a 20 ... 1.3 mm "coast" fBm) exceeds 0.52 (smooth step):
// ocean albedo ~0.22, land ~0.62, both modulated by relief detail at 12 ... 0.75 mm and grain at 4 ... 1 mm.
//
// Workpiece map: nx x ny texels over the plate (nx = ceil(plate_x / texel), texel sizes plate / n), row i
// at y = -plate_y/2 + (i + 0.5) ty, column j at x = -plate_x/2 + (j + 0.5) tx; bilinear lookup clamps
// at the plate border. Content ("drawn random pattern"): paper of contrast-stretched fBm (3 ... 0.09 mm) with a
// slow 12 ... 3 mm shading, overdrawn with marker strokes (0.09 per mm^2: smooth random curves 1 ... 9 mm long,
// 0.06 ... 0.41 mm wide, ink darkness 0.55 ... 0.92, anti-aliased) and dots (0.06 per mm^2, 0.12 ... 0.5 mm),
// all generated from the seed. Plateau walls take the texture at their (x, y).

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "../common/text.h"
#include "skin3d/sim/render.h"

namespace skin3d {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

using common::num;

/** Runs f(r0, r1) over [0, rows) in chunks of `chunk` rows on hardware_concurrency() threads. */
template <typename F>
void parallelRows(int rows, int chunk, F&& f) {
  const int hw = static_cast<int>(std::thread::hardware_concurrency());
  const int n = std::max(1, std::min(hw > 0 ? hw : 1, (rows + chunk - 1) / chunk));
  std::atomic<int> next{0};
  auto work = [&]() {
    for (;;) {
      const int r0 = next.fetch_add(chunk);
      if (r0 >= rows) return;
      f(r0, std::min(rows, r0 + chunk));
    }
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < n; ++i) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
}

/** atan(x) for x >= 0 (Cephes' rational approximation, |error| < 1e-15; cheaper than std::atan2 here). */
inline double atanPositive(double x) {
  constexpr double P0 = -8.750608600031904122785E-1, P1 = -1.615753718733365076637E1, P2 = -7.500855792314704667340E1,
                   P3 = -1.228866684490136173410E2, P4 = -6.485021904942025371773E1;
  constexpr double Q0 = 2.485846490142306297962E1, Q1 = 1.650270098316988542046E2, Q2 = 4.328810604912902668951E2,
                   Q3 = 4.853903996359136964868E2, Q4 = 1.945506571482613964425E2;
  constexpr double kMoreBits = 6.123233995736765886130E-17;
  double y = 0.0, extra = 0.0;
  if (x > 2.41421356237309504880) {
    y = 0.5 * kPi;
    extra = kMoreBits;
    x = -1.0 / x;
  } else if (x > 0.66) {
    y = 0.25 * kPi;
    extra = 0.5 * kMoreBits;
    x = (x - 1.0) / (x + 1.0);
  }
  const double z = x * x;
  const double p = (((P0 * z + P1) * z + P2) * z + P3) * z + P4;
  const double q = ((((z + Q0) * z + Q1) * z + Q2) * z + Q3) * z + Q4;
  return y + (x * (z * p / q) + x + extra);
}

/** atan2(y, x) in [-pi, pi] from atanPositive (agrees with std::atan2 to < 1e-15). */
inline double fastAtan2(double y, double x) {
  const double ax = std::abs(x), ay = std::abs(y);
  double a;
  if (ax >= ay) {
    a = ax > 0.0 ? atanPositive(ay / ax) : 0.0;
  } else {
    a = 0.5 * kPi - atanPositive(ax / ay);
  }
  if (x < 0.0) a = kPi - a;
  return y < 0.0 ? -a : a;
}

inline double smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

std::uint64_t mix(std::uint64_t seed, std::uint64_t salt) {
  std::uint64_t x = seed ^ (salt * 0x9E3779B97F4A7C15ull);
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// ------------------------------------------------------------------------------------------ globe

/** The globe's procedural albedo at a body-frame surface point (m). */
struct GlobeTexture {
  NoiseTexture continents, coast, detail, fine;
  explicit GlobeTexture(std::uint64_t seed) {
    continents = NoiseTexture{0.15, 4, 0.5, mix(seed, 1)};  // continents: 150 mm ... 19 mm
    coast = NoiseTexture{0.02, 5, 0.6, mix(seed, 2)};       // fractal coast lines: 20 mm ... 1.3 mm
    detail = NoiseTexture{0.012, 5, 0.7, mix(seed, 3)};     // relief / vegetation: 12 mm ... 0.75 mm
    fine = NoiseTexture{0.004, 3, 0.7, mix(seed, 4)};       // fine grain: 4 mm ... 1 mm
  }
  float operator()(const Eigen::Vector3d& q) const {
    // Land where the low-frequency noise plus a fractal coast perturbation exceeds ~0.52.
    const double c = continents.at(q) + 0.35 * (coast.at(q) - 0.5);
    const double land = smoothstep(0.515, 0.525, c);
    const double d = detail.at(q) - 0.5;
    const double f = fine.at(q) - 0.5;
    const double ocean_v = 0.22 + 1.1 * d + 0.6 * f;
    const double land_v = 0.62 + 1.8 * d + 0.9 * f;
    const double v = ocean_v + land * (land_v - ocean_v);
    return static_cast<float>(std::clamp(v, 0.02, 0.98));
  }
};

// ------------------------------------------------------------------------------------------ workpiece

/** A marker stroke: a polyline (plate x, y in m) drawn with a round pen of `width`, ink `darkness`. */
struct Stroke {
  std::vector<Eigen::Vector2d> pts;
  double width = 0.0;
  double darkness = 0.0;
  double ymin = 0.0, ymax = 0.0;  // bounding rows in metres, including the pen radius
};

/** Uniform in [0, 1) from 53 bits (std:: distributions are implementation-defined). */
inline double uniform01(std::mt19937_64& rng) {
  return static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);
}
inline double uniform(std::mt19937_64& rng, double a, double b) {
  return a + (b - a) * uniform01(rng);
}
inline double gauss(std::mt19937_64& rng) {
  const double u1 = 1.0 - uniform01(rng), u2 = uniform01(rng);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
}

std::vector<Stroke> makeStrokes(const Eigen::Vector2d& plate, std::uint64_t seed) {
  std::mt19937_64 rng(mix(seed, 11));
  const double margin = 0.004;
  const double area_mm2 = (plate.x() + 2 * margin) * (plate.y() + 2 * margin) * 1e6;
  const int n_strokes = static_cast<int>(std::lround(0.09 * area_mm2));
  const int n_dots = static_cast<int>(std::lround(0.06 * area_mm2));
  std::vector<Stroke> strokes;
  strokes.reserve(n_strokes + n_dots);
  const double ds = 0.08e-3;  // polyline step
  for (int s = 0; s < n_strokes + n_dots; ++s) {
    Stroke st;
    Eigen::Vector2d p(uniform(rng, -plate.x() / 2 - margin, plate.x() / 2 + margin),
                      uniform(rng, -plate.y() / 2 - margin, plate.y() / 2 + margin));
    const bool dot = s >= n_strokes;
    st.width = dot ? uniform(rng, 0.12e-3, 0.5e-3) : 0.06e-3 + 0.35e-3 * std::pow(uniform01(rng), 1.5);
    st.darkness = uniform(rng, 0.55, 0.92);
    const double length = dot ? 0.0 : uniform(rng, 1.0e-3, 9.0e-3);
    double heading = uniform(rng, 0.0, 2.0 * kPi);
    double curvature = gauss(rng) * 250.0;  // 1/m: radius ~ 4 mm
    st.pts.push_back(p);
    const int steps = static_cast<int>(std::ceil(length / ds));
    for (int k = 0; k < steps; ++k) {
      curvature += gauss(rng) * 60.0;
      curvature = std::clamp(curvature, -1500.0, 1500.0);
      heading += curvature * ds;
      p += ds * Eigen::Vector2d(std::cos(heading), std::sin(heading));
      st.pts.push_back(p);
    }
    st.ymin = std::numeric_limits<double>::infinity();
    st.ymax = -st.ymin;
    for (const auto& q : st.pts) {
      st.ymin = std::min(st.ymin, q.y() - st.width);
      st.ymax = std::max(st.ymax, q.y() + st.width);
    }
    strokes.push_back(std::move(st));
  }
  return strokes;
}

/** Distance from point p to the segment a-b. */
inline double segmentDistance(double px, double py, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const double dx = b.x() - a.x(), dy = b.y() - a.y();
  const double l2 = dx * dx + dy * dy;
  double t = l2 > 0.0 ? ((px - a.x()) * dx + (py - a.y()) * dy) / l2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double ex = px - a.x() - t * dx, ey = py - a.y() - t * dy;
  return std::sqrt(ex * ex + ey * ey);
}

/** Nearest hit of a ray with a plateau box [x0,x1] x [y0,y1] x [0,h] through its top or a side face. */
bool boxHit(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const double lo[3], const double hi[3], double* t,
            int* axis) {
  double tmin = -std::numeric_limits<double>::infinity();
  double tmax = std::numeric_limits<double>::infinity();
  int ax = -1;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    const double t1 = (lo[a] - o[a]) / d[a];
    const double t2 = (hi[a] - o[a]) / d[a];
    const double tn = std::min(t1, t2), tf = std::max(t1, t2);
    if (tn > tmin) {
      tmin = tn;
      ax = a;
    }
    tmax = std::min(tmax, tf);
  }
  if (ax < 0 || tmin > tmax || !(tmin > 0.0)) return false;
  if (ax == 2 && d.z() > 0.0) return false;  // bottom face: lies on the plate, which the plate test handles
  *t = tmin;
  *axis = ax;
  return true;
}

}  // namespace

// ============================================================================================ SphereScene

SphereScene::SphereScene(const Eigen::Vector3d& centre, double radius, std::uint64_t seed, double texel)
    : centre_(centre), radius_(radius) {
  if (!centre.allFinite()) throw std::invalid_argument("SphereScene: centre must be finite");
  if (!(radius > 0.0) || !std::isfinite(radius)) {
    throw std::invalid_argument("SphereScene: radius must be > 0 (got " + num(radius) + ")");
  }
  if (!(texel > 0.0) || !std::isfinite(texel)) {
    throw std::invalid_argument("SphereScene: texel must be > 0 (got " + num(texel) + ")");
  }
  const double half = std::ceil(kPi * radius / texel);
  const int W = static_cast<int>(std::clamp(2.0 * half, 16.0, 8192.0));
  const int H = W / 2;
  map_.create(H, W, CV_32F);
  const GlobeTexture tex(seed);
  // Longitude tables once (cos, sin per column).
  std::vector<double> clon(W), slon(W);
  for (int j = 0; j < W; ++j) {
    const double lon = -kPi + (j + 0.5) * 2.0 * kPi / W;
    clon[j] = std::cos(lon);
    slon[j] = std::sin(lon);
  }
  parallelRows(H, 8, [&](int r0, int r1) {
    for (int i = r0; i < r1; ++i) {
      const double lat = kPi / 2 - (i + 0.5) * kPi / H;
      const double cl = std::cos(lat), sl = std::sin(lat);
      float* row = map_.ptr<float>(i);
      for (int j = 0; j < W; ++j) {
        row[j] = tex(Eigen::Vector3d(radius * cl * clon[j], radius * cl * slon[j], radius * sl));
      }
    }
  });
}

bool SphereScene::intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* hit) const {
  const Eigen::Vector3d oc = origin - centre_;
  const double b = oc.dot(dir);
  const double c = oc.squaredNorm() - radius_ * radius_;
  const double disc = b * b - c;
  if (disc < 0.0) return false;
  // Numerically stable roots of t^2 + 2 b t + c = 0 (dir is unit).
  const double q = -b - std::copysign(std::sqrt(disc), b);
  double t0 = q, t1 = q != 0.0 ? c / q : 0.0;
  if (t0 > t1) std::swap(t0, t1);
  const double t = t0 > 0.0 ? t0 : t1;
  if (!(t > 0.0)) return false;
  if (hit) {
    hit->distance = t;
    hit->point = origin + t * dir;
    hit->normal = (hit->point - centre_) / radius_;
  }
  return true;
}

float SphereScene::albedo(const Hit& hit) const {
  const Eigen::Vector3d q = R_world_body_.transpose() * (hit.point - centre_);
  const int W = map_.cols, H = map_.rows;
  const double lon = fastAtan2(q.y(), q.x());
  const double lat = fastAtan2(q.z(), std::sqrt(q.x() * q.x() + q.y() * q.y()));
  const double fx = (lon + kPi) * (W / (2.0 * kPi)) - 0.5;
  const double fy = (kPi / 2 - lat) * (H / kPi) - 0.5;
  const double x0 = std::floor(fx), y0 = std::floor(fy);
  const float ax = static_cast<float>(fx - x0), ay = static_cast<float>(fy - y0);
  int j0 = static_cast<int>(x0), i0 = static_cast<int>(y0);
  int j1 = j0 + 1, i1 = i0 + 1;
  if (j0 < 0) j0 += W;
  if (j1 >= W) j1 -= W;
  if (j0 >= W) j0 -= W;
  i0 = std::clamp(i0, 0, H - 1);
  i1 = std::clamp(i1, 0, H - 1);
  const float* r0 = map_.ptr<float>(i0);
  const float* r1 = map_.ptr<float>(i1);
  const float top = r0[j0] + ax * (r0[j1] - r0[j0]);
  const float bot = r1[j0] + ax * (r1[j1] - r1[j0]);
  return top + ay * (bot - top);
}

// ============================================================================================ WorkpieceScene

WorkpieceScene::WorkpieceScene(const Eigen::Vector2d& plate_size, std::vector<Plateau> plateaus, std::uint64_t seed,
                               double texel)
    : plate_size_(plate_size), plateaus_(std::move(plateaus)), texel_(texel) {
  if (!(plate_size.x() > 0.0) || !(plate_size.y() > 0.0) || !plate_size.allFinite()) {
    throw std::invalid_argument("WorkpieceScene: plate_size must be > 0 (got " + num(plate_size.x()) + " x " +
                                num(plate_size.y()) + ")");
  }
  if (!(texel > 0.0) || !std::isfinite(texel)) {
    throw std::invalid_argument("WorkpieceScene: texel must be > 0 (got " + num(texel) + ")");
  }
  for (std::size_t k = 0; k < plateaus_.size(); ++k) {
    const Plateau& p = plateaus_[k];
    const std::string name = "WorkpieceScene: plateaus[" + std::to_string(k) + "]";
    if (!p.centre.allFinite()) throw std::invalid_argument(name + ".centre must be finite");
    if (!(p.size.x() > 0.0) || !(p.size.y() > 0.0) || !p.size.allFinite()) {
      throw std::invalid_argument(name + ".size must be > 0 (got " + num(p.size.x()) + " x " + num(p.size.y()) + ")");
    }
    if (!(p.height >= 0.0) || !std::isfinite(p.height)) {
      throw std::invalid_argument(name + ".height must be >= 0 (got " + num(p.height) + ")");
    }
  }
  const double nxd = std::ceil(plate_size.x() / texel - 1e-9), nyd = std::ceil(plate_size.y() / texel - 1e-9);
  if (nxd * nyd > static_cast<double>(1 << 28)) {
    throw std::invalid_argument("WorkpieceScene: texel " + num(texel) + " m over a plate of " + num(plate_size.x()) +
                                " x " + num(plate_size.y()) + " m needs more than 2^28 texels (1 GiB)");
  }
  const int nx = std::max(1, static_cast<int>(nxd)), ny = std::max(1, static_cast<int>(nyd));
  const double tx = plate_size.x() / nx, ty = plate_size.y() / ny;
  map_.create(ny, nx, CV_32F);

  const NoiseTexture base{3e-3, 6, 0.8, mix(seed, 21)};     // 3 mm ... 0.09 mm
  const NoiseTexture blotch{12e-3, 3, 0.5, mix(seed, 22)};  // slow shading of the paper, 12 ... 3 mm
  const std::vector<Stroke> strokes = makeStrokes(plate_size, seed);
  const double x_min = -plate_size.x() / 2, y_min = -plate_size.y() / 2;
  const double aa = 0.5 * std::max(tx, ty);  // half width of the anti-aliased pen edge

  parallelRows(ny, 32, [&](int r0, int r1) {
    std::vector<float> ink(static_cast<std::size_t>(r1 - r0) * nx, 0.0f);
    const double cy0 = y_min + (r0 + 0.5) * ty, cy1 = y_min + (r1 - 0.5) * ty;
    for (const Stroke& st : strokes) {
      if (st.ymax < cy0 || st.ymin > cy1) continue;
      const double reach = 0.5 * st.width + aa;
      for (std::size_t k = 0; k < st.pts.size(); ++k) {
        const Eigen::Vector2d& a = st.pts[k];
        const Eigen::Vector2d& b = st.pts[std::min(k + 1, st.pts.size() - 1)];
        if (k + 1 == st.pts.size() && st.pts.size() > 1) break;
        const double sx0 = std::min(a.x(), b.x()) - reach, sx1 = std::max(a.x(), b.x()) + reach;
        const double sy0 = std::min(a.y(), b.y()) - reach, sy1 = std::max(a.y(), b.y()) + reach;
        const int j0 = std::max(0, static_cast<int>(std::ceil((sx0 - x_min) / tx - 0.5)));
        const int j1 = std::min(nx - 1, static_cast<int>(std::floor((sx1 - x_min) / tx - 0.5)));
        const int i0 = std::max(r0, static_cast<int>(std::ceil((sy0 - y_min) / ty - 0.5)));
        const int i1 = std::min(r1 - 1, static_cast<int>(std::floor((sy1 - y_min) / ty - 0.5)));
        for (int i = i0; i <= i1; ++i) {
          const double y = y_min + (i + 0.5) * ty;
          float* row = ink.data() + static_cast<std::size_t>(i - r0) * nx;
          for (int j = j0; j <= j1; ++j) {
            const double x = x_min + (j + 0.5) * tx;
            const double dist = segmentDistance(x, y, a, b);
            const double cover = std::clamp(0.5 + (0.5 * st.width - dist) / (2.0 * aa), 0.0, 1.0);
            row[j] = std::max(row[j], static_cast<float>(cover * st.darkness));
          }
        }
      }
    }
    for (int i = r0; i < r1; ++i) {
      const double y = y_min + (i + 0.5) * ty;
      float* out = map_.ptr<float>(i);
      const float* ink_row = ink.data() + static_cast<std::size_t>(i - r0) * nx;
      for (int j = 0; j < nx; ++j) {
        const Eigen::Vector3d p(x_min + (j + 0.5) * tx, y, 0.0);
        const double paper = 0.55 + 2.4 * (base.at(p) - 0.5) + 0.5 * (blotch.at(p) - 0.5);
        out[j] = static_cast<float>(std::clamp(paper, 0.1, 0.95) * (1.0 - ink_row[j]));
      }
    }
  });
}

double WorkpieceScene::heightAt(const Eigen::Vector2d& xy) const {
  double h = 0.0;
  for (const Plateau& p : plateaus_) {
    if (std::abs(xy.x() - p.centre.x()) <= 0.5 * p.size.x() && std::abs(xy.y() - p.centre.y()) <= 0.5 * p.size.y()) {
      h = std::max(h, p.height);
    }
  }
  return h;
}

bool WorkpieceScene::intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, Hit* hit) const {
  double best_t = std::numeric_limits<double>::infinity();
  Eigen::Vector3d best_n = Eigen::Vector3d::UnitZ();
  bool found = false;

  // The plate: z = 0 within its extent, unless the point is inside a plateau's footprint (seen from above,
  // the plateau is then in front of it).
  int covering = -1;
  double t_plate = std::numeric_limits<double>::infinity();
  if (dir.z() != 0.0) {
    const double t = -origin.z() / dir.z();
    if (t > 0.0) {
      const double x = origin.x() + t * dir.x(), y = origin.y() + t * dir.y();
      if (std::abs(x) <= 0.5 * plate_size_.x() && std::abs(y) <= 0.5 * plate_size_.y()) {
        if (origin.z() > 0.0) {
          for (std::size_t k = 0; k < plateaus_.size() && covering < 0; ++k) {
            const Plateau& p = plateaus_[k];
            if (std::abs(x - p.centre.x()) < 0.5 * p.size.x() && std::abs(y - p.centre.y()) < 0.5 * p.size.y()) {
              covering = static_cast<int>(k);
            }
          }
        }
        if (covering < 0) {
          best_t = t;
          found = true;
        }
        t_plate = t;
      }
    }
  }

  // The plateau boxes: top and side faces.
  bool covering_hit = false;
  for (std::size_t k = 0; k < plateaus_.size(); ++k) {
    const Plateau& p = plateaus_[k];
    const double lo[3] = {p.centre.x() - 0.5 * p.size.x(), p.centre.y() - 0.5 * p.size.y(), 0.0};
    const double hi[3] = {p.centre.x() + 0.5 * p.size.x(), p.centre.y() + 0.5 * p.size.y(), p.height};
    double t;
    int axis;
    bool ok = boxHit(origin, dir, lo, hi, &t, &axis);
    if (static_cast<int>(k) == covering) {
      if (!ok || t > t_plate) {
        // Rounding at a footprint border: the ray provably enters this box before the plate; take the entry
        // through the slab that is entered last.
        t = -std::numeric_limits<double>::infinity();
        axis = 2;
        for (int a = 0; a < 3; ++a) {
          if (dir[a] == 0.0) continue;
          const double tn = std::min((lo[a] - origin[a]) / dir[a], (hi[a] - origin[a]) / dir[a]);
          if (tn > t) {
            t = tn;
            axis = a;
          }
        }
        t = std::min(t, t_plate);
        ok = t > 0.0;
      }
      covering_hit = ok;
    }
    if (ok && t < best_t) {
      best_t = t;
      best_n = Eigen::Vector3d::Zero();
      best_n[axis] = dir[axis] > 0.0 ? -1.0 : 1.0;
      found = true;
    }
  }
  if (covering >= 0 && !covering_hit && !found) {
    best_t = t_plate;  // degenerate (zero-length ray part in the box): fall back to the plate point
    found = true;
  }
  if (!found) return false;
  if (hit) {
    hit->distance = best_t;
    hit->point = origin + best_t * dir;
    hit->normal = best_n;
  }
  return true;
}

float WorkpieceScene::albedo(const Hit& hit) const {
  const int nx = map_.cols, ny = map_.rows;
  const double fx = (hit.point.x() + 0.5 * plate_size_.x()) * (nx / plate_size_.x()) - 0.5;
  const double fy = (hit.point.y() + 0.5 * plate_size_.y()) * (ny / plate_size_.y()) - 0.5;
  const double cx = std::clamp(fx, 0.0, nx - 1.0), cy = std::clamp(fy, 0.0, ny - 1.0);
  const int j0 = std::min(static_cast<int>(cx), nx - 1), i0 = std::min(static_cast<int>(cy), ny - 1);
  const int j1 = std::min(j0 + 1, nx - 1), i1 = std::min(i0 + 1, ny - 1);
  const float ax = static_cast<float>(cx - j0), ay = static_cast<float>(cy - i0);
  const float* r0 = map_.ptr<float>(i0);
  const float* r1 = map_.ptr<float>(i1);
  const float top = r0[j0] + ax * (r0[j1] - r0[j0]);
  const float bot = r1[j0] + ax * (r1[j1] - r1[j0]);
  return top + ay * (bot - top);
}

}  // namespace sim
}  // namespace skin3d
