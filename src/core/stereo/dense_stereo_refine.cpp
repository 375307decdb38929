// SPDX-License-Identifier: BSD-3-Clause
// Dense matching: the coarse-to-fine local correlation fit and the judgement of each pixel's fit.
// See include/skin3d/stereo/dense_stereo.h for the method.
#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "../common/parallel.h"
#include "dense_stereo_detail.h"

namespace skin3d {
namespace stereo {
namespace dense_detail {

namespace {

// Where SGBM left a hole, the fit alone decides: it needs a full-resolution correlation of 0.5 and a low-passed one
// (Refined::corr_smooth) of 0.7 (on the skin scenes, hole fits below that were mostly wrong by > 0.15 mm).
constexpr float kHoleCorrelation = 0.5f;
constexpr float kHoleCorrelationSmooth = 0.7f;

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

}  // namespace

/**
 * A fit that disagrees with the semi-global value is kept when it lies on the surface of the fits around it that
 * agree (`neighbour_check`). On weakly textured skin the coarse semi-global answer has scattered, row-streaked
 * errors of a coarse pixel or more, while the full-resolution fit (started from its surroundings) lands on the
 * surface; a fit at a wrong minimum lands a pixel or more off it. The agreeing fits within `radius` px (at least
 * half the square) give a least-squares plane; the pixel is kept when its fit differs from the plane at its centre
 * by at most 3 sigma of a prediction: the neighbours' scatter about the plane (their noise and the surface's
 * curvature) or the pixel's own fit sigma, whichever is larger, plus the plane's uncertainty at the centre. Where
 * the neighbours scatter about their plane by more than twice their own stated sigma, they do not lie on one smooth
 * surface (a step between two surfaces), and nothing is kept.
 * One pass, judged against the agreeing fits only (kept pixels do not vouch for others). Returns the pixels kept.
 */
long keepFitsOnTheirNeighbours(const cv::Mat& d, const cv::Mat& sigma, cv::Mat& valid, cv::Mat& reason, int radius) {
  constexpr int kStride = 2;
  const cv::Mat agree = valid.clone();  // the judge's verdict before this pass
  const int rows = d.rows, cols = d.cols;
  std::vector<long> kept_per_row(static_cast<size_t>(rows), 0);
  forEachIndex(rows, [&](int y) {
    uchar* rp = reason.ptr<uchar>(y);
    uchar* vp = valid.ptr<uchar>(y);
    const float* dy0 = d.ptr<float>(y);
    const float* sy0 = sigma.ptr<float>(y);
    for (int x = 0; x < cols; ++x) {
      if (rp[x] != static_cast<uchar>(UnknownReason::kDisagreement)) continue;
      const double d0 = dy0[x];
      if (!std::isfinite(d0)) continue;
      // sums over the agreeing neighbours, in coordinates centred on the pixel and disparities relative to its fit
      // (every second row and column: neighbouring fits share most of their window, and a 12 MP frame has millions
      // of pixels to judge)
      double n = 0, su = 0, sv = 0, suu = 0, suv = 0, svv = 0, se = 0, sue = 0, sve = 0, see = 0, ss2 = 0;
      int square = 0;  // sampled positions inside the field
      for (int v = -radius; v <= radius; v += kStride) {
        const int yy = y + v;
        if (yy < 0 || yy >= rows) continue;
        const uchar* ap = agree.ptr<uchar>(yy);
        const float* dp = d.ptr<float>(yy);
        const float* sp = sigma.ptr<float>(yy);
        for (int u = -radius; u <= radius; u += kStride) {
          const int xx = x + u;
          if (xx < 0 || xx >= cols) continue;
          ++square;
          if (!ap[xx] || !std::isfinite(dp[xx])) continue;
          const double e = dp[xx] - d0;
          n += 1;
          su += u;
          sv += v;
          suu += u * u;
          suv += u * v;
          svv += v * v;
          se += e;
          sue += u * e;
          sve += v * e;
          see += e * e;
          if (std::isfinite(sp[xx])) ss2 += static_cast<double>(sp[xx]) * sp[xx];
        }
      }
      if (n < std::max(10, square / 2)) continue;  // at least half the square (clipped to the field)
      const cv::Matx33d A(n, su, sv, su, suu, suv, sv, suv, svv);
      const cv::Matx33d Ai = A.inv(cv::DECOMP_CHOLESKY);
      const cv::Vec3d b(se, sue, sve);
      const cv::Vec3d beta = Ai * b;
      const double rss = std::max(0.0, see - beta.dot(b));
      const double scatter2 = rss / (n - 3);
      const double own2 = std::isfinite(sy0[x]) ? static_cast<double>(sy0[x]) * sy0[x] : scatter2;
      const double var = std::max(scatter2, own2) + scatter2 * Ai(0, 0);
      // the neighbours vouch only where they lie on a smooth surface: their scatter about the plane within twice
      // their own stated sigma (at a step between two surfaces it is many times wider, and a fit there proves nothing)
      if (scatter2 > 4.0 * ss2 / n) continue;
      if (beta[0] * beta[0] <= 9.0 * var) {  // beta[0] = the plane at the centre - the pixel's fit
        vp[x] = 255;
        rp[x] = static_cast<uchar>(UnknownReason::kKnown);
        ++kept_per_row[static_cast<size_t>(y)];
      }
    }
  });
  long kept = 0;
  for (long k : kept_per_row) kept += k;
  return kept;
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
  if (o.neighbour_check) keepFitsOnTheirNeighbours(f.d, f.sigma, f.valid, f.reason, o.refine_window);
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

}  // namespace dense_detail
}  // namespace stereo
}  // namespace skin3d
