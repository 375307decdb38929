// SPDX-License-Identifier: BSD-3-Clause
// The front end's parameters by name (see include/skin3d/stereo/front_end.h): one table for
// config/frontend.yaml, the stereo_front_end nodelet's ROS parameters, process_bag's --set and the tests.
#include "../common/option_table.h"
#include "skin3d/stereo/front_end.h"

namespace skin3d {
namespace stereo {

namespace {
using Table = common::OptionTable<FrontEndOptions>;
const common::OptionText kText("front end");

#define SKIN3D_DOUBLE(key, member)                                                                              \
  {key, {[](const FrontEndOptions& o) { return common::exactNum(o.member); },                                   \
         [](FrontEndOptions* o, const std::string& v) { o->member = kText.toDouble(key, v); }}}
#define SKIN3D_INT(key, member)                                                                                 \
  {key, {[](const FrontEndOptions& o) { return std::to_string(o.member); },                                     \
         [](FrontEndOptions* o, const std::string& v) { o->member = kText.toInt(key, v); }}}
#define SKIN3D_BOOL(key, member)                                                                                \
  {key, {[](const FrontEndOptions& o) { return std::string(o.member ? "true" : "false"); },                     \
         [](FrontEndOptions* o, const std::string& v) { o->member = kText.toBool(key, v); }}}

const Table& table() {
  static const Table t(
      kText,
      {
          {"feature_type",
           {[](const FrontEndOptions& o) { return featureTypeName(o.features.type); },
            [](FrontEndOptions* o, const std::string& v) {
              o->features.type = parseFeatureType(kText.oneOf("feature_type", v, {"kaze", "akaze", "orb"}));
            }}},
          SKIN3D_DOUBLE("threshold", features.threshold),
          SKIN3D_INT("max_features", features.max_features),
          SKIN3D_INT("octaves", features.octaves),
          SKIN3D_INT("octave_layers", features.octave_layers),
          SKIN3D_DOUBLE("ratio", features.ratio),
          SKIN3D_DOUBLE("max_row_diff", features.max_row_diff),
          SKIN3D_DOUBLE("min_disparity", features.min_disparity),
          SKIN3D_DOUBLE("max_disparity", features.max_disparity),
          SKIN3D_BOOL("cross_check", features.cross_check),
          SKIN3D_DOUBLE("border_margin", features.border_margin),
          SKIN3D_DOUBLE("sigma_px", triangulate.sigma_px),
          SKIN3D_DOUBLE("min_depth", triangulate.min_depth),
          SKIN3D_DOUBLE("max_depth", triangulate.max_depth),
          SKIN3D_INT("max_landmarks", max_landmarks),
          SKIN3D_DOUBLE("row_gate", triangulate.row_gate),
          SKIN3D_DOUBLE("disparity_gate", triangulate.disparity_gate),
          SKIN3D_INT("neighbours", triangulate.neighbours),
          SKIN3D_BOOL("slant_noise", triangulate.slant_noise),
          SKIN3D_BOOL("size_noise", triangulate.size_noise),
      });
  return t;
}

}  // namespace

const std::vector<std::string>& frontEndOptionKeys() { return table().keys(); }
std::string getFrontEndOption(const FrontEndOptions& o, const std::string& key) { return table().get(o, key); }
void setFrontEndOption(FrontEndOptions* o, const std::string& key, const std::string& value) { table().set(o, key, value); }
void applyFrontEndOptions(FrontEndOptions* o, const std::string& yaml_path) { table().applyYaml(o, yaml_path); }

}  // namespace stereo
}  // namespace skin3d
