// SPDX-License-Identifier: BSD-3-Clause
// The one option-table mechanism of the core (private header): an options struct's keys, each read and written
// as text, with the same converters, range checks and messages for every table (SLAM, induration, ...), and
// the YAML file reader of a table. Tables: src/core/slam/slam_config.cpp, src/core/induration/induration_config.cpp.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "text.h"

namespace skin3d {
namespace common {

/** Text <-> value of one table's keys; `what` names the table in every message ("slam", "induration"). */
class OptionText {
 public:
  explicit OptionText(std::string what) : what_(std::move(what)) {}
  const std::string& what() const { return what_; }

  [[noreturn]] void bad(const std::string& key, const std::string& why) const {
    throw std::invalid_argument(what_ + " parameter '" + key + "': " + why);
  }
  /** A finite number. */
  double toDouble(const std::string& key, const std::string& v) const {
    std::istringstream is(v);
    double d;
    if (!(is >> d) || !(is >> std::ws).eof()) bad(key, "'" + v + "' is not a number");
    if (!std::isfinite(d)) bad(key, "'" + v + "' is not a finite number");
    return d;
  }
  /** A whole number of at most 2e9 in magnitude. */
  int toInt(const std::string& key, const std::string& v) const {
    const double d = toDouble(key, v);
    if (std::floor(d) != d || std::abs(d) > 2e9) bad(key, "'" + v + "' is not a whole number");
    return static_cast<int>(d);
  }
  bool toBool(const std::string& key, const std::string& v) const {
    if (v == "true" || v == "True" || v == "1") return true;
    if (v == "false" || v == "False" || v == "0") return false;
    bad(key, "'" + v + "' is not true/false");
  }
  /** v when it is one of `names`. */
  std::string oneOf(const std::string& key, const std::string& v, const std::vector<std::string>& names) const {
    std::string known;
    for (const auto& n : names) {
      if (n == v) return v;
      known += (known.empty() ? "" : ", ") + n;
    }
    bad(key, "'" + v + "' is not one of " + known);
  }
  /** Numbers separated by spaces (commas and brackets are accepted too: "[a, b]" from a ROS parameter). */
  std::vector<double> toList(const std::string& key, const std::string& v) const {
    std::string s = v;
    for (char& c : s)
      if (c == ',' || c == '[' || c == ']') c = ' ';
    std::istringstream is(s);
    std::vector<double> out;
    std::string item;
    while (is >> item) out.push_back(toDouble(key, item));
    return out;
  }
  /** Numbers as toList reads them back (shortest exact text each). */
  static std::string listText(const std::vector<double>& v) {
    std::string s;
    for (double d : v) s += (s.empty() ? "" : " ") + exactNum(d);
    return s;
  }

 private:
  std::string what_;
};

/** An options struct's table: its keys in file order, each with a getter and a setter of text. */
template <class Options>
class OptionTable {
 public:
  struct Field {
    std::function<std::string(const Options&)> get;
    std::function<void(Options*, const std::string&)> set;
  };
  using Rows = std::vector<std::pair<std::string, Field>>;

  OptionTable(const OptionText& text, Rows rows) : text_(text), rows_(std::move(rows)) {
    for (const auto& r : rows_) keys_.push_back(r.first);
  }
  const std::vector<std::string>& keys() const { return keys_; }
  std::string get(const Options& o, const std::string& key) const { return field(key).get(o); }
  void set(Options* o, const std::string& key, const std::string& value) const { field(key).set(o, value); }

  /** Every key of a YAML map file (a value, or a list of values written space-separated); an error names the
   *  file and the key. */
  void applyYaml(Options* o, const std::string& path) const {
    YAML::Node root;
    try {
      root = YAML::LoadFile(path);
    } catch (const std::exception& e) {
      throw std::invalid_argument("cannot read " + text_.what() + " parameters from '" + path + "': " + e.what());
    }
    if (!root || root.IsNull()) return;
    if (!root.IsMap()) throw std::invalid_argument("'" + path + "': expected a map of " + text_.what() + " parameters");
    for (const auto& kv : root) {
      const std::string key = kv.first.as<std::string>();
      std::string value;
      if (kv.second.IsSequence()) {
        for (const auto& item : kv.second) {
          if (!item.IsScalar())
            throw std::invalid_argument("'" + path + "': " + text_.what() + " parameter '" + key +
                                        "' must be a list of numbers");
          value += (value.empty() ? "" : " ") + item.Scalar();
        }
      } else if (kv.second.IsScalar() || kv.second.IsNull()) {
        value = kv.second.IsNull() ? "" : kv.second.Scalar();
      } else {
        throw std::invalid_argument("'" + path + "': " + text_.what() + " parameter '" + key + "' must be a value or a list");
      }
      try {
        set(o, key, value);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("'" + path + "': " + e.what());
      }
    }
  }

 private:
  const Field& field(const std::string& key) const {
    for (const auto& r : rows_)
      if (r.first == key) return r.second;
    std::string known;
    for (const auto& k : keys_) known += (known.empty() ? "" : ", ") + k;
    throw std::invalid_argument("unknown " + text_.what() + " parameter '" + key + "' (known: " + known + ")");
  }

  const OptionText& text_;
  Rows rows_;
  std::vector<std::string> keys_;
};

}  // namespace common
}  // namespace skin3d
