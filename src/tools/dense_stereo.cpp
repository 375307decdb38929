// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file dense_stereo.cpp
 * @brief Command-line dense matching of one rectified stereo pair of image files (skin3d::stereo::computeDisparity).
 *
 *   dense_stereo --left L --right R [--calib DIR] [--out DIR]
 *                [--min-disparity N --max-disparity N | --z-range ZMIN ZMAX]
 *                [--roi x,y,w,h] [--mode sgbm_3way|hh|sgbm] [--subpixel lk|sgbm] [--block N]
 *
 * Writes into DIR: disparity.tiff (32-bit float, px, x_left - x_right, NaN = unknown), sigma.tiff (32-bit float,
 * px, 1 sigma of the disparity, NaN = unknown), disparity.png (false-colour preview, black = unknown) and, with
 * --calib DIR holding left.yaml / right.yaml (ROS camera_info YAML of the rectified pair), cloud.ply (binary PLY,
 * x y z in metres in the left camera's optical frame, colour from the left image). Prints a summary (valid
 * fraction, time per stage, warnings).
 * Exit codes: 0 ok, 1 the pair cannot be processed (missing or unreadable file, size mismatch, bad calibration,
 * ROI outside the image, ...), 2 bad command line.
 */
#include <sys/stat.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/common/large_buffers.h"
#include "skin3d/geometry/camera.h"
#include "skin3d/stereo/calibration.h"
#include "skin3d/stereo/dense_stereo.h"

namespace {

using namespace skin3d;
using Clock = std::chrono::steady_clock;

const char* kUsage =
    "usage: dense_stereo --left L --right R [--calib DIR] [--out DIR]\n"
    "                    (--min-disparity N --max-disparity N | --z-range ZMIN ZMAX)\n"
    "                    [--roi x,y,w,h] [--mode sgbm_3way|hh|sgbm] [--subpixel lk|sgbm] [--block N]\n"
    "Dense disparity of a RECTIFIED stereo pair of image files (8- or 16-bit, grey or colour, same size).\n"
    "  --left L, --right R   the rectified left and right images (any format OpenCV reads)\n"
    "  --calib DIR           folder with left.yaml and right.yaml: ROS camera_info YAML of the rectified pair\n"
    "                        (P of each camera); enables --z-range and the point cloud cloud.ply\n"
    "  --out DIR             output folder, created if missing (default: .)\n"
    "  --min-disparity N     smallest disparity x_left - x_right searched, px at full resolution\n"
    "  --max-disparity N     largest disparity searched, px (> min-disparity); give both, or --z-range\n"
    "  --z-range ZMIN ZMAX   working depths in metres (0 < ZMIN < ZMAX, needs --calib): the disparity range\n"
    "                        follows from the rectified projections\n"
    "  --roi x,y,w,h         region of the left image to match, px (default: the whole image)\n"
    "  --mode M              semi-global matcher: sgbm_3way (default), hh (8 paths, more memory) or sgbm (5 paths)\n"
    "  --subpixel S          lk (default: local correlation fit, no pixel locking) or sgbm (OpenCV's 1/16 px)\n"
    "  --block N             SGBM block size, odd, 1 ... 11 (default 5)\n"
    "  -h, --help            this text\n"
    "Writes DIR/disparity.tiff (CV_32F, px, NaN = unknown), DIR/sigma.tiff (CV_32F, px, 1 sigma),\n"
    "DIR/disparity.png (false colour, black = unknown) and, with --calib, DIR/cloud.ply (binary PLY: x y z in m\n"
    "in the left camera's optical frame, colour of the left image).\n"
    "Exit codes: 0 ok, 1 the pair cannot be processed, 2 bad command line.\n";

/** Thrown for a bad command line (exit code 2). */
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

double parseNumber(const std::string& option, const std::string& text) {
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || !end || *end || errno == ERANGE || !std::isfinite(v))
    throw UsageError(option + " expects a finite number, got '" + text + "'");
  return v;
}

int parseInt(const std::string& option, const std::string& text) {
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || !end || *end || errno == ERANGE || v < std::numeric_limits<int>::min() ||
      v > std::numeric_limits<int>::max())
    throw UsageError(option + " expects an integer, got '" + text + "'");
  return static_cast<int>(v);
}

cv::Rect parseRoi(const std::string& text) {
  std::vector<int> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) v.push_back(parseInt("--roi", item));
  if (v.size() != 4) throw UsageError("--roi expects x,y,w,h (four integers), got '" + text + "'");
  if (v[0] < 0 || v[1] < 0 || v[2] <= 0 || v[3] <= 0)
    throw UsageError("--roi x,y,w,h needs x, y >= 0 and w, h > 0, got '" + text + "'");
  return {v[0], v[1], v[2], v[3]};
}

bool isFile(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

bool isDir(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

/** Creates `path` and its parents (like mkdir -p); throws naming the folder. */
void makeDirs(const std::string& path) {
  if (path.empty() || isDir(path)) return;
  const auto slash = path.find_last_of('/');
  if (slash != std::string::npos && slash > 0) makeDirs(path.substr(0, slash));
  if (::mkdir(path.c_str(), 0755) != 0 && !isDir(path))
    throw std::runtime_error("cannot create the output folder '" + path + "'");
}

cv::Mat readImage(const std::string& path, const std::string& which) {
  if (!isFile(path)) throw std::runtime_error(which + " image '" + path + "' does not exist (or is not a file)");
  cv::Mat img = cv::imread(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  if (img.empty()) throw std::runtime_error(which + " image '" + path + "' cannot be read as an image");
  if (img.depth() != CV_8U && img.depth() != CV_16U)
    throw std::runtime_error(which + " image '" + path + "' is neither 8-bit nor 16-bit");
  if (img.channels() == 4) cv::cvtColor(img, img, cv::COLOR_BGRA2BGR);
  if (img.channels() != 1 && img.channels() != 3)
    throw std::runtime_error(which + " image '" + path + "' has " + std::to_string(img.channels()) +
                             " channels (1 or 3 expected)");
  return img;
}

/** 8-bit BGR copy of an 8/16-bit grey or colour image (for the cloud's colours). */
cv::Mat toBgr8(const cv::Mat& img) {
  cv::Mat out = img;
  if (img.depth() == CV_16U) img.convertTo(out, CV_8U, 1.0 / 257.0);
  if (out.channels() == 1) cv::cvtColor(out, out, cv::COLOR_GRAY2BGR);
  return out;
}

/** False-colour preview: the 1st ... 99th percentile of the known disparities on the turbo map, unknown black. */
cv::Mat disparityPreview(const cv::Mat& disparity, double* lo_out, double* hi_out) {
  std::vector<float> v;
  v.reserve(disparity.total());
  for (int y = 0; y < disparity.rows; ++y) {
    const float* d = disparity.ptr<float>(y);
    for (int x = 0; x < disparity.cols; ++x)
      if (std::isfinite(d[x])) v.push_back(d[x]);
  }
  double lo = 0, hi = 1;
  if (!v.empty()) {
    const size_t a = v.size() / 100, b = v.size() - 1 - v.size() / 100;
    std::nth_element(v.begin(), v.begin() + a, v.end());
    lo = v[a];
    std::nth_element(v.begin(), v.begin() + b, v.end());
    hi = v[b];
    if (hi <= lo) hi = lo + 1;
  }
  cv::Mat grey(disparity.size(), CV_8U), mask(disparity.size(), CV_8U);
  for (int y = 0; y < disparity.rows; ++y) {
    const float* d = disparity.ptr<float>(y);
    uint8_t* g = grey.ptr<uint8_t>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < disparity.cols; ++x) {
      m[x] = std::isfinite(d[x]) ? 255 : 0;
      g[x] = m[x] ? cv::saturate_cast<uint8_t>(255.0 * (d[x] - lo) / (hi - lo)) : 0;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  cv::Mat out = cv::Mat::zeros(colour.size(), colour.type());
  colour.copyTo(out, mask);
  *lo_out = lo;
  *hi_out = hi;
  return out;
}

/** Binary little-endian PLY of the known points (float x y z in m, uchar red green blue); returns the count. */
size_t writeCloudPly(const std::string& path, const stereo::DenseCloud& cloud, const cv::Mat& bgr) {
  struct Vertex {
    float x, y, z;
    uint8_t r, g, b;
  };
  std::vector<Vertex> points;
  points.reserve(cloud.xyz.total() / 2);
  for (int y = 0; y < cloud.xyz.rows; ++y) {
    const cv::Vec3f* p = cloud.xyz.ptr<cv::Vec3f>(y);
    const cv::Vec3b* c = bgr.ptr<cv::Vec3b>(y);
    for (int x = 0; x < cloud.xyz.cols; ++x)
      if (std::isfinite(p[x][0]) && std::isfinite(p[x][1]) && std::isfinite(p[x][2]))
        points.push_back({p[x][0], p[x][1], p[x][2], c[x][2], c[x][1], c[x][0]});
  }
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot write '" + path + "'");
  f << "ply\nformat binary_little_endian 1.0\n"
    << "comment skin3d dense_stereo: metres, left camera optical frame (x right, y down, z forward)\n"
    << "element vertex " << points.size() << "\n"
    << "property float x\nproperty float y\nproperty float z\n"
    << "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  const uint16_t probe = 1;
  const bool little = *reinterpret_cast<const uint8_t*>(&probe) == 1;
  for (const Vertex& v : points) {
    float xyz[3] = {v.x, v.y, v.z};
    if (!little)
      for (float& q : xyz) {
        uint8_t* b = reinterpret_cast<uint8_t*>(&q);
        std::reverse(b, b + 4);
      }
    f.write(reinterpret_cast<const char*>(xyz), sizeof xyz);
    const uint8_t rgb[3] = {v.r, v.g, v.b};
    f.write(reinterpret_cast<const char*>(rgb), sizeof rgb);
  }
  if (!f) throw std::runtime_error("error while writing '" + path + "' (disk full?)");
  return points.size();
}

void writeFloatTiff(const std::string& path, const cv::Mat& m) {
  bool ok = false;
  try {
    ok = cv::imwrite(path, m);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("cannot write '" + path + "': " + e.what());
  }
  if (!ok) throw std::runtime_error("cannot write '" + path + "'");
}

struct Args {
  std::string left, right, calib, out = ".";
  double min_d = std::numeric_limits<double>::quiet_NaN(), max_d = std::numeric_limits<double>::quiet_NaN();
  double z_min = std::numeric_limits<double>::quiet_NaN(), z_max = std::numeric_limits<double>::quiet_NaN();
  bool have_min = false, have_max = false, have_z = false;
  cv::Rect roi;
  std::string mode = "sgbm_3way", subpixel = "lk";
  int block = 5;
};

/** Parses the command line; returns false for --help. @throws UsageError naming the option. */
bool parseArgs(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    auto value = [&](int k = 1) -> std::string {
      if (i + k >= argc || std::string(argv[i + k]).rfind("--", 0) == 0)
        throw UsageError(opt + " needs " + (k == 1 ? "a value" : "two values"));
      return argv[i + k];
    };
    if (opt == "-h" || opt == "--help") {
      return false;
    } else if (opt == "--left") {
      a->left = value();
      ++i;
    } else if (opt == "--right") {
      a->right = value();
      ++i;
    } else if (opt == "--calib") {
      a->calib = value();
      ++i;
    } else if (opt == "--out") {
      a->out = value();
      ++i;
    } else if (opt == "--min-disparity") {
      a->min_d = parseNumber(opt, value());
      a->have_min = true;
      ++i;
    } else if (opt == "--max-disparity") {
      a->max_d = parseNumber(opt, value());
      a->have_max = true;
      ++i;
    } else if (opt == "--z-range") {
      value(2);
      a->z_min = parseNumber(opt, argv[i + 1]);
      a->z_max = parseNumber(opt, argv[i + 2]);
      a->have_z = true;
      i += 2;
    } else if (opt == "--roi") {
      a->roi = parseRoi(value());
      ++i;
    } else if (opt == "--mode") {
      a->mode = value();
      ++i;
      if (a->mode != "sgbm_3way" && a->mode != "hh" && a->mode != "sgbm")
        throw UsageError("--mode must be sgbm_3way, hh or sgbm, got '" + a->mode + "'");
    } else if (opt == "--subpixel") {
      a->subpixel = value();
      ++i;
      if (a->subpixel != "lk" && a->subpixel != "sgbm")
        throw UsageError("--subpixel must be lk or sgbm, got '" + a->subpixel + "'");
    } else if (opt == "--block") {
      a->block = parseInt(opt, value());
      ++i;
      if (a->block < 1 || a->block > 11 || a->block % 2 == 0)
        throw UsageError("--block must be odd, 1 ... 11, got " + std::to_string(a->block));
    } else {
      throw UsageError("unknown argument '" + opt + "'");
    }
  }
  if (a->left.empty()) throw UsageError("--left is required");
  if (a->right.empty()) throw UsageError("--right is required");
  if (a->have_z && (a->have_min || a->have_max))
    throw UsageError("give either --min-disparity/--max-disparity or --z-range, not both");
  if (a->have_z) {
    if (a->calib.empty()) throw UsageError("--z-range needs --calib DIR (the rectified projections)");
    if (!(a->z_min > 0 && a->z_min < a->z_max))
      throw UsageError("--z-range needs 0 < ZMIN < ZMAX (metres), got " + std::to_string(a->z_min) + " " +
                       std::to_string(a->z_max));
  } else {
    if (!a->have_min && !a->have_max)
      throw UsageError("a disparity range is required: --min-disparity N --max-disparity N, or --z-range ZMIN ZMAX");
    if (!a->have_min) throw UsageError("--max-disparity given without --min-disparity");
    if (!a->have_max) throw UsageError("--min-disparity given without --max-disparity");
    if (!(a->min_d < a->max_d))
      throw UsageError("--min-disparity (" + std::to_string(a->min_d) + ") must be smaller than --max-disparity (" +
                       std::to_string(a->max_d) + ")");
  }
  return true;
}

std::string fixed(double v, int digits) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(digits) << v;
  return os.str();
}

}  // namespace

int main(int argc, char** argv) {
  skin3d::keepLargeBuffers();  // 13-megapixel buffers from the heap, not fresh mmap()s
  Args args;
  try {
    if (!parseArgs(argc, argv, &args)) {
      std::cout << kUsage;
      return 0;
    }
  } catch (const UsageError& e) {
    std::cerr << "dense_stereo: " << e.what() << "\n" << kUsage;
    return 2;
  }

  try {
    const auto t_read0 = Clock::now();
    const cv::Mat left = readImage(args.left, "left");
    const cv::Mat right = readImage(args.right, "right");
    if (left.size() != right.size())
      throw std::runtime_error("the images differ in size: left " + std::to_string(left.cols) + "x" +
                               std::to_string(left.rows) + ", right " + std::to_string(right.cols) + "x" +
                               std::to_string(right.rows) + " (a rectified pair has one size)");
    if (left.depth() != right.depth())
      throw std::runtime_error(std::string("the images differ in bit depth: left ") +
                               (left.depth() == CV_8U ? "8" : "16") + "-bit, right " +
                               (right.depth() == CV_8U ? "8" : "16") + "-bit");
    cv::Mat left_m = left, right_m = right;
    std::vector<std::string> notes;
    if (left.channels() != right.channels()) {  // one grey, one colour: match on grey
      if (left_m.channels() == 3) cv::cvtColor(left_m, left_m, cv::COLOR_BGR2GRAY);
      if (right_m.channels() == 3) cv::cvtColor(right_m, right_m, cv::COLOR_BGR2GRAY);
      notes.push_back("one image is grey and the other colour: both matched as grey");
    }

    // Calibration of the rectified pair (optional).
    geometry::CameraInfo li, ri;
    const bool have_calib = !args.calib.empty();
    if (have_calib) {
      if (!isDir(args.calib)) throw std::runtime_error("--calib folder '" + args.calib + "' does not exist");
      for (const std::string side : {"left", "right"})
        if (!isFile(args.calib + "/" + side + ".yaml"))
          throw std::runtime_error("--calib folder '" + args.calib + "' has no " + side +
                                   ".yaml (camera_info YAML of the rectified " + side + " camera)");
      try {
        li = stereo::readCameraInfoYaml(args.calib + "/left.yaml");
        ri = stereo::readCameraInfoYaml(args.calib + "/right.yaml");
      } catch (const stereo::CalibrationError& e) {
        throw std::runtime_error(std::string("bad calibration in '") + args.calib + "': " + e.what());
      }
      for (const auto* info : {&li, &ri})
        if (info->width != left.cols || info->height != left.rows)
          throw std::runtime_error("calibration " + std::string(info == &li ? "left" : "right") + ".yaml is for " +
                                   std::to_string(info->width) + "x" + std::to_string(info->height) +
                                   " images, the pair is " + std::to_string(left.cols) + "x" +
                                   std::to_string(left.rows));
    }
    const auto t_read1 = Clock::now();
    if (!args.roi.empty() && (args.roi & cv::Rect(0, 0, left.cols, left.rows)).empty())
      throw std::runtime_error("--roi " + std::to_string(args.roi.x) + "," + std::to_string(args.roi.y) + "," +
                               std::to_string(args.roi.width) + "," + std::to_string(args.roi.height) +
                               " lies outside the " + std::to_string(left.cols) + "x" + std::to_string(left.rows) +
                               " image");

    stereo::DenseStereoOptions opt;
    if (args.have_z) {
      const auto range = stereo::disparityRangeForDepth(li, ri, args.z_min, args.z_max);
      opt.min_disparity = range.first;
      opt.max_disparity = range.second;
    } else {
      opt.min_disparity = args.min_d;
      opt.max_disparity = args.max_d;
    }
    opt.roi = args.roi;
    opt.sgbm_mode = args.mode;
    opt.subpixel = args.subpixel;
    opt.block_size = args.block;

    const stereo::DisparityMap map = stereo::computeDisparity(left_m, right_m, opt);

    double t_tri = 0;
    stereo::DenseCloud cloud;
    if (have_calib) {
      const auto t0 = Clock::now();
      cloud = stereo::triangulateDisparity(map, li, ri);
      t_tri = seconds(t0, Clock::now());
    }

    const auto t_write0 = Clock::now();
    makeDirs(args.out);
    std::vector<std::string> written;
    writeFloatTiff(args.out + "/disparity.tiff", map.disparity);
    written.push_back(args.out + "/disparity.tiff");
    writeFloatTiff(args.out + "/sigma.tiff", map.sigma);
    written.push_back(args.out + "/sigma.tiff");
    double lo = 0, hi = 0;
    const cv::Mat preview = disparityPreview(map.disparity, &lo, &hi);
    if (!cv::imwrite(args.out + "/disparity.png", preview))
      throw std::runtime_error("cannot write '" + args.out + "/disparity.png'");
    written.push_back(args.out + "/disparity.png (turbo colours " + fixed(lo, 1) + " ... " + fixed(hi, 1) +
                      " px, black = unknown)");
    size_t n_points = 0;
    if (have_calib) {
      n_points = writeCloudPly(args.out + "/cloud.ply", cloud, toBgr8(left));
      written.push_back(args.out + "/cloud.ply (" + std::to_string(n_points) + " points)");
    }
    const double t_write = seconds(t_write0, Clock::now());

    // Summary.
    std::cout << "dense_stereo: " << left.cols << "x" << left.rows << " " << (left_m.channels() == 1 ? "grey" : "colour")
              << " " << (left.depth() == CV_8U ? 8 : 16) << "-bit pair, ROI " << map.roi.x << "," << map.roi.y << ","
              << map.roi.width << "," << map.roi.height << ", disparity " << fixed(opt.min_disparity, 2) << " ... "
              << fixed(opt.max_disparity, 2) << " px"
              << (args.have_z ? " (z " + fixed(args.z_min, 3) + " ... " + fixed(args.z_max, 3) + " m)" : "") << "\n"
              << "  matcher: " << opt.sgbm_mode << ", block " << opt.block_size << ", sub-pixel " << opt.subpixel
              << ", coarse level 1/" << map.coarse_scale << "\n"
              << "  valid: " << fixed(100.0 * map.valid_fraction, 1) << " % of the ROI\n"
              << "  time [s]: read " << fixed(seconds(t_read0, t_read1), 3) << ", prepare "
              << fixed(map.timing.prepare, 3) << ", sgbm " << fixed(map.timing.sgbm, 3) << ", refine "
              << fixed(map.timing.refine, 3) << ", disparity total " << fixed(map.timing.total, 3);
    if (have_calib) std::cout << ", triangulate " << fixed(t_tri, 3);
    std::cout << ", write " << fixed(t_write, 3) << "\n";
    for (const std::string& n : notes) std::cout << "  note: " << n << "\n";
    for (const std::string& w : map.warnings) std::cout << "  WARNING: " << w << "\n";
    if (!have_calib) std::cout << "  no --calib: disparity only, no point cloud\n";
    for (const std::string& w : written) std::cout << "  wrote " << w << "\n";
    return 0;
  } catch (const stereo::DenseStereoError& e) {
    std::cerr << "dense_stereo: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "dense_stereo: " << e.what() << "\n";
    return 1;
  }
}
