// SPDX-License-Identifier: BSD-3-Clause
// A site.yaml against its sweep's truth (BAG.truth.yaml of make_dataset skin with skin.sweep): the check that
// test_site_scan (process_bag --site) and the site_fusion rostest share.
#pragma once

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

namespace skin3d_test {

inline Eigen::Vector3d vec(const YAML::Node& n) { return Eigen::Vector3d(n[0].as<double>(), n[1].as<double>(), n[2].as<double>()); }

/** PASI class of a height (mm) with the default boundaries. */
inline int pasi(double mm) {
  int k = 0;
  for (double b : {0.125, 0.375, 0.625, 0.875}) k += mm >= b;
  return k;
}

/** Every true plaque of at least 0.2 mm that some frame sees within 45 deg found exactly once, its top within
 *  max(20 um, 3 x its stated sigma), its PASI class right, seen by a view of its own; no site plaque that no true
 *  plaque claims. */
inline void expectPlaquesMatchTheTruth(const YAML::Node& truth, const YAML::Node& site) {
  const YAML::Node measured = site["plaques"];
  std::vector<int> claimed(measured.size(), 0);
  int required = 0;
  for (std::size_t i = 0; i < truth["plaques"].size(); ++i) {
    const YAML::Node p = truth["plaques"][i];
    const double top = p["height_mm"].as<double>();
    const double best_inc = truth["plaques_seen"][i]["best_incidence_deg"].as<double>();
    const double reach = std::max(3e-3, std::sqrt(p["area_mm2"].as<double>() / M_PI) * 1e-3);
    int match = -1, n = 0;
    for (std::size_t j = 0; j < measured.size(); ++j)
      if ((vec(measured[j]["centroid_m"]) - vec(p["centroid_left_m"])).norm() <= reach) {
        ++claimed[j];
        ++n;
        match = static_cast<int>(j);
      }
    if (top < 0.2 || best_inc > 45) continue;
    ++required;
    ASSERT_EQ(n, 1) << "true plaque " << i << " (" << top << " mm, best incidence " << best_inc << " deg) is matched by " << n
                    << " site plaques";
    const YAML::Node m = measured[match];
    const double err = m["top_height_mm"].as<double>() - top, sig = m["top_height_sigma_mm"].as<double>();
    EXPECT_LE(std::fabs(err), std::max(0.020, 3 * sig)) << "plaque " << i << ": top " << m["top_height_mm"].as<double>()
                                                       << " mm against " << top << " (sigma " << sig << ")";
    EXPECT_EQ(m["pasi"].as<int>(), pasi(top)) << "plaque " << i;
    EXPECT_GE(m["views"].as<int>(), 1) << "plaque " << i;
  }
  EXPECT_GE(required, 2) << "the sweep must hold plaques to measure";
  for (std::size_t j = 0; j < measured.size(); ++j)
    EXPECT_GE(claimed[j], 1) << "site plaque " << measured[j]["id"].as<int>() << " at "
                             << vec(measured[j]["centroid_m"]).transpose() << " is no true plaque";
}

}  // namespace skin3d_test
