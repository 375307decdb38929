// SPDX-License-Identifier: BSD-3-Clause
// Dense stereo and induration parameters by name (see induration_config.h, config/induration.yaml).
#include "skin3d/induration/induration_config.h"

#include "../common/option_table.h"

#include <cmath>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace skin3d {
namespace induration {

namespace {

using Table = common::OptionTable<PipelineOptions>;
using Field = Table::Field;
const common::OptionText kText("induration");

[[noreturn]] void bad(const std::string& key, const std::string& why) { kText.bad(key, why); }
double toDouble(const std::string& key, const std::string& v) { return kText.toDouble(key, v); }
int toInt(const std::string& key, const std::string& v) { return kText.toInt(key, v); }
bool toBool(const std::string& key, const std::string& v) { return kText.toBool(key, v); }
std::string oneOf(const std::string& key, const std::string& v, const std::vector<std::string>& names) {
  return kText.oneOf(key, v, names);
}
std::vector<double> toList(const std::string& key, const std::string& v) { return kText.toList(key, v); }
std::string listText(const std::vector<double>& v) { return common::OptionText::listText(v); }
std::string num(double d) { return common::exactNum(d); }

cv::Rect toRoi(const std::string& key, const std::string& v) {
  const std::vector<double> n = toList(key, v);
  if (n.empty()) return cv::Rect();
  if (n.size() != 4) bad(key, "'" + v + "' must be \"x y w h\" (4 whole numbers, px) or empty");
  int i[4];
  for (int k = 0; k < 4; ++k) {
    if (std::floor(n[k]) != n[k] || n[k] < 0 || n[k] > 1e6) bad(key, "'" + v + "' must be 4 whole numbers >= 0 (px)");
    i[k] = static_cast<int>(n[k]);
  }
  return cv::Rect(i[0], i[1], i[2], i[3]);
}

// One table row per key: text <-> member, through the converters above (they name the key).
// clang-format off
#define SKIN3D_DOUBLE(key, member)                                                \
  {key, {[](const PipelineOptions& o) { return num(o.member); },                  \
         [](PipelineOptions* o, const std::string& v) { o->member = toDouble(key, v); }}}
#define SKIN3D_INT(key, member)                                                   \
  {key, {[](const PipelineOptions& o) { return std::to_string(o.member); },       \
         [](PipelineOptions* o, const std::string& v) { o->member = toInt(key, v); }}}
#define SKIN3D_BOOL(key, member)                                                  \
  {key, {[](const PipelineOptions& o) { return std::string(o.member ? "true" : "false"); }, \
         [](PipelineOptions* o, const std::string& v) { o->member = toBool(key, v); }}}
#define SKIN3D_CHOICE(key, member, ...)                                           \
  {key, {[](const PipelineOptions& o) { return o.member; },                       \
         [](PipelineOptions* o, const std::string& v) { o->member = oneOf(key, v, __VA_ARGS__); }}}
// clang-format on

const Table& table() {
  static const Table t(kText, {
      // --- working range
      SKIN3D_DOUBLE("z_min", z_min),
      SKIN3D_DOUBLE("z_max", z_max),
      {"roi",
       {[](const PipelineOptions& o) {
          const cv::Rect& r = o.dense.roi;
          return std::to_string(r.x) + " " + std::to_string(r.y) + " " + std::to_string(r.width) + " " +
                 std::to_string(r.height);
        },
        [](PipelineOptions* o, const std::string& v) { o->dense.roi = toRoi("roi", v); }}},
      // --- dense matching (DenseStereoOptions)
      SKIN3D_INT("coarse_max_width", dense.coarse_max_width),
      SKIN3D_INT("coarse_min_levels", dense.coarse_min_levels),
      SKIN3D_CHOICE("sgbm_mode", dense.sgbm_mode, {"sgbm", "hh", "sgbm_3way"}),
      SKIN3D_INT("block_size", dense.block_size),
      SKIN3D_INT("p1", dense.p1),
      SKIN3D_INT("p2", dense.p2),
      SKIN3D_INT("uniqueness_ratio", dense.uniqueness_ratio),
      SKIN3D_DOUBLE("lr_max_diff", dense.lr_max_diff),
      SKIN3D_INT("speckle_window", dense.speckle_window),
      SKIN3D_DOUBLE("speckle_range", dense.speckle_range),
      SKIN3D_INT("slant_passes", dense.slant_passes),
      SKIN3D_CHOICE("subpixel", dense.subpixel, {"lk", "sgbm"}),
      SKIN3D_INT("refine_window", dense.refine_window),
      SKIN3D_INT("refine_iterations", dense.refine_iterations),
      SKIN3D_DOUBLE("refine_max_shift", dense.refine_max_shift),
      SKIN3D_BOOL("neighbour_check", dense.neighbour_check),
      SKIN3D_DOUBLE("max_sigma", dense.max_sigma),
      SKIN3D_DOUBLE("min_texture", dense.min_texture),
      SKIN3D_DOUBLE("min_correlation", dense.min_correlation),
      SKIN3D_BOOL("weak_texture", dense.weak_texture),
      SKIN3D_BOOL("vertical", dense.vertical),
      // --- induration (IndurationOptions)
      SKIN3D_CHOICE("reference_model", induration.reference_model, {"auto", "plane", "quadric", "quadratic"}),
      SKIN3D_DOUBLE("min_height", induration.min_height),
      SKIN3D_DOUBLE("min_area", induration.min_area),
      SKIN3D_DOUBLE("max_height", induration.max_height),
      SKIN3D_DOUBLE("max_incidence_deg", induration.max_incidence_deg),
      SKIN3D_DOUBLE("smoothing_px", induration.smoothing_px),
      SKIN3D_DOUBLE("max_smoothing_px", induration.max_smoothing_px),
      SKIN3D_DOUBLE("edge_fraction", induration.edge_fraction),
      SKIN3D_DOUBLE("min_measured_share", induration.min_measured_share),
      SKIN3D_INT("exclusion_margin_px", induration.exclusion_margin_px),
      SKIN3D_INT("interior_margin_px", induration.interior_margin_px),
      SKIN3D_DOUBLE("sor_std_ratio", induration.sor_std_ratio),
      SKIN3D_DOUBLE("ransac_threshold", induration.ransac_threshold),
      SKIN3D_INT("fit_points", induration.fit_points),
      SKIN3D_INT("max_iterations", induration.max_iterations),
      SKIN3D_DOUBLE("min_reference_fraction", induration.min_reference_fraction),
      {"pasi_boundaries",
       {[](const PipelineOptions& o) { return listText(o.induration.pasi_boundaries); },
        [](PipelineOptions* o, const std::string& v) {
          std::vector<double> b = toList("pasi_boundaries", v);
          if (b.empty()) bad("pasi_boundaries", "'" + v + "' must be a list of increasing heights in m");
          o->induration.pasi_boundaries = std::move(b);
        }}},
  });
  return t;
}

void require(bool ok, const std::string& key, const std::string& why) {
  if (!ok) bad(key, why);
}

}  // namespace

void PipelineOptions::validate() const {
  if (!autoDepthRange()) {  // both 0: searched in each pair
    require(z_min > 0 && std::isfinite(z_min), "z_min", num(z_min) + " must be > 0 (m), or z_min = z_max = 0 (searched)");
    require(z_max > z_min && std::isfinite(z_max), "z_max",
            num(z_max) + " must be > z_min = " + num(z_min) + " (m), or z_min = z_max = 0 (searched)");
  }
  const cv::Rect& r = dense.roi;
  require(r.x >= 0 && r.y >= 0 && r.width >= 0 && r.height >= 0 && ((r.width == 0) == (r.height == 0)), "roi",
          "must be \"x y w h\" with x, y >= 0 and w, h both > 0 (or \"0 0 0 0\" for the whole image)");
  // The same limits as computeDisparity's (which cannot name the key), checked at start-up.
  require(dense.coarse_max_width >= 64, "coarse_max_width",
          std::to_string(dense.coarse_max_width) + " must be >= 64 px");
  require(dense.coarse_min_levels >= 0 && dense.coarse_min_levels <= 6, "coarse_min_levels",
          std::to_string(dense.coarse_min_levels) + " must be 0 ... 6");
  require(dense.block_size >= 1 && dense.block_size <= 11 && dense.block_size % 2 == 1, "block_size",
          std::to_string(dense.block_size) + " must be odd, 1 ... 11");
  require(dense.p1 >= 0, "p1", "must be >= 0 (0 = 8 x block_size^2)");
  require(dense.p2 >= 0, "p2", "must be >= 0 (0 = 32 x block_size^2)");
  require(dense.p1 == 0 || dense.p2 == 0 || dense.p2 > dense.p1, "p2",
          "must be > p1 (OpenCV's StereoSGBM requires P2 > P1)");
  require(dense.uniqueness_ratio >= 0 && dense.uniqueness_ratio <= 100, "uniqueness_ratio", "must be 0 ... 100 (%)");
  require(dense.lr_max_diff >= 0, "lr_max_diff", "must be >= 0 px");
  require(dense.speckle_window >= 0, "speckle_window", "must be >= 0 px (0 = off)");
  require(dense.speckle_range >= 0, "speckle_range", "must be >= 0 px");
  require(dense.refine_window >= 3 && dense.refine_window <= 51 && dense.refine_window % 2 == 1, "refine_window",
          std::to_string(dense.refine_window) + " must be odd, 3 ... 51 px");
  require(dense.refine_iterations >= 1 && dense.refine_iterations <= 20, "refine_iterations",
          std::to_string(dense.refine_iterations) + " must be 1 ... 20");
  require(dense.refine_max_shift > 0, "refine_max_shift", "must be > 0 px");
  require(dense.max_sigma > 0, "max_sigma", "must be > 0 px");
  require(dense.min_texture >= 0, "min_texture", "must be >= 0");
  require(dense.min_correlation >= -1 && dense.min_correlation < 1, "min_correlation", "must be in [-1, 1)");
  // The string choices are checked when set; re-check here for options filled in by code.
  for (const auto& key : {"sgbm_mode", "subpixel", "reference_model"}) {
    PipelineOptions copy;
    table().set(&copy, key, table().get(*this, key));
  }
  induration.validate();  // IndurationError (an std::invalid_argument) naming the option = the key
}

const std::vector<std::string>& pipelineOptionKeys() { return table().keys(); }

std::string getPipelineOption(const PipelineOptions& options, const std::string& key) { return table().get(options, key); }

void setPipelineOption(PipelineOptions* options, const std::string& key, const std::string& value) {
  table().set(options, key, value);
}

void applyPipelineOptions(PipelineOptions* options, const std::string& yaml_path) { table().applyYaml(options, yaml_path); }

}  // namespace induration
}  // namespace skin3d
