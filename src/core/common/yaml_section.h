// SPDX-License-Identifier: BSD-3-Clause
// Private helper of the core (not installed): strict reading of one YAML mapping with errors that name
// the dotted field path and its value. Error must be constructible as Error(field, message).
#pragma once

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace common {

template <class Error>
class YamlSection {
 public:
  [[noreturn]] static void fail(const std::string& field, const std::string& why) {
    throw Error(field, "field '" + field + "': " + why);
  }

  /** @param known every key this section may hold; others are reported before anything else is read. */
  YamlSection(const YAML::Node& node, std::string path, std::set<std::string> known)
      : node_(node), path_(std::move(path)), known_(std::move(known)) {
    if (present() && !node_.IsMap()) fail(path_.empty() ? "(top level)" : path_, "must be a mapping (key: value lines)");
    if (!present()) return;
    for (const auto& kv : node_) {
      const std::string k = kv.first.as<std::string>();
      if (!known_.count(k)) {
        std::string list;
        for (const auto& n : known_) list += (list.empty() ? "" : ", ") + n;
        fail(field(k), "unknown field (misspelt?); known here: " + list);
      }
    }
  }
  bool present() const { return node_.IsDefined() && !node_.IsNull(); }
  bool has(const std::string& key) const { return present() && get(key).IsDefined() && !get(key).IsNull(); }
  YAML::Node get(const std::string& key) const { return node_[key]; }  // const: never inserts
  std::string field(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

  double number(const std::string& key, bool required, double fallback = std::nan("")) const {
    if (!has(key)) {
      if (required) fail(field(key), "missing (required)");
      return fallback;
    }
    const YAML::Node v = get(key);
    if (!v.IsScalar()) fail(field(key), "must be a number");
    double d;
    try {
      d = v.as<double>();
    } catch (const YAML::Exception&) {
      fail(field(key), "'" + v.Scalar() + "' is not a number");
    }
    if (!std::isfinite(d)) fail(field(key), "'" + v.Scalar() + "' must be a finite number");
    return d;
  }

  int integer(const std::string& key, bool required, int fallback = 0) const {
    const double d = number(key, required, fallback);
    if (std::floor(d) != d || std::abs(d) > 1e9) fail(field(key), std::to_string(d) + " must be a whole number");
    return static_cast<int>(d);
  }

  bool boolean(const std::string& key, bool fallback) const {
    if (!has(key)) return fallback;
    try {
      return get(key).template as<bool>();
    } catch (const YAML::Exception&) {
      fail(field(key), "'" + get(key).Scalar() + "' must be true or false");
    }
  }

  /** @brief A list of numbers; n = 0 accepts any length. */
  std::vector<double> list(const std::string& key, size_t n, bool required) const {
    if (!has(key)) {
      if (required) fail(field(key), "missing (required)");
      return {};
    }
    const YAML::Node v = get(key);
    if (!v.IsSequence() || (n != 0 && v.size() != n))
      fail(field(key), n ? "must be a list of " + std::to_string(n) + " numbers, e.g. [" +
                               (n == 3 ? "105, 0, 15" : "7, 5") + "]"
                         : "must be a list of numbers");
    std::vector<double> out;
    for (size_t i = 0; i < v.size(); ++i) {
      double d;
      try {
        d = v[i].as<double>();
      } catch (const YAML::Exception&) {
        fail(field(key), "element " + std::to_string(i) + " '" + v[i].Scalar() + "' is not a number");
      }
      if (!std::isfinite(d)) fail(field(key), "element " + std::to_string(i) + " must be a finite number");
      out.push_back(d);
    }
    return out;
  }

  std::string text(const std::string& key, const std::string& fallback) const {
    if (!has(key)) return fallback;
    if (!get(key).IsScalar()) fail(field(key), "must be text");
    return get(key).Scalar();
  }

  YamlSection sub(const std::string& key, bool required, std::set<std::string> known) const {
    if (!has(key) && required) fail(field(key), "missing section (required)");
    return YamlSection(has(key) ? get(key) : YAML::Node(), field(key), std::move(known));
  }

  /** @brief The elements of a list of mappings, each a section "key[i]". */
  std::vector<YamlSection> sequence(const std::string& key, const std::set<std::string>& known) const {
    std::vector<YamlSection> out;
    if (!has(key)) return out;
    const YAML::Node v = get(key);
    if (!v.IsSequence()) fail(field(key), "must be a list");
    for (size_t i = 0; i < v.size(); ++i) out.emplace_back(v[i], field(key) + "[" + std::to_string(i) + "]", known);
    return out;
  }

 private:
  YAML::Node node_;
  std::string path_;
  std::set<std::string> known_;
};

}  // namespace common
}  // namespace skin3d
