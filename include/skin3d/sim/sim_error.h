/**
 * @file sim_error.h
 * @brief Error type of the simulators: a bad configuration field, named with its value.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <stdexcept>
#include <string>

namespace skin3d {
namespace sim {

/** @brief A bad simulator configuration. field() is the dotted YAML path, e.g. "globe.radius_mm". */
class SimConfigError : public std::runtime_error {
 public:
  SimConfigError(const std::string& field, const std::string& message)
      : std::runtime_error(message), field_(field) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

}  // namespace sim
}  // namespace skin3d
