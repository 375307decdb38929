// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file bench_dense.cpp
 * @brief Dense stereo timing per stage on a workpiece bag, side by side with plain cv::StereoSGBM (benchmark, not a test).
 *
 *   bench_dense --bag WORKPIECE.bag [--frames N] [--roi-mp MP] [--z-range ZMIN ZMAX] [--no-full]
 *
 * Reads the first N stereo pairs of a workpiece bag (make_dataset workpiece: stereo/{left,right}/image_raw and
 * camera_info) into memory (bag I/O is not timed), and for each pair times
 *   rectify      cv::remap of both raw images (skin3d::stereo::Rectifier, maps built once)
 *   skin3d       computeDisparity's prepare / sgbm / refine stages (DisparityMap::timing), then triangulateDisparity
 *   plain SGBM   cv::StereoSGBM in MODE_HH and MODE_SGBM_3WAY on the same rectified grey input and disparity range
 *                (block 5, P1 = 8 * 25, P2 = 32 * 25, the rest OpenCV's defaults); for the region the SGBM input is
 *                the region plus the columns the search needs (cropped, zero-padded outside the image).
 * for the full-resolution pair and for regions of MP megapixels (default 1, the image's aspect ratio): one at the
 * image centre and one centred on the textured part of the first left rectified image (the working area of a
 * converged rig rectified with flags 0 can be far from the image centre). The disparity range comes from
 * stereo::disparityRangeForDepth with z 0.18 ... 0.40 m. MODE_HH needs about W * H * D * 4 bytes: it is skipped
 * (and the table says so) when that exceeds half of the available memory.
 * Prints a Markdown table with the machine (CPU model, nproc, load), the date and the command.
 * Exit codes: 0 ok, 1 the bag cannot be read or lacks images / camera_info, 2 bad command line.
 */
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "skin3d/ros/bag_topics.h"
#include "skin3d/ros/conversions.h"
#include "skin3d/ros/stereo_pairs.h"
#include "skin3d/common/large_buffers.h"
#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/dense_stereo.h"
#include "skin3d/stereo/rectification.h"

#include "bench_common.h"

namespace {

using skin3d::bench::cpuModel;
using skin3d::bench::loadAverage;
using skin3d::bench::availableMemory;
using skin3d::bench::today;
using skin3d::bench::fixed;
using skin3d::bench::median;

using namespace skin3d;
using Clock = std::chrono::steady_clock;

const char* kUsage =
    "usage: bench_dense --bag WORKPIECE.bag [--frames N] [--roi-mp MP] [--z-range ZMIN ZMAX] [--no-full] [--ns NS]\n"
    "  --ns NAMESPACE   the bag's topics are under this namespace (default: the root, or the only one)\n"
    "  --bag FILE        a workpiece bag (make_dataset workpiece): stereo/{left,right}/image_raw and camera_info\n"
    "  --frames N        time the first N stereo pairs (default 1); the table gives the median per pair\n"
    "  --roi-mp MP       size of the regions (image centre, textured area), megapixels (default 1; 0 = none)\n"
    "  --z-range A B     working depths, m, for the disparity range (default 0.18 0.40)\n"
    "  --no-full         skip the full-resolution runs (region only)\n"
    "  -h, --help        this text\n";

double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

/** A crop of `img` over `r`, zero outside the image. */
cv::Mat paddedCrop(const cv::Mat& img, const cv::Rect& r) {
  cv::Mat out(r.size(), img.type(), cv::Scalar::all(0));
  const cv::Rect inside = r & cv::Rect(0, 0, img.cols, img.rows);
  if (!inside.empty()) img(inside).copyTo(out(inside - r.tl()));
  return out;
}

/** One row of the table: times in ms (median over the pairs), NaN = not applicable. */
struct Row {
  std::string input, method, note;
  std::vector<double> prepare, sgbm, refine, total, triangulate, valid;
};

/**
 * Plain StereoSGBM over `roi` of the left image with disparities [d_min, d_max]: both images cropped (the left one
 * extended by the search width to the left, the right one shifted by floor(d_min)), so that the matcher sees
 * exactly what it needs. Fills prepare (crop), sgbm (compute), total and the valid fraction over the ROI.
 */
void plainSgbm(const cv::Mat& left, const cv::Mat& right, const cv::Rect& roi, double d_min, double d_max, int mode,
               Row* row) {
  const int block = 5;
  const int shift = static_cast<int>(std::floor(d_min));
  const int num = ((static_cast<int>(std::ceil(d_max)) - shift + 1 + 15) / 16) * 16;
  const auto t0 = Clock::now();
  const cv::Rect lr(roi.x - num, roi.y, roi.width + num, roi.height);
  const cv::Mat l = paddedCrop(left, lr), r = paddedCrop(right, lr - cv::Point(shift, 0));
  const auto t1 = Clock::now();
  cv::Ptr<cv::StereoSGBM> sgbm = cv::StereoSGBM::create(0, num, block, 8 * block * block, 32 * block * block);
  sgbm->setMode(mode);
  cv::Mat raw;
  sgbm->compute(l, r, raw);
  const auto t2 = Clock::now();
  const cv::Mat d = raw(cv::Rect(num, 0, roi.width, roi.height));
  row->prepare.push_back(ms(t0, t1));
  row->sgbm.push_back(ms(t1, t2));
  row->total.push_back(ms(t0, t2));
  row->valid.push_back(static_cast<double>(cv::countNonZero(d >= 0)) / d.total());
}

/** A strongly converged rig rectified with flags 0 may put the working area far from the image centre: a region
 *  of the roi's size centred on the textured part of the first left rectified image (none: no textured part).
 *  Throws what the rectification throws. */
std::optional<std::pair<std::string, cv::Rect>> texturedRegion(const geometry::CameraInfo& li, const cv::Mat& first_left,
                                                               const cv::Rect& roi) {
  const cv::Size size = first_left.size();
  const cv::Mat left = stereo::Rectifier(li)(first_left);
  cv::Mat small, f, mean, sq;
  const double k = std::max(1.0, size.width / 512.0);
  cv::resize(left, small, cv::Size(), 1.0 / k, 1.0 / k, cv::INTER_AREA);
  small.convertTo(f, CV_32F);
  cv::boxFilter(f, mean, CV_32F, cv::Size(7, 7));
  cv::boxFilter(f.mul(f), sq, CV_32F, cv::Size(7, 7));
  const cv::Mat stddev_sq = sq - mean.mul(mean);
  const cv::Mat textured = stddev_sq > 8.0 * 8.0;  // grey levels
  const cv::Moments mo = cv::moments(textured, true);
  if (!(mo.m00 > 0)) return std::nullopt;
  const cv::Point2d c(k * mo.m10 / mo.m00, k * mo.m01 / mo.m00);
  cv::Rect t(static_cast<int>(std::lround(c.x - roi.width / 2.0)), static_cast<int>(std::lround(c.y - roi.height / 2.0)),
             roi.width, roi.height);
  t.x = std::clamp(t.x, 0, size.width - t.width);
  t.y = std::clamp(t.y, 0, size.height - t.height);
  return std::make_pair("textured area " + std::to_string(t.width) + "x" + std::to_string(t.height) + " at (" +
                            std::to_string(t.x) + ", " + std::to_string(t.y) + ")",
                        t);
}

/** The benchmark's Markdown report on stdout: machine, date, command, inputs, then one row per input and method. */
void printReport(int argc, char** argv, const std::string& bag_path, std::size_t pairs, const cv::Size& size,
                 double z_min, double z_max, const std::pair<double, double>& range, int num,
                 const std::vector<double>& rectify_ms, const std::vector<Row>& rows, const std::vector<std::string>& warnings) {
  const long nproc = sysconf(_SC_NPROCESSORS_ONLN);
  std::string cmd;
  for (int i = 0; i < argc; ++i) cmd += (i ? " " : "") + std::string(i ? argv[i] : "bench_dense");
  auto cell = [](const std::vector<double>& v, int digits) {
    return v.empty() ? std::string("—") : fixed(median(v), digits);
  };
  std::cout << "# Dense stereo benchmark\n\n"
            << "- date: " << today() << "\n"
            << "- machine: " << nproc << " cores (nproc), " << cpuModel() << ", OpenCV " << CV_VERSION << " with "
            << cv::getNumThreads() << " threads; load average at the end " << loadAverage() << "\n"
            << "- command: `" << cmd << "`\n"
            << "- bag: " << bag_path << ", " << pairs << " stereo pair(s) of " << size.width << "x"
            << size.height << " (median over the pairs; no warm-up run)\n"
            << "- disparity range for z " << fixed(z_min, 2) << " ... " << fixed(z_max, 2) << " m: "
            << fixed(range.first, 1) << " ... " << fixed(range.second, 1) << " px (plain SGBM: " << num
            << " disparities)\n"
            << "- rectify (remap of both raw images): " << cell(rectify_ms, 0) << " ms per pair\n\n";
  std::cout << "| input | method | prepare ms | sgbm ms | refine ms | disparity total ms | triangulate ms | valid % | "
               "note |\n|---|---|---:|---:|---:|---:|---:|---:|---|\n";
  for (const Row& r : rows) {
    const bool ran = !r.total.empty();
    std::cout << "| " << r.input << " | " << r.method << " | " << (ran ? cell(r.prepare, 0) : "—") << " | "
              << (ran ? cell(r.sgbm, 0) : "—") << " | " << cell(r.refine, 0) << " | " << cell(r.total, 0) << " | "
              << cell(r.triangulate, 0) << " | " << (ran ? fixed(100 * median(r.valid), 1) : "—") << " | " << r.note
              << " |\n";
  }
  std::cout << "\nplain SGBM: block 5, P1 = 200, P2 = 800, other parameters OpenCV's defaults (no left-right check, "
               "no speckle filter), 1/16 px; its prepare = cropping the region plus the search width; valid = "
               "pixels of the region with a disparity.\n";
  for (const std::string& w : warnings) std::cout << "- warning: " << w << "\n";
}

/** The first `frames_wanted` raw stereo pairs of the bag and its camera_infos; false (with a message) if none. */
bool readPairs(const std::string& bag_path, const std::string& bag_ns, long frames_wanted,
               std::vector<std::pair<cv::Mat, cv::Mat>>* frames, geometry::CameraInfo* li, geometry::CameraInfo* ri) {
  try {
    ros_io::RawStereoPairs in = ros_io::readRawStereoPairs(bag_path, bag_ns, frames_wanted);
    *frames = std::move(in.pairs);
    *li = in.left;
    *ri = in.right;
    return true;
  } catch (const std::exception& e) {
    std::cerr << "bench_dense: " << e.what() << "\n";
    return false;
  }
}

}  // namespace

int main(int argc, char** argv) {
  skin3d::keepLargeBuffers();  // 13-megapixel buffers from the heap, not fresh mmap()s
  std::string bag_ns;  // "" = the root, or the one namespace holding the stereo topics
  std::string bag_path;
  long frames_wanted = 1;
  double roi_mp = 1.0, z_min = 0.18, z_max = 0.40;
  bool full = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    char* end = nullptr;
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--bag" && has_value) {
      bag_path = argv[++i];
    } else if (a == "--ns" && has_value) {
      bag_ns = argv[++i];
    } else if (a == "--frames" && has_value) {
      frames_wanted = std::strtol(argv[++i], &end, 10);
      if (!end || *end || frames_wanted < 1) {
        std::cerr << "bench_dense: --frames must be a positive integer (got '" << argv[i] << "')\n" << kUsage;
        return 2;
      }
    } else if (a == "--roi-mp" && has_value) {
      roi_mp = std::strtod(argv[++i], &end);
      if (!end || *end || !(roi_mp >= 0) || !std::isfinite(roi_mp)) {
        std::cerr << "bench_dense: --roi-mp must be a number >= 0 (got '" << argv[i] << "')\n" << kUsage;
        return 2;
      }
    } else if (a == "--z-range" && i + 2 < argc) {
      char* e2 = nullptr;
      z_min = std::strtod(argv[i + 1], &end);
      z_max = std::strtod(argv[i + 2], &e2);
      if (!end || *end || !e2 || *e2 || !(z_min > 0 && z_min < z_max)) {
        std::cerr << "bench_dense: --z-range needs 0 < ZMIN < ZMAX in metres (got '" << argv[i + 1] << "' '"
                  << argv[i + 2] << "')\n"
                  << kUsage;
        return 2;
      }
      i += 2;
    } else if (a == "--no-full") {
      full = false;
    } else {
      std::cerr << "bench_dense: unknown or incomplete argument '" << a << "'\n" << kUsage;
      return 2;
    }
  }
  if (bag_path.empty()) {
    std::cerr << "bench_dense: --bag is required\n" << kUsage;
    return 2;
  }
  if (!full && roi_mp <= 0) {
    std::cerr << "bench_dense: --no-full with --roi-mp 0 leaves nothing to run\n" << kUsage;
    return 2;
  }

  // Read the pairs (matched by stamp) and the first camera_info of each side.
  std::vector<std::pair<cv::Mat, cv::Mat>> frames;
  geometry::CameraInfo li, ri;
  if (!readPairs(bag_path, bag_ns, frames_wanted, &frames, &li, &ri)) return 1;
  const cv::Size size = frames[0].first.size();

  std::pair<double, double> range;
  try {
    range = stereo::disparityRangeForDepth(li, ri, z_min, z_max);
  } catch (const std::exception& e) {
    std::cerr << "bench_dense: " << e.what() << "\n";
    return 1;
  }
  // Central region of roi_mp megapixels with the image's aspect ratio.
  const double scale = std::min(1.0, std::sqrt(roi_mp * 1e6 / size.area()));
  const cv::Size rs(static_cast<int>(std::lround(size.width * scale)), static_cast<int>(std::lround(size.height * scale)));
  const cv::Rect roi((size.width - rs.width) / 2, (size.height - rs.height) / 2, rs.width, rs.height);

  struct Input { std::string name; cv::Rect roi; };  // a named region (empty roi: the whole image)
  std::vector<Input> inputs;
  if (full) inputs.push_back({"full " + std::to_string(size.width) + "x" + std::to_string(size.height), cv::Rect()});
  if (roi_mp > 0) {
    inputs.push_back({"image centre " + std::to_string(roi.width) + "x" + std::to_string(roi.height), roi});
    try {
      const auto t = texturedRegion(li, frames[0].first, roi);
      if (t)
        inputs.push_back({t->first, t->second});
      else
        std::cerr << "bench_dense: no textured area found in the first left image: no second region\n";
    } catch (const std::exception& e) {
      std::cerr << "bench_dense: " << e.what() << "\n";
      return 1;
    }
  }

  const int num = ((static_cast<int>(std::ceil(range.second)) - static_cast<int>(std::floor(range.first)) + 1 + 15) / 16) * 16;
  std::vector<double> rectify_ms;
  std::vector<Row> rows;
  std::vector<std::string> warnings;
  try {
    const stereo::Rectifier lr(li), rr(ri);
    for (const Input& in : inputs) {
      Row sk{in.name, "skin3d (sgbm_3way + lk)", "", {}, {}, {}, {}, {}, {}};
      Row hh{in.name, "StereoSGBM HH", "", {}, {}, {}, {}, {}, {}};
      Row w3{in.name, "StereoSGBM 3WAY", "", {}, {}, {}, {}, {}, {}};
      const cv::Rect area = in.roi.empty() ? cv::Rect(0, 0, size.width, size.height) : in.roi;
      // MODE_HH keeps the cost and the aggregated cost of every matched pixel and disparity (2 x int16).
      const double hh_bytes = 4.0 * area.width * area.height * num;
      const bool run_hh = hh_bytes < 0.5 * availableMemory();
      if (!run_hh)
        hh.note = "skipped: needs " + fixed(hh_bytes / 1e9, 1) + " GB (> half of the available " +
                  fixed(availableMemory() / 1e9, 1) + " GB)";
      for (const auto& f : frames) {
        std::cerr << "bench_dense: " << in.name << " ..." << std::endl;
        const auto t0 = Clock::now();
        const cv::Mat left = lr(f.first), right = rr(f.second);
        const auto t1 = Clock::now();
        if (&in == &inputs.front()) rectify_ms.push_back(ms(t0, t1));  // the same work for every input

        stereo::DenseStereoOptions opt;
        opt.min_disparity = range.first;
        opt.max_disparity = range.second;
        opt.roi = in.roi;
        const stereo::DisparityMap map = stereo::computeDisparity(left, right, opt);
        const auto t2 = Clock::now();
        const stereo::DenseCloud cloud = stereo::triangulateDisparity(map, li, ri);
        const auto t3 = Clock::now();
        sk.prepare.push_back(1e3 * map.timing.prepare);
        sk.sgbm.push_back(1e3 * map.timing.sgbm);
        sk.refine.push_back(1e3 * map.timing.refine);
        sk.total.push_back(1e3 * map.timing.total);
        sk.triangulate.push_back(ms(t2, t3));
        sk.valid.push_back(map.valid_fraction);
        sk.note = "coarse level 1/" + std::to_string(map.coarse_scale);
        for (const std::string& w : map.warnings) warnings.push_back(in.name + ": " + w);

        std::cerr << "bench_dense: " << in.name << " plain StereoSGBM ..." << std::endl;
        plainSgbm(left, right, area, range.first, range.second, cv::StereoSGBM::MODE_SGBM_3WAY, &w3);
        if (run_hh) plainSgbm(left, right, area, range.first, range.second, cv::StereoSGBM::MODE_HH, &hh);
      }
      rows.push_back(sk);
      rows.push_back(w3);
      rows.push_back(hh);
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_dense: " << e.what() << "\n";
    return 1;
  }

  printReport(argc, argv, bag_path, frames.size(), size, z_min, z_max, range, num, rectify_ms, rows, warnings);
  return 0;
}
