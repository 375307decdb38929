// SPDX-License-Identifier: BSD-3-Clause
/**
 * bench_frontend --bag FILE.bag [--frames N] [--features kaze|akaze|orb|all]
 *
 * Times the sparse stereo front end per frame on a globe-images bag (make_dataset globe-images):
 *   rectify      cv::remap of both raw images with maps built once from the bag's camera_info (CV_16SC2)
 *   detect       StereoFeatureMatcher::detect on both rectified images, concurrently (as process() does)
 *   match        StereoFeatureMatcher::match (rows, disparity window with the P matrices' cx offset, ratio,
 *                cross-check)
 *   triangulate  skin3d::stereo::triangulateMatches (MMSE, 0.5 px) into landmarks
 * and prints a Markdown report: machine (nproc, CPU model, OpenCV threads), date, per stage and per frame
 * mean / median / max ms, and matches and landmarks per frame (min / median / max). The images are read into
 * memory first (bag I/O is not timed); frame 0 is processed once untimed per feature type (warm-up).
 * A benchmark, not a test: nothing is asserted. No ROS master needed.
 * Exit codes: 0 ok, 1 the bag cannot be read or lacks images / camera_info, 2 bad command line.
 */
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <exception>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "skin3d/ros/bag_topics.h"
#include "skin3d/ros/conversions.h"
#include "skin3d/ros/stereo_pairs.h"
#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/features.h"
#include "skin3d/stereo/rectification.h"
#include "skin3d/stereo/stereo_landmarks.h"

#include "bench_common.h"

namespace {

using skin3d::bench::cpuModel;
using skin3d::bench::today;
using skin3d::bench::fixed;

using namespace skin3d;
using Clock = std::chrono::steady_clock;

const char* kUsage =
    "usage: bench_frontend --bag FILE.bag [--frames N] [--features kaze|akaze|orb|all] [--ns NS]\n"
    "  --ns NAMESPACE   the bag's topics are under this namespace (default: the root, or the only one)\n"
    "  --bag FILE.bag   a globe-images bag: stereo/{left,right}/image_raw (mono8) and camera_info\n"
    "  --frames N       only the first N stereo pairs (default: all)\n"
    "  --features T     kaze, akaze, orb or all (default: all)\n"
    "  --octaves N, --layers N   KAZE/AKAZE scale space (default 4 x 4)\n";

struct RawPair {
  cv::Mat left, right;
};

double ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

struct Summary {
  double mean = 0, median = 0, min = 0, max = 0;
};

Summary summarise(std::vector<double> v) {
  Summary s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0;
  for (double x : v) sum += x;
  s.mean = sum / v.size();
  s.median = v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
  s.min = v.front();
  s.max = v.back();
  return s;
}

struct Result {
  std::string name;
  std::vector<double> rectify, detect, match, triangulate, total;
  std::vector<double> left_features, right_features, matches, landmarks;
};

Result run(stereo::FeatureType type, const std::vector<RawPair>& frames, const geometry::CameraInfo& li,
           const geometry::CameraInfo& ri, const stereo::Rectifier& lm, const stereo::Rectifier& rm, int octaves, int layers) {
  stereo::FeatureOptions opt;
  opt.type = type;
  opt.octaves = octaves;
  opt.octave_layers = layers;
  opt.disparity_offset = li.P(0, 2) - ri.P(0, 2);
  const stereo::StereoFeatureMatcher matcher(opt);
  const stereo::TriangulateOptions tri;
  Result r;
  r.name = stereo::featureTypeName(type);
  if (type != stereo::FeatureType::ORB && (octaves != 4 || layers != 4))
    r.name += " (" + std::to_string(octaves) + "x" + std::to_string(layers) + ")";
  for (size_t k = 0; k <= frames.size(); ++k) {
    const bool warm_up = k == 0;  // frame 0 once untimed, then every frame timed
    const RawPair& f = frames[warm_up ? 0 : k - 1];
    const auto t0 = Clock::now();
    const cv::Mat left = lm(f.left), right = rm(f.right);
    const auto t1 = Clock::now();
    stereo::ImageFeatures fl, fr;
    std::exception_ptr error;
    std::thread worker([&] {
      try {
        fr = matcher.detect(right);
      } catch (...) {
        error = std::current_exception();
      }
    });
    try {
      fl = matcher.detect(left);
    } catch (...) {
      worker.join();
      throw;
    }
    worker.join();
    if (error) std::rethrow_exception(error);
    const auto t2 = Clock::now();
    const std::vector<stereo::StereoMatch> matches = matcher.match(fl, fr);
    const auto t3 = Clock::now();
    const std::vector<stereo::StereoLandmark> landmarks = stereo::triangulateMatches(li, ri, matches, tri);
    const auto t4 = Clock::now();
    if (warm_up) continue;
    r.rectify.push_back(ms(t0, t1));
    r.detect.push_back(ms(t1, t2));
    r.match.push_back(ms(t2, t3));
    r.triangulate.push_back(ms(t3, t4));
    r.total.push_back(ms(t0, t4));
    r.left_features.push_back(static_cast<double>(fl.keypoints.size()));
    r.right_features.push_back(static_cast<double>(fr.keypoints.size()));
    r.matches.push_back(static_cast<double>(matches.size()));
    r.landmarks.push_back(static_cast<double>(landmarks.size()));
  }
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  std::string bag_ns;  // "" = the root, or the one namespace holding the stereo topics
  std::string bag_path, features = "all";
  long frames_wanted = -1;
  int octaves = 4, layers = 4;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--bag" && has_value) {
      bag_path = argv[++i];
    } else if (a == "--ns" && has_value) {
      bag_ns = argv[++i];
    } else if (a == "--features" && has_value) {
      features = argv[++i];
    } else if ((a == "--octaves" || a == "--layers") && has_value) {
      (a == "--octaves" ? octaves : layers) = std::atoi(argv[++i]);
      if ((a == "--octaves" ? octaves : layers) < 1) {
        std::cerr << "bench_frontend: " << a << " must be a positive integer\n" << kUsage;
        return 2;
      }
    } else if (a == "--frames" && has_value) {
      char* end = nullptr;
      frames_wanted = std::strtol(argv[++i], &end, 10);
      if (!end || *end || frames_wanted < 1) {
        std::cerr << "bench_frontend: --frames must be a positive integer (got '" << argv[i] << "')\n" << kUsage;
        return 2;
      }
    } else {
      std::cerr << "bench_frontend: unknown or incomplete argument '" << a << "'\n" << kUsage;
      return 2;
    }
  }
  if (bag_path.empty()) {
    std::cerr << "bench_frontend: --bag is required\n" << kUsage;
    return 2;
  }
  std::vector<stereo::FeatureType> types;
  if (features == "all") {
    types = {stereo::FeatureType::KAZE, stereo::FeatureType::AKAZE, stereo::FeatureType::ORB};
  } else {
    try {
      types = {stereo::parseFeatureType(features)};
    } catch (const std::invalid_argument& e) {
      std::cerr << "bench_frontend: --features: " << e.what() << " or all\n" << kUsage;
      return 2;
    }
  }

  // Read the pairs (matched by header stamp) and the first camera_info of each side into memory.
  std::vector<RawPair> frames;
  geometry::CameraInfo left_info, right_info;
  try {
    ros_io::RawStereoPairs in = ros_io::readRawStereoPairs(bag_path, bag_ns, frames_wanted);
    for (auto& p : in.pairs) frames.push_back({std::move(p.first), std::move(p.second)});
    left_info = in.left;
    right_info = in.right;
  } catch (const std::exception& e) {
    std::cerr << "bench_frontend: " << e.what() << "\n";
    return 1;
  }

  std::vector<Result> results;
  try {
    const stereo::Rectifier lm(left_info), rm(right_info);
    for (stereo::FeatureType t : types) {
      std::cerr << "bench_frontend: " << stereo::featureTypeName(t) << " on " << frames.size() << " frames ..."
                << std::endl;
      results.push_back(run(t, frames, left_info, right_info, lm, rm, octaves, layers));
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_frontend: " << e.what() << "\n";
    return 1;
  }

  const long nproc = sysconf(_SC_NPROCESSORS_ONLN);
  std::cout << "# Stereo front-end benchmark\n\n"
            << "- date: " << today() << "\n"
            << "- machine: " << nproc << " cores (nproc), " << cpuModel() << ", OpenCV " << CV_VERSION << " with "
            << cv::getNumThreads() << " threads\n"
            << "- bag: " << bag_path << ", " << frames.size() << " stereo pairs of " << frames[0].left.cols << "x"
            << frames[0].left.rows << "\n"
            << "- per frame: rectify = remap of both images; detect = both images concurrently; match = rows, "
               "disparity window, ratio 0.8, cross-check; triangulate = MMSE into landmarks. Frame 0 once untimed "
               "(warm-up).\n\n";
  std::cout << "| features | stage | mean ms | median ms | max ms |\n|---|---|---:|---:|---:|\n";
  for (const Result& r : results) {
    const std::pair<const char*, const std::vector<double>*> stages[] = {{"rectify", &r.rectify},
                                                                         {"detect", &r.detect},
                                                                         {"match", &r.match},
                                                                         {"triangulate", &r.triangulate},
                                                                         {"**frame**", &r.total}};
    for (const auto& s : stages) {
      const Summary x = summarise(*s.second);
      std::cout << "| " << r.name << " | " << s.first << " | " << fixed(x.mean, 1) << " | " << fixed(x.median, 1)
                << " | " << fixed(x.max, 1) << " |\n";
    }
  }
  std::cout << "\n| features | features left / right (median) | matches per frame min / median / max | "
               "landmarks per frame min / median / max | frames within 100 ms |\n|---|---:|---:|---:|---:|\n";
  for (const Result& r : results) {
    const Summary fl = summarise(r.left_features), fr = summarise(r.right_features), m = summarise(r.matches),
                  l = summarise(r.landmarks);
    const long within = std::count_if(r.total.begin(), r.total.end(), [](double t) { return t <= 100.0; });
    std::cout << "| " << r.name << " | " << fixed(fl.median, 0) << " / " << fixed(fr.median, 0) << " | "
              << fixed(m.min, 0) << " / " << fixed(m.median, 0) << " / " << fixed(m.max, 0) << " | " << fixed(l.min, 0)
              << " / " << fixed(l.median, 0) << " / " << fixed(l.max, 0) << " | " << within << " / " << r.total.size()
              << " |\n";
  }
  return 0;
}
