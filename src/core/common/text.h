// SPDX-License-Identifier: BSD-3-Clause
// Private helper of the core (not installed): numbers in error messages.
#pragma once

#include <cstdio>
#include <string>

namespace skin3d {
namespace common {

/** @brief A number as people read it in an error message: up to 10 significant digits. */
inline std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.10g", v);
  return buf;
}

}  // namespace common
}  // namespace skin3d
