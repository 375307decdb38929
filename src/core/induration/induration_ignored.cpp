// SPDX-License-Identifier: BSD-3-Clause
// The warnings that list the raised regions the plaque search found not to be plaques (see warnIgnored in
// induration_detail.h).
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "../common/text.h"
#include "induration_detail.h"

namespace skin3d {
namespace induration {
namespace induration_detail {

using common::num;

void warnIgnored(double threshold, double min_measured_share, double correlation_area, IgnoredRegions* ignored,
                 std::vector<std::string>* warnings) {
  IgnoredRegions& ig = *ignored;
  auto largest = [](IgnoredRegions::List& v) {
    std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    std::string list;
    for (size_t i = 0; i < std::min<size_t>(3, v.size()); ++i) list += (i ? "; " : "") + v[i].second;
    return list;
  };
  if (!ig.at_edge.empty()) {
    const std::string list = largest(ig.at_edge);
    warnings->push_back(ig.at_edge.size() == 1
                            ? "a raised region of " + list + " was ignored: it lies at the edge of the measured surface"
                            : std::to_string(ig.at_edge.size()) + " raised regions were ignored: they lie at the edge of the "
                              "measured surface (their height above the reference means nothing); the largest: " + list);
  }
  auto ignoredAs = [&](IgnoredRegions::List& v, const std::string& why) {
    if (!v.empty()) warnings->push_back(std::to_string(v.size()) + " raised region" + (v.size() == 1 ? " was" : "s were") +
                                        " ignored: " + why + "; the largest: " + largest(v));
  };
  ignoredAs(ig.low, "drawn on the smoothed heights, the measured heights inside stand less than the detection threshold (" +
                        num(std::round(threshold * 1e5) / 100) + " mm) above the reference on average (the noise, not a plaque)");
  ignoredAs(ig.on_raised, "each rises above the skin around it by less than the detection threshold and less than that skin "
                          "stands above the reference (a bump on a low plaque or on relief, not a plaque of its own)");
  ignoredAs(ig.scattered, "scattered pieces fill under " + num(std::round(100 * kMinEllipseFill)) +
                              " % of the ellipse of their moments (a plaque is one patch of skin)");
  ignoredAs(ig.mismatch, "smaller than " + num(kMismatchAreas) + " correlation areas of the height noise (" +
                             num(std::round(kMismatchAreas * correlation_area)) + " px) with a top not 3 stated sigma above "
                             "the detection threshold: one mismatch of the matcher (a window-sized patch settled on a wrong "
                             "disparity) looks the same (a second view of the skin can tell)");
  if (!ig.relief.empty())
    warnings->push_back(std::to_string(ig.relief.size()) + " raised region" + (ig.relief.size() == 1 ? " is" : "s are") +
                        " not plaque-like: a plaque is sharply demarcated with one top, these rise smoothly (the "
                        "lower part of their rise, 20 to 50 %, spans more than a plaque's border ramp blurred by the matcher) "
                        "or have two tops: healthy relief (a fold, a ridge, a nose?) the reference does not follow, "
                        "not measured as plaques (hatched in the height map; a plaque on such relief cannot be told "
                        "from it: measure it from a view where the skin around it is smooth); the largest: " +
                        largest(ig.relief));
  ignoredAs(ig.sparse, "under " + num(std::round(100 * min_measured_share)) +
                           " % of the footprint has a height (scattered matches, mostly where the skin turns away from the rig, "
                           "are not a plaque)");
}

}  // namespace induration_detail
}  // namespace induration
}  // namespace skin3d
