// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the induration measurement's runner (see include/skin3d/ros/induration_runner.h).
#include "skin3d/ros/induration_runner.h"

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <skin3d/IndurationReport.h>
#include <skin3d/SaveResults.h>

#include <cmath>
#include <cstdio>

#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_run {

IndurationRunner::IndurationRunner(const induration::PipelineOptions& options, const std::string& results, RunLog log)
    : log_(std::move(log)), ledger_(&log_), measurer_(options), results_(results) {}

IndurationRunner::~IndurationRunner() {
  std::lock_guard<std::mutex> lock(mutex_);
  sync_.reset();
  if (!results_.empty() && unsaved_ && !frames_.empty()) {  // no data is lost
    std::string message;
    saveLocked(results_, &message, {node_name_ + " nodelet"}, "", nullptr);
    std::fprintf(stderr, "%s: %s\n", node_name_.c_str(), message.c_str());
  }
}

void IndurationRunner::keepEveryFrameMaps(const std::string& dir) {
  std::lock_guard<std::mutex> lock(mutex_);
  every_frame_maps_ = dir;
}

int IndurationRunner::framesNotFollowed() const {
  std::lock_guard<std::mutex> lock(mutex_);
  int n = 0;
  for (const auto& f : frames_) n += f.result.reference_ok && !f.result.reference_follows;
  return n;
}

int IndurationRunner::frames() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(frames_.size());
}

InputLedger IndurationRunner::ledger() const {
  std::lock_guard<std::mutex> lock(mutex_);
  InputLedger copy = ledger_;
  copy.setLog(nullptr);
  return copy;
}

bool IndurationRunner::onStereo(const sensor_msgs::Image& li, const sensor_msgs::CameraInfo& lc,
                                const sensor_msgs::Image& ri, const sensor_msgs::CameraInfo& rc) {
  std::lock_guard<std::mutex> serial(serial_mutex_);  // live callbacks on several threads: one pair after the other
  return complete(match(li, lc, ri, rc), li.header);
}

std::unique_ptr<induration::FrameMeasurement> IndurationRunner::match(const sensor_msgs::Image& li,
                                                                      const sensor_msgs::CameraInfo& lc,
                                                                      const sensor_msgs::Image& ri,
                                                                      const sensor_msgs::CameraInfo& rc) {
  std::lock_guard<std::mutex> order(match_mutex_);  // the rectification it keeps: one pair at a time
  const double t = li.header.stamp.toSec();
  const ros_conv::PairFault bad = ros_conv::checkStereoPair(li, lc, ri, rc);
  if (bad) {
    std::lock_guard<std::mutex> lock(mutex_);
    ledger_.drop(bad.topic, t, bad.fault);
    return nullptr;
  }
  auto m = std::make_unique<induration::FrameMeasurement>();
  try {
    *m = measurer_.match(ros_conv::toMono8(li), ros_conv::toMono8(ri), ros_conv::fromMsg(lc), ros_conv::fromMsg(rc), t);
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(mutex_);
    ledger_.drop("stereo/left/image_raw", t, e.what(), "the pair could not be measured");
    return nullptr;
  }
  return m;
}

bool IndurationRunner::complete(std::unique_ptr<induration::FrameMeasurement> m, const std_msgs::Header& header) {
  if (!m) return false;
  try {
    measurer_.finish(m.get());
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(mutex_);
    ledger_.drop("stereo/left/image_raw", header.stamp.toSec(), e.what(), "the pair could not be measured");
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  status_.frameDone();
  for (const auto& w : m->record.result.warnings) log_.warnThrottled("warning " + w.substr(0, 40), w);
  if (!frames_.empty()) {  // only the last frame keeps its maps
    frames_.back().result.height_map.release();
    frames_.back().result.labels.release();
  }
  frames_.push_back(m->record);
  if (!every_frame_maps_.empty()) {
    const std::string dir = induration::frameMapsDirectory(every_frame_maps_, static_cast<int>(frames_.size()) - 1);
    try {
      induration::writeFrameMaps(dir, *m);
    } catch (const std::exception& e) {
      log_.warnThrottled("frame maps", std::string("the frame's maps were not written: ") + e.what());
    }
  }
  frame_id_ = header.frame_id;
  unsaved_ = true;
  if (attached_) {
    pub_report_.publish(ros_conv::toReportMsg(m->record.result, header));
    if (!m->record.result.height_map.empty())
      pub_height_.publish(cv_bridge::CvImage(header, sensor_msgs::image_encodings::TYPE_32FC1,
                                             m->record.result.height_map).toImageMsg());
    if (pub_points_.getNumSubscribers() > 0) pub_points_.publish(ros_conv::toCloudMsg(m->cloud, m->left_rect, header));
    if (pub_rect_.getNumSubscribers() > 0)
      pub_rect_.publish(ros_conv::toMono8Msg(m->left_rect, header.frame_id, header.stamp));
  }
  last_ = std::move(m);
  return true;
}

bool IndurationRunner::save(const std::string& dir, std::string* message, const std::vector<std::string>& command_line,
                            const std::string& source, const InputLedger* upstream) {
  std::lock_guard<std::mutex> lock(mutex_);
  return saveLocked(dir, message, command_line, source, upstream);
}

bool IndurationRunner::saveLocked(const std::string& dir, std::string* message,
                                  const std::vector<std::string>& command_line, const std::string& source,
                                  const InputLedger* upstream) {
  if (frames_.empty() || !last_) {
    *message = "nothing measured yet: no results written";
    return false;
  }
  try {
    InputLedger all;
    if (upstream) all.absorb(*upstream);
    all.absorb(ledger_);
    induration::writeMeasurementResults(dir, frames_, *last_, measurer_.options(), frame_id_,
                                        source.empty() ? live_source_ : source,
                                        command_line.empty() ? std::vector<std::string>{node_name_} : command_line,
                                        all.dropped(), all.summary());
    if (dir == results_) unsaved_ = false;
    *message = "results of " + std::to_string(frames_.size()) + " frames written to " + dir;
    return true;
  } catch (const std::exception& e) {
    *message = "cannot write the results to '" + dir + "': " + e.what();
    return false;
  }
}

void IndurationRunner::diagnose(diagnostic_updater::DiagnosticStatusWrapper& s) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int n = static_cast<int>(frames_.size());
  if (!ledger_.lastError().empty())
    s.summary(diagnostic_msgs::DiagnosticStatus::WARN, ledger_.lastError());
  else if (n == 0)
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "waiting for stereo pairs");
  else if (frames_.back().result.reference_ok && !frames_.back().result.reference_follows)
    s.summary(diagnostic_msgs::DiagnosticStatus::WARN,
              "the reference does not follow the skin over " +
                  std::to_string(static_cast<int>(std::lround(100 * frames_.back().result.unfollowed_share))) +
                  " % of the working band: plaques there cannot be measured");
  else
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "measuring");
  s.add("frames", n);
  s.add("frame rate (Hz)", status_.rate());
  s.add("s per frame (last)", n ? frames_.back().seconds : 0.0);
  s.add("plaques (last frame)", n ? static_cast<int>(frames_.back().result.plaques.size()) : 0);
  s.add("reference follows the skin (last frame)", n ? frames_.back().result.reference_follows : true);
  s.add("dropped", ledger_.dropped());
  s.add("dropped by fault", ledger_.summary());
}

void IndurationRunner::attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name,
                              int queue_size, bool approximate_sync) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    node_name_ = node_name;
    pub_report_ = nh.advertise<skin3d::IndurationReport>("induration/report", 10);
    pub_height_ = nh.advertise<sensor_msgs::Image>("induration/height_map", 2);
    pub_points_ = nh.advertise<sensor_msgs::PointCloud2>("induration/points", 1);
    pub_rect_ = nh.advertise<sensor_msgs::Image>("stereo/left/image_rect", 1);
    attached_ = true;
  }
  srv_save_ = pnh.advertiseService<skin3d::SaveResults::Request, skin3d::SaveResults::Response>(
      "save_results", saveResultsHandler<skin3d::SaveResults::Request, skin3d::SaveResults::Response>(
                          results_, [this](const std::string& dir, std::string* message) { return save(dir, message); },
                          &log_));
  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  diagnostics_->setHardwareID("skin3d " + node_name);
  diagnostics_->add("induration", this, &IndurationRunner::diagnose);
  diag_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_->update(); });
  // The measurement is the node's output (its results directory too): it subscribes whether or not anyone listens.
  const std::string transport = ros_conv::imageTransportParam(pnh);
  if (transport == "compressed") live_source_ = "stereo/{left,right}/image_raw/compressed";
  sync_ = std::make_unique<ros_conv::StereoSync>();
  sync_->subscribe(nh, "image_raw", queue_size, approximate_sync,
                   [this](const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                          const sensor_msgs::Image::ConstPtr& ri,
                          const sensor_msgs::CameraInfo::ConstPtr& rc) { onStereo(*li, *lc, *ri, *rc); },
                   transport);
  const auto& o = measurer_.options().induration;
  const auto& po = measurer_.options();
  log_.info("reference '" + o.reference_model + "', plaques above " + std::to_string(o.min_height * 1e3) + " mm; depth " +
            (po.autoDepthRange() ? std::string("range searched in each pair")
                                 : std::to_string(po.z_min) + "-" + std::to_string(po.z_max) + " m") +
            (results_.empty() ? "" : "; results on shutdown to " + results_));
}

std::unique_ptr<IndurationRunner> startIndurationRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh,
                                                        const std::string& name, RunLog log) {
  std::vector<std::string> errors;
  induration::PipelineOptions opt;
  std::string config;
  if (pnh.getParam("config", config) && !config.empty()) {
    try {
      induration::applyPipelineOptions(&opt, config);
    } catch (const std::exception& e) {
      errors.push_back(std::string("~config: ") + e.what());
    }
  }
  ros_conv::loadOptionParams(
      pnh, induration::pipelineOptionKeys(),
      [&](const std::string& k, const std::string& v) { induration::setPipelineOption(&opt, k, v); },
      [&](const std::string& k) { return induration::getPipelineOption(opt, k); }, &errors);
  std::string results;
  int queue = 2;
  bool approximate = false;
  pnh.param<std::string>("results", results, results);
  pnh.param("queue_size", queue, queue);
  pnh.param("approximate_sync", approximate, approximate);
  std::string maps = "last";
  pnh.param<std::string>("maps", maps, maps);
  if (maps != "last" && maps != "all") errors.push_back("~maps = '" + maps + "' must be last or all");
  if (maps == "all" && results.empty()) errors.push_back("~maps = all needs ~results (the directory they go to)");
  try {
    ros_conv::imageTransportParam(pnh);
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  if (queue < 1) errors.push_back("~queue_size = " + std::to_string(queue) + " must be >= 1");
  try {
    opt.validate();
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  if (!errors.empty()) {
    std::string all;
    for (const auto& e : errors) all += (all.empty() ? "" : "; ") + e;
    throw std::invalid_argument(all);
  }
  auto runner = std::make_unique<IndurationRunner>(opt, results, std::move(log));
  if (maps == "all") runner->keepEveryFrameMaps(results);
  runner->attach(nh, pnh, name, queue, approximate);
  return runner;
}

}  // namespace ros_run
}  // namespace skin3d
