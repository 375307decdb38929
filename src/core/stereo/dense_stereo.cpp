// SPDX-License-Identifier: BSD-3-Clause
// Dense matching: semi-global matching at a coarse level, then a coarse-to-fine local correlation fit.
// See include/skin3d/stereo/dense_stereo.h for the method.
#include "skin3d/stereo/dense_stereo.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "../common/parallel.h"
#include "../common/text.h"

namespace skin3d {
namespace stereo {
namespace {

using common::num;
using Clock = std::chrono::steady_clock;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kMaxCoarseDisparities = 640;  // deeper searches are done at a coarser level
// Where SGBM left a hole, the fit alone decides: it needs a full-resolution correlation of 0.5 and a low-passed one
// (Refined::corr_smooth) of 0.7 (on the skin scenes, hole fits below that were mostly wrong by > 0.15 mm).
constexpr float kHoleCorrelation = 0.5f;
constexpr float kHoleCorrelationSmooth = 0.7f;
constexpr float kMinSigma = 0.005f;  // px: floor of the reported sigma (interpolation and 8-bit quantisation)

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

/** Grey float image in [0, 1]. */
cv::Mat toGreyFloat(const cv::Mat& img) {
  cv::Mat grey = img;
  if (img.channels() == 3) cv::cvtColor(img, grey, cv::COLOR_BGR2GRAY);
  else if (img.channels() == 4) cv::cvtColor(img, grey, cv::COLOR_BGRA2GRAY);
  cv::Mat f;
  grey.convertTo(f, CV_32F, img.depth() == CV_16U ? 1.0 / 65535.0 : 1.0 / 255.0);
  return f;
}

/** Crop of `img` at `r` (may reach outside): outside, the border pixels are replicated (a zero fill would
 *  put a step edge there, which the matcher would take for texture). */
cv::Mat paddedCrop(const cv::Mat& img, const cv::Rect& r) {
  const cv::Rect inside = r & cv::Rect(0, 0, img.cols, img.rows);
  cv::Mat out;
  if (inside.area() == 0) return cv::Mat(r.size(), img.type(), cv::Scalar::all(0));
  cv::copyMakeBorder(img(inside), out, inside.y - r.y, r.br().y - inside.br().y, inside.x - r.x, r.br().x - inside.br().x,
                     cv::BORDER_REPLICATE);
  return out;
}

/** Zero local mean, unit local contrast (Gaussian window of sigma s); eps keeps flat areas near 0. */
cv::Mat normaliseLocal(const cv::Mat& img, double s) {
  cv::Mat mean, d, var, out;
  cv::GaussianBlur(img, mean, cv::Size(), s, s, cv::BORDER_REFLECT);
  d = img - mean;
  cv::GaussianBlur(d.mul(d), var, cv::Size(), s, s, cv::BORDER_REFLECT);
  cv::sqrt(var + 4e-4, var);  // contrast floor 0.02: about 5x the sensor noise of an 8-bit image
  cv::divide(d, var, out);
  return out;
}

/** NaN-aware fill: holes take a Gaussian-weighted average of their known surroundings (for initial values only). */
cv::Mat fillHoles(const cv::Mat& d) {
  cv::Mat known = (d == d);  // false for NaN
  cv::Mat v = d.clone();
  v.setTo(0, ~known);
  cv::Mat w;
  known.convertTo(w, CV_32F, 1.0 / 255.0);
  cv::Mat out = d.clone();
  for (double s = 2; s < 4 * std::max(d.rows, d.cols); s *= 3) {
    cv::Mat vs, ws;
    cv::GaussianBlur(v, vs, cv::Size(), s, s, cv::BORDER_REPLICATE);
    cv::GaussianBlur(w, ws, cv::Size(), s, s, cv::BORDER_REPLICATE);
    bool remaining = false;
    for (int y = 0; y < d.rows; ++y) {
      float* o = out.ptr<float>(y);
      const float* a = vs.ptr<float>(y);
      const float* b = ws.ptr<float>(y);
      for (int x = 0; x < d.cols; ++x) {
        if (std::isnan(o[x])) {
          if (b[x] > 1e-4f) o[x] = a[x] / b[x];
          else remaining = true;
        }
      }
    }
    if (!remaining) break;
  }
  out.setTo(0, out != out);
  return out;
}

int sgbmMode(const std::string& m) {
  if (m == "sgbm") return cv::StereoSGBM::MODE_SGBM;
  if (m == "hh") return cv::StereoSGBM::MODE_HH;
  if (m == "sgbm_3way") return cv::StereoSGBM::MODE_SGBM_3WAY;
  throw DenseStereoError("sgbm_mode '" + m + "' is not one of sgbm, hh, sgbm_3way");
}

void validate(const cv::Mat& left, const cv::Mat& right, const DenseStereoOptions& o) {
  if (left.empty() || right.empty()) throw DenseStereoError(std::string(left.empty() ? "left" : "right") + " image is empty");
  if (left.size() != right.size())
    throw DenseStereoError("left and right images differ in size (" + std::to_string(left.cols) + "x" +
                           std::to_string(left.rows) + " vs " + std::to_string(right.cols) + "x" +
                           std::to_string(right.rows) + ")");
  if (left.type() != right.type()) throw DenseStereoError("left and right images differ in type");
  if (left.depth() != CV_8U && left.depth() != CV_16U) throw DenseStereoError("images must be 8-bit or 16-bit");
  if (left.channels() != 1 && left.channels() != 3 && left.channels() != 4)
    throw DenseStereoError("images must be grey or colour (1, 3 or 4 channels)");
  if (!std::isfinite(o.min_disparity) || !std::isfinite(o.max_disparity) || o.min_disparity >= o.max_disparity)
    throw DenseStereoError("disparity range [" + num(o.min_disparity) + ", " + num(o.max_disparity) +
                           "] px must be finite with min < max (set it, e.g. from disparityRangeForDepth)");
  if (o.max_disparity - o.min_disparity > 8 * left.cols)
    throw DenseStereoError("disparity range " + num(o.max_disparity - o.min_disparity) + " px is wider than 8 image widths");
  if (o.block_size < 1 || o.block_size > 11 || o.block_size % 2 == 0)
    throw DenseStereoError("block_size " + std::to_string(o.block_size) + " must be odd, 1 ... 11");
  sgbmMode(o.sgbm_mode);
  if (o.subpixel != "lk" && o.subpixel != "sgbm") throw DenseStereoError("subpixel '" + o.subpixel + "' is not lk or sgbm");
  if (o.refine_window < 3 || o.refine_window % 2 == 0 || o.refine_window > 51)
    throw DenseStereoError("refine_window " + std::to_string(o.refine_window) + " must be odd, 3 ... 51");
  if (o.refine_iterations < 1 || o.refine_iterations > 20)
    throw DenseStereoError("refine_iterations " + std::to_string(o.refine_iterations) + " must be 1 ... 20");
  if (o.coarse_max_width < 64) throw DenseStereoError("coarse_max_width " + std::to_string(o.coarse_max_width) + " must be >= 64");
  if (!(o.lr_max_diff >= 0) || !(o.refine_max_shift > 0) || !(o.max_sigma > 0) || !(o.min_texture >= 0) ||
      o.uniqueness_ratio < 0 || o.speckle_window < 0 || !(o.speckle_range >= 0) || o.p1 < 0 || o.p2 < 0)
    throw DenseStereoError("lr_max_diff, refine_max_shift, max_sigma, min_texture, uniqueness_ratio, speckle_* and p1/p2 "
                           "must be >= 0 (refine_max_shift and max_sigma > 0)");
  if (o.p1 > 0 && o.p2 > 0 && o.p2 <= o.p1) throw DenseStereoError("p2 must be larger than p1");
  if (o.slant_passes < 0 || o.slant_passes > 3)
    throw DenseStereoError("slant_passes " + std::to_string(o.slant_passes) + " must be 0 ... 3");
}

/** Remap maps of a row shift: mapx = x + x_offset - d(x, y), mapy = y + v(x, y) (v empty: 0). */
void rowShiftMaps(const cv::Mat& d, const cv::Mat& v, int x_offset, cv::Mat& mapx, cv::Mat& mapy) {
  mapx.create(d.size(), CV_32F);
  mapy.create(d.size(), CV_32F);
  for (int y = 0; y < d.rows; ++y) {
    const float* dp = d.ptr<float>(y);
    const float* vp = v.empty() ? nullptr : v.ptr<float>(y);
    float* mx = mapx.ptr<float>(y);
    float* my = mapy.ptr<float>(y);
    for (int x = 0; x < d.cols; ++x) {
      mx[x] = static_cast<float>(x + x_offset) - dp[x];
      my[x] = static_cast<float>(y) + (vp ? vp[x] : 0.f);
    }
  }
}

/**
 * One semi-global pass that follows slanted surfaces: the right image is resampled along each row by a smooth
 * prior of the disparity (the previous pass, holes filled from their surroundings, smoothed over a few blocks), so
 * that in the resampled pair a slanted or curved surface is nearly fronto-parallel and SGBM's square blocks and
 * its smoothness penalty fit it again. SGBM then searches only a residual e in [-16, 16) px around the prior:
 * d(x) = e + P(x - e). New answers replace the previous ones; where the pass finds none, the previous value stays.
 */
cv::Mat followSlant(const cv::Mat& l8, const cv::Mat& r8, const cv::Mat& dc, const cv::Ptr<cv::StereoSGBM>& base,
                    const DenseStereoOptions& o) {
  constexpr int kResidual = 16;
  cv::Mat prior = fillHoles(dc);
  const double smooth = 2.0 * o.block_size;
  cv::GaussianBlur(prior, prior, cv::Size(), smooth, smooth, cv::BORDER_REPLICATE);
  cv::Mat mapx, mapy, rw, e16;
  rowShiftMaps(prior, cv::Mat(), 0, mapx, mapy);
  cv::remap(r8, rw, mapx, mapy, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  auto sgbm = cv::StereoSGBM::create(-kResidual, 2 * kResidual, base->getBlockSize(), base->getP1(), base->getP2(),
                                     base->getDisp12MaxDiff(), 0, base->getUniquenessRatio(), base->getSpeckleWindowSize(),
                                     base->getSpeckleRange(), base->getMode());
  sgbm->compute(l8, rw, e16);
  cv::Mat out = dc.clone();
  const short invalid = static_cast<short>((-kResidual - 1) * 16);
  for (int y = 0; y < dc.rows; ++y) {
    const short* e = e16.ptr<short>(y);
    const float* p = prior.ptr<float>(y);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < dc.cols; ++x) {
      if (e[x] <= invalid) continue;
      const float r = e[x] / 16.0f;
      // the matched point of the resampled right image lies at x - r; its prior was read there
      const float xs = std::clamp(static_cast<float>(x) - r, 0.f, static_cast<float>(dc.cols - 1));
      const int x0 = std::min(static_cast<int>(xs), dc.cols - 2);
      const float f = xs - static_cast<float>(x0);
      d[x] = r + (1 - f) * p[x0] + f * p[x0 + 1];
    }
  }
  return out;
}

/**
 * Bicubic resampling with the Catmull-Rom kernel (a = -0.5, the interpolating cubic of least phase error)
 * at exact float positions. cv::remap's INTER_CUBIC uses a = -0.75 and quantises positions to 1/32 px:
 * both bias a sub-pixel fit by a few hundredths of a pixel depending on the fractional disparity.
 */
inline void catmullRomWeights(float t, float w[4]) {
  const float t2 = t * t, t3 = t2 * t;
  w[0] = 0.5f * (-t3 + 2 * t2 - t);
  w[1] = 0.5f * (3 * t3 - 5 * t2 + 2);
  w[2] = 0.5f * (-3 * t3 + 4 * t2 + t);
  w[3] = 0.5f * (t3 - t2);
}

/** src (CV_32F) at (ix - 1 ... ix + 2) x (iy - 1 ... iy + 2) weighted by wx, wy. */
inline float catmullRomAt(const cv::Mat& src, int ix, int iy, const float wx[4], const float wy[4]) {
  float acc = 0.f;
  for (int j = 0; j < 4; ++j) {
    const float* row = src.ptr<float>(iy - 1 + j) + ix - 1;
    acc += wy[j] * (wx[0] * row[0] + wx[1] * row[1] + wx[2] * row[2] + wx[3] * row[3]);
  }
  return acc;
}

/** The normalised pair and its gradients at one level (L may be a crop starting x_offset columns in). */
struct LevelImages {
  cv::Mat L, R, Lx, Ly, Rx, Ry;
  int x_offset = 0;
};

/** The terms of the local fit at the current field, per pixel (buffers reused from iteration to iteration). */
struct FitTerms {
  cv::Mat rw, e, a, b;         // resampled right image, residual L - Rw, symmetric gradients (e = a delta + b nu)
  cv::Mat aa, ae, ab, bb, be;  // their products (b, ab, bb, be with the vertical fit only)
};

/**
 * Resamples the right image and its gradients (Catmull-Rom) where each left pixel looks under the field (d, v):
 * x_r = x + x_offset - d, y_r = y + v (0 outside the image), and forms the fit's terms in the same pass.
 * Symmetric gradients (mean of both images): no first-order bias from using one image's gradient; the right
 * gradient, resampled into left coordinates, is scaled by the horizontal compression 1 - dd/dx (`slope_x`).
 * L = Rw(x - delta, y + nu) ~ Rw - gx delta + gy nu  =>  e = a delta + b nu, a = -gx, b = gy.
 */
void fitTerms(const LevelImages& im, const cv::Mat& d, const cv::Mat& v, const cv::Mat& slope_x, bool vertical, FitTerms& t) {
  const cv::Size sz = im.L.size();
  for (cv::Mat* m : {&t.rw, &t.e, &t.a, &t.aa, &t.ae}) m->create(sz, CV_32F);
  if (vertical)
    for (cv::Mat* m : {&t.b, &t.ab, &t.bb, &t.be}) m->create(sz, CV_32F);
  const int W = im.R.cols, H = im.R.rows;
  forEachIndex(sz.height, [&](int y) {
    const float *dp = d.ptr<float>(y), *vp = v.ptr<float>(y), *sx = slope_x.ptr<float>(y);
    const float *l = im.L.ptr<float>(y), *lx = im.Lx.ptr<float>(y), *ly = vertical ? im.Ly.ptr<float>(y) : nullptr;
    float *rw = t.rw.ptr<float>(y), *e = t.e.ptr<float>(y), *a = t.a.ptr<float>(y), *b = vertical ? t.b.ptr<float>(y) : nullptr;
    float *aa = t.aa.ptr<float>(y), *ae = t.ae.ptr<float>(y);
    float *ab = vertical ? t.ab.ptr<float>(y) : nullptr, *bb = vertical ? t.bb.ptr<float>(y) : nullptr,
          *be = vertical ? t.be.ptr<float>(y) : nullptr;
    for (int x = 0; x < sz.width; ++x) {
      const float fx = static_cast<float>(x + im.x_offset) - dp[x], fy = static_cast<float>(y) + vp[x];
      const int ix = static_cast<int>(std::floor(fx)), iy = static_cast<int>(std::floor(fy));
      float r = 0.f, rx = 0.f, ry = 0.f;
      if (!(ix < 1 || iy < 1 || ix >= W - 2 || iy >= H - 2)) {
        float wx[4], wy[4];
        catmullRomWeights(fx - ix, wx);
        catmullRomWeights(fy - iy, wy);
        r = catmullRomAt(im.R, ix, iy, wx, wy);
        rx = catmullRomAt(im.Rx, ix, iy, wx, wy);
        if (vertical) ry = catmullRomAt(im.Ry, ix, iy, wx, wy);
      }
      rw[x] = r;
      e[x] = l[x] - r;
      a[x] = -0.5f * (lx[x] + rx * (1.0f - sx[x]));
      aa[x] = a[x] * a[x];
      ae[x] = a[x] * e[x];
      if (vertical) {
        b[x] = 0.5f * (ly[x] + ry);
        ab[x] = a[x] * b[x];
        bb[x] = b[x] * b[x];
        be[x] = b[x] * e[x];
      }
    }
  });
}

/** Box mean over `win` (reflected border), into dst. */
void boxMean(const cv::Mat& src, cv::Mat& dst, const cv::Size& win) {
  cv::boxFilter(src, dst, CV_32F, win, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
}

/** Result of the local fit at one level. */
struct Refined {
  cv::Mat d, v;            // disparity (crop coordinates: x_l - x_r') and vertical shift
  cv::Mat sigma, corr, texture;
  /** Normalised correlation of the pair low-passed (Gaussian, sigma 1 px) over a window twice as wide: the
   *  views compared where the sensor noise is averaged (skin's texture is mostly coarser than a pixel). */
  cv::Mat corr_smooth;
};

/**
 * The fit's statistics at its final field: the Gauss-Newton sigma (inflated for correlated residuals), the
 * normalised correlation at full resolution and low-passed over a doubled window, and the texture (saa).
 */
void finalStatistics(const LevelImages& im, const cv::Mat& d, const cv::Mat& v, const cv::Mat& slope_x, int window,
                     FitTerms& t, Refined& out) {
  const cv::Size win(window, window), sz = im.L.size();
  fitTerms(im, d, v, slope_x, false, t);
  // Neighbouring residuals (and gradients) are correlated (optics blur, interpolation), so the window holds
  // fewer independent samples than pixels. With lag-1 correlations rho_e of the residual and rho_a of the
  // gradient, an AR(1) model of their product phi = rho_e rho_a inflates the variance by
  // (1 + phi) / (1 - phi) per direction. Products with the right / lower neighbour (reflected at the border).
  cv::Mat eh(sz, CV_32F), ev(sz, CV_32F), ah(sz, CV_32F), av(sz, CV_32F), ee(sz, CV_32F), ll(sz, CV_32F), rr(sz, CV_32F),
      lr(sz, CV_32F);
  forEachIndex(sz.height, [&](int y) {
    const int yn = std::min(y + 1, sz.height - 1);
    const float *e = t.e.ptr<float>(y), *a = t.a.ptr<float>(y), *en = t.e.ptr<float>(yn), *an = t.a.ptr<float>(yn);
    const float *l = im.L.ptr<float>(y), *r = t.rw.ptr<float>(y);
    float *peh = eh.ptr<float>(y), *pev = ev.ptr<float>(y), *pah = ah.ptr<float>(y), *pav = av.ptr<float>(y);
    float *pee = ee.ptr<float>(y), *pll = ll.ptr<float>(y), *prr = rr.ptr<float>(y), *plr = lr.ptr<float>(y);
    for (int x = 0; x < sz.width; ++x) {
      const int xn = std::min(x + 1, sz.width - 1);
      peh[x] = e[x] * e[xn];
      pah[x] = a[x] * a[xn];
      pev[x] = e[x] * en[x];
      pav[x] = a[x] * an[x];
      pee[x] = e[x] * e[x];
      pll[x] = l[x] * l[x];
      prr[x] = r[x] * r[x];
      plr[x] = l[x] * r[x];
    }
  });
  cv::Mat saa;
  {
    std::vector<std::function<void()>> boxes{[&] { boxMean(t.aa, saa, win); }};
    for (cv::Mat* m : {&eh, &ev, &ah, &av, &ee, &ll, &rr, &lr}) boxes.emplace_back([m, &win] { boxMean(*m, *m, win); });
    runTasks(boxes);
  }
  {
    // the low-passed views, compared over a doubled window
    cv::Mat lb, rb;
    runTasks({[&] { cv::GaussianBlur(im.L, lb, cv::Size(), 1.0, 1.0, cv::BORDER_REFLECT); },
              [&] { cv::GaussianBlur(t.rw, rb, cv::Size(), 1.0, 1.0, cv::BORDER_REFLECT); }});
    t.b.create(sz, CV_32F);
    forEachIndex(sz.height, [&](int y) {
      const float *p = lb.ptr<float>(y), *q = rb.ptr<float>(y);
      float *a = t.aa.ptr<float>(y), *b = t.ae.ptr<float>(y), *c = t.b.ptr<float>(y);
      for (int x = 0; x < sz.width; ++x) {
        a[x] = p[x] * p[x];
        b[x] = q[x] * q[x];
        c[x] = p[x] * q[x];
      }
    });
    const cv::Size win2(2 * window + 1, 2 * window + 1);
    runTasks({[&] { boxMean(t.aa, t.aa, win2); }, [&] { boxMean(t.ae, t.ae, win2); }, [&] { boxMean(t.b, t.b, win2); }});
    out.corr_smooth.create(sz, CV_32F);
    forEachIndex(sz.height, [&](int y) {
      const float *a = t.aa.ptr<float>(y), *b = t.ae.ptr<float>(y), *c = t.b.ptr<float>(y);
      float* o = out.corr_smooth.ptr<float>(y);
      for (int x = 0; x < sz.width; ++x) {
        // (box means of squares can round below 0 where the right view is outside the image: NaN -> the floor)
        float den = std::sqrt(a[x] * b[x]);
        if (!(den > 1e-8f)) den = 1e-8f;
        o[x] = c[x] / den;
      }
    });
  }
  const double n = static_cast<double>(window) * window;
  out.sigma.create(sz, CV_32F);
  out.corr.create(sz, CV_32F);
  out.texture = saa;
  forEachIndex(sz.height, [&](int y) {
    const float *p = saa.ptr<float>(y), *q = ee.ptr<float>(y), *l = ll.ptr<float>(y), *r = rr.ptr<float>(y), *c = lr.ptr<float>(y);
    const float *neh = eh.ptr<float>(y), *nev = ev.ptr<float>(y), *nah = ah.ptr<float>(y), *nav = av.ptr<float>(y);
    float* sg = out.sigma.ptr<float>(y);
    float* cr = out.corr.ptr<float>(y);
    for (int x = 0; x < sz.width; ++x) {
      // lag-1 correlations: the boxed products over the boxed squares (e^2: q, a^2: p)
      const float fx = (neh[x] / (q[x] + 1e-12f)) * (nah[x] / (p[x] + 1e-12f));
      const float fy = (nev[x] / (q[x] + 1e-12f)) * (nav[x] / (p[x] + 1e-12f));
      const double ax = std::min(0.95, std::max(0.0, static_cast<double>(fx)));
      const double ay = std::min(0.95, std::max(0.0, static_cast<double>(fy)));
      const double inflate = (1 + ax) / (1 - ax) * (1 + ay) / (1 - ay);
      sg[x] = p[x] > 1e-8f ? static_cast<float>(std::sqrt(inflate * q[x] / ((n - 1.0) * p[x]))) : kNaN;
      const float den = std::sqrt(l[x] * r[x]);
      cr[x] = den > 1e-8f ? c[x] / den : 0.f;
    }
  });
}

/**
 * Iterative local correlation fit: left L, right R (both normalised, same size), initial d and v.
 * Model: L(x, y) = R(x + x_offset - d, y + v) (L may be a crop of the left image starting x_offset columns
 * in). Each iteration resamples R (Catmull-Rom) at the current field.
 */
Refined refineLevel(const cv::Mat& L, const cv::Mat& R, int x_offset, cv::Mat d, cv::Mat v, int window, int iterations,
                    bool fit_vertical, bool final_stats) {
  const cv::Size win(window, window), sz = L.size();
  LevelImages im;
  im.L = L;
  im.R = R;
  im.x_offset = x_offset;
  cv::Sobel(R, im.Rx, CV_32F, 1, 0, 3, 1.0 / 8.0, 0, cv::BORDER_REFLECT);  // central difference, smoothed
  cv::Sobel(R, im.Ry, CV_32F, 0, 1, 3, 1.0 / 8.0, 0, cv::BORDER_REFLECT);
  cv::Sobel(L, im.Lx, CV_32F, 1, 0, 3, 1.0 / 8.0, 0, cv::BORDER_REFLECT);
  cv::Sobel(L, im.Ly, CV_32F, 0, 1, 3, 1.0 / 8.0, 0, cv::BORDER_REFLECT);
  const int big = std::max(3, 4 * window + 1) | 1;  // the vertical shift is a smooth field: averaged widely
  // Slant of the disparity field (px per px), from the starting field smoothed over about a window: a window's
  // answer is referred to its centre along this slant (see below), and the right image's gradient, resampled
  // into left coordinates, is scaled by the horizontal compression 1 - dd/dx.
  cv::Mat slope_x, slope_y, ramp, ones;
  {
    cv::Mat ds;
    cv::GaussianBlur(d, ds, cv::Size(), 0.5 * window, 0.5 * window, cv::BORDER_REPLICATE);
    cv::Sobel(ds, slope_x, CV_32F, 1, 0, 3, 1.0 / 8.0, 0, cv::BORDER_REPLICATE);
    cv::Sobel(ds, slope_y, CV_32F, 0, 1, 3, 1.0 / 8.0, 0, cv::BORDER_REPLICATE);
    forEachIndex(sz.height, [&](int y) {
      float *sx = slope_x.ptr<float>(y), *sy = slope_y.ptr<float>(y);
      for (int x = 0; x < sz.width; ++x) {
        sx[x] = std::min(std::max(sx[x], -2.0f), 0.9f);  // 1 - dd/dx > 0 on any surface both cameras see
        sy[x] = std::min(std::max(sy[x], -2.0f), 2.0f);
      }
    });
    ramp.create(1, window, CV_32F);
    ones = cv::Mat(1, window, CV_32F, cv::Scalar(1.0 / window));
    for (int i = 0; i < window; ++i) ramp.at<float>(0, i) = static_cast<float>(i - window / 2) / window;
  }
  FitTerms t;
  cv::Mat saa, sae, sab, sbb, sbe, sad, mx, my, nu(sz, CV_32F);
  for (int it = 0; it < iterations; ++it) {
    fitTerms(im, d, v, slope_x, fit_vertical, t);
    if (fit_vertical) {
      runTasks({[&] { boxMean(t.aa, saa, win); }, [&] { boxMean(t.ae, sae, win); }, [&] { boxMean(t.ab, sab, win); },
                [&] { boxMean(t.bb, sbb, win); }, [&] { boxMean(t.be, sbe, win); }});
      forEachIndex(sz.height, [&](int y) {
        const float *p = saa.ptr<float>(y), *q = sab.ptr<float>(y), *r = sbb.ptr<float>(y), *s = sae.ptr<float>(y),
                    *w = sbe.ptr<float>(y);
        float* n = nu.ptr<float>(y);
        for (int x = 0; x < sz.width; ++x) {
          const float det = p[x] * r[x] - q[x] * q[x];
          n[x] = det > 1e-8f ? (p[x] * w[x] - q[x] * s[x]) / det : 0.f;
          n[x] = std::max(-0.5f, std::min(0.5f, n[x]));
        }
      });
      cv::boxFilter(nu, nu, CV_32F, cv::Size(big, big), cv::Point(-1, -1), true, cv::BORDER_REFLECT);
      // the horizontal fit given the smoothed vertical update
      forEachIndex(sz.height, [&](int y) {
        const float *n = nu.ptr<float>(y), *a = t.a.ptr<float>(y), *e = t.e.ptr<float>(y), *b = t.b.ptr<float>(y);
        float *vp = v.ptr<float>(y), *ae = t.ae.ptr<float>(y);
        for (int x = 0; x < sz.width; ++x) {
          vp[x] += n[x];
          ae[x] = a[x] * (e[x] - b[x] * n[x]);
        }
      });
      boxMean(t.ae, sae, win);
    } else {
      runTasks({[&] { boxMean(t.aa, saa, win); }, [&] { boxMean(t.ae, sae, win); }});
    }
    // Each window's estimate linearises around its neighbours' current values, so the window's answer is
    // its a^2-weighted mean of d plus the update (not the pixel's own d plus the update: with a box window
    // that would amplify high-frequency noise, whose box response is negative, every iteration).
    // On a slanted field that mean belongs to the window's texture centroid, not to its centre: where the
    // texture sits off-centre (a freckle near one side) it is moved back along the slant,
    // d(centre) = mean - slope . (centroid - centre); mx, my = the a^2-weighted mean offsets (times saa).
    runTasks({[&] { cv::sepFilter2D(t.aa, mx, CV_32F, ramp, ones, cv::Point(-1, -1), 0, cv::BORDER_REFLECT); },
              [&] { cv::sepFilter2D(t.aa, my, CV_32F, ones, ramp, cv::Point(-1, -1), 0, cv::BORDER_REFLECT); },
              [&] {
                cv::multiply(t.aa, d, t.ab);  // aa d (t.ab is free here)
                boxMean(t.ab, sad, win);
              }});
    forEachIndex(sz.height, [&](int y) {
      const float *p = saa.ptr<float>(y), *s = sae.ptr<float>(y), *m = sad.ptr<float>(y), *ox = mx.ptr<float>(y),
                  *oy = my.ptr<float>(y), *sx = slope_x.ptr<float>(y), *sy = slope_y.ptr<float>(y);
      float* dp = d.ptr<float>(y);
      for (int x = 0; x < sz.width; ++x) {
        if (p[x] > 1e-8f) {
          const float centred = m[x] - (sx[x] * ox[x] + sy[x] * oy[x]);
          const float target = (centred + s[x]) / p[x];
          dp[x] += std::max(-1.f, std::min(1.f, target - dp[x]));
        }
      }
    });
  }
  Refined out;
  out.d = d;
  out.v = v;
  if (final_stats) {
    // the iterations' buffers go back to the heap first: the statistics' own buffers reuse them (a 13-megapixel
    // frame's peak memory, and with it the pages the kernel must fault in and clear, is lower)
    for (cv::Mat* m : {&saa, &sae, &sab, &sbb, &sbe, &sad, &mx, &my, &nu, &t.ab, &t.bb, &t.be, &im.Ly, &im.Ry, &slope_y}) m->release();
    finalStatistics(im, d, v, slope_x, window, t, out);
  }
  return out;
}

/** The matcher's working frame: the crops around the roi and their pyramids (coarse level last). */
struct Crops {
  cv::Rect roi;          // in the image
  int d_min = 0;         // the right crop is shifted by d_min: crop disparity d_c = d - d_min in [0, range]
  int range = 0;
  int levels = 0;        // pyramid levels below full resolution; s = 2^levels
  int s = 1;
  int num_disp = 0;      // SGBM's search at the coarse level
  int pad = 0;           // the left crop starts pad columns before the roi (SGBM leaves them unknown)
  int margin_y = 8;
  std::vector<cv::Mat> pl, pr;  // grey float pyramids of the left and right crops
};

/** The roi checked (clipped to the image with a warning), the crops and their pyramids, a saturation warning. */
Crops prepareCrops(const cv::Mat& left, const cv::Mat& right, const DenseStereoOptions& o, DisparityMap& out) {
  Crops c;
  const cv::Rect image(0, 0, left.cols, left.rows);
  cv::Rect roi = o.roi.area() > 0 ? o.roi : image;
  if (o.roi.width < 0 || o.roi.height < 0) throw DenseStereoError("roi has a negative size");
  if ((roi & image).area() == 0)
    throw DenseStereoError("roi (" + std::to_string(roi.x) + ", " + std::to_string(roi.y) + ", " +
                           std::to_string(roi.width) + " x " + std::to_string(roi.height) + ") lies outside the " +
                           std::to_string(left.cols) + "x" + std::to_string(left.rows) + " image");
  if ((roi & image) != roi) {
    out.warnings.push_back("roi clipped to the image");
    roi &= image;
  }
  if (roi.width < 16 || roi.height < 16) throw DenseStereoError("roi is smaller than 16 x 16 px");
  c.roi = roi;
  // the right crop is shifted by the minimum disparity so that the crop disparity d_c = d - d_min lies in
  // [0, range]; the left crop is extended leftwards by the range.
  c.d_min = static_cast<int>(std::floor(o.min_disparity));
  c.range = static_cast<int>(std::ceil(o.max_disparity)) - c.d_min;
  // halve until the roi is at most coarse_max_width wide and the search at most kMaxCoarseDisparities deep
  while (((roi.width >> c.levels) > o.coarse_max_width || (c.range >> c.levels) > kMaxCoarseDisparities) && c.levels < 6)
    ++c.levels;
  c.s = 1 << c.levels;
  // SGBM searches [0, num_disp) at the coarse level and leaves the first num_disp columns unknown: the left
  // crop starts num_disp * s columns before the roi.
  c.num_disp = ((static_cast<int>(std::ceil(static_cast<double>(c.range) / c.s)) + 1 + 15) / 16) * 16;
  c.pad = c.num_disp * c.s;
  const cv::Rect lcrop(roi.x - c.pad, roi.y - c.margin_y, roi.width + c.pad, roi.height + 2 * c.margin_y);
  const cv::Rect rcrop = lcrop - cv::Point(c.d_min, 0);
  c.pl = {paddedCrop(toGreyFloat(left(image)), lcrop)};
  c.pr = {paddedCrop(toGreyFloat(right(image)), rcrop)};
  {
    // Saturation: clipped pixels carry no texture.
    const cv::Mat lr = toGreyFloat(left(roi)), rr = toGreyFloat(right(roi));
    const double sl = cv::countNonZero(lr >= 0.995f) / static_cast<double>(roi.area());
    const double sr = cv::countNonZero(rr >= 0.995f) / static_cast<double>(roi.area());
    if (std::max(sl, sr) > 0.05)
      out.warnings.push_back("saturated images: " + num(std::round(100 * sl)) + " % (left) and " +
                             num(std::round(100 * sr)) + " % (right) of the roi at full scale");
  }
  for (int l = 1; l <= c.levels; ++l) {
    cv::Mat a, b;
    cv::pyrDown(c.pl.back(), a);
    cv::pyrDown(c.pr.back(), b);
    c.pl.push_back(a);
    c.pr.push_back(b);
  }
  return c;
}

/** Semi-global matching at the coarse level (then the slant passes): crop disparities, NaN where unknown.
 *  l8, r8: the 8-bit images SGBM saw (the slant passes need them). */
cv::Mat coarseSemiGlobal(const Crops& c, const DenseStereoOptions& o) {
  const int bs = o.block_size;
  auto sgbm = cv::StereoSGBM::create(0, c.num_disp, bs, o.p1 > 0 ? o.p1 : 8 * bs * bs, o.p2 > 0 ? o.p2 : 32 * bs * bs,
                                     static_cast<int>(std::lround(o.lr_max_diff)), 0, o.uniqueness_ratio,
                                     o.speckle_window, static_cast<int>(std::lround(o.speckle_range)), sgbmMode(o.sgbm_mode));
  if (o.lr_max_diff <= 0) sgbm->setDisp12MaxDiff(-1);
  cv::Mat l8, r8, d16, dc;
  // SGBM sees locally normalised images (zero mean, unit contrast over a few blocks, stretched to 8 bits): the
  // cameras' gain, offset, gamma and vignetting differences drop out, and skin's few grey levels of texture
  // fill the 8-bit range instead of being quantised away
  if (!o.weak_texture) {
    c.pl[c.levels].convertTo(l8, CV_8U, 255.0);
    c.pr[c.levels].convertTo(r8, CV_8U, 255.0);
  } else {
    const double ns = 1.5 * bs;
    normaliseLocal(c.pl[c.levels], ns).convertTo(l8, CV_8U, 40.0, 128.0);
    normaliseLocal(c.pr[c.levels], ns).convertTo(r8, CV_8U, 40.0, 128.0);
  }
  sgbm->compute(l8, r8, d16);
  d16.convertTo(dc, CV_32F, 1.0 / 16.0);
  dc.setTo(kNaN, d16 < 0);  // invalid: OpenCV marks (min_disparity - 1) * 16
  for (int pass = 0; pass < o.slant_passes; ++pass) dc = followSlant(l8, r8, dc, sgbm, o);
  return dc;
}

/** The fine-level answer over the crop from column c0 on: disparity, vertical shift, sigma, validity and why not. */
struct FineMaps {
  cv::Mat d, v, sigma, valid, reason;
  int c0 = 0;
};

/** subpixel = "sgbm": the coarse answer, upsampled (nearest), with a nominal sigma. */
FineMaps fromSemiGlobal(const Crops& c, const cv::Mat& dc) {
  FineMaps f;
  const cv::Size size = c.pl[0].size();
  cv::resize(dc, f.d, size, 0, 0, cv::INTER_NEAREST);
  f.d *= c.s;
  cv::resize(cv::Mat(dc == dc), f.valid, size, 0, 0, cv::INTER_NEAREST);
  f.reason = cv::Mat(size, CV_8U, cv::Scalar(static_cast<int>(UnknownReason::kNoSemiGlobal)));
  f.reason.setTo(0, f.valid);
  // SGBM's parabola: typically 0.1-0.3 px at its level (pixel locking); a nominal 0.25 px, scaled
  f.sigma = cv::Mat(size, CV_32F, cv::Scalar(0.25 * c.s));
  f.v = cv::Mat(size, CV_32F, cv::Scalar(0));
  return f;
}

/** Why the fit at one pixel is not kept (kKnown: kept). hole: the semi-global matcher had no answer there. */
UnknownReason judgeFit(const DenseStereoOptions& o, bool hole, float d, float sgm, float sigma, float corr,
                       float corr_smooth, float texture, float max_shift) {
  // where the semi-global matcher had no answer, the fit alone must show that the views look alike, at full
  // resolution too
  const bool alike = hole ? corr_smooth >= kHoleCorrelationSmooth && corr >= kHoleCorrelation
                          : corr_smooth >= static_cast<float>(o.min_correlation);
  if (texture < o.min_texture) return UnknownReason::kTexture;  // nothing to fit
  if (!alike) return UnknownReason::kCorrelation;                // the images do not look alike here
  if (!(sigma <= o.max_sigma)) return UnknownReason::kSigma;
  if ((!o.weak_texture || !hole) && !(std::fabs(d - sgm) <= max_shift))
    return UnknownReason::kDisagreement;  // the fit and the semi-global matcher disagree: one of them is wrong
  return UnknownReason::kKnown;
}

/** subpixel = "lk": the coarse-to-fine local fit from the coarse answer, then each pixel judged (judgeFit). */
FineMaps fitCoarseToFine(const Crops& c, const cv::Mat& dc, const DenseStereoOptions& o) {
  const int s = c.s;
  const cv::Size full = c.pl[0].size();
  FineMaps f;
  // the fit covers the roi plus a margin only (the columns before it were needed by the semi-global search)
  const double norm_sigma = 0.75 * o.refine_window;
  const int margin_x = s * (2 * o.refine_window + 4);
  f.c0 = std::max(0, (c.pad - margin_x) / s * s);
  cv::Mat d = fillHoles(dc)(cv::Rect(f.c0 / s, 0, dc.cols - f.c0 / s, dc.rows)).clone();
  cv::Mat v = cv::Mat::zeros(d.size(), CV_32F);
  Refined r;
  for (int l = c.levels; l >= 0; --l) {
    const int cl = f.c0 >> l;
    const cv::Rect crop(cl, 0, c.pl[l].cols - cl, c.pl[l].rows);
    if (l < c.levels) {
      cv::Mat du, vu;
      cv::resize(d, du, crop.size(), 0, 0, cv::INTER_LINEAR);
      cv::resize(v, vu, crop.size(), 0, 0, cv::INTER_LINEAR);
      d = du * 2.0;
      v = vu * 2.0;
    }
    // the two views normalised side by side (two tasks: each filter runs on one core)
    cv::Mat Ln, Rn;
    runTasks({[&] { Ln = normaliseLocal(c.pl[l], norm_sigma)(crop); }, [&] { Rn = normaliseLocal(c.pr[l], norm_sigma); }});
    r = refineLevel(Ln, Rn, cl, d, v, o.refine_window, o.refine_iterations + (l == 0 ? 1 : 0), o.vertical, l == 0);
    d = r.d;
    v = r.v;
  }
  f.d = d;
  f.v = v;
  f.sigma = r.sigma;
  // validity: the semi-global value known (nearest), the fit close to it, enough texture, correlation, sigma
  // Holes of the semi-global map were filled from their surroundings for the start; the fit decides there
  // (weak texture is aggregated by the fit's window instead of dropped), held to the filled field.
  // (The fit is held to the semi-global value where there is one; in its holes the filled start may be off
  // by more than that, and the fit's own statistics decide.)
  cv::Mat sgm_up;
  cv::resize(dc, sgm_up, full, 0, 0, cv::INTER_LINEAR);
  const cv::Rect fine(f.c0, 0, full.width - f.c0, full.height);
  sgm_up = sgm_up(fine) * s;
  if (o.weak_texture) {
    f.valid = cv::Mat(sgm_up.size(), CV_8U, cv::Scalar(255));
  } else {  // only where the semi-global matcher answered
    cv::resize(cv::Mat(dc == dc), f.valid, full, 0, 0, cv::INTER_NEAREST);
    f.valid = f.valid(fine).clone();
  }
  f.reason = cv::Mat(f.valid.size(), CV_8U, cv::Scalar(static_cast<int>(UnknownReason::kNoSemiGlobal)));
  f.reason.setTo(0, f.valid);
  const float max_shift = static_cast<float>(o.refine_max_shift * s);
  for (int y = 0; y < f.valid.rows; ++y) {
    uchar* vp = f.valid.ptr<uchar>(y);
    uchar* rp = f.reason.ptr<uchar>(y);
    const float *dp = f.d.ptr<float>(y), *gp = sgm_up.ptr<float>(y), *sg = r.sigma.ptr<float>(y),
                *cr = r.corr.ptr<float>(y), *cs = r.corr_smooth.ptr<float>(y), *tx = r.texture.ptr<float>(y);
    for (int x = 0; x < f.valid.cols; ++x) {
      if (!vp[x]) continue;
      const UnknownReason why = judgeFit(o, !std::isfinite(gp[x]), dp[x], gp[x], sg[x], cr[x], cs[x], tx[x], max_shift);
      if (why != UnknownReason::kKnown) {
        vp[x] = 0;
        rp[x] = static_cast<uchar>(why);
      }
    }
  }
  return f;
}

/** Small islands of valid pixels (a few window sizes) in a sea of unknown ones are chance fits on noise (a dark
 *  background, normalised, is all noise): removed as SGBM's speckle filter does at the coarse level. */
void removeIslands(FineMaps& f, const DenseStereoOptions& o, int s) {
  cv::Mat d16(f.d.size(), CV_16S);
  for (int y = 0; y < d16.rows; ++y) {
    const float* dp = f.d.ptr<float>(y);
    const uchar* vp = f.valid.ptr<uchar>(y);
    short* q = d16.ptr<short>(y);
    for (int x = 0; x < d16.cols; ++x)
      q[x] = vp[x] && std::isfinite(dp[x]) ? static_cast<short>(std::clamp(std::lround(dp[x] * 4.0f), -32000L, 32000L)) : -32768;
  }
  cv::filterSpeckles(d16, -32768, o.speckle_window * s * s, static_cast<double>(4 * s) * o.speckle_range);
  const cv::Mat island = (d16 == -32768) & f.valid;
  f.reason.setTo(static_cast<int>(UnknownReason::kIsland), island);
  f.valid.setTo(0, island);
}

/** Back to image coordinates: d = d_c + d_min. A pixel whose matching window reaches beyond either image (the
 *  crops are padded there) is unknown. Fills out's maps, valid_fraction and unknown_share. */
void writeImageMaps(const Crops& c, const FineMaps& f, const DenseStereoOptions& o, const cv::Mat& left, DisparityMap& out) {
  const cv::Rect& roi = c.roi;
  const cv::Rect in_crop(c.pad - f.c0, c.margin_y, roi.width, roi.height);
  const int half = (o.subpixel == "lk" ? o.refine_window : o.block_size) / 2;
  int known = 0;
  out.unknown_reason = cv::Mat(left.size(), CV_8U, cv::Scalar(255));
  out.unknown_reason(roi).setTo(static_cast<int>(UnknownReason::kBorder));
  for (int y = 0; y < roi.height; ++y) {
    const int yi = y + roi.y;
    if (yi < half || yi >= left.rows - half) continue;
    const uchar* why = f.reason.ptr<uchar>(y + in_crop.y) + in_crop.x;
    uchar* ow = out.unknown_reason.ptr<uchar>(yi) + roi.x;
    const float* dp = f.d.ptr<float>(y + in_crop.y) + in_crop.x;
    const float* vp = f.v.ptr<float>(y + in_crop.y) + in_crop.x;
    const float* sp = f.sigma.ptr<float>(y + in_crop.y) + in_crop.x;
    const uchar* ok = f.valid.ptr<uchar>(y + in_crop.y) + in_crop.x;
    float* od = out.disparity.ptr<float>(yi) + roi.x;
    float* ov = out.vertical.ptr<float>(yi) + roi.x;
    float* os = out.sigma.ptr<float>(yi) + roi.x;
    for (int x = 0; x < roi.width; ++x) {
      if (!ok[x]) {
        ow[x] = why[x];
        continue;
      }
      const int xi = x + roi.x;
      const float d = dp[x] + static_cast<float>(c.d_min);
      const float xr = static_cast<float>(xi) - d;
      if (xi < half || xi >= left.cols - half || !(xr >= half) || !(xr <= left.cols - 1 - half)) continue;
      od[x] = d;
      ov[x] = vp[x];
      os[x] = std::max(sp[x], kMinSigma);
      ow[x] = 0;
      ++known;
    }
  }
  out.valid_fraction = known / static_cast<double>(roi.area());
  std::vector<int> counts(static_cast<size_t>(UnknownReason::kCount), 0);
  for (int y = roi.y; y < roi.y + roi.height; ++y) {
    const uchar* w = out.unknown_reason.ptr<uchar>(y);
    for (int x = roi.x; x < roi.x + roi.width; ++x) ++counts[w[x] < counts.size() ? w[x] : 0];
  }
  for (int n : counts) out.unknown_share.push_back(n / static_cast<double>(roi.area()));
}

/** Why nothing could be matched (empty: something can): no texture in the roi, or no overlap in the range. */
std::string nothingToMatch(const Crops& c, const cv::Mat& dc, const DenseStereoOptions& o) {
  const cv::Rect coarse_roi(c.pad / c.s, c.margin_y / c.s, std::max(1, c.roi.width / c.s), std::max(1, c.roi.height / c.s));
  const cv::Rect coarse_roi_c = coarse_roi & cv::Rect(0, 0, dc.cols, dc.rows);
  const double coarse_valid =
      coarse_roi_c.area() > 0 ? cv::countNonZero(dc(coarse_roi_c) == dc(coarse_roi_c)) / static_cast<double>(coarse_roi_c.area())
                              : 0.0;
  // texture of the left roi at the coarse level (normalised gradient energy; a uniform image has ~0)
  cv::Mat gx, gy;
  const cv::Mat a = c.pl[c.levels](coarse_roi_c);
  cv::Sobel(a, gx, CV_32F, 1, 0, 3, 1.0 / 8.0, 0, cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
  cv::Sobel(a, gy, CV_32F, 0, 1, 3, 1.0 / 8.0, 0, cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
  const double texture = cv::mean(gx.mul(gx) + gy.mul(gy))[0];
  if (texture < 1e-6) return "no texture: the left image is uniform in the roi (nothing to match)";
  if (coarse_valid < 0.02)
    return "no overlap: under 2 % of the roi matched within the disparity range [" + num(o.min_disparity) + ", " +
           num(o.max_disparity) + "] px (do the images overlap? is the working depth range right?)";
  return "";
}

}  // namespace

DisparityMap computeDisparity(const cv::Mat& left, const cv::Mat& right, const DenseStereoOptions& o) {
  const auto t0 = Clock::now();
  validate(left, right, o);
  DisparityMap out;
  out.disparity = cv::Mat(left.size(), CV_32F, cv::Scalar(kNaN));
  out.sigma = cv::Mat(left.size(), CV_32F, cv::Scalar(kNaN));
  out.vertical = cv::Mat(left.size(), CV_32F, cv::Scalar(kNaN));
  const Crops c = prepareCrops(left, right, o, out);
  out.roi = c.roi;
  out.coarse_scale = c.s;
  const auto t1 = Clock::now();
  const cv::Mat dc = coarseSemiGlobal(c, o);
  const auto t2 = Clock::now();
  out.timing.prepare = seconds(t0, t1);
  out.timing.sgbm = seconds(t1, t2);
  const std::string nothing = nothingToMatch(c, dc, o);
  if (!nothing.empty()) {
    out.warnings.push_back(nothing);
    out.timing.total = seconds(t0, Clock::now());
    return out;
  }
  FineMaps f = o.subpixel == "sgbm" ? fromSemiGlobal(c, dc) : fitCoarseToFine(c, dc, o);
  if (o.weak_texture && o.speckle_window > 0 && o.subpixel == "lk") removeIslands(f, o, c.s);
  const auto t3 = Clock::now();
  writeImageMaps(c, f, o, left, out);
  if (out.valid_fraction < 0.1)
    out.warnings.push_back("little matched: " + num(std::round(1000 * out.valid_fraction) / 10) +
                           " % of the roi has a disparity (texture, overlap, saturation or disparity range?)");
  out.timing.refine = seconds(t2, t3);
  out.timing.total = seconds(t0, Clock::now());
  return out;
}

const char* unknownReasonName(UnknownReason r) {
  switch (r) {
    case UnknownReason::kKnown: return "known";
    case UnknownReason::kNoSemiGlobal: return "no semi-global answer";
    case UnknownReason::kTexture: return "texture";
    case UnknownReason::kSigma: return "sigma";
    case UnknownReason::kCorrelation: return "correlation";
    case UnknownReason::kDisagreement: return "disagreement";
    case UnknownReason::kIsland: return "island";
    case UnknownReason::kBorder: return "border";
    default: return "?";
  }
}

std::string describeUnknown(const DisparityMap& map) {
  std::vector<std::pair<double, int>> r;
  for (size_t i = 1; i < map.unknown_share.size(); ++i)
    if (map.unknown_share[i] >= 5e-4) r.emplace_back(map.unknown_share[i], static_cast<int>(i));
  std::sort(r.rbegin(), r.rend());
  std::string s = "unknown:";
  if (r.empty()) s += " none";
  for (size_t i = 0; i < r.size(); ++i)
    s += (i ? ", " : " ") + num(std::round(1000 * r[i].first) / 10) + " % " +
         unknownReasonName(static_cast<UnknownReason>(r[i].second));
  return s;
}

cv::Mat unknownReasonImage(const DisparityMap& map, const cv::Mat& left) {
  if (map.unknown_reason.empty() || left.size() != map.unknown_reason.size()) return {};
  static const cv::Vec3b colour[] = {{0, 0, 0},     {0, 140, 255}, {255, 80, 0},   {0, 220, 255},
                                     {0, 0, 230},   {220, 0, 220}, {230, 230, 0},  {60, 60, 60}};  // BGR
  cv::Mat grey = left, out;
  if (grey.channels() == 3) cv::cvtColor(grey, grey, cv::COLOR_BGR2GRAY);
  if (grey.depth() != CV_8U) grey.convertTo(grey, CV_8U, grey.depth() == CV_16U ? 1.0 / 256 : 255.0);
  cv::cvtColor(grey, out, cv::COLOR_GRAY2BGR);
  for (int y = 0; y < out.rows; ++y) {
    const uchar* w = map.unknown_reason.ptr<uchar>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < out.cols; ++x)
      if (w[x] > 0 && w[x] < static_cast<uchar>(UnknownReason::kCount)) {
        const cv::Vec3b& c = colour[w[x]];
        for (int k = 0; k < 3; ++k) o[x][k] = static_cast<uchar>((o[x][k] + 3 * c[k]) / 4);
      }
  }
  const double scale = std::max(1.0, out.cols / 1500.0);
  for (int i = 1; i < static_cast<int>(UnknownReason::kCount); ++i) {
    const int y = static_cast<int>(scale * (10 + 24 * i));
    cv::rectangle(out, cv::Rect(static_cast<int>(10 * scale), y - static_cast<int>(16 * scale), static_cast<int>(16 * scale),
                                static_cast<int>(16 * scale)),
                  cv::Scalar(colour[i][0], colour[i][1], colour[i][2]), cv::FILLED);
    cv::putText(out, unknownReasonName(static_cast<UnknownReason>(i)), cv::Point(static_cast<int>(34 * scale), y),
                cv::FONT_HERSHEY_SIMPLEX, 0.6 * scale, cv::Scalar(255, 255, 255), std::max(1, static_cast<int>(scale)));
  }
  return out;
}

std::pair<double, double> disparityRangeForDepth(const geometry::CameraInfo& left, const geometry::CameraInfo& right,
                                                 double z_min, double z_max) {
  if (!(z_min > 0) || !(z_max > z_min))
    throw DenseStereoError("working depth range [" + num(z_min) + ", " + num(z_max) + "] m must have 0 < z_min < z_max");
  const double fx = left.P(0, 0);
  if (!(fx > 0) || !(right.P(0, 0) > 0)) throw DenseStereoError("rectified projection P has no focal length");
  const double fb = -right.P(0, 3);  // fx * B
  if (!(fb > 0)) throw DenseStereoError("right P(0,3) = -fx B must be negative (a horizontal rectified pair, right camera on the right)");
  if (std::fabs(right.P(1, 3)) > 1e-9 * std::max(1.0, fb))
    throw DenseStereoError("right P(1,3) is not 0: a vertical rectified pair is not supported");
  const double dc = left.P(0, 2) - right.P(0, 2);
  return {fb / z_max + dc, fb / z_min + dc};
}

DenseCloud triangulateDisparity(const DisparityMap& map, const geometry::CameraInfo& left,
                                const geometry::CameraInfo& right) {
  if (map.disparity.empty() || map.disparity.type() != CV_32F) throw DenseStereoError("disparity map is empty");
  if (left.width != map.disparity.cols || left.height != map.disparity.rows)
    throw DenseStereoError("left camera_info is " + std::to_string(left.width) + "x" + std::to_string(left.height) +
                           " but the disparity map is " + std::to_string(map.disparity.cols) + "x" +
                           std::to_string(map.disparity.rows));
  const double fx = left.P(0, 0), fy = left.P(1, 1), cx = left.P(0, 2), cy = left.P(1, 2);
  if (!(fx > 0) || !(fy > 0)) throw DenseStereoError("left P has no focal length");
  const double fb = -right.P(0, 3);
  if (!(fb > 0)) throw DenseStereoError("right P(0,3) = -fx B must be negative (a horizontal rectified pair)");
  const double dc = cx - right.P(0, 2);
  const Eigen::Matrix3d Rt = left.R.transpose();  // rectified -> left optical
  DenseCloud c;
  c.xyz = cv::Mat(map.disparity.size(), CV_32FC3, cv::Scalar::all(kNaN));
  c.sigma = cv::Mat(map.disparity.size(), CV_32F, cv::Scalar(kNaN));
  c.ray = cv::Mat(map.disparity.size(), CV_32FC3);
  {
    // the right camera sits at x = B on the rectified x axis: B = fx B / fx
    const Eigen::Vector3d rc = Rt * Eigen::Vector3d(fb / fx, 0, 0);
    c.right_centre = cv::Vec3d(rc.x(), rc.y(), rc.z());
  }
  const bool have_sigma = !map.sigma.empty();
  for (int y = 0; y < map.disparity.rows; ++y) {
    const float* dp = map.disparity.ptr<float>(y);
    const float* sp = have_sigma ? map.sigma.ptr<float>(y) : nullptr;
    cv::Vec3f* xp = c.xyz.ptr<cv::Vec3f>(y);
    cv::Vec3f* rp = c.ray.ptr<cv::Vec3f>(y);
    float* op = c.sigma.ptr<float>(y);
    for (int x = 0; x < map.disparity.cols; ++x) {
      const Eigen::Vector3d m((x - cx) / fx, (y - cy) / fy, 1.0);
      const Eigen::Vector3d ray = Rt * m.normalized();
      rp[x] = cv::Vec3f(static_cast<float>(ray.x()), static_cast<float>(ray.y()), static_cast<float>(ray.z()));
      const double den = dp[x] - dc;
      if (std::isnan(dp[x]) || !(den > 0)) continue;
      const double z = fb / den;
      const Eigen::Vector3d X = Rt * (m * z);
      xp[x] = cv::Vec3f(static_cast<float>(X.x()), static_cast<float>(X.y()), static_cast<float>(X.z()));
      if (sp && std::isfinite(sp[x])) op[x] = static_cast<float>(z / den * sp[x] * m.norm());
    }
  }
  return c;
}

}  // namespace stereo
}  // namespace skin3d
