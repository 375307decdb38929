// SPDX-License-Identifier: BSD-3-Clause
// Dense matching: the images prepared (grey, crops, pyramids) and semi-global matching at the coarse level.
// See include/skin3d/stereo/dense_stereo.h for the method.
#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "../common/text.h"
#include "dense_stereo_detail.h"

namespace skin3d {
namespace stereo {
namespace dense_detail {

using common::num;
constexpr int kMaxCoarseDisparities = 640;  // deeper searches are done at a coarser level

namespace {

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

}  // namespace

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

namespace {

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

}  // namespace

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
  // halve coarse_min_levels times, then until the roi is at most coarse_max_width wide and the search at most
  // kMaxCoarseDisparities deep
  while ((c.levels < o.coarse_min_levels || (roi.width >> c.levels) > o.coarse_max_width ||
          (c.range >> c.levels) > kMaxCoarseDisparities) && c.levels < 6)
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

}  // namespace dense_detail
}  // namespace stereo
}  // namespace skin3d
