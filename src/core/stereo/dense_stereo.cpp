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
#include "dense_stereo_detail.h"

namespace skin3d {
namespace stereo {

using namespace dense_detail;  // NOLINT(build/namespaces): the private helpers of the dense matcher's files

namespace {

using common::num;
using Clock = std::chrono::steady_clock;
constexpr float kMinSigma = 0.005f;  // px: floor of the reported sigma (interpolation and 8-bit quantisation)

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

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
  if (o.coarse_min_levels < 0 || o.coarse_min_levels > 6)
    throw DenseStereoError("coarse_min_levels " + std::to_string(o.coarse_min_levels) + " must be 0 ... 6");
  if (o.coarse_max_width < 64) throw DenseStereoError("coarse_max_width " + std::to_string(o.coarse_max_width) + " must be >= 64");
  if (!(o.lr_max_diff >= 0) || !(o.refine_max_shift > 0) || !(o.max_sigma > 0) || !(o.min_texture >= 0) ||
      o.uniqueness_ratio < 0 || o.speckle_window < 0 || !(o.speckle_range >= 0) || o.p1 < 0 || o.p2 < 0)
    throw DenseStereoError("lr_max_diff, refine_max_shift, max_sigma, min_texture, uniqueness_ratio, speckle_* and p1/p2 "
                           "must be >= 0 (refine_max_shift and max_sigma > 0)");
  if (o.p1 > 0 && o.p2 > 0 && o.p2 <= o.p1) throw DenseStereoError("p2 must be larger than p1");
  if (o.slant_passes < 0 || o.slant_passes > 3)
    throw DenseStereoError("slant_passes " + std::to_string(o.slant_passes) + " must be 0 ... 3");
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
    case UnknownReason::kOblique: return "oblique";
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
                                     {0, 0, 230},   {220, 0, 220}, {230, 230, 0},  {60, 60, 60},
                                     {150, 150, 255}};  // BGR
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
