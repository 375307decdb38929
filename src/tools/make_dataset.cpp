// SPDX-License-Identifier: BSD-3-Clause
/**
 * make_dataset KIND --out FILE.bag [--seed N] [--config FILE.yaml] [--ideal] [--frames N] [--start S] [--compress C] [--quiet]
 *
 * Generates a simulated dataset (DESIGN.md "Datasets") as a rosbag, deterministically from the seed,
 * without a ROS master, plus FILE.truth.yaml beside it (and FILE.map.csv, the landmarks with their descriptors, for
 * globe-landmarks). KIND: globe-landmarks, globe-images, workpiece.
 * Topics: stereo/{left,right}/camera_info, stereo/{left,right}/image_raw (image kinds),
 * stereo/landmarks (landmark kind), imu/data (globe kinds), ground_truth/pose.
 * Exit codes: 0 ok, 1 bad configuration, 2 bad command line, 3 cannot write the output.
 */
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>
#include <sys/stat.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "skin3d/ros/conversions.h"
#include "skin3d/common/large_buffers.h"
#include "skin3d/common/run_info.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/dataset.h"
#include "skin3d/sim/globe.h"
#include "skin3d/sim/render.h"
#include "skin3d/stereo/rectification.h"

#include "make_dataset_detail.h"

namespace {

using namespace skin3d;
using namespace make_dataset_detail;  // NOLINT(build/namespaces): the tool's own helpers

const char* kUsage =
    "usage: make_dataset KIND --out FILE.bag [--seed N] [--config FILE.yaml] [--ideal] [--frames N] [--start S] [--compress jpeg[:Q]|png] [--truth-only] [--quiet]\n"
    "  KIND            globe-landmarks | globe-images | workpiece | skin\n"
    "  --out FILE.bag  the bag to write; the ground truth goes to FILE.truth.yaml beside it\n"
    "  --seed N        random seed (default 1, or the config's seed); same seed + config = same data\n"
    "  --config FILE   YAML overrides of the defaults (config/datasets/globe.yaml, workpiece.yaml, skin.yaml)\n"
    "  --ideal         no realism (blur, vignetting, photometry, noise) and an exact calibration\n"
    "  --frames N      only the first N frames (quick tests)\n"
    "  --start SECONDS stamp of the first frame (default 1000; e.g. 1700000000 for epoch stamps as a recording has)\n"
    "  --compress C    images as image_transport's compressed topics (stereo/{left,right}/image_raw/compressed,\n"
    "                  sensor_msgs/CompressedImage): jpeg (quality 90), jpeg:Q (Q 1 ... 100) or png (lossless)\n"
    "  --truth-only    skin sweeps: write FILE.truth.yaml and FILE.visible.png only, not the bag (nothing rendered):\n"
    "                  the truth of a bag made with the same kind, seed, config and --frames\n"
    "  --quiet         no progress output (progress goes to stderr)\n";

struct Options {
  std::string kind, out, config;
  long long seed = -1;
  bool ideal = false, quiet = false, truth_only = false;
  int frames = -1;
};

bool writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  return static_cast<bool>(out);
}

long long fileSize(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0 ? static_cast<long long>(st.st_size) : -1;
}

std::string stemOf(const std::string& bag) {
  return bag.size() > 4 && bag.substr(bag.size() - 4) == ".bag" ? bag.substr(0, bag.size() - 4) : bag;
}

std::string truthPath(const std::string& bag) { return stemOf(bag) + ".truth.yaml"; }
std::string mapPath(const std::string& bag) { return stemOf(bag) + ".map.csv"; }
std::string visiblePath(const std::string& bag) { return stemOf(bag) + ".visible.png"; }

bool parseArgs(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (a == "--out" && has_value) {
      o->out = argv[++i];
    } else if (a == "--config" && has_value) {
      o->config = argv[++i];
    } else if ((a == "--seed" || a == "--frames") && has_value) {
      const std::string v = argv[++i];
      char* end = nullptr;
      const long long n = std::strtoll(v.c_str(), &end, 10);
      if (v.empty() || *end != '\0' || n < (a == "--seed" ? 0 : 1)) {
        std::cerr << "make_dataset: " << a << " takes a whole number" << (a == "--seed" ? " >= 0" : " >= 1")
                  << ", got '" << v << "'\n";
        return false;
      }
      if (a == "--seed")
        o->seed = n;
      else
        o->frames = static_cast<int>(std::min<long long>(n, 1 << 30));
    } else if (a == "--start" && has_value) {
      const std::string v = argv[++i];
      char* end = nullptr;
      const double t = std::strtod(v.c_str(), &end);
      if (v.empty() || *end != '\0' || !(t > 0.0) || t > 4.0e9) {
        std::cerr << "make_dataset: --start takes seconds in (0, 4e9] (a ROS time), got '" << v << "'\n";
        return false;
      }
      g_start = ros::Time(t);
    } else if (a == "--compress" && has_value) {
      const std::string v = argv[++i];
      char* end = nullptr;
      if (v == "png") {
        g_compress = 0;
      } else if (v == "jpeg") {
        g_compress = 90;
      } else if (v.rfind("jpeg:", 0) == 0) {
        const long q = std::strtol(v.c_str() + 5, &end, 10);
        if (v.size() == 5 || *end != '\0' || q < 1 || q > 100) {
          std::cerr << "make_dataset: --compress jpeg:Q takes a quality Q of 1 ... 100, got '" << v << "'\n";
          return false;
        }
        g_compress = static_cast<int>(q);
      } else {
        std::cerr << "make_dataset: --compress takes jpeg, jpeg:Q (1 ... 100) or png, got '" << v << "'\n";
        return false;
      }
    } else if (a == "--ideal") {
      o->ideal = true;
    } else if (a == "--quiet") {
      o->quiet = true;
    } else if (a == "--truth-only") {
      o->truth_only = true;
    } else if (a.rfind("__", 0) == 0) {
      // roslaunch/rosrun remapping arguments: ignore.
    } else if (a[0] != '-' && o->kind.empty()) {
      o->kind = a;
    } else {
      std::cerr << "make_dataset: unknown or incomplete argument '" << a << "'\n";
      return false;
    }
  }
  if (o->kind.empty() || o->out.empty()) {
    std::cerr << "make_dataset: KIND and --out FILE.bag are required\n";
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  skin3d::keepLargeBuffers();  // 13-megapixel buffers from the heap, not fresh mmap()s
  Options o;
  if (!parseArgs(argc, argv, &o)) {
    std::cerr << kUsage;
    return 2;
  }
  sim::DatasetConfig c;
  int frames = 0;
  try {
    c = sim::defaultDatasetConfig(sim::parseDatasetKind(o.kind));
    if (!o.config.empty()) {
      std::ifstream in(o.config);
      if (!in) throw sim::SimConfigError("--config", "cannot read config file '" + o.config + "'");
      std::stringstream ss;
      ss << in.rdbuf();
      sim::applyDatasetYaml(&c, ss.str(), o.config);
    }
    if (o.seed >= 0) c.seed = static_cast<std::uint64_t>(o.seed);
    if (o.ideal) sim::makeIdeal(&c);
    sim::validateDatasetConfig(c);
    frames = c.kind == sim::DatasetKind::Workpiece ? c.workpiece.frames
             : c.kind == sim::DatasetKind::Skin    ? (c.skin.sweep.enabled ? c.skin.sweep.frames : c.skin.frames)
                                                   : c.globe.frames;
    if (o.frames > 0) frames = std::min(frames, o.frames);
  } catch (const sim::SimConfigError& e) {
    std::cerr << "make_dataset: " << (o.config.empty() ? "" : o.config + ": ") << e.what() << "\n";
    return 1;
  }

  if (o.truth_only && !(c.kind == sim::DatasetKind::Skin && c.skin.sweep.enabled)) {
    std::cerr << "make_dataset: --truth-only is for skin sweeps (skin.sweep.enabled)\n";
    return 2;
  }
  g_truth_only = o.truth_only;
  const std::string bag_path = o.truth_only ? o.out + ".truth-only.tmp" : o.out;
  const auto t0 = std::chrono::steady_clock::now();
  rosbag::Bag bag;
  try {
    bag.open(bag_path, rosbag::bagmode::Write);
  } catch (const std::exception& e) {
    std::cerr << "make_dataset: cannot write '" << o.out << "': " << e.what() << "\n";
    return 3;
  }
  if (!o.quiet)
    std::cout << "make_dataset: " << o.kind << ", seed " << c.seed << ", " << frames << " frames -> " << o.out
              << std::endl;
  YAML::Emitter truth;
  truth.SetDoublePrecision(12);
  truth << YAML::Comment("skin3d simulated dataset ground truth (SI units unless the key says mm/deg/px)");
  truth << YAML::BeginMap;
  truth << YAML::Key << "kind" << YAML::Value << o.kind << YAML::Key << "seed" << YAML::Value << c.seed;
  truth << YAML::Key << "frames" << YAML::Value << frames;
  truth << YAML::Key << "config" << YAML::Value << (o.config.empty() ? std::string("(defaults)") : o.config);
  truth << YAML::Key << "world_frame" << YAML::Value
        << (c.kind == sim::DatasetKind::Workpiece ? "plate frame (top surface z = 0)"
            : c.kind == sim::DatasetKind::Skin    ? (c.skin.sweep.enabled ? "the first pair's left optical frame"
                                                                          : "limb frame (x along the axis, cross-section in y, z)")
                                                  : "left optical frame at t = 0");
  int rc = 0;
  try {
    if (c.kind == sim::DatasetKind::Workpiece)
      rc = makeWorkpiece(c, frames, bag, truth, o.quiet);
    else if (c.kind == sim::DatasetKind::Skin)
      rc = makeSkin(c, frames, bag, truth, o.quiet, visiblePath(o.out));
    else
      rc = makeGlobe(c, frames, bag, truth, o.quiet, mapPath(o.out));
  } catch (const sim::SimConfigError& e) {
    bag.close();
    std::remove(o.out.c_str());
    std::cerr << "make_dataset: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    bag.close();
    std::cerr << "make_dataset: failed while writing '" << o.out << "': " << e.what() << "\n";
    return 3;
  }
  truth << YAML::EndMap;
  bag.close();
  if (o.truth_only) std::remove(bag_path.c_str());
  const std::string tpath = truthPath(o.out);
  if (!writeText(tpath, std::string(truth.c_str()) + "\n")) {
    std::cerr << "make_dataset: cannot write " << tpath << "\n";
    return 3;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!o.quiet)
    std::cout << "make_dataset: wrote " << (o.truth_only ? std::string() : o.out + " (" + std::to_string(fileSize(o.out) / 1e6) + " MB) and ")
              << tpath << " in " << secs << " s" << std::endl;
  return rc;
}
