// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the pieces every pipeline runner shares (see include/skin3d/ros/runner.h).
#include "skin3d/ros/runner.h"

#include <ros/console.h>

#include <cmath>
#include <cstdio>
#include <sstream>

namespace skin3d {
namespace ros_run {

RunLog RunLog::stderrLog(const std::string& name, bool quiet, double throttle_s) {
  return RunLog(name,
                [quiet](int level, const std::string& text) {
                  if (level < 1 || (quiet && level < 2)) return;
                  std::fprintf(stderr, "%s%s\n", level >= 3 ? "error: " : level == 2 ? "warning: " : "", text.c_str());
                },
                throttle_s);
}

RunLog rosLog(const std::string& name, double throttle_s) {
  return RunLog(name,
                [](int level, const std::string& text) {
                  switch (level) {
                    case 0: ROS_DEBUG("%s", text.c_str()); break;
                    case 1: ROS_INFO("%s", text.c_str()); break;
                    case 2: ROS_WARN("%s", text.c_str()); break;
                    default: ROS_ERROR("%s", text.c_str()); break;
                  }
                },
                throttle_s);
}

void RunLog::warnThrottled(const std::string& key, const std::string& text) {
  const auto now = std::chrono::steady_clock::now();
  auto it = last_.find(key);
  if (it != last_.end() && throttle_s_ > 0 &&
      std::chrono::duration<double>(now - it->second.at).count() < throttle_s_) {
    ++it->second.skipped;
    return;
  }
  const int skipped = it == last_.end() ? 0 : it->second.skipped;
  last_[key] = Last{now, 0};
  warn(skipped > 0 ? text + " (and " + std::to_string(skipped) + " more like it since the last message)" : text);
}

void InputLedger::drop(const std::string& topic, double stamp, const std::string& fault, const std::string& detail) {
  ++total_;
  const std::string key = topic + ": " + fault;
  ++counts_[key];
  char t[64];
  if (std::isfinite(stamp))
    std::snprintf(t, sizeof t, "%.9f", stamp);
  else
    std::snprintf(t, sizeof t, "(no stamp)");
  last_ = "dropped " + topic + " at t = " + t + " s: " + fault + (detail.empty() ? "" : " (" + detail + ")");
  if (log_) log_->warnThrottled(key, last_);
}

std::string InputLedger::summary() const {
  if (counts_.empty()) return "none";
  std::ostringstream os;
  bool first = true;
  for (const auto& kv : counts_) {
    os << (first ? "" : "; ") << kv.first << " x" << kv.second;
    first = false;
  }
  return os.str();
}

}  // namespace ros_run
}  // namespace skin3d
