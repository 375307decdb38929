// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file bench_common.h
 * @brief What every skin3d benchmark prints beside its figures: the machine (CPU model, load average, memory
 * available), the date, and numbers in fixed notation; the median of the repeated runs.
 */
#pragma once

#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

namespace skin3d {
namespace bench {

/** The CPU's model name from /proc/cpuinfo ("unknown" if none). */
inline std::string cpuModel() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0) {
      const auto p = line.find(':');
      if (p != std::string::npos) return line.substr(line.find_first_not_of(" \t", p + 1));
    }
  return "unknown";
}

/** The 1, 5 and 15 minute load averages, "a, b, c" ("unknown" if unreadable). */
inline std::string loadAverage() {
  std::ifstream f("/proc/loadavg");
  double a = 0, b = 0, c = 0;
  if (!(f >> a >> b >> c)) return "unknown";
  std::ostringstream os;
  os << std::fixed << std::setprecision(2) << a << ", " << b << ", " << c;
  return os.str();
}

/** MemAvailable from /proc/meminfo, bytes (0 if unknown). */
inline double availableMemory() {
  std::ifstream f("/proc/meminfo");
  std::string key, unit;
  double kb = 0;
  while (f >> key >> kb >> unit)
    if (key == "MemAvailable:") return kb * 1024.0;
  return 0;
}

/** Local date and time, "YYYY-MM-DD HH:MM". */
inline std::string today() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M", std::localtime(&t));
  return buf;
}

/** v with `digits` decimals, never an exponent. */
inline std::string fixed(double v, int digits) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(digits) << v;
  return os.str();
}

/** The median (mean of the two middle values for an even count; NaN when empty). */
inline double median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace bench
}  // namespace skin3d
