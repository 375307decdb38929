// SPDX-License-Identifier: BSD-3-Clause
//
// NoiseTexture: fractal Brownian motion (fBm) of Ken Perlin's "improved" 3D gradient noise (2002:
// quintic fade 6t^5 - 15t^4 + 10t^3, the 12 cube-edge gradients picked by hash & 15), deterministic in
// the seed through a seeded permutation table.
//
// Definition (what NoiseTexture::at computes):
//   value(p) = 0.5 + 0.5 * sum_k a_k n(p / s_k + o_k) / sum_k a_k,   k = 0 .. octaves-1,
//   s_k = scale / 2^k (lattice spacing of octave k, m), a_k = persistence^k,
//   n = improved Perlin noise (|n| <= ~1) over a lattice hashed with a permutation of 0..4095 that is a
//   Fisher-Yates shuffle driven by std::mt19937_64(seed), o_k a per-octave lattice offset in [0, 4096)^3
//   from splitmix64(seed, k) (so that the octaves are decorrelated and the origin is not a zero of all of
//   them). The noise is periodic with 4096 lattice cells per axis (4096 * s_k), far beyond any object.
// octaves must be in [1, 32], scale > 0. The result is always in [0, 1] and has mean 0.5; one octave has a
// standard deviation of about 0.13 (range ~[0.03, 0.97]), 4-8 octaves about 0.06-0.08 (range ~[0.2, 0.8]),
// so callers stretch the contrast as they need.

#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>

#include "skin3d/sim/render.h"

namespace skin3d {
namespace sim {
namespace {

constexpr int kPermBits = 12;
constexpr int kPermSize = 1 << kPermBits;  // 4096 lattice cells per period
constexpr int kPermMask = kPermSize - 1;
constexpr int kMaxOctaves = 32;  // keeps p / s_k far inside int64 for any sane p

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

/** Permutation table (doubled, as in Perlin's reference code) and octave offsets of one seed. */
struct NoiseTables {
  std::uint64_t seed = 0;
  std::array<std::uint16_t, 2 * kPermSize> perm{};
  std::array<std::array<double, 3>, kMaxOctaves> offset{};

  explicit NoiseTables(std::uint64_t s) : seed(s) {
    for (int i = 0; i < kPermSize; ++i) perm[i] = static_cast<std::uint16_t>(i);
    // Own Fisher-Yates (std::shuffle / uniform_int_distribution are implementation-defined).
    std::mt19937_64 rng(s);
    for (int i = kPermSize - 1; i > 0; --i) {
      const int j = static_cast<int>(rng() % static_cast<std::uint64_t>(i + 1));
      std::swap(perm[i], perm[j]);
    }
    for (int i = 0; i < kPermSize; ++i) perm[kPermSize + i] = perm[i];
    for (int k = 0; k < kMaxOctaves; ++k) {
      for (int a = 0; a < 3; ++a) {
        const std::uint64_t h = splitmix64(s * 0x2545F4914F6CDD1Dull + static_cast<std::uint64_t>(3 * k + a));
        offset[k][a] = static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0) * kPermSize;
      }
    }
  }
};

/** Small per-thread cache of tables (a scene uses a handful of seeds, interleaved per texel). */
const NoiseTables& tablesFor(std::uint64_t seed) {
  constexpr int kSlots = 8;
  thread_local std::array<std::unique_ptr<NoiseTables>, kSlots> cache;
  thread_local int next = 0;
  for (const auto& t : cache) {
    if (t && t->seed == seed) return *t;
  }
  auto& slot = cache[next];
  next = (next + 1) % kSlots;
  slot = std::make_unique<NoiseTables>(seed);
  return *slot;
}

inline double fade(double t) {
  return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}
inline double lerp(double t, double a, double b) {
  return a + t * (b - a);
}
inline double grad(int hash, double x, double y, double z) {
  const int h = hash & 15;
  const double u = h < 8 ? x : y;
  const double v = h < 4 ? y : (h == 12 || h == 14 ? x : z);
  return ((h & 1) == 0 ? u : -u) + ((h & 2) == 0 ? v : -v);
}

/** Improved Perlin noise at lattice coordinates (x, y, z), in about [-1, 1]. */
double perlin(const std::uint16_t* p, double x, double y, double z) {
  const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  const int X = static_cast<int>(static_cast<std::int64_t>(fx) & kPermMask);
  const int Y = static_cast<int>(static_cast<std::int64_t>(fy) & kPermMask);
  const int Z = static_cast<int>(static_cast<std::int64_t>(fz) & kPermMask);
  x -= fx;
  y -= fy;
  z -= fz;
  const double u = fade(x), v = fade(y), w = fade(z);
  const int A = p[X] + Y, AA = p[A] + Z, AB = p[A + 1] + Z;
  const int B = p[X + 1] + Y, BA = p[B] + Z, BB = p[B + 1] + Z;
  return lerp(w,
              lerp(v, lerp(u, grad(p[AA], x, y, z), grad(p[BA], x - 1, y, z)),
                   lerp(u, grad(p[AB], x, y - 1, z), grad(p[BB], x - 1, y - 1, z))),
              lerp(v, lerp(u, grad(p[AA + 1], x, y, z - 1), grad(p[BA + 1], x - 1, y, z - 1)),
                   lerp(u, grad(p[AB + 1], x, y - 1, z - 1), grad(p[BB + 1], x - 1, y - 1, z - 1))));
}

}  // namespace

double NoiseTexture::at(const Eigen::Vector3d& p) const {
  if (!(scale > 0.0) || !std::isfinite(scale)) {
    throw std::invalid_argument("NoiseTexture.scale must be > 0 (got " + std::to_string(scale) + ")");
  }
  if (octaves < 1 || octaves > kMaxOctaves) {
    throw std::invalid_argument("NoiseTexture.octaves must be in [1, 32] (got " + std::to_string(octaves) + ")");
  }
  const NoiseTables& t = tablesFor(seed);
  double freq = 1.0 / scale;
  double amp = 1.0;
  double sum = 0.0;
  double norm = 0.0;
  for (int k = 0; k < octaves; ++k) {
    sum += amp * perlin(t.perm.data(), p.x() * freq + t.offset[k][0], p.y() * freq + t.offset[k][1],
                        p.z() * freq + t.offset[k][2]);
    norm += std::abs(amp);
    amp *= persistence;
    freq *= 2.0;
  }
  return 0.5 + 0.5 * sum / norm;
}

}  // namespace sim
}  // namespace skin3d
