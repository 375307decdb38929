// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file run_info.h
 * @brief What a run of skin3d shares (process_bag's two modes, the SLAM nodelet's results): progress on long
 * runs and the parameters.yaml of the results directory (the effective value of every parameter, and the command line,
 * so that a run can be repeated and the report can show its parameters).
 */
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace common {

/**
 * @brief Progress of a long offline run on stderr: "k / N frames (p %), elapsed, remaining" at most every
 * 2 s on a terminal (one line, overwritten), every 10 % of the frames otherwise (logs stay short). The
 * word "frames" is the unit's name, which the caller may change (e.g. "frames rendered").
 */
class Progress {
 public:
  /** @param total frames expected (<= 0: unknown), @param quiet print nothing, @param unit what is counted */
  Progress(int total, bool quiet, std::string unit = "frames")
      : total_(total), quiet_(quiet), tty_(::isatty(2) != 0), t0_(clock::now()), unit_(std::move(unit)) {}
  /** @brief Frame k (1-based) is done; `detail` is appended to the line. */
  void tick(int k, const std::string& detail = "") {
    if (quiet_) return;
    const double el = std::chrono::duration<double>(clock::now() - t0_).count();
    const bool last = total_ > 0 && k >= total_;
    if (tty_) {
      if (!last && el - last_ < 2.0) return;
    } else {
      const int decile = total_ > 0 ? (10 * k) / total_ : k / 50;
      if (!last && decile == last_decile_) return;
      last_decile_ = decile;
    }
    last_ = el;
    char head[160];
    if (total_ > 0) {
      const double remaining = k > 0 ? el * (total_ - k) / k : 0.0;
      std::snprintf(head, sizeof head, "  %d / %d %s (%3.0f %%), %.0f s elapsed, ~%.0f s to go", k, total_,
                    unit_.c_str(), 100.0 * k / total_, el, remaining);
    } else {
      std::snprintf(head, sizeof head, "  %d %s, %.0f s elapsed", k, unit_.c_str(), el);
    }
    std::fprintf(stderr, "%s%s%s%s", tty_ ? "\r" : "", head, detail.empty() ? "" : "; ", detail.c_str());
    std::fprintf(stderr, tty_ && !last ? "\033[K" : "\n");
    std::fflush(stderr);
  }
  /** @brief Ends a terminal progress line (call once after the loop). */
  void done() {
    if (!quiet_ && tty_ && last_ > 0.0) std::fprintf(stderr, "\n");
  }

 private:
  using clock = std::chrono::steady_clock;
  int total_;
  bool quiet_, tty_;
  clock::time_point t0_;
  std::string unit_;
  double last_ = 0.0;
  int last_decile_ = -1;
};

/**
 * @brief Writes DIR/parameters.yaml: the command line and `keys` with their effective values (`get(key)`, the
 * text the config files accept), under a comment naming what they are.
 * @throws std::runtime_error naming the file when it cannot be written.
 */
template <class Get>
void writeParameters(const std::string& path, const std::string& what, const std::vector<std::string>& command_line,
                     const std::vector<std::string>& keys, Get get) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write '" + path + "'");
  f << "# skin3d: the parameters this run used (" << what << "), every key with its effective value\n";
  f << "command: \"";
  for (size_t i = 0; i < command_line.size(); ++i) {
    for (char c : command_line[i]) {
      if (c == '"' || c == '\\') f << '\\';
      f << c;
    }
    if (i + 1 < command_line.size()) f << ' ';
  }
  f << "\"\nparameters:\n";
  for (const auto& k : keys) f << "  " << k << ": " << get(k) << '\n';
  f.close();
  if (!f) throw std::runtime_error("error while writing '" + path + "'");
}

}  // namespace common
}  // namespace skin3d
