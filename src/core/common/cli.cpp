// SPDX-License-Identifier: BSD-3-Clause
// skin3d_core: strict option parsing and the results directory of the tools (see include/skin3d/common/cli.h).
#include "skin3d/common/cli.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>
#include <unistd.h>

namespace skin3d {
namespace common {

namespace fs = std::filesystem;

namespace {
std::string number(double v) {
  std::ostringstream s;
  s.precision(15);
  s << v;
  return s.str();
}

std::string range(const std::string& lo, bool has_lo, const char* lo_op, const std::string& hi, bool has_hi) {
  if (has_lo && has_hi) return std::string(" ") + lo_op + " " + lo + " and <= " + hi;
  if (has_lo) return std::string(" ") + lo_op + " " + lo;
  if (has_hi) return " <= " + hi;
  return "";
}
}  // namespace

long parseWholeNumber(const std::string& option, const std::string& text, long min, long max) {
  const bool has_lo = min != std::numeric_limits<long>::min(), has_hi = max != std::numeric_limits<long>::max();
  const std::string want = "is not a whole number" + range(std::to_string(min), has_lo, ">=", std::to_string(max), has_hi);
  auto fail = [&]() { return CliError(option + ": '" + text + "' " + want); };
  std::size_t i = 0;
  if (i < text.size() && (text[i] == '+' || text[i] == '-')) ++i;
  if (i == text.size()) throw fail();
  for (std::size_t j = i; j < text.size(); ++j)
    if (text[j] < '0' || text[j] > '9') throw fail();
  errno = 0;
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (errno == ERANGE || end != text.c_str() + text.size() || v < min || v > max) throw fail();
  return v;
}

double parseNumber(const std::string& option, const std::string& text, double min, bool min_exclusive, double max) {
  const double lowest = -std::numeric_limits<double>::max(), highest = std::numeric_limits<double>::max();
  const std::string want =
      "is not a number" + range(number(min), min != lowest, min_exclusive ? ">" : ">=", number(max), max != highest);
  auto fail = [&]() { return CliError(option + ": '" + text + "' " + want); };
  if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) throw fail();
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (errno == ERANGE || end != text.c_str() + text.size() || !std::isfinite(v)) throw fail();
  if ((min_exclusive ? !(v > min) : !(v >= min)) || v > max) throw fail();
  return v;
}

PreparedOutput prepareOutputDirectory(const std::string& path) {
  PreparedOutput out;
  out.path = path;
  auto fail = [&](const std::string& why) {
    removeIfUnused(out);
    return OutputError("cannot write the results directory '" + path + "': " + why);
  };
  if (path.empty()) throw fail("the path is empty");
  std::error_code ec;
  const fs::path dir(path);
  // The directories to create: the missing ones from the outermost down (a file on the way is an error).
  std::vector<fs::path> missing;
  for (fs::path p = dir.lexically_normal(); !p.empty(); p = p.parent_path()) {
    if (p.filename().empty() && p.has_parent_path() && p != p.root_path()) continue;  // a trailing '/'
    const fs::file_status st = fs::status(p, ec);
    if (fs::exists(st)) {
      if (!fs::is_directory(st))
        throw fail(p == dir.lexically_normal() ? "it exists and is not a directory"
                                               : "'" + p.string() + "' is not a directory");
      break;
    }
    missing.push_back(p);
    if (p == p.root_path() || p.parent_path() == p) break;
  }
  for (auto it = missing.rbegin(); it != missing.rend(); ++it) {
    if (!fs::create_directory(*it, ec) && ec) throw fail("cannot create '" + it->string() + "': " + ec.message());
    out.created.push_back(it->string());
  }
  // Writable? Create and remove a probe file (access() would not see a read-only file system or a full disk).
  const fs::path probe = dir / (".skin3d_write_probe." + std::to_string(::getpid()));
  {
    std::ofstream f(probe);
    if (!f) throw fail(std::string("cannot create a file in it: ") + std::strerror(errno));
    f << "probe\n";
    f.flush();
    if (!f) {
      f.close();
      fs::remove(probe, ec);
      throw fail(std::string("cannot write a file in it: ") + std::strerror(errno));
    }
  }
  if (!fs::remove(probe, ec) || ec) throw fail("cannot remove the probe file '" + probe.string() + "': " + ec.message());
  return out;
}

bool removeIfUnused(const PreparedOutput& prepared) noexcept {
  bool removed_self = false;
  try {
    for (auto it = prepared.created.rbegin(); it != prepared.created.rend(); ++it) {
      std::error_code ec;
      if (!fs::is_directory(*it, ec) || !fs::is_empty(*it, ec) || ec) break;  // kept: outer ones hold it
      if (!fs::remove(*it, ec) || ec) break;
      if (it == prepared.created.rbegin()) removed_self = true;
    }
  } catch (...) {
  }
  return removed_self;
}

}  // namespace common
}  // namespace skin3d
