// SPDX-License-Identifier: BSD-3-Clause
//
// Ray-casting renderer and the camera realism chain.
//
// renderIrradiance: pixel (u, v) (centre at integer coordinates, covering [u-0.5, u+0.5] x [v-0.5, v+0.5])
// is the mean of s x s samples at (u + (i + 0.5)/s - 0.5, v + (j + 0.5)/s - 0.5), i, j = 0 .. s-1. A sample's
// ray leaves the camera centre T_world_cam.translation() along R_world_cam * normalized(camera.unproject(uv))
// (the camera's plumb_bob distortion is inverted exactly: Newton iterations, warm-started from the previous
// sample of the same row, until a step is < 1e-9, leaving an error ~1e-17 in normalised coordinates, i.e. the
// same ray as camera.unproject). A hit contributes albedo * (ambient + (1 - ambient) max(0, -n . light_dir)),
// a miss `background`; the pixel value is the mean of its samples. Rows are shared out to `threads`
// std::threads (0 = hardware concurrency); the result does not depend on the number of threads. An exception
// thrown by the scene in a worker is rethrown to the caller.
//
// applyRealism, in this order, on a CV_32FC1 irradiance E:
//   1. blur:       Gaussian, sigma = blur_sigma px (cv::GaussianBlur, BORDER_REFLECT_101); skipped if 0.
//   2. vignetting: E *= V(r), V(r) = (1 + a (r / r_c)^2)^-2, a = (1 - vignetting)^-1/2 - 1, r = distance of
//                  the pixel from the image centre ((w-1)/2, (h-1)/2), r_c = that of the corner pixel (0, 0).
//                  This is the cos^4 law of a lens with focal length r_c / sqrt(a) px: V(0) = 1 and exactly
//                  V(r_c) = 1 - vignetting at the corners. vignetting in [0, 1).
//   3. response:   y = max(0, gain E + offset)^(1 / gamma).
//   4. noise:      y += sigma n, n ~ N(0, 1), sigma^2 = y / full_well (shot noise, Gaussian approximation,
//                  intensity units; skipped if full_well <= 0) + (read_noise / 255)^2. Normal deviates by
//                  Box-Muller from std::mt19937_64(seed), in row-major pixel order (deterministic).
//   5. clamp to [0, 1]; quantise: round(255 y) as CV_8UC1. With quantise = false the clamped CV_32FC1 image
//      is returned instead (same noise).

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <mutex>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/LU>
#include <opencv2/imgproc.hpp>

#include "../common/text.h"
#include "skin3d/sim/render.h"

namespace skin3d {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

using common::num;

/**
 * Undistorts pixels to ideal normalised coordinates. For a distorted camera: Newton iterations on the
 * plumb_bob model (the same equations as PinholeCamera::distortNormalized, inlined), warm-started with the
 * previous sample's correction; stops once a step is < 1e-9 (quadratic convergence: the remaining error is
 * then ~1e-17), falling back to camera.unproject if it does not converge.
 */
class RayMaker {
 public:
  explicit RayMaker(const geometry::PinholeCamera& cam)
      : cam_(cam), Kinv_(cam.K().inverse()), distorted_(cam.hasDistortion()) {
    const std::vector<double>& D = cam.D();
    for (std::size_t i = 0; i < 5 && i < D.size(); ++i) d_[i] = D[i];
  }

  /** Forgets the warm start (at the start of each row, so that a row's rays do not depend on the thread). */
  void reset() { cx_ = cy_ = 0.0; }

  /** Ray (x, y, 1) of pixel (u, v). */
  Eigen::Vector3d ray(double u, double v) {
    const double xd = Kinv_(0, 0) * u + Kinv_(0, 1) * v + Kinv_(0, 2);
    const double yd = Kinv_(1, 1) * v + Kinv_(1, 2);
    if (!distorted_) return Eigen::Vector3d(xd, yd, 1.0);
    const double k1 = d_[0], k2 = d_[1], p1 = d_[2], p2 = d_[3], k3 = d_[4];
    double x = xd + cx_, y = yd + cy_;
    bool converged = false;
    for (int it = 0; it < 30; ++it) {
      const double r2 = x * x + y * y;
      const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
      const double fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd;
      const double fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd;
      const double dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
      const double j00 = radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x;
      const double j01 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
      const double j10 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
      const double j11 = radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x;
      const double det = j00 * j11 - j01 * j10;
      if (!(std::abs(det) > 1e-12)) break;
      const double sx = (j11 * fx - j01 * fy) / det, sy = (j00 * fy - j10 * fx) / det;
      x -= sx;
      y -= sy;
      if (sx * sx + sy * sy < 1e-18) {
        converged = std::isfinite(x) && std::isfinite(y);
        break;
      }
    }
    if (!converged) {
      const Eigen::Vector3d r = cam_.unproject(Eigen::Vector2d(u, v));
      x = r.x();
      y = r.y();
    }
    cx_ = x - xd;
    cy_ = y - yd;
    return Eigen::Vector3d(x, y, 1.0);
  }

 private:
  const geometry::PinholeCamera& cam_;
  Eigen::Matrix3d Kinv_;
  bool distorted_;
  double d_[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
  double cx_ = 0.0, cy_ = 0.0;  // correction (undistorted - distorted) of the previous sample
};

/** Box-Muller normal deviates from a std::mt19937_64 (std::normal_distribution is implementation-defined). */
class Gauss {
 public:
  explicit Gauss(std::uint64_t seed) : rng_(seed) {}
  double operator()() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double u1 = 1.0 - static_cast<double>(rng_() >> 11) * (1.0 / 9007199254740992.0);  // (0, 1]
    const double u2 = static_cast<double>(rng_() >> 11) * (1.0 / 9007199254740992.0);
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * kPi * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * kPi * u2);
  }

 private:
  std::mt19937_64 rng_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace

RealismOptions RealismOptions::ideal() {
  RealismOptions r;
  r.blur_sigma = 0.0;
  r.vignetting = 0.0;
  r.gain = 1.0;
  r.offset = 0.0;
  r.gamma = 1.0;
  r.full_well = 0.0;
  r.read_noise = 0.0;
  r.quantise = true;
  return r;
}

cv::Mat renderIrradiance(const Scene& scene, const geometry::PinholeCamera& camera,
                         const Eigen::Isometry3d& T_world_cam, const RenderOptions& options) {
  if (camera.width() <= 0 || camera.height() <= 0) {
    throw std::invalid_argument("renderIrradiance: camera has no image size (" + std::to_string(camera.width()) +
                                " x " + std::to_string(camera.height()) + ")");
  }
  if (options.supersample < 1) {
    throw std::invalid_argument("renderIrradiance: supersample must be >= 1 (got " +
                                std::to_string(options.supersample) + ")");
  }
  if (options.threads < 0) {
    throw std::invalid_argument("renderIrradiance: threads must be >= 0 (got " + std::to_string(options.threads) + ")");
  }
  if (!(options.ambient >= 0.0 && options.ambient <= 1.0)) {
    throw std::invalid_argument("renderIrradiance: ambient must be in [0, 1] (got " + num(options.ambient) + ")");
  }
  if (!options.light_dir.allFinite() || !(options.light_dir.norm() > 0.0)) {
    throw std::invalid_argument("renderIrradiance: light_dir must be a finite non-zero vector");
  }
  if (!T_world_cam.matrix().allFinite()) throw std::invalid_argument("renderIrradiance: T_world_cam is not finite");

  const int W = camera.width(), H = camera.height(), s = options.supersample;
  cv::Mat out(H, W, CV_32F);
  const Eigen::Vector3d origin = T_world_cam.translation();
  const Eigen::Matrix3d R = T_world_cam.linear();
  const Eigen::Vector3d light = options.light_dir.normalized();
  const double ambient = options.ambient;
  const double background = options.background;
  std::vector<double> off(s);
  for (int i = 0; i < s; ++i) off[i] = (i + 0.5) / s - 0.5;
  const double inv_n = 1.0 / (s * s);

  int n_threads = options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  n_threads = std::max(1, std::min(n_threads, H));
  std::atomic<int> next_row{0};
  std::mutex error_mutex;
  std::exception_ptr error;
  auto work = [&]() {
    RayMaker rays(camera);
    Hit hit;
    try {
      for (;;) {
        const int v = next_row.fetch_add(1);
        if (v >= H) return;
        rays.reset();
        float* row = out.ptr<float>(v);
        for (int u = 0; u < W; ++u) {
          double sum = 0.0;
          for (int j = 0; j < s; ++j) {
            const double sv = v + off[j];
            for (int i = 0; i < s; ++i) {
              const Eigen::Vector3d d = R * rays.ray(u + off[i], sv).normalized();
              if (scene.intersect(origin, d, &hit)) {
                const double lambert = std::max(0.0, -hit.normal.dot(light));
                sum += scene.albedo(hit) * (ambient + (1.0 - ambient) * lambert);
              } else {
                sum += background;
              }
            }
          }
          row[u] = static_cast<float>(sum * inv_n);
        }
      }
    } catch (...) {
      next_row = H;  // stop the other workers
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < n_threads; ++i) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  return out;
}

cv::Mat applyRealism(const cv::Mat& irradiance, const RealismOptions& realism, std::uint64_t seed) {
  if (irradiance.empty() || irradiance.type() != CV_32FC1) {
    throw std::invalid_argument("applyRealism: irradiance must be a non-empty CV_32FC1 image");
  }
  if (!(realism.blur_sigma >= 0.0) || !std::isfinite(realism.blur_sigma)) {
    throw std::invalid_argument("applyRealism: blur_sigma must be >= 0 (got " + num(realism.blur_sigma) + ")");
  }
  if (!(realism.vignetting >= 0.0 && realism.vignetting < 1.0)) {
    throw std::invalid_argument("applyRealism: vignetting must be in [0, 1) (got " + num(realism.vignetting) + ")");
  }
  if (!std::isfinite(realism.gain))
    throw std::invalid_argument("applyRealism: gain must be finite (got " + num(realism.gain) + ")");
  if (!std::isfinite(realism.offset)) {
    throw std::invalid_argument("applyRealism: offset must be finite (got " + num(realism.offset) + ")");
  }
  if (!(realism.gamma > 0.0) || !std::isfinite(realism.gamma)) {
    throw std::invalid_argument("applyRealism: gamma must be > 0 (got " + num(realism.gamma) + ")");
  }
  if (!std::isfinite(realism.full_well)) {
    throw std::invalid_argument("applyRealism: full_well must be finite (got " + num(realism.full_well) + ")");
  }
  if (!(realism.read_noise >= 0.0) || !std::isfinite(realism.read_noise)) {
    throw std::invalid_argument("applyRealism: read_noise must be >= 0 (got " + num(realism.read_noise) + ")");
  }

  cv::Mat img;
  if (realism.blur_sigma > 0.0) {
    cv::GaussianBlur(irradiance, img, cv::Size(0, 0), realism.blur_sigma, realism.blur_sigma, cv::BORDER_REFLECT_101);
  } else {
    img = irradiance.clone();
  }

  const int W = img.cols, H = img.rows;
  const double cx = 0.5 * (W - 1), cy = 0.5 * (H - 1);
  const double rc2 = std::max(cx * cx + cy * cy, 1e-12);
  const double a = realism.vignetting > 0.0 ? 1.0 / std::sqrt(1.0 - realism.vignetting) - 1.0 : 0.0;
  const double inv_gamma = 1.0 / realism.gamma;
  const double inv_fw = realism.full_well > 0.0 ? 1.0 / realism.full_well : 0.0;
  const double read_var = (realism.read_noise / 255.0) * (realism.read_noise / 255.0);
  const bool noisy = inv_fw > 0.0 || read_var > 0.0;
  Gauss gauss(seed);

  cv::Mat out(H, W, realism.quantise ? CV_8UC1 : CV_32FC1);
  for (int v = 0; v < H; ++v) {
    const float* in = img.ptr<float>(v);
    const double dy2 = (v - cy) * (v - cy);
    for (int u = 0; u < W; ++u) {
      double e = in[u];
      if (a > 0.0) {
        const double q = 1.0 + a * ((u - cx) * (u - cx) + dy2) / rc2;
        e /= q * q;
      }
      double y = std::max(0.0, realism.gain * e + realism.offset);
      if (inv_gamma != 1.0) y = std::pow(y, inv_gamma);
      if (noisy) y += std::sqrt(y * inv_fw + read_var) * gauss();
      y = std::clamp(y, 0.0, 1.0);
      if (realism.quantise) {
        out.ptr<std::uint8_t>(v)[u] = static_cast<std::uint8_t>(std::lround(255.0 * y));
      } else {
        out.ptr<float>(v)[u] = static_cast<float>(y);
      }
    }
  }
  return out;
}

}  // namespace sim
}  // namespace skin3d
