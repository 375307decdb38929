// SPDX-License-Identifier: BSD-3-Clause
// Results of an induration measurement: induration.yaml, the false-colour height map and the surface
// mesh (see induration_io.h).
#include "skin3d/induration/induration_io.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <utility>

namespace skin3d {
namespace induration {

namespace {

constexpr double kMm = 1e3;            //!< m -> mm
constexpr double kMm2 = 1e6;           //!< m^2 -> mm^2
constexpr double kMatchRadius = 5e-3;  //!< m: a plaque is the same one in another frame within this distance

// ------------------------------------------------------------------------------------------ induration.yaml

/** @brief Sample mean and standard deviation (n - 1; NaN for fewer than two values). */
std::pair<double, double> meanStd(const std::vector<double>& v) {
  if (v.empty()) return {std::nan(""), std::nan("")};
  double sum = 0;
  for (double x : v) sum += x;
  const double mean = sum / v.size();
  if (v.size() < 2) return {mean, std::nan("")};
  double ss = 0;
  for (double x : v) ss += (x - mean) * (x - mean);
  return {mean, std::sqrt(ss / (v.size() - 1))};
}

void emitVector(YAML::Emitter& y, const Eigen::Vector3d& v, double scale = 1.0) {
  y << YAML::Flow << YAML::BeginSeq << scale * v.x() << scale * v.y() << scale * v.z() << YAML::EndSeq;
}

/** @brief A finite number, or null (a program reading the file sees "no value", not a NaN to compare). */
void emitNumber(YAML::Emitter& y, double v) {
  if (std::isfinite(v))
    y << v;
  else
    y << YAML::Null;
}

void emitMeanStd(YAML::Emitter& y, const char* key, const std::vector<double>& v, double scale) {
  std::vector<double> s;
  for (double x : v) s.push_back(scale * x);
  const auto ms = meanStd(s);
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "mean" << YAML::Value;
  emitNumber(y, ms.first);
  y << YAML::Key << "std" << YAML::Value;
  emitNumber(y, ms.second);
  y << YAML::EndMap;
}

void emitOptions(YAML::Emitter& y, const IndurationOptions& o) {
  y << YAML::Key << "options" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "reference_model" << YAML::Value << o.reference_model;
  y << YAML::Key << "min_height_mm" << YAML::Value << kMm * o.min_height;
  y << YAML::Key << "min_area_mm2" << YAML::Value << kMm2 * o.min_area;
  y << YAML::Key << "max_height_mm" << YAML::Value << kMm * o.max_height;
  y << YAML::Key << "max_incidence_deg" << YAML::Value << o.max_incidence_deg;
  y << YAML::Key << "smoothing_px" << YAML::Value << o.smoothing_px;
  y << YAML::Key << "max_smoothing_px" << YAML::Value << o.max_smoothing_px;
  y << YAML::Key << "edge_fraction" << YAML::Value << o.edge_fraction;
  y << YAML::Key << "min_measured_share" << YAML::Value << o.min_measured_share;
  y << YAML::Key << "exclusion_margin_px" << YAML::Value << o.exclusion_margin_px;
  y << YAML::Key << "interior_margin_px" << YAML::Value << o.interior_margin_px;
  y << YAML::Key << "sor_std_ratio" << YAML::Value << o.sor_std_ratio;
  y << YAML::Key << "ransac_threshold_mm" << YAML::Value << kMm * o.ransac_threshold;
  y << YAML::Key << "fit_points" << YAML::Value << o.fit_points;
  y << YAML::Key << "max_iterations" << YAML::Value << o.max_iterations;
  y << YAML::Key << "min_reference_fraction" << YAML::Value << o.min_reference_fraction;
  y << YAML::Key << "pasi_boundaries_mm" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (double b : o.pasi_boundaries) y << kMm * b;
  y << YAML::EndSeq << YAML::EndMap;
}

void emitReference(YAML::Emitter& y, const IndurationResult& r) {
  y << YAML::Key << "reference_ok" << YAML::Value << r.reference_ok;
  y << YAML::Key << "reference" << YAML::Value;
  if (!r.reference_ok) {
    y << YAML::Null;
    return;
  }
  const ReferenceSurface& s = r.reference;
  y << YAML::BeginMap;
  y << YAML::Key << "model" << YAML::Value << s.model;
  y << YAML::Key << "n" << YAML::Value;
  emitVector(y, s.normal);
  y << YAML::Key << "d" << YAML::Value << s.d;
  y << YAML::Key << "rms_mm" << YAML::Value << kMm * s.rms;
  y << YAML::Key << "points" << YAML::Value << s.points;
  // whether it follows the skin: the share of the working band beyond the detection threshold off it, and its
  // healthy-skin scatter over the matcher's stated noise
  y << YAML::Key << "follows_skin" << YAML::Value << r.reference_follows;
  y << YAML::Key << "unfollowed_share" << YAML::Value << r.unfollowed_share;
  if (std::isfinite(r.reference_noise_ratio)) y << YAML::Key << "noise_ratio" << YAML::Value << r.reference_noise_ratio;
  if (std::isfinite(r.height_noise)) {
    y << YAML::Key << "height_noise_mm" << YAML::Value << kMm * r.height_noise;
    y << YAML::Key << "noise_correlation_px2" << YAML::Value << r.noise_correlation_px2;
  }
  y << YAML::Key << "candidates" << YAML::Value << YAML::BeginSeq;  // every model tried, robust scale of its healthy residuals
  for (const auto& c : s.candidates)
    y << YAML::Flow << YAML::BeginMap << YAML::Key << "model" << YAML::Value << c.first << YAML::Key << "scale_mm"
      << YAML::Value << kMm * c.second << YAML::EndMap;
  y << YAML::EndSeq;
  if (s.model == "quadric") {
    y << YAML::Key << "centre" << YAML::Value;
    emitVector(y, s.q_centre);
    y << YAML::Key << "scale_m" << YAML::Value << s.q_scale;
    y << YAML::Key << "sign" << YAML::Value << s.q_sign;
    y << YAML::Key << "coefficients" << YAML::Value << YAML::Flow << YAML::BeginSeq;
    for (int i = 0; i < 10; ++i) y << s.coefficients[i];
    y << YAML::EndSeq;
  } else if (s.model != "plane") {
    y << YAML::Key << "origin" << YAML::Value;
    emitVector(y, s.origin);
    y << YAML::Key << "e1" << YAML::Value;
    emitVector(y, s.e1);
    y << YAML::Key << "e2" << YAML::Value;
    emitVector(y, s.e2);
    y << YAML::Key << "quadric" << YAML::Value << YAML::Flow << YAML::BeginSeq;
    for (int i = 0; i < 6; ++i) y << s.quadric[i];
    y << YAML::EndSeq;
  }
  y << YAML::EndMap;
}

void emitPlaque(YAML::Emitter& y, const Plaque& p) {
  y << YAML::BeginMap;
  y << YAML::Key << "id" << YAML::Value << p.id;
  y << YAML::Key << "centroid_m" << YAML::Value;
  emitVector(y, p.centroid);
  y << YAML::Key << "area_mm2" << YAML::Value << kMm2 * p.area;
  y << YAML::Key << "top_height_mm" << YAML::Value << kMm * p.top_height;
  y << YAML::Key << "mean_height_mm" << YAML::Value << kMm * p.mean_height;
  y << YAML::Key << "max_height_mm" << YAML::Value << kMm * p.max_height;
  y << YAML::Key << "std_height_mm" << YAML::Value << kMm * p.std_height;
  y << YAML::Key << "mean_height_sigma_mm" << YAML::Value;
  emitNumber(y, kMm * p.mean_height_sigma);
  y << YAML::Key << "top_height_sigma_mm" << YAML::Value;
  emitNumber(y, kMm * p.top_height_sigma);
  y << YAML::Key << "surround_offset_mm" << YAML::Value;
  emitNumber(y, kMm * p.surround_offset);
  y << YAML::Key << "pasi_class" << YAML::Value << p.pasi_class;
  y << YAML::Key << "pixels" << YAML::Value << p.pixels;
  y << YAML::Key << "measured_share" << YAML::Value << p.measured_fraction;
  y << YAML::Key << "outline_unmeasured_share" << YAML::Value << p.outline_unmeasured;
  y << YAML::Key << "border_width_mm" << YAML::Value << p.border_width * 1e3;
  y << YAML::Key << "volume_mm3" << YAML::Value << p.volume * 1e9;
  y << YAML::Key << "bbox_px" << YAML::Value << YAML::Flow << YAML::BeginSeq << p.bbox.x << p.bbox.y << p.bbox.width
    << p.bbox.height << YAML::EndSeq;
  y << YAML::EndMap;
}

/** @brief For each plaque of frame 0, its match in `frame` (index into its plaques, or -1): pairs closest
 *  first, each plaque used once, centroids at most kMatchRadius apart. */
std::vector<int> matchPlaques(const std::vector<Plaque>& base, const std::vector<Plaque>& frame) {
  std::vector<std::pair<double, std::pair<int, int>>> pairs;
  for (size_t i = 0; i < base.size(); ++i)
    for (size_t j = 0; j < frame.size(); ++j) {
      const double d = (base[i].centroid - frame[j].centroid).norm();
      if (d <= kMatchRadius) pairs.push_back({d, {static_cast<int>(i), static_cast<int>(j)}});
    }
  std::sort(pairs.begin(), pairs.end());
  std::vector<int> match(base.size(), -1);
  std::vector<bool> used(frame.size(), false);
  for (const auto& p : pairs) {
    const int i = p.second.first, j = p.second.second;
    if (match[i] < 0 && !used[j]) {
      match[i] = j;
      used[j] = true;
    }
  }
  return match;
}

void emitRepeatability(YAML::Emitter& y, const std::vector<FrameRecord>& frames, const IndurationOptions& options) {
  y << YAML::Key << "repeatability" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "frames" << YAML::Value << frames.size();
  y << YAML::Key << "match_radius_mm" << YAML::Value << kMm * kMatchRadius;
  y << YAML::Key << "plaques" << YAML::Value << YAML::BeginSeq;
  const std::vector<Plaque> empty;
  const std::vector<Plaque>& base = frames.empty() ? empty : frames.front().result.plaques;
  std::vector<std::vector<int>> matches;  // [frame][base plaque]
  for (size_t f = 0; f < frames.size(); ++f) {
    std::vector<int> identity(base.size());
    for (size_t i = 0; i < base.size(); ++i) identity[i] = static_cast<int>(i);
    matches.push_back(f == 0 ? identity : matchPlaques(base, frames[f].result.plaques));
  }
  for (size_t i = 0; i < base.size(); ++i) {
    std::vector<double> top, mean, max, stdh, area, sigma, top_sigma;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    y << YAML::BeginMap;
    y << YAML::Key << "id" << YAML::Value << base[i].id;
    y << YAML::Key << "ids_per_frame" << YAML::Value << YAML::Flow << YAML::BeginSeq;
    for (size_t f = 0; f < frames.size(); ++f) {
      const int j = matches[f][i];
      if (j < 0) {
        y << YAML::Null;
        continue;
      }
      const Plaque& p = frames[f].result.plaques[j];
      y << p.id;
      top.push_back(p.top_height);
      mean.push_back(p.mean_height);
      max.push_back(p.max_height);
      stdh.push_back(p.std_height);
      area.push_back(p.area);
      sigma.push_back(p.mean_height_sigma);
      top_sigma.push_back(p.top_height_sigma);
      centroid += p.centroid;
    }
    y << YAML::EndSeq;
    y << YAML::Key << "frames_found" << YAML::Value << mean.size();
    y << YAML::Key << "centroid_m" << YAML::Value;
    emitVector(y, centroid / static_cast<double>(mean.size()));  // frame 0 always matches itself: size >= 1
    emitMeanStd(y, "top_height_mm", top, kMm);
    emitMeanStd(y, "mean_height_mm", mean, kMm);
    emitMeanStd(y, "max_height_mm", max, kMm);
    emitMeanStd(y, "std_height_mm", stdh, kMm);
    emitMeanStd(y, "area_mm2", area, kMm2);
    emitMeanStd(y, "mean_height_sigma_mm", sigma, kMm);
    emitMeanStd(y, "top_height_sigma_mm", top_sigma, kMm);
    y << YAML::Key << "pasi_class_of_mean" << YAML::Value << pasiClass(meanStd(top).first, options.pasi_boundaries);
    y << YAML::EndMap;
  }
  y << YAML::EndSeq << YAML::EndMap;
}

// ------------------------------------------------------------------------------------------ height map image

const cv::Scalar kUnknown(60, 60, 60);  //!< BGR, dark grey
const cv::Scalar kBackground(0, 0, 0);
const cv::Scalar kWhite(255, 255, 255);
constexpr int kColourMap = cv::COLORMAP_VIRIDIS;
constexpr int kTitleHeight = 28;    //!< px
constexpr int kPanelWidth = 110;    //!< px, right of the map: the scale bar and its labels
constexpr int kMinBarRegion = 160;  //!< px, the canvas below the title is at least this high

/** @brief White text with a black outline (readable on any colour). */
void label(cv::Mat& img, const std::string& text, cv::Point at, double scale) {
  cv::putText(img, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(img, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, kWhite, 1, cv::LINE_AA);
}

/** @brief 1, 2, 2.5 or 5 x 10^k nearest above `raw`; `decimals` to print its multiples. */
double niceStep(double raw, int* decimals) {
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  double m = 10;
  for (double c : {1.0, 2.0, 2.5, 5.0})
    if (c * p >= raw * (1 - 1e-6)) {  // tolerant: a float height map gives 0.50000002 mm
      m = c;
      break;
    }
  const int k = static_cast<int>(std::lround(std::log10(p))) + (m == 10 ? 1 : 0);
  *decimals = std::max(0, -k) + (m == 2.5 ? 1 : 0);
  return m * p;
}

void drawScaleBar(cv::Mat& canvas, int x0, int top, int bottom, double max_mm) {
  const int width = 18;
  const int h = bottom - top;
  cv::Mat ramp(h + 1, 1, CV_8U);
  for (int i = 0; i <= h; ++i) ramp.at<uchar>(i) = cv::saturate_cast<uchar>(255.0 * (h - i) / h);
  cv::Mat ramp_colour;
  cv::applyColorMap(ramp, ramp_colour, kColourMap);
  for (int i = 0; i <= h; ++i)
    cv::line(canvas, {x0, top + i}, {x0 + width - 1, top + i}, cv::Scalar(ramp_colour.at<cv::Vec3b>(i)));
  cv::rectangle(canvas, {x0 - 1, top - 1}, {x0 + width, bottom + 1}, kWhite, 1);
  int decimals = 0;
  const double step = niceStep(max_mm / 5.0, &decimals);
  for (int k = 0; k * step <= max_mm * (1 + 1e-6); ++k) {
    const double t = k * step;
    const int y = bottom - static_cast<int>(std::lround(t / max_mm * h));
    cv::line(canvas, {x0 + width, y}, {x0 + width + 5, y}, kWhite, 1);
    char text[32];
    std::snprintf(text, sizeof(text), "%.*f", decimals, t);
    cv::putText(canvas, text, {x0 + width + 8, y + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.42, kWhite, 1, cv::LINE_AA);
  }
  cv::putText(canvas, "mm", {x0, top - 6}, cv::FONT_HERSHEY_SIMPLEX, 0.45, kWhite, 1, cv::LINE_AA);
}

// ------------------------------------------------------------------------------------------ PLY

/** @brief Little-endian binary output through a buffer (independent of the machine's byte order). */
class LeWriter {
 public:
  LeWriter(std::ofstream& f, const std::string& path) : f_(f), path_(path) { buf_.reserve(kChunk + 64); }
  void u8(uint8_t v) { buf_.push_back(static_cast<char>(v)); }
  void u32(uint32_t v) {
    for (int i = 0; i < 4; ++i) buf_.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  }
  void f32(float v) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    u32(u);
  }
  void i32(int32_t v) { u32(static_cast<uint32_t>(v)); }
  void maybeFlush() {
    if (buf_.size() >= kChunk) flush();
  }
  void flush() {
    f_.write(buf_.data(), static_cast<std::streamsize>(buf_.size()));
    if (!f_) throw std::runtime_error("error while writing '" + path_ + "'");
    buf_.clear();
  }

 private:
  static constexpr size_t kChunk = 1 << 20;
  std::ofstream& f_;
  const std::string& path_;
  std::vector<char> buf_;
};

/** @brief The colour image as 8-bit BGR of the cloud's size (white when empty). */
cv::Mat colourBgr8(const cv::Mat& colour, const cv::Size& size, const std::string& path) {
  if (colour.empty()) return cv::Mat(size, CV_8UC3, kWhite);
  if (colour.size() != size)
    throw std::invalid_argument("writeSurfacePly('" + path + "'): colour image " + std::to_string(colour.cols) + "x" +
                                std::to_string(colour.rows) + " is not the cloud's size " + std::to_string(size.width) +
                                "x" + std::to_string(size.height));
  cv::Mat c8;
  if (colour.depth() == CV_8U)
    c8 = colour;
  else if (colour.depth() == CV_16U)
    colour.convertTo(c8, CV_8U, 1.0 / 256.0);
  else
    throw std::invalid_argument("writeSurfacePly('" + path + "'): colour image must be 8- or 16-bit");
  cv::Mat bgr;
  switch (c8.channels()) {
    case 1:
      cv::cvtColor(c8, bgr, cv::COLOR_GRAY2BGR);
      break;
    case 3:
      bgr = c8;
      break;
    case 4:
      cv::cvtColor(c8, bgr, cv::COLOR_BGRA2BGR);
      break;
    default:
      throw std::invalid_argument("writeSurfacePly('" + path + "'): colour image must be grey, BGR or BGRA");
  }
  return bgr;
}

}  // namespace

void writeInduration(const std::string& path, const std::vector<FrameRecord>& frames, const IndurationOptions& options,
                     const std::string& frame_id, const std::string& source) {
  YAML::Emitter y;
  y.SetDoublePrecision(10);
  y << YAML::BeginMap;
  y << YAML::Key << "units" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "length" << YAML::Value << "mm (keys ending in _mm)";
  y << YAML::Key << "area" << YAML::Value << "mm^2 (keys ending in _mm2)";
  y << YAML::Key << "position" << YAML::Value << "m (centroid_m; reference n unit, d, origin in m)";
  y << YAML::Key << "time" << YAML::Value << "s";
  y << YAML::EndMap;
  y << YAML::Key << "frame_id" << YAML::Value << frame_id;
  y << YAML::Key << "source" << YAML::Value << source;
  emitOptions(y, options);
  y << YAML::Key << "frames" << YAML::Value << YAML::BeginSeq;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameRecord& f = frames[i];
    const IndurationResult& r = f.result;
    y << YAML::BeginMap;
    y << YAML::Key << "index" << YAML::Value << i;
    y << YAML::Key << "stamp" << YAML::Value << YAML::Precision(17) << f.stamp;
    y << YAML::Key << "seconds" << YAML::Value << f.seconds;
    y << YAML::Key << "valid_fraction" << YAML::Value << f.valid_fraction;
    y << YAML::Key << "depth_range_m" << YAML::Value << YAML::Flow << YAML::BeginSeq << f.z_near
      << (std::isfinite(f.z_far) ? f.z_far : -1.0) << YAML::EndSeq;
    y << YAML::Key << "disparity_range_px" << YAML::Value << YAML::Flow << YAML::BeginSeq << f.min_disparity
      << f.max_disparity << YAML::EndSeq;
    y << YAML::Key << "depth_range" << YAML::Value << (f.range_searched ? "searched" : "set");
    if (std::isfinite(f.vertical_median))
      y << YAML::Key << "vertical_disparity_px" << YAML::Value << YAML::BeginMap << YAML::Key << "median"
        << YAML::Value << f.vertical_median << YAML::Key << "spread" << YAML::Value << f.vertical_spread
        << YAML::EndMap;
    y << YAML::Key << "known_points" << YAML::Value << r.known_points;
    y << YAML::Key << "outliers_removed" << YAML::Value << r.outliers_removed;
    y << YAML::Key << "smoothing_px" << YAML::Value << r.smoothing_px;
    y << YAML::Key << "band_fraction" << YAML::Value << r.band_fraction;
    y << YAML::Key << "detection_threshold_mm" << YAML::Value << kMm * r.detection_threshold;
    if (r.wide_smoothing_px > 0)
      y << YAML::Key << "wide_scale" << YAML::Value << YAML::BeginMap << YAML::Key << "smoothing_px" << YAML::Value
        << r.wide_smoothing_px << YAML::Key << "detection_threshold_mm" << YAML::Value << kMm * r.wide_detection_threshold
        << YAML::Key << "min_area_mm2" << YAML::Value << 1e6 * r.wide_min_area << YAML::EndMap;
    emitReference(y, r);
    y << YAML::Key << "warnings" << YAML::Value << YAML::BeginSeq;
    for (const auto& w : r.warnings) y << w;
    y << YAML::EndSeq;
    y << YAML::Key << "plaques" << YAML::Value << YAML::BeginSeq;
    for (const auto& p : r.plaques) emitPlaque(y, p);
    y << YAML::EndSeq;
    y << YAML::EndMap;
  }
  y << YAML::EndSeq;
  emitRepeatability(y, frames, options);
  y << YAML::EndMap;
  if (!y.good()) throw std::runtime_error("cannot format '" + path + "': " + y.GetLastError());

  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write induration results to '" + path + "'");
  f << "# skin3d induration measurement (docs/design.md, \"Results of an offline run\").\n"
       "# Heights above the healthy-skin reference in mm, areas on the reference in mm^2, positions in m\n"
       "# (frame_id); the reference plane is n.x + d = 0 with n towards the camera. repeatability: each plaque\n"
       "# of frame 0 matched in every frame by the nearest centroid within match_radius_mm; mean and sample\n"
       "# std (n - 1, null with fewer than 2 frames) over the frames where it was found.\n"
    << y.c_str() << '\n';
  f.close();
  if (!f) throw std::runtime_error("error while writing induration results to '" + path + "'");
}

// Layout: a title line, the map (left, shrunk if needed), the scale bar with ticks in mm on the right. An empty
// height map (no reference surface) gives a small picture saying so, so that a results directory is complete.
// Throws std::invalid_argument for a map that is not CV_32F, labels of another size or type, max_mm < 0, or a
// max_width too small for the scale bar.
cv::Mat heightMapImage(const cv::Mat& height_map, const cv::Mat& labels, const std::vector<Plaque>& plaques,
                       double max_mm, int max_width, const cv::Mat& unfollowed) {
  if (!(max_mm >= 0) || !std::isfinite(max_mm))
    throw std::invalid_argument("heightMapImage: max_mm must be >= 0 (0 = automatic), got " + std::to_string(max_mm));
  if (max_width < kPanelWidth + 100)
    throw std::invalid_argument("heightMapImage: max_width " + std::to_string(max_width) + " px is below the minimum " +
                                std::to_string(kPanelWidth + 100));
  if (height_map.empty()) {
    cv::Mat img(120, 480, CV_8UC3, kBackground);
    label(img, "no height map (no reference surface)", {10, 65}, 0.6);
    return img;
  }
  if (height_map.type() != CV_32FC1)
    throw std::invalid_argument("heightMapImage: the height map must be CV_32F (m above the reference), got type " +
                                std::to_string(height_map.type()));
  if (!labels.empty() && (labels.type() != CV_32SC1 || labels.size() != height_map.size()))
    throw std::invalid_argument("heightMapImage: the labels must be CV_32S of the height map's size (" +
                                std::to_string(height_map.cols) + "x" + std::to_string(height_map.rows) + ")");

  // Colour scale: 0 ... max_mm (automatic: 1.25 x the highest plaque's max height, or without plaques the 99th
  // percentile of the known heights; at least 0.25 mm). Plaques first: on skin a few per cent of the points (the
  // limb's silhouette, the background) lie millimetres off the reference and would squeeze the plaques into
  // the bottom colour.
  if (max_mm == 0 && !plaques.empty()) {
    double top = 0;
    for (const auto& p : plaques) top = std::max(top, kMm * p.max_height);
    max_mm = std::max(0.25, 1.25 * top);
  }
  if (max_mm == 0) {
    std::vector<float> known;
    for (int r = 0; r < height_map.rows; ++r) {
      const float* h = height_map.ptr<float>(r);
      for (int c = 0; c < height_map.cols; ++c)
        if (std::isfinite(h[c])) known.push_back(h[c]);
    }
    double p99 = 0;
    if (!known.empty()) {
      const size_t k = static_cast<size_t>(std::floor(0.99 * (known.size() - 1)));
      std::nth_element(known.begin(), known.begin() + k, known.end());
      p99 = kMm * known[k];
    }
    max_mm = std::max(0.25, p99);
  }
  cv::Mat index(height_map.size(), CV_8U), unknown(height_map.size(), CV_8U);
  for (int r = 0; r < height_map.rows; ++r) {
    const float* h = height_map.ptr<float>(r);
    uchar* idx = index.ptr<uchar>(r);
    uchar* unk = unknown.ptr<uchar>(r);
    for (int c = 0; c < height_map.cols; ++c) {
      unk[c] = std::isfinite(h[c]) ? 0 : 255;
      const double v = std::isfinite(h[c]) ? std::clamp(kMm * h[c] / max_mm, 0.0, 1.0) : 0.0;
      idx[c] = static_cast<uchar>(std::lround(255.0 * v));
    }
  }
  cv::Mat map_colour;
  cv::applyColorMap(index, map_colour, kColourMap);
  map_colour.setTo(kUnknown, unknown);
  if (!unfollowed.empty()) {  // where the reference does not follow the skin: magenta hatching
    if (unfollowed.type() != CV_8UC1 || unfollowed.size() != height_map.size())
      throw std::invalid_argument("heightMapImage: the unfollowed mask must be CV_8U of the height map's size");
    const int period = std::max(8, height_map.cols / 120);
    for (int r = 0; r < height_map.rows; ++r) {
      const uchar* u = unfollowed.ptr<uchar>(r);
      cv::Vec3b* c = map_colour.ptr<cv::Vec3b>(r);
      for (int x = 0; x < height_map.cols; ++x)
        if (u[x] && (x + r) % period < std::max(2, period / 4)) c[x] = cv::Vec3b(255, 0, 255);
    }
  }

  // Shrink wide maps so that map + scale bar panel fit in max_width.
  const double s = std::min(1.0, static_cast<double>(max_width - kPanelWidth) / height_map.cols);
  if (s < 1.0) {
    cv::Mat small;
    const cv::Size size(std::max(1, static_cast<int>(std::lround(height_map.cols * s))),
                        std::max(1, static_cast<int>(std::lround(height_map.rows * s))));
    cv::resize(map_colour, small, size, 0, 0, cv::INTER_AREA);
    map_colour = small;
  }
  const int map_w = map_colour.cols, map_h = map_colour.rows;
  cv::Mat canvas(kTitleHeight + std::max(map_h, kMinBarRegion), map_w + kPanelWidth, CV_8UC3, kBackground);
  map_colour.copyTo(canvas(cv::Rect(0, kTitleHeight, map_w, map_h)));

  // Plaque outlines (from the labels) and "id: mean mm" next to each plaque.
  const cv::Rect whole(0, 0, height_map.cols, height_map.rows);
  const auto toCanvas = [&](cv::Point2d p) {
    return cv::Point(static_cast<int>(std::lround((p.x + 0.5) * s - 0.5)),
                     static_cast<int>(std::lround((p.y + 0.5) * s - 0.5)) + kTitleHeight);
  };
  const double font = map_w >= 800 ? 0.6 : 0.45;
  for (const Plaque& p : plaques) {
    cv::Rect box = p.bbox & whole;
    if (!labels.empty()) {
      const cv::Rect roi = box.empty() ? whole : ((box - cv::Point(1, 1)) + cv::Size(2, 2)) & whole;
      cv::Mat mask = labels(roi) == p.id;
      std::vector<std::vector<cv::Point>> contours;
      cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE, roi.tl());
      if (box.empty()) {
        for (const auto& c : contours) box |= cv::boundingRect(c);
      }
      for (auto& c : contours)
        for (auto& q : c) q = toCanvas(q);
      cv::drawContours(canvas, contours, -1, kWhite, map_w >= 800 ? 2 : 1, cv::LINE_8);
    }
    if (box.empty()) continue;
    char text[64];
    // the top's uncertainty where it shows at this precision
    if (kMm * p.top_height_sigma >= 0.005)
      std::snprintf(text, sizeof(text), "%d: %.2f +- %.2f mm", p.id, kMm * p.top_height, kMm * p.top_height_sigma);
    else
      std::snprintf(text, sizeof(text), "%d: %.2f mm", p.id, kMm * p.top_height);
    int baseline = 0;
    const cv::Size ts = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, font, 1, &baseline);
    cv::Point at = toCanvas(cv::Point2d(box.x, box.y));
    at.y -= 4;
    if (at.y - ts.height < kTitleHeight) at.y = toCanvas(cv::Point2d(box.x, box.br().y)).y + ts.height + 4;
    at.x = std::clamp(at.x, 2, std::max(2, map_w - ts.width - 2));
    at.y = std::clamp(at.y, kTitleHeight + ts.height + 2, kTitleHeight + std::max(map_h, ts.height + 4) - 2);
    label(canvas, text, at, font);
  }

  // Title line and the scale bar.
  char title[160];
  std::snprintf(title, sizeof(title), "height above the reference, 0 - %.2f mm  |  %zu plaque%s  |  grey: unknown%s",
                max_mm, plaques.size(), plaques.size() == 1 ? "" : "s",
                cv::countNonZero(unfollowed.empty() ? cv::Mat(1, 1, CV_8U, cv::Scalar(0)) : unfollowed) > 0
                    ? "  |  hatched: the reference does not follow the skin"
                    : "");
  cv::putText(canvas, title, {6, 19}, cv::FONT_HERSHEY_SIMPLEX, 0.5, kWhite, 1, cv::LINE_AA);
  drawScaleBar(canvas, map_w + 14, kTitleHeight + 24, canvas.rows - 12, max_mm);
  return canvas;
}

void writeSurfacePly(const std::string& path, const stereo::DenseCloud& cloud, const cv::Mat& colour, int step) {
  if (step < 1)
    throw std::invalid_argument("writeSurfacePly('" + path + "'): step must be >= 1, got " + std::to_string(step));
  if (cloud.xyz.empty() || cloud.xyz.type() != CV_32FC3)
    throw std::invalid_argument("writeSurfacePly('" + path + "'): the cloud's xyz must be a non-empty CV_32FC3 image");
  const cv::Mat bgr = colourBgr8(colour, cloud.xyz.size(), path);

  // Vertices: the known pixels of the grid (every `step` px), numbered row by row.
  const int gr = (cloud.xyz.rows - 1) / step + 1, gc = (cloud.xyz.cols - 1) / step + 1;
  cv::Mat index(gr, gc, CV_32S, cv::Scalar(-1));
  int32_t vertices = 0;
  for (int i = 0; i < gr; ++i)
    for (int j = 0; j < gc; ++j) {
      const cv::Vec3f& p = cloud.xyz.at<cv::Vec3f>(i * step, j * step);
      if (std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])) index.at<int32_t>(i, j) = vertices++;
    }
  // Faces: cells whose four corners are known and whose range does not jump by more than 20 x the cell size
  // (the shortest of its four edges: a surface seen even at a grazing angle never exceeds it).
  const auto point = [&](int i, int j) {
    const cv::Vec3f& p = cloud.xyz.at<cv::Vec3f>(i * step, j * step);
    return Eigen::Vector3d(p[0], p[1], p[2]);
  };
  std::vector<uint8_t> cell_ok(gr > 1 && gc > 1 ? static_cast<size_t>(gr - 1) * (gc - 1) : 0, 0);
  int64_t faces = 0;
  for (int i = 0; i + 1 < gr; ++i)
    for (int j = 0; j + 1 < gc; ++j) {
      if (index.at<int32_t>(i, j) < 0 || index.at<int32_t>(i, j + 1) < 0 || index.at<int32_t>(i + 1, j) < 0 ||
          index.at<int32_t>(i + 1, j + 1) < 0)
        continue;
      const Eigen::Vector3d a = point(i, j), b = point(i, j + 1), c = point(i + 1, j), d = point(i + 1, j + 1);
      const double size = std::min({(b - a).norm(), (c - a).norm(), (d - b).norm(), (d - c).norm()});
      const double ra = a.norm(), rb = b.norm(), rc = c.norm(), rd = d.norm();
      const double jump = std::max({ra, rb, rc, rd}) - std::min({ra, rb, rc, rd});
      if (jump > 20.0 * size) continue;
      cell_ok[static_cast<size_t>(i) * (gc - 1) + j] = 1;
      faces += 2;
    }

  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot write the surface mesh to '" + path + "'");
  f << "ply\nformat binary_little_endian 1.0\n"
    << "comment skin3d dense surface: x y z in m (left camera optical frame), colour of the left rectified image\n"
    << "comment every " << step << " px of a " << cloud.xyz.cols << "x" << cloud.xyz.rows << " organised cloud\n"
    << "element vertex " << vertices << "\nproperty float x\nproperty float y\nproperty float z\n"
    << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    << "element face " << faces << "\nproperty list uchar int vertex_indices\nend_header\n";
  LeWriter w(f, path);
  for (int i = 0; i < gr; ++i)
    for (int j = 0; j < gc; ++j) {
      if (index.at<int32_t>(i, j) < 0) continue;
      const cv::Vec3f& p = cloud.xyz.at<cv::Vec3f>(i * step, j * step);
      const cv::Vec3b& c = bgr.at<cv::Vec3b>(i * step, j * step);
      w.f32(p[0]);
      w.f32(p[1]);
      w.f32(p[2]);
      w.u8(c[2]);
      w.u8(c[1]);
      w.u8(c[0]);
      w.maybeFlush();
    }
  // Two triangles per cell, counter-clockwise seen from the camera (normals towards it): a c b and b c d
  // with a = (i, j), b = (i, j + 1), c = (i + 1, j), d = (i + 1, j + 1).
  for (int i = 0; i + 1 < gr; ++i)
    for (int j = 0; j + 1 < gc; ++j) {
      if (!cell_ok[static_cast<size_t>(i) * (gc - 1) + j]) continue;
      const int32_t a = index.at<int32_t>(i, j), b = index.at<int32_t>(i, j + 1), c = index.at<int32_t>(i + 1, j),
                    d = index.at<int32_t>(i + 1, j + 1);
      w.u8(3);
      w.i32(a);
      w.i32(c);
      w.i32(b);
      w.u8(3);
      w.i32(b);
      w.i32(c);
      w.i32(d);
      w.maybeFlush();
    }
  w.flush();
  f.close();
  if (!f) throw std::runtime_error("error while writing the surface mesh to '" + path + "'");
}

}  // namespace induration
}  // namespace skin3d
