// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file runner.h
 * @brief skin3d_ros: what every pipeline runner shares (the ROS runner layer, docs/design.md "Architecture").
 *
 * A runner is the ROS side of one core pipeline (front end, frame measurer, SLAM): it owns the pipeline object,
 * its parameters, its input checks, its topics, its diagnostics and its results. The nodelet only constructs it
 * (live); process_bag constructs the same class without a node and calls the same callbacks with the messages of
 * a bag, in the bag's order (offline), as open_vins' serial runner feeds its live callbacks. So a bag gives the
 * same numbers through both doors.
 *
 * The shared pieces here:
 *  - RunLog: where a runner's messages go (ROS's log in a nodelet, stderr in process_bag); warnings about bad
 *    input are throttled per (topic, fault);
 *  - InputLedger: the one place where bad input is dropped and counted: every drop names the topic, the stamp
 *    and the fault, is logged (throttled) and counted per fault for the results (summary.yaml / induration.yaml)
 *    and the diagnostics;
 *  - RunnerStatus: frames, rate, drops and the last error, published as a diagnostic_updater status by the node.
 */
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace ros_run {

/** @brief Where a runner's messages go. Level: 0 debug, 1 info, 2 warning, 3 error. */
class RunLog {
 public:
  using Sink = std::function<void(int level, const std::string& text)>;
  RunLog() = default;
  /** @param name the runner's name, put before every message ("eskf_slam: ...")
   *  @param throttle_s a warning with the same key is repeated at most this often (0: every time) */
  RunLog(std::string name, Sink sink, double throttle_s) : name_(std::move(name)), sink_(std::move(sink)), throttle_s_(throttle_s) {}
  /** @brief A log on stderr (process_bag): info only when not quiet. */
  static RunLog stderrLog(const std::string& name, bool quiet, double throttle_s = 5.0);

  void info(const std::string& text) const { emit(1, text); }
  void warn(const std::string& text) const { emit(2, text); }
  void error(const std::string& text) const { emit(3, text); }
  /** @brief A warning repeated at most every throttle_s per `key` (the skipped ones are counted and said next time). */
  void warnThrottled(const std::string& key, const std::string& text);

 private:
  void emit(int level, const std::string& text) const {
    if (sink_) sink_(level, name_.empty() ? text : name_ + ": " + text);
  }
  std::string name_;
  Sink sink_;
  double throttle_s_ = 2.0;
  struct Last {
    std::chrono::steady_clock::time_point at;
    int skipped = 0;
  };
  std::map<std::string, Last> last_;
};

/** @brief A log into ROS's (rosout) under `name`: what a nodelet's runner uses. */
RunLog rosLog(const std::string& name, double throttle_s = 2.0);

/** @brief How a runner writes its results when asked: into `dir`, false with the reason in `message`. */
using SaveFunction = std::function<bool(const std::string& dir, std::string* message)>;
/** @brief The ~save_results service's handler (skin3d/SaveResults): the request's directory, else `results` (both
 *  empty: refused, saying so); the outcome logged (info or error) through `log` when given. A runner advertises it as
 *  pnh.advertiseService<skin3d::SaveResults::Request, skin3d::SaveResults::Response>("save_results", handler). */
template <class Request, class Response>
std::function<bool(Request&, Response&)> saveResultsHandler(std::string results, SaveFunction save, const RunLog* log) {
  return [results, save, log](Request& req, Response& res) {
    const std::string dir = req.directory.empty() ? results : req.directory;
    if (dir.empty()) {
      res.success = false;
      res.message = "no directory given and ~results is not set";
      return true;
    }
    res.success = save(dir, &res.message);
    if (log && res.success) log->info(res.message);
    if (log && !res.success) log->error(res.message);
    return true;
  };
}

/** @brief The one place that drops bad input: counted per fault, logged (throttled), kept for the results. */
class InputLedger {
 public:
  explicit InputLedger(RunLog* log = nullptr) : log_(log) {}
  void setLog(RunLog* log) { log_ = log; }
  /**
   * @brief Drops one message (or frame).
   * @param topic the topic it came on (relative name, e.g. "imu/data")
   * @param stamp its header stamp, s (NaN when it has none)
   * @param fault short name of the fault, the key of the count ("non-finite angular velocity")
   * @param detail more text for the log (optional)
   */
  void drop(const std::string& topic, double stamp, const std::string& fault, const std::string& detail = "");
  int dropped() const { return total_; }
  /** @brief Adds the drops of another ledger (a stage before this one) to these counts. */
  void absorb(const InputLedger& other) {
    total_ += other.total_;
    for (const auto& kv : other.counts_) counts_[kv.first] += kv.second;
    if (!other.last_.empty()) last_ = other.last_;
  }
  /** @brief "topic: fault" -> count. */
  const std::map<std::string, int>& byFault() const { return counts_; }
  const std::string& lastError() const { return last_; }
  /** @brief The counts as one line ("imu/data: non-finite angular velocity x3; ..."), or "none". */
  std::string summary() const;
  void clear() {
    total_ = 0;
    counts_.clear();
    last_.clear();
  }

 private:
  RunLog* log_;
  int total_ = 0;
  std::map<std::string, int> counts_;
  std::string last_;
};

/** @brief Figures of a runner for its diagnostics: frames done, their rate, drops and the last error. */
class RunnerStatus {
 public:
  void frameDone() {
    const auto now = std::chrono::steady_clock::now();
    std::lock_guard<std::mutex> l(m_);
    if (frames_ == 0) first_ = now;
    last_ = now;
    ++frames_;
  }
  int frames() const {
    std::lock_guard<std::mutex> l(m_);
    return frames_;
  }
  /** @brief Frames per second of wall time between the first and the last frame (0 before two frames). */
  double rate() const {
    std::lock_guard<std::mutex> l(m_);
    const double s = std::chrono::duration<double>(last_ - first_).count();
    return frames_ > 1 && s > 0 ? (frames_ - 1) / s : 0.0;
  }
  void reset() {
    std::lock_guard<std::mutex> l(m_);
    frames_ = 0;
  }

 private:
  mutable std::mutex m_;
  int frames_ = 0;
  std::chrono::steady_clock::time_point first_, last_;
};

}  // namespace ros_run
}  // namespace skin3d
