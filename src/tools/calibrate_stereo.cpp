// SPDX-License-Identifier: BSD-3-Clause
// calibrate_stereo --images DIR --pattern 9x6 --square SIZE --out DIR [options]
//
// Chessboard stereo calibration (OpenCV; thesis Table 4.1). Writes
//   DIR/left.yaml, DIR/right.yaml   camera_info in the ROS camera_calibration format (camera_info_manager,
//                                   camera_calibration_parsers); lengths in metres (P[3] = -fx' B)
//   DIR/report.yaml                 RMS reprojection error, baseline, angle between the optical axes, per-pair
//                                   errors, skipped pairs, rectification flags/alpha (mm, deg, px)
//   DIR/rectified_preview.png       the first used pair rectified side by side, with epipolar lines
// and prints the report as a table. Needs no ROS master.
//
// Pairing: by default every file left<KEY> in DIR is paired with right<KEY> (left01.jpg + right01.jpg; KEY is
// everything after "left"/"right", extension included, and only image files count). --left-glob/--right-glob
// take patterns with exactly one '*' that stands for KEY, optionally in a sub-folder of DIR:
//   --left-glob 'cam0/*.png' --right-glob 'cam1/*.png'     (cam0/0001.png + cam1/0001.png)
//   --left-glob 'L_*.bmp'    --right-glob 'R_*.bmp'
// Files without a partner are listed and ignored; pairs where the board is not found are listed and skipped.
//
// Exit codes: 0 ok; 1 bad input (no pairs, board found in fewer than 3 pairs, unreadable image, images of
// different sizes, bad --pattern or --square); 2 bad command line; 3 the output could not be written.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "skin3d/stereo/calibration.h"

namespace fs = std::filesystem;
using skin3d::stereo::CalibrationError;

namespace {

const char* kUsage =
    "usage: calibrate_stereo --images DIR --pattern COLSxROWS --square SIZE --out DIR [options]\n"
    "  --images DIR          folder with the stereo pairs (left01.jpg + right01.jpg, ...)\n"
    "  --pattern 9x6         inner corners of the chessboard (columns x rows), not squares\n"
    "  --square SIZE         side of one square: 25 or 25mm, 2.5cm, 0.025m (a bare number is mm)\n"
    "  --out DIR             writes left.yaml, right.yaml (ROS camera_info), report.yaml, rectified_preview.png\n"
    "options:\n"
    "  --left-glob PATTERN   left images, one '*' = the pairing key, may name a sub-folder (default 'left*')\n"
    "  --right-glob PATTERN  right images (default 'right*'); e.g. --left-glob 'cam0/*.png' --right-glob 'cam1/*.png'\n"
    "  --k-coefficients N    radial distortion terms estimated, 0..3 (default 2: k1 k2, as ROS camera_calibration;\n"
    "                        3 adds k3, which extrapolates badly beyond the board's corners)\n"
    "  --fix-intrinsic       stereo step keeps each camera's own calibration (ROS camera_calibration's way);\n"
    "                        default: both cameras refined jointly with the extrinsics\n"
    "  --converged-deg A     axes angle above which the rig counts as converged (default 15): rectified with\n"
    "                        flags 0, alpha 0, or projections fitted to keep the boards inside both images\n"
    "  --left-name NAME      camera_name in left.yaml (default 'left'); --right-name likewise ('right')\n"
    "  --quiet               no progress lines and no table (warnings and errors still go to stderr)\n"
    "exit codes: 0 ok, 1 bad input, 2 bad command line, 3 cannot write the output\n";

bool isImageFile(const std::string& name) {
  const auto dot = name.rfind('.');
  if (dot == std::string::npos) return false;
  std::string ext = name.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
  for (const char* e : {"png", "jpg", "jpeg", "bmp", "tif", "tiff", "pgm", "ppm", "pnm", "pbm", "webp", "jp2"})
    if (ext == e) return true;
  return false;
}

/** Natural order: "2" before "10". */
bool naturalLess(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) && std::isdigit(static_cast<unsigned char>(b[j]))) {
      size_t i2 = i, j2 = j;
      while (i2 < a.size() && std::isdigit(static_cast<unsigned char>(a[i2]))) ++i2;
      while (j2 < b.size() && std::isdigit(static_cast<unsigned char>(b[j2]))) ++j2;
      const std::string na = a.substr(i, i2 - i), nb = b.substr(j, j2 - j);
      const std::string ta = na.substr(std::min(na.find_first_not_of('0'), na.size()));
      const std::string tb = nb.substr(std::min(nb.find_first_not_of('0'), nb.size()));
      if (ta.size() != tb.size()) return ta.size() < tb.size();
      if (ta != tb) return ta < tb;
      if (na.size() != nb.size()) return na.size() < nb.size();
      i = i2;
      j = j2;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

struct Glob {
  std::string dir;     //!< sub-folder of --images ("" = itself)
  std::string prefix;  //!< file name before '*'
  std::string suffix;  //!< file name after '*'
};

bool parseGlob(const std::string& pattern, Glob* g, std::string* why) {
  const auto slash = pattern.rfind('/');
  g->dir = slash == std::string::npos ? "" : pattern.substr(0, slash);
  const std::string file = slash == std::string::npos ? pattern : pattern.substr(slash + 1);
  if (std::count(file.begin(), file.end(), '*') != 1 || g->dir.find('*') != std::string::npos) {
    *why = "must contain exactly one '*' (the pairing key), in the file name";
    return false;
  }
  const auto star = file.find('*');
  g->prefix = file.substr(0, star);
  g->suffix = file.substr(star + 1);
  return true;
}

/** key -> file (relative to the images folder) of the files matching a glob. */
std::map<std::string, std::string> listMatches(const std::string& images, const Glob& g) {
  std::map<std::string, std::string> out;
  const fs::path dir = g.dir.empty() ? fs::path(images) : fs::path(images) / g.dir;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return out;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file(ec)) continue;
    const std::string name = entry.path().filename().string();
    if (name.size() < g.prefix.size() + g.suffix.size() + 1) continue;
    if (name.compare(0, g.prefix.size(), g.prefix) != 0) continue;
    if (name.compare(name.size() - g.suffix.size(), g.suffix.size(), g.suffix) != 0) continue;
    if (!isImageFile(name)) continue;
    const std::string key = name.substr(g.prefix.size(), name.size() - g.prefix.size() - g.suffix.size());
    out[key] = g.dir.empty() ? name : g.dir + "/" + name;
  }
  return out;
}

std::string displayKey(const std::string& key) {
  const auto dot = key.rfind('.');
  return (dot != std::string::npos && dot > 0 && isImageFile(key)) ? key.substr(0, dot) : key;
}

bool makeDirs(const std::string& path) {
  std::error_code ec;
  fs::create_directories(path, ec);
  return fs::is_directory(path, ec);
}

bool writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  out.close();
  return static_cast<bool>(out);
}

/** The image pairs of `images` (left and right files with the same key, naturally sorted); files without a
 *  partner are listed. @return 0, or 1 (with a message) when the folder is unreadable or has no pair. */
int findPairs(const std::string& images, const Glob& lg, const Glob& rg, const std::string& left_glob,
              const std::string& right_glob, std::vector<skin3d::stereo::ImagePair>* out) {
  std::vector<skin3d::stereo::ImagePair>& pairs = *out;
  std::error_code ec;
  if (!fs::is_directory(images, ec)) {
    std::cerr << "calibrate_stereo: --images '" << images << "' is not a readable directory\n";
    return 1;
  }
  const auto lefts = listMatches(images, lg), rights = listMatches(images, rg);
  std::vector<std::string> keys;
  std::vector<std::string> unpaired;
  for (const auto& [key, file] : lefts) {
    if (rights.count(key))
      keys.push_back(key);
    else
      unpaired.push_back(file);
  }
  for (const auto& [key, file] : rights)
    if (!lefts.count(key)) unpaired.push_back(file);
  std::sort(keys.begin(), keys.end(), naturalLess);
  std::sort(unpaired.begin(), unpaired.end(), naturalLess);
  if (!unpaired.empty()) {
    std::cerr << "calibrate_stereo: " << unpaired.size() << " image(s) without a partner, ignored:";
    for (const auto& f : unpaired) std::cerr << " " << f;
    std::cerr << "\n";
  }
  if (keys.empty()) {
    std::cerr << "calibrate_stereo: no image pairs in '" << images << "': expected image files matching '" << left_glob
              << "' and '" << right_glob << "' with the same key (e.g. left01.jpg + right01.jpg); " << lefts.size()
              << " left and " << rights.size() << " right image(s) found; see --left-glob/--right-glob\n";
    return 1;
  }
  for (const auto& k : keys)
    pairs.push_back(
        {displayKey(k), (fs::path(images) / lefts.at(k)).string(), (fs::path(images) / rights.at(k)).string()});

  return 0;
}

/** left.yaml, right.yaml, report.yaml and rectified_preview.png (of the first pair used) in out_dir.
 *  @return 0, 1 (the preview failed) or 3 (a file cannot be written). */
int writeOutputs(const skin3d::stereo::StereoCalibration& calib, const std::vector<skin3d::stereo::SkippedPair>& skipped,
                 const std::vector<skin3d::stereo::ImagePair>& pairs, const skin3d::stereo::StereoCorners& corners,
                 const std::string& out_dir, const std::string& left_name, const std::string& right_name, bool quiet,
                 double seconds) {
  const std::string left_yaml = out_dir + "/left.yaml", right_yaml = out_dir + "/right.yaml",
                    report_yaml = out_dir + "/report.yaml", preview_png = out_dir + "/rectified_preview.png";
  for (const auto& [path, text] :
       {std::make_pair(left_yaml, skin3d::stereo::cameraInfoYaml(calib.left, left_name)),
        std::make_pair(right_yaml, skin3d::stereo::cameraInfoYaml(calib.right, right_name)),
        std::make_pair(report_yaml, skin3d::stereo::calibrationReportYaml(calib, skipped))}) {
    if (!writeText(path, text)) {
      std::cerr << "calibrate_stereo: cannot write " << path << ": " << std::strerror(errno) << "\n";
      return 3;
    }
  }
  // Preview of the first used pair.
  const auto it = std::find_if(pairs.begin(), pairs.end(),
                               [&](const skin3d::stereo::ImagePair& p) { return p.name == corners.names.front(); });
  const cv::Mat l = cv::imread(it->left_path, cv::IMREAD_COLOR), r = cv::imread(it->right_path, cv::IMREAD_COLOR);
  cv::Mat preview;
  try {
    preview = skin3d::stereo::drawRectifiedPreview(calib, l, r, corners.left.front(), corners.right.front());
  } catch (const std::exception& e) {
    std::cerr << "calibrate_stereo: preview of pair " << it->name << ": " << e.what() << "\n";
    return 1;
  }
  bool ok = false;
  try {
    ok = cv::imwrite(preview_png, preview);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) {
    std::cerr << "calibrate_stereo: cannot write " << preview_png << "\n";
    return 3;
  }
  if (!quiet)
    std::cout << "wrote " << left_yaml << ", " << right_yaml << ", " << report_yaml << ", " << preview_png
              << " (preview: pair " << it->name << "; corners and calibration took " << std::fixed
              << std::setprecision(1) << seconds << " s)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string images, pattern_text, square_text, out_dir;
  std::string left_glob = "left*", right_glob = "right*", left_name = "left", right_name = "right";
  skin3d::stereo::CalibrationOptions options;
  bool quiet = false;
  const auto bad = [](const std::string& why) {
    std::cerr << "calibrate_stereo: " << why << "\n" << kUsage;
    return 2;
  };
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--quiet") {
      quiet = true;
    } else if (a == "--fix-intrinsic") {
      options.fix_intrinsic = true;
    } else if (a.rfind("__", 0) == 0) {
      // roslaunch/rosrun remapping arguments (__name:=, __log:=): ignore.
    } else if (a == "--images" || a == "--pattern" || a == "--square" || a == "--out" || a == "--left-glob" ||
               a == "--right-glob" || a == "--left-name" || a == "--right-name" || a == "--k-coefficients" ||
               a == "--converged-deg") {
      if (!has_value) return bad("option " + a + " needs a value");
      const std::string v = argv[++i];
      if (a == "--images") images = v;
      if (a == "--pattern") pattern_text = v;
      if (a == "--square") square_text = v;
      if (a == "--out") out_dir = v;
      if (a == "--left-glob") left_glob = v;
      if (a == "--right-glob") right_glob = v;
      if (a == "--left-name") left_name = v;
      if (a == "--right-name") right_name = v;
      if (a == "--k-coefficients") {
        if (v.size() != 1 || v[0] < '0' || v[0] > '3') return bad("--k-coefficients '" + v + "' must be 0, 1, 2 or 3");
        options.k_coefficients = v[0] - '0';
      }
      if (a == "--converged-deg") {
        char* end = nullptr;
        const double d = std::strtod(v.c_str(), &end);
        if (v.empty() || *end != '\0' || !(d >= 0.0 && d < 180.0))
          return bad("--converged-deg '" + v + "' must be an angle in degrees in [0, 180)");
        options.converged_threshold_rad = d * M_PI / 180.0;
      }
    } else {
      return bad("unknown argument '" + a + "'");
    }
  }
  for (const auto& [name, value] : {std::make_pair("--images", &images), std::make_pair("--pattern", &pattern_text),
                                    std::make_pair("--square", &square_text), std::make_pair("--out", &out_dir)})
    if (value->empty()) return bad(std::string(name) + " is required");
  Glob lg, rg;
  std::string why;
  if (!parseGlob(left_glob, &lg, &why)) return bad("--left-glob '" + left_glob + "' " + why);
  if (!parseGlob(right_glob, &rg, &why)) return bad("--right-glob '" + right_glob + "' " + why);

  // ---- input checks (exit 1)
  skin3d::stereo::ChessboardPattern pattern;
  try {
    const cv::Size s = skin3d::stereo::parsePatternSize(pattern_text);
    pattern.cols = s.width;
    pattern.rows = s.height;
    pattern.square_m = skin3d::stereo::parseLengthToMetres(square_text, "--square");
  } catch (const CalibrationError& e) {
    std::cerr << "calibrate_stereo: " << e.what() << "\n";
    return 1;
  }
  if (pattern.cols == pattern.rows)
    std::cerr << "calibrate_stereo: warning: a square " << pattern_text
              << " board has no defined orientation; a board with different column and row counts is safer\n";
  if (pattern.square_m < 1e-3)
    std::cerr << "calibrate_stereo: warning: --square " << square_text
              << " is read as less than 1 mm (a bare number is millimetres; write e.g. 0.025m for metres)\n";
  std::vector<skin3d::stereo::ImagePair> pairs;
  if (const int code = findPairs(images, lg, rg, left_glob, right_glob, &pairs)) return code;

  // ---- output folder first, so that a bad --out fails before the work (exit 3)
  if (!makeDirs(out_dir) || access(out_dir.c_str(), W_OK) != 0) {
    std::cerr << "calibrate_stereo: cannot create or write the output directory '" << out_dir
              << "': " << std::strerror(errno ? errno : EACCES) << "\n";
    return 3;
  }

  // ---- corners
  const auto t0 = std::chrono::steady_clock::now();
  if (!quiet)
    std::cout << "Detecting the " << pattern.cols << "x" << pattern.rows << " chessboard in " << pairs.size()
              << " pairs of '" << images << "'\n";
  std::vector<skin3d::stereo::SkippedPair> skipped;
  skin3d::stereo::StereoCorners corners;
  try {
    corners = skin3d::stereo::detectStereoCorners(pairs, pattern.size(), &skipped, [&](const std::string& line) {
      if (!quiet) std::cout << "  " << line << std::endl;
    });
  } catch (const CalibrationError& e) {
    std::cerr << "calibrate_stereo: " << e.what() << "\n";
    return 1;
  }
  if (static_cast<int>(corners.names.size()) < options.min_pairs) {
    std::cerr << "calibrate_stereo: the " << pattern.cols << "x" << pattern.rows
              << " board was found in both images of only " << corners.names.size() << " of " << pairs.size()
              << " pairs; at least " << options.min_pairs
              << " are needed (is --pattern the number of INNER corners, columns x rows?)\n"
              << "skipped pairs:\n";
    for (const auto& s : skipped) std::cerr << "  " << s.name << ": " << s.reason << "\n";
    return 1;
  }

  // ---- calibration
  skin3d::stereo::StereoCalibration calib;
  try {
    calib = skin3d::stereo::calibrateStereo(corners, pattern, options);
  } catch (const CalibrationError& e) {
    std::cerr << "calibrate_stereo: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "calibrate_stereo: the calibration failed: " << e.what() << "\n";
    return 1;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!quiet) std::cout << skin3d::stereo::calibrationReportTable(calib, skipped);

  // ---- outputs
  if (const int code = writeOutputs(calib, skipped, pairs, corners, out_dir, left_name, right_name, quiet, seconds))
    return code;
  return 0;
}
