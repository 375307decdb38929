// SPDX-License-Identifier: BSD-3-Clause
/**
 * process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map MAP.csv]
 *             [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--ns NAMESPACE]
 *             [--input auto|images|landmarks] [--ate-align auto|none|first_pose|se3] [--ate-max-dt S] [--serial]
 *             [--quiet]
 *
 * Runs a recorded or simulated session through the same runners as the nodelets (ros_run::FrontEndRunner,
 * ros_run::SlamRunner; induration: ros_run::IndurationRunner), without a ROS master, as fast as the CPU allows: landmark bags (stereo/landmarks) go straight into the ES-EKF SLAM, image bags
 * (stereo/{left,right}/image_raw + camera_info) through the front end (rectify, features, MMSE
 * triangulation) first; imu/data feeds the gyroscope with --gyro. Writes the results directory of
 * DESIGN.md: trajectory.tum, map.ply, sphere_fit.yaml (robust sphere fit of the map), state.csv (per-frame
 * filter state), rig_covariance.csv (per-frame rig covariance), map_covariance.csv (each landmark's covariance),
 * summary.yaml (with the absolute trajectory error when the bag has ground_truth/pose), ground_truth.tum, and
 * parameters.yaml (the command line and every
 * parameter's effective value). Progress on stderr (every 2 s on a terminal, every 10 % in a log).
 *
 * --known-map MAP.csv: thesis experiment 1, the landmarks are known (make_dataset globe-landmarks writes
 * FILE.map.csv beside the bag: positions and descriptors); association by descriptor + Mahalanobis gate.
 *
 * --induration: the induration measurement instead of SLAM: every stereo pair is rectified, densely
 * matched and measured (process_bag_induration.cpp); --config / --set then take the keys of
 * config/induration.yaml. Writes induration.yaml, height_map.png and surface.ply.
 *
 * Bags recorded by others: topics are found under their relative names (stereo/landmarks), absolute names
 * (/stereo/landmarks, as `rosbag record -a` writes them) or a namespace (/rig1/stereo/landmarks; --ns rig1, or
 * found when it is the only one); when nothing matches, the error lists the bag's topics. A bag with both the
 * raw images and the front end's stereo/landmarks (record -a of a running rig) is processed from the images
 * (--input landmarks replays the recorded landmarks instead).
 *
 * Image bags run as a two-stage pipeline on two threads (process_bag_slam.cpp): the front end of pair k runs
 * while the SLAM processes pair k-1; --serial runs one after the other (same results). summary.yaml gives both
 * stages' ms per frame (front_end_ms_per_frame, slam_ms_per_frame).
 *
 * Exit codes: 0 ok, 1 bad configuration or data, 2 bad command line, 3 cannot write the output.
 */
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <iostream>
#include <string>

#include "process_bag.h"
#include "skin3d/common/cli.h"
#include "process_bag_induration.h"
#include "skin3d/common/large_buffers.h"
#include "skin3d/slam/results.h"

namespace {

using namespace skin3d;

const char* kUsage =
    "usage: process_bag --bag FILE.bag --out DIR [--config slam.yaml] [--gyro] [--known-map MAP.csv]\n"
    "                   [--features kaze|akaze|orb] [--frames N] [--set key=value ...] [--ns NAMESPACE]\n"
    "                   [--input auto|images|landmarks] [--ate-align auto|none|first_pose|se3] [--quiet]\n"
    "  --bag        dataset or recorded session (stereo/landmarks, or stereo/*/image_raw + camera_info; image_transport's\n"
    "               stereo/*/image_raw/compressed, JPEG or PNG, are read when image_raw is not in the bag)\n"
    "  --out        results directory (created with its parents before the bag is read)\n"
    "  --config     SLAM parameters over the defaults of config/slam.yaml (repeatable: later files win); image\n"
    "               input first applies the front end's measurement model (docs/slam.md)\n"
    "  --gyro       fuse imu/data (thesis experiment 3); same as --set use_gyro=true\n"
    "  --known-map  make_dataset's FILE.map.csv (landmarks + descriptors): localisation with a known map (exp. 1)\n"
    "  --features   front end for image bags: akaze (default, as the rig's launch files), kaze or orb; akaze and orb\n"
    "               also set max_descriptor_distance 5.5 (binary descriptors; a --config or --set still wins)\n"
    "  --frontend-config  front-end parameters (keys of config/frontend.yaml) over the defaults (repeatable)\n"
    "  --frontend-set     override one front-end parameter, key=value (repeatable)\n"
    "  --frames     process at most N frames (a whole number >= 0)\n"
    "  --set        override one SLAM parameter (repeatable)\n"
    "  --ns         the bag's topics are under this namespace (e.g. rig1 for /rig1/stereo/...; '/' = the root);\n"
    "               default: the root, or the one namespace that holds skin3d's topics\n"
    "  --input      auto (default: the images when the bag has them, else stereo/landmarks) | images | landmarks\n"
    "  --ate-align  how the ground truth is aligned for summary.yaml's ate: auto (default: none when its world is\n"
    "               the SLAM's, i.e. its first pose is the first estimate's, else se3) | none | first_pose | se3;\n"
    "               ate_se3 (SE(3)-aligned, as evo_ape --align) is always written too\n"
    "  --ate-max-dt time association tolerance of the ATE, s (default 0.01, as evo)\n"
    "  --serial     image bags: run the front end and the SLAM one after the other instead of overlapping them on\n"
    "               two threads (same results; for timing comparisons)\n"
    "  --induration measure plaque heights instead (dense stereo + induration; --config/--set take the keys of\n"
    "               config/induration.yaml; writes induration.yaml, height_map.png, surface.ply)\n"
    "  --site       a sweep over one body site: every pair measured as with --induration, registered to the site\n"
    "               fused so far and fused into one height field over the body; plaques measured once on it; writes\n"
    "               site.yaml, site_height_map.png, site_coverage.png, site_surface.ply too (docs/site.md). Site keys\n"
    "               for --set: those of config/site.yaml (site_cell_mm, site_max_incidence_deg, site_register, ...)\n"
    "  --site-poses with --site: the pose topic (geometry_msgs/PoseStamped or nav_msgs/Odometry, world <- left\n"
    "               optical frame; default slam/odometry; ground_truth/pose for a simulated sweep), or images:\n"
    "               each pair placed by its stereo features matched with the last pair fused\n"
    "  --maps       with --induration: last (default: the last frame's maps) | all (every frame's too, in\n"
    "               DIR/frames/NNNN/ as it is measured)\n"
    "exit status: 0 done; 1 bad data (nothing could be processed); 2 bad command line; 3 the results could not be\n"
    "  written (or the bag not read); 4 (--induration) results written, but in some frame the healthy-skin reference\n"
    "  did not follow the skin: plaques there could not be measured (the warnings and the hatched height map say where);\n"
    "  5 (--site) results written, but fewer than two frames could be fused (the sweep does not overlap)\n";

/** A strict whole number for `option`, or exit 2 with the message naming it. */
long whole(const std::string& option, const std::string& v, long min, long max) {
  try {
    return common::parseWholeNumber(option, v, min, max);
  } catch (const std::invalid_argument& e) {
    std::cerr << "process_bag: " << e.what() << "\n";
    std::exit(2);
  }
}

/** A strict number for `option`, or exit 2 with the message naming it. */
double number(const std::string& option, const std::string& v, double min, bool min_exclusive) {
  try {
    return common::parseNumber(option, v, min, min_exclusive);
  } catch (const std::invalid_argument& e) {
    std::cerr << "process_bag: " << e.what() << "\n";
    std::exit(2);
  }
}

std::pair<std::string, std::string> keyValue(const std::string& option, const std::string& kv) {
  const auto eq = kv.find('=');
  if (eq == std::string::npos || eq == 0) {
    std::cerr << "process_bag: " << option << " needs key=value (got '" << kv << "')\n";
    std::exit(2);
  }
  return {kv.substr(0, eq), kv.substr(eq + 1)};
}

}  // namespace

int main(int argc, char** argv) {
  skin3d::keepLargeBuffers();  // 13-megapixel buffers from the heap, not fresh mmap()s
  tools::SlamRun a;
  bool induration = false, site = false;
  std::string maps = "last", site_poses;
  a.command_line.assign(argv, argv + argc);
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "process_bag: " << k << " needs a value\n" << kUsage;
        std::exit(2);
      }
      return argv[++i];
    };
    if (k == "--bag") a.bag = value();
    else if (k == "--out") a.out = value();
    else if (k == "--config") a.configs.push_back(value());
    else if (k == "--known-map") a.known_map = value();
    else if (k == "--features") a.features = value();
    else if (k == "--frontend-config") a.front_end_configs.push_back(value());
    else if (k == "--frontend-set") a.front_end_sets.push_back(keyValue(k, value()));
    else if (k == "--ns") a.ns = value();
    else if (k == "--input") a.input = value();
    else if (k == "--ate-align") a.ate_align = value();
    else if (k == "--ate-max-dt") a.ate_max_dt = number(k, value(), 0.0, true);
    else if (k == "--frames") a.frames = static_cast<int>(whole(k, value(), 0, 2000000000L));
    else if (k == "--gyro") a.gyro = true;
    else if (k == "--quiet") a.quiet = true;
    else if (k == "--serial") a.serial = true;
    else if (k == "--induration") induration = true;
    else if (k == "--site") site = induration = true;
    else if (k == "--site-poses") site_poses = value();
    else if (k == "--maps") maps = value();
    else if (k == "--set") a.sets.push_back(keyValue(k, value()));
    else if (k == "-h" || k == "--help") {
      std::cout << kUsage;
      return 0;
    } else if (k.rfind("__", 0) == 0) {
      // roslaunch remapping arguments: ignore.
    } else {
      std::cerr << "process_bag: unknown argument '" << k << "'\n" << kUsage;
      return 2;
    }
  }
  if (a.bag.empty() || a.out.empty()) {
    std::cerr << "process_bag: --bag and --out are required\n" << kUsage;
    return 2;
  }
  if (maps != "last" && maps != "all") {
    std::cerr << "process_bag: --maps must be last or all (got '" << maps << "')\n";
    return 2;
  }
  if (maps != "last" && !induration) {
    std::cerr << "process_bag: --maps needs --induration (the SLAM writes no maps)\n";
    return 2;
  }
  if (a.input != "auto" && a.input != "images" && a.input != "landmarks") {
    std::cerr << "process_bag: --input must be auto, images or landmarks (got '" << a.input << "')\n";
    return 2;
  }
  if (a.features != "kaze" && a.features != "akaze" && a.features != "orb") {
    std::cerr << "process_bag: --features must be kaze, akaze or orb (got '" << a.features << "')\n";
    return 2;
  }
  try {
    slam::parseAteAlignment(a.ate_align);
  } catch (const std::invalid_argument& e) {
    std::cerr << "process_bag: --ate-align: " << e.what() << "\n";
    return 2;
  }
  // The results directory is made and probed before the bag is read (a run is never lost to an unwritable --out);
  // an early failure leaves no empty results directory behind (the guard removes what it created, if still empty).
  std::unique_ptr<common::OutputDirectoryGuard> out_guard;
  try {
    out_guard = std::make_unique<common::OutputDirectoryGuard>(common::prepareOutputDirectory(a.out));
  } catch (const std::exception& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 3;
  }
  try {
    if (induration) {
      tools::IndurationRun r;
      r.bag = a.bag;
      r.out = a.out;
      r.configs = a.configs;
      r.sets = a.sets;
      r.frames = a.frames;
      r.every_frame_maps = maps == "all";
      r.quiet = a.quiet;
      r.ns = a.ns;
      r.command_line = a.command_line;
      r.site = site;
      r.site_poses = site_poses;
      r.sets.clear();
      for (const auto& kv : a.sets) (kv.first.rfind("site_", 0) == 0 ? r.site_sets : r.sets).push_back(kv);
      return tools::runInduration(r);
    }
    return tools::runSlam(a);
  } catch (const std::runtime_error& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "process_bag: " << e.what() << std::endl;
    return 1;
  }
}
