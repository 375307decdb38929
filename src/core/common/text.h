// SPDX-License-Identifier: BSD-3-Clause
// Private helper of the core (not installed): numbers as text. num() in messages, exactNum() where the text must
// read back as the same double (option tables, parameters.yaml), fixed() with a set number of decimals.
#pragma once

#include <cstdio>
#include <sstream>
#include <string>

namespace skin3d {
namespace common {

/** @brief A number as people read it in an error message: up to 10 significant digits. */
inline std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.10g", v);
  return buf;
}

/** @brief The shortest text (15, 16 or 17 significant digits) that reads back as exactly the same double. */
inline std::string exactNum(double d) {
  for (int precision : {15, 16, 17}) {
    std::ostringstream os;
    os.precision(precision);
    os << d;
    if (precision == 17 || std::stod(os.str()) == d) return os.str();
  }
  return "";  // not reached
}

/** @brief v with `decimals` decimals (printf %.*f). */
inline std::string fixed(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, v);
  return buf;
}

}  // namespace common
}  // namespace skin3d
