// SPDX-License-Identifier: BSD-3-Clause
// Dense stereo / induration parameters by name (induration_config.h): every key round-trips through its
// text, bad keys and values are named, lists and the ROI are read from YAML lists and from text, and
// config/induration.yaml lists exactly the code's keys with the code's defaults.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <functional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/induration/induration_config.h"

using namespace skin3d::induration;

namespace {

/** @brief A value different from `current` that is still valid for the key (text). */
std::string otherValue(const std::string& key, const std::string& current) {
  if (key == "roi") return "10 20 300 200";
  if (key == "sgbm_mode") return current == "hh" ? "sgbm" : "hh";
  if (key == "subpixel") return current == "lk" ? "sgbm" : "lk";
  if (key == "reference_model") return current == "plane" ? "quadratic" : "plane";
  if (current == "true" || current == "false") return current == "true" ? "false" : "true";  // the switches
  if (key == "pasi_boundaries") return "0.0001 0.0003 0.0005 0.0007";
  if (key == "block_size" || key == "refine_window") return "7";
  if (key == "z_max") return "0.75";
  return current == "3" ? "4" : "3";  // every other key is a number that may be 3 or 4
}

std::string expectThrowMessage(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "no std::invalid_argument";
  return "";
}

std::string tempPath(const std::string& name) {
  return ::testing::TempDir() + "skin3d_test_induration_config_" + name;
}

}  // namespace

TEST(IndurationConfig, KeysAreUniqueAndCoverTheHeader) {
  const auto& keys = pipelineOptionKeys();
  const std::set<std::string> unique(keys.begin(), keys.end());
  EXPECT_EQ(unique.size(), keys.size());
  // The keys the header promises (induration_config.h), typed in here by hand.
  const std::vector<std::string> promised = {
      "z_min", "z_max", "roi",
      // DenseStereoOptions but min/max_disparity and roi
      "coarse_max_width", "coarse_min_levels", "sgbm_mode", "block_size", "p1", "p2", "uniqueness_ratio", "lr_max_diff", "speckle_window",
      "speckle_range", "slant_passes", "subpixel", "refine_window", "refine_iterations", "refine_max_shift", "neighbour_check", "max_sigma", "min_texture",
      "min_correlation", "weak_texture",
      "vertical",
      // IndurationOptions
      "reference_model", "min_height", "min_area", "max_height", "max_incidence_deg", "smoothing_px", "max_smoothing_px", "edge_fraction", "min_measured_share", "exclusion_margin_px",
      "interior_margin_px", "sor_std_ratio", "ransac_threshold", "fit_points", "max_iterations",
      "min_reference_fraction", "pasi_boundaries"};
  EXPECT_EQ(std::set<std::string>(promised.begin(), promised.end()), unique);
}

TEST(IndurationConfig, EveryKeyRoundTripsThroughText) {
  for (const auto& key : pipelineOptionKeys()) {
    PipelineOptions o;
    const std::string before = getPipelineOption(o, key);
    // The current value read back and set again changes nothing.
    setPipelineOption(&o, key, before);
    EXPECT_EQ(getPipelineOption(o, key), before) << key;
    // A different value is stored and read back, and only this key changes.
    const std::string other = otherValue(key, before);
    ASSERT_NE(other, before) << key;
    setPipelineOption(&o, key, other);
    EXPECT_EQ(getPipelineOption(o, key), other) << key;
    const PipelineOptions defaults;
    for (const auto& k : pipelineOptionKeys())
      if (k != key) {
        EXPECT_EQ(getPipelineOption(o, k), getPipelineOption(defaults, k)) << key << " changed " << k;
      }
  }
}

TEST(IndurationConfig, ValuesReachTheOptionStructs) {
  PipelineOptions o;
  setPipelineOption(&o, "z_min", "0.2");
  setPipelineOption(&o, "roi", "10 20 300 200");
  setPipelineOption(&o, "block_size", "7");
  setPipelineOption(&o, "vertical", "false");
  setPipelineOption(&o, "min_height", "0.1e-3");
  setPipelineOption(&o, "fit_points", "5000");
  setPipelineOption(&o, "reference_model", "quadratic");
  setPipelineOption(&o, "pasi_boundaries", "0.1e-3 0.3e-3 0.5e-3 0.7e-3");
  EXPECT_EQ(o.z_min, 0.2);
  EXPECT_EQ(o.dense.roi, cv::Rect(10, 20, 300, 200));
  EXPECT_EQ(o.dense.block_size, 7);
  EXPECT_FALSE(o.dense.vertical);
  EXPECT_EQ(o.induration.min_height, 0.1e-3);
  EXPECT_EQ(o.induration.fit_points, 5000);
  EXPECT_EQ(o.induration.reference_model, "quadratic");
  EXPECT_EQ(o.induration.pasi_boundaries, (std::vector<double>{0.1e-3, 0.3e-3, 0.5e-3, 0.7e-3}));
  // Lists as ROS parameters may arrive with commas and brackets; an empty ROI is the whole image.
  setPipelineOption(&o, "pasi_boundaries", "[0.2e-3, 0.4e-3]");
  EXPECT_EQ(o.induration.pasi_boundaries, (std::vector<double>{0.2e-3, 0.4e-3}));
  setPipelineOption(&o, "roi", "");
  EXPECT_TRUE(o.dense.roi.empty());
  EXPECT_EQ(getPipelineOption(o, "roi"), "0 0 0 0");
  // Numbers keep their full precision in text.
  setPipelineOption(&o, "min_texture", "0.1");
  PipelineOptions p;
  setPipelineOption(&p, "min_texture", getPipelineOption(o, "min_texture"));
  EXPECT_EQ(p.dense.min_texture, 0.1);
}

TEST(IndurationConfig, BadKeysAndValuesAreNamed) {
  PipelineOptions o;
  EXPECT_NE(expectThrowMessage([&] { setPipelineOption(&o, "no_such_key", "1"); }).find("no_such_key"),
            std::string::npos);
  EXPECT_THROW(getPipelineOption(o, "no_such_key"), std::invalid_argument);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"z_min", "abc"},           {"z_max", "0.5m"},       {"block_size", "5.5"},    {"fit_points", "many"},
      {"vertical", "yes please"}, {"sgbm_mode", "bm"},     {"subpixel", "parabola"}, {"reference_model", "cubic"},
      {"roi", "1 2 3"},           {"roi", "0 0 -5 10"},    {"pasi_boundaries", ""},  {"pasi_boundaries", "0.1 x"},
      {"min_height", "nan"},      {"speckle_range", "inf"}};
  for (const auto& kv : bad) {
    PipelineOptions before = o;
    const std::string msg = expectThrowMessage([&] { setPipelineOption(&o, kv.first, kv.second); });
    EXPECT_NE(msg.find("'" + kv.first + "'"), std::string::npos) << kv.first << "=" << kv.second << ": " << msg;
    EXPECT_EQ(getPipelineOption(o, kv.first), getPipelineOption(before, kv.first)) << kv.first << " changed";
  }
}

TEST(IndurationConfig, ValidateNamesTheKey) {
  EXPECT_NO_THROW(PipelineOptions().validate());
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"z_min", "-0.1"}, {"z_max", "0.1"}, {"block_size", "4"}, {"refine_window", "8"}, {"max_sigma", "0"}};
  for (const auto& kv : bad) {
    PipelineOptions o;
    setPipelineOption(&o, kv.first, kv.second);  // a number: accepted here, refused by validate()
    const std::string msg = expectThrowMessage([&] { o.validate(); });
    EXPECT_NE(msg.find(kv.first), std::string::npos) << kv.first << "=" << kv.second << ": " << msg;
  }
}

TEST(IndurationConfig, YamlFileLayersOverTheOptions) {
  const std::string path = tempPath("layer.yaml");
  {
    std::ofstream f(path);
    f << "z_max: 0.4\nroi: [1, 2, 30, 40]\npasi_boundaries: [1.0e-4, 2.0e-4]\nsgbm_mode: hh\n";
  }
  PipelineOptions o;
  o.z_min = 0.1;  // not in the file: kept
  applyPipelineOptions(&o, path);
  EXPECT_EQ(o.z_min, 0.1);
  EXPECT_EQ(o.z_max, 0.4);
  EXPECT_EQ(o.dense.roi, cv::Rect(1, 2, 30, 40));
  EXPECT_EQ(o.induration.pasi_boundaries, (std::vector<double>{1.0e-4, 2.0e-4}));
  EXPECT_EQ(o.dense.sgbm_mode, "hh");
  {
    std::ofstream f(path);
    f << "z_max: 0.4\nblock_sise: 5\n";
  }
  std::string msg = expectThrowMessage([&] { applyPipelineOptions(&o, path); });
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find("block_sise"), std::string::npos) << msg;
  {
    std::ofstream f(path);
    f << "min_area: four\n";
  }
  msg = expectThrowMessage([&] { applyPipelineOptions(&o, path); });
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find("min_area"), std::string::npos) << msg;
  std::remove(path.c_str());
  msg = expectThrowMessage([&] { applyPipelineOptions(&o, path); });
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
}

TEST(IndurationConfig, ConfigFileListsExactlyTheKeysWithTheCodeDefaults) {
  const std::string path = std::string(SKIN3D_SOURCE_DIR) + "/config/induration.yaml";
  // Each value equals the code default: the file is applied over options that differ from the defaults in
  // every key, so a key missing from the file would show, and a key the code does not know throws.
  PipelineOptions from_file;
  for (const auto& k : pipelineOptionKeys())
    setPipelineOption(&from_file, k, otherValue(k, getPipelineOption(from_file, k)));
  ASSERT_NO_THROW(applyPipelineOptions(&from_file, path));
  const PipelineOptions defaults;
  for (const auto& k : pipelineOptionKeys())
    EXPECT_EQ(getPipelineOption(from_file, k), getPipelineOption(defaults, k)) << "key " << k;
  EXPECT_NO_THROW(from_file.validate());
  // The defaults are the documented ones (a spot check against the header's numbers).
  EXPECT_EQ(from_file.induration.pasi_boundaries, (std::vector<double>{0.125e-3, 0.375e-3, 0.625e-3, 0.875e-3}));
  EXPECT_TRUE(from_file.dense.roi.empty());
  // Exactly the keys, each once at the start of a line, in the order of pipelineOptionKeys().
  std::ifstream f(path);
  ASSERT_TRUE(f.good()) << path;
  std::vector<std::string> file_keys;
  std::string line;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#' || line[0] == ' ') continue;
    const size_t colon = line.find(':');
    ASSERT_NE(colon, std::string::npos) << "not a key line: " << line;
    file_keys.push_back(line.substr(0, colon));
  }
  EXPECT_EQ(file_keys, pipelineOptionKeys());
}
