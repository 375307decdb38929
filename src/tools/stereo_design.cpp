// SPDX-License-Identifier: BSD-3-Clause
/**
 * stereo_design --config FILE.yaml [--out DIR] [--no-plots] [--quiet]
 *
 * The stereo design calculator (thesis ch. 3, "Camera Geometry Visualiser"):
 * prints the design table (mm, degrees) and, with --out, writes
 * DIR/report.yaml and the design plots (PNG, through scripts/plot_design.py).
 * Needs no ROS master. Exit codes: 0 ok, 1 bad configuration or impossible
 * geometry, 2 bad command line, 3 cannot write the output.
 */
#include <sys/stat.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "skin3d/geometry/design.h"

#ifndef SKIN3D_PLOT_SCRIPT
#define SKIN3D_PLOT_SCRIPT ""
#endif

namespace {

const char* kUsage =
    "usage: stereo_design --config FILE.yaml [--out DIR] [--no-plots] [--quiet]\n"
    "  --config FILE  design configuration (see config/part1_rig_design.yaml)\n"
    "  --out DIR      write DIR/report.yaml and the design plots (PNG)\n"
    "  --no-plots     with --out: only report.yaml\n"
    "  --quiet        do not print the table\n";

bool makeDirs(const std::string& path) {
  std::string partial;
  for (size_t i = 0; i <= path.size(); ++i) {
    if (i == path.size() || path[i] == '/') {
      if (!partial.empty() && mkdir(partial.c_str(), 0755) != 0 && errno != EEXIST) return false;
    }
    if (i < path.size()) partial += path[i];
  }
  struct stat st;
  return stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

bool fileExists(const std::string& p) {
  struct stat st;
  return !p.empty() && stat(p.c_str(), &st) == 0;
}

std::string findPlotScript(const char* argv0) {
  if (const char* env = std::getenv("SKIN3D_PLOT_SCRIPT")) return env;
  const std::string self(argv0);
  const auto slash = self.rfind('/');
  if (slash != std::string::npos) {
    const std::string sibling = self.substr(0, slash + 1) + "plot_design.py";
    if (fileExists(sibling)) return sibling;
  }
  if (fileExists(SKIN3D_PLOT_SCRIPT)) return SKIN3D_PLOT_SCRIPT;
  return "";
}

std::string shellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

}  // namespace

int main(int argc, char** argv) {
  std::string config_path, out_dir;
  bool plots = true, quiet = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if ((a == "--config" || a == "--out") && i + 1 < argc) {
      (a == "--config" ? config_path : out_dir) = argv[++i];
    } else if (a == "--no-plots") {
      plots = false;
    } else if (a == "--quiet") {
      quiet = true;
    } else if (a.rfind("__", 0) == 0) {
      // roslaunch/rosrun remapping arguments (__name:=, __log:=): ignore.
    } else {
      std::cerr << "stereo_design: unknown or incomplete argument '" << a << "'\n" << kUsage;
      return 2;
    }
  }
  if (config_path.empty()) {
    std::cerr << "stereo_design: --config FILE.yaml is required\n" << kUsage;
    return 2;
  }

  skin3d::geometry::DesignReport report;
  try {
    report = skin3d::geometry::computeDesign(skin3d::geometry::loadDesignConfig(config_path));
  } catch (const skin3d::geometry::DesignConfigError& e) {
    std::cerr << "stereo_design: " << config_path << ": " << e.what() << "\n";
    return 1;
  }
  if (!quiet) std::cout << skin3d::geometry::designReportTable(report);

  if (out_dir.empty()) return 0;
  if (!makeDirs(out_dir)) {
    std::cerr << "stereo_design: cannot create output directory '" << out_dir << "': " << std::strerror(errno) << "\n";
    return 3;
  }
  const std::string yaml_path = out_dir + "/report.yaml";
  {
    std::ofstream out(yaml_path);
    out << skin3d::geometry::designReportYaml(report);
    if (!out) {
      std::cerr << "stereo_design: cannot write " << yaml_path << "\n";
      return 3;
    }
  }
  if (!quiet) std::cout << "wrote " << yaml_path << "\n";
  if (!plots) return 0;
  const std::string script = findPlotScript(argv[0]);
  if (script.empty()) {
    std::cerr << "stereo_design: plot_design.py not found (set SKIN3D_PLOT_SCRIPT); use --no-plots to skip the plots\n";
    return 3;
  }
  const std::string cmd = "/usr/bin/python3 " + shellQuote(script) + " " + shellQuote(yaml_path) + " --out " +
                          shellQuote(out_dir) + (quiet ? " --quiet" : "");
  const int rc = std::system(cmd.c_str());
  if (rc != 0) {
    std::cerr << "stereo_design: the plots failed (" << cmd << " exited with " << WEXITSTATUS(rc) << ")\n";
    return 3;
  }
  return 0;
}
