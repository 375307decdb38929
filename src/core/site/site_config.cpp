// SPDX-License-Identifier: BSD-3-Clause
// The site options by key (config/site.yaml, process_bag's --set site_*=value, the site_fusion nodelet's parameters).
#include <yaml-cpp/yaml.h>

#include <sstream>
#include <stdexcept>

#include "skin3d/common/cli.h"
#include "skin3d/site/site_fusion.h"

namespace skin3d {
namespace site {

const std::vector<std::string>& siteOptionKeys() {
  static const std::vector<std::string> keys = {"site_cell_mm",          "site_max_incidence_deg", "site_register",
                                                "site_register_stride",  "site_register_iterations",
                                                "site_min_overlap",      "site_max_correction_mm", "site_seam_block_mm",
                                                "site_pose_graph"};
  return keys;
}

void setSiteOption(SiteOptions* o, const std::string& k, const std::string& v) {
  auto num = [&](double min) { return common::parseNumber(k, v, min, false); };
  if (k == "site_cell_mm") o->cell = num(0) * 1e-3;
  else if (k == "site_max_incidence_deg") o->max_incidence_deg = num(0);
  else if (k == "site_register") {
    if (v != "true" && v != "false") throw std::invalid_argument("site_register must be true or false (got '" + v + "')");
    o->register_frames = v == "true";
  } else if (k == "site_register_stride") o->register_stride = static_cast<int>(common::parseWholeNumber(k, v, 1, 64));
  else if (k == "site_register_iterations") o->register_iterations = static_cast<int>(common::parseWholeNumber(k, v, 1, 100));
  else if (k == "site_min_overlap") o->min_overlap = num(0);
  else if (k == "site_max_correction_mm") o->max_correction = num(0) * 1e-3;
  else if (k == "site_seam_block_mm") o->seam_block = num(0) * 1e-3;
  else if (k == "site_pose_graph") {
    if (v != "true" && v != "false") throw std::invalid_argument("site_pose_graph must be true or false (got '" + v + "')");
    o->pose_graph = v == "true";
  }
  else {
    std::string known;
    for (const auto& key : siteOptionKeys()) known += (known.empty() ? "" : ", ") + key;
    throw std::invalid_argument("unknown site option '" + k + "' (" + known + ")");
  }
}

std::string getSiteOption(const SiteOptions& o, const std::string& k) {
  std::ostringstream s;
  s.precision(12);
  if (k == "site_cell_mm") s << o.cell * 1e3;
  else if (k == "site_max_incidence_deg") s << o.max_incidence_deg;
  else if (k == "site_register") s << (o.register_frames ? "true" : "false");
  else if (k == "site_register_stride") s << o.register_stride;
  else if (k == "site_register_iterations") s << o.register_iterations;
  else if (k == "site_min_overlap") s << o.min_overlap;
  else if (k == "site_max_correction_mm") s << o.max_correction * 1e3;
  else if (k == "site_seam_block_mm") s << o.seam_block * 1e3;
  else if (k == "site_pose_graph") s << (o.pose_graph ? "true" : "false");
  else throw std::invalid_argument("unknown site option '" + k + "'");
  return s.str();
}

void applySiteOptions(SiteOptions* o, const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const std::exception& e) {
    throw std::invalid_argument("cannot read the site options '" + path + "': " + e.what());
  }
  if (!root.IsMap()) throw std::invalid_argument("'" + path + "' is not a map of site_* keys");
  for (const auto& kv : root) setSiteOption(o, kv.first.as<std::string>(), kv.second.as<std::string>());
}

}  // namespace site
}  // namespace skin3d
