// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the stereo front end's runner (see include/skin3d/ros/front_end_runner.h).
#include "skin3d/ros/front_end_runner.h"

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <skin3d/StereoMatchArray.h>

#include <chrono>

#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_run {

namespace {

sensor_msgs::PointCloud2 pointsMsg(const skin3d::LandmarkArray& lms) {
  sensor_msgs::PointCloud2 pc;
  pc.header = lms.header;
  sensor_msgs::PointCloud2Modifier mod(pc);
  mod.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z",
                           1, sensor_msgs::PointField::FLOAT32, "strength", 1, sensor_msgs::PointField::FLOAT32);
  mod.resize(lms.landmarks.size());
  sensor_msgs::PointCloud2Iterator<float> x(pc, "x"), y(pc, "y"), z(pc, "z"), s(pc, "strength");
  for (const auto& l : lms.landmarks) {
    *x = l.position.x;
    *y = l.position.y;
    *z = l.position.z;
    *s = l.strength;
    ++x, ++y, ++z, ++s;
  }
  return pc;
}

skin3d::StereoMatchArray matchesMsg(const std_msgs::Header& header, const std::string& type,
                                    const std::vector<stereo::StereoMatch>& matches) {
  skin3d::StereoMatchArray msg;
  msg.header = header;
  msg.feature_type = type;
  msg.matches.reserve(matches.size());
  for (const auto& m : matches) {
    skin3d::StereoMatch s;
    s.u_left = m.left.x();
    s.v_left = m.left.y();
    s.u_right = m.right.x();
    s.v_right = m.right.y();
    s.descriptor = m.descriptor;
    s.strength = m.strength;
    s.size = m.size;
    msg.matches.push_back(std::move(s));
  }
  return msg;
}

}  // namespace

FrontEndRunner::FrontEndRunner(const stereo::FrontEndOptions& options, RunLog log)
    : log_(std::move(log)), ledger_(&log_), front_end_(options) {}

FrontEndRunner::~FrontEndRunner() {
  std::lock_guard<std::mutex> l(connect_mutex_);
  sync_.reset();
}

InputLedger FrontEndRunner::ledger() const {
  std::lock_guard<std::mutex> l(mutex_);
  InputLedger copy = ledger_;
  copy.setLog(nullptr);
  return copy;
}

double FrontEndRunner::secondsPerFrame() const {
  std::lock_guard<std::mutex> l(mutex_);
  const int n = status_.frames();
  return n > 0 ? seconds_ / n : 0.0;
}

std::optional<skin3d::LandmarkArray> FrontEndRunner::onStereo(const sensor_msgs::Image& li,
                                                              const sensor_msgs::CameraInfo& lc,
                                                              const sensor_msgs::Image& ri,
                                                              const sensor_msgs::CameraInfo& rc) {
  std::lock_guard<std::mutex> lock(mutex_);
  const double t = li.header.stamp.toSec();
  const ros_conv::PairFault bad = ros_conv::checkStereoPair(li, lc, ri, rc);
  if (bad) {
    ledger_.drop(bad.topic, t, bad.fault);
    return std::nullopt;
  }
  stereo::FrontEndFrame f;
  try {
    f = front_end_.process(ros_conv::toMono8(li), ros_conv::toMono8(ri), ros_conv::fromMsg(lc), ros_conv::fromMsg(rc));
  } catch (const std::exception& e) {
    ledger_.drop("stereo/left/image_raw", t, e.what(), "the pair could not be processed");
    return std::nullopt;
  }
  seconds_ += f.seconds;
  status_.frameDone();
  if (f.stats.left_features == 0 || f.stats.right_features == 0)
    log_.warnThrottled("no features", std::string("no features found in stereo/") +
                                          (f.stats.left_features == 0 ? "left" : "right") +
                                          "/image_raw (black, saturated or textureless image?)");
  else if (f.matches.empty())
    log_.warnThrottled("no matches", std::to_string(f.stats.left_features) + " / " +
                                         std::to_string(f.stats.right_features) +
                                         " features but no match (check the calibration's rectification, "
                                         "~max_row_diff, ~ratio)");
  skin3d::LandmarkArray out;
  out.header = li.header;
  out.landmarks.reserve(f.landmarks.size());
  for (const auto& l : f.landmarks)  // pixels: rectified
    out.landmarks.push_back(
        ros_conv::toLandmarkMsg(l.position, l.covariance, l.descriptor, l.strength, l.uv_left, l.uv_right));
  if (attached_) {
    pub_landmarks_.publish(out);
    publishExtras(li.header, f, out);
  }
  return out;
}

void FrontEndRunner::publishExtras(const std_msgs::Header& header, const stereo::FrontEndFrame& f,
                                   const skin3d::LandmarkArray& out) {
  if (pub_points_.getNumSubscribers() > 0) pub_points_.publish(pointsMsg(out));
  if (pub_matches_.getNumSubscribers() > 0)
    pub_matches_.publish(matchesMsg(header, stereo::featureTypeName(front_end_.options().features.type), f.matches));
  if (pub_matches_image_.getNumSubscribers() > 0)
    pub_matches_image_.publish(cv_bridge::CvImage(header, sensor_msgs::image_encodings::BGR8,
                                                  stereo::drawStereoMatches(f.left_rect, f.right_rect, f.matches))
                                   .toImageMsg());
  if (pub_rect_l_.getNumSubscribers() > 0)
    pub_rect_l_.publish(ros_conv::toMono8Msg(f.left_rect, header.frame_id, header.stamp));
  if (pub_rect_r_.getNumSubscribers() > 0)
    pub_rect_r_.publish(ros_conv::toMono8Msg(f.right_rect, header.frame_id, header.stamp));
}

void FrontEndRunner::connectionChanged() {
  std::lock_guard<std::mutex> l(connect_mutex_);
  const bool wanted = pub_landmarks_.getNumSubscribers() + pub_points_.getNumSubscribers() +
                          pub_matches_.getNumSubscribers() + pub_matches_image_.getNumSubscribers() +
                          pub_rect_l_.getNumSubscribers() + pub_rect_r_.getNumSubscribers() >
                      0;
  if (wanted && !sync_) {
    sync_ = std::make_unique<ros_conv::StereoSync>();
    sync_->subscribe(*nh_, "image_raw", queue_size_, approximate_,
                     [this](const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                            const sensor_msgs::Image::ConstPtr& ri,
                            const sensor_msgs::CameraInfo::ConstPtr& rc) { onStereo(*li, *lc, *ri, *rc); },
                     transport_);
  } else if (!wanted && sync_) {
    sync_.reset();
  }
}

void FrontEndRunner::diagnose(diagnostic_updater::DiagnosticStatusWrapper& s) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int n = status_.frames();
  if (!ledger_.lastError().empty())
    s.summary(diagnostic_msgs::DiagnosticStatus::WARN, ledger_.lastError());
  else if (n == 0)
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, sync_ ? "waiting for stereo pairs" : "idle (no subscriber)");
  else
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "matching");
  s.add("frames", n);
  s.add("frame rate (Hz)", status_.rate());
  s.add("ms per frame", n ? 1e3 * seconds_ / n : 0.0);
  s.add("dropped", ledger_.dropped());
  s.add("dropped by fault", ledger_.summary());
}

void FrontEndRunner::attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name, int queue_size,
                            bool approximate_sync) {
  nh_ = std::make_unique<ros::NodeHandle>(nh);
  queue_size_ = queue_size;
  approximate_ = approximate_sync;
  transport_ = ros_conv::imageTransportParam(pnh);
  const ros::SubscriberStatusCallback changed = [this](const ros::SingleSubscriberPublisher&) { connectionChanged(); };
  {
    std::lock_guard<std::mutex> l(connect_mutex_);  // no connectionChanged() before every publisher exists
    pub_landmarks_ = nh.advertise<skin3d::LandmarkArray>("stereo/landmarks", queue_size, changed, changed);
    pub_points_ = nh.advertise<sensor_msgs::PointCloud2>("stereo/points", 2, changed, changed);
    pub_matches_ = nh.advertise<skin3d::StereoMatchArray>("stereo/matches", 5, changed, changed);
    pub_matches_image_ = nh.advertise<sensor_msgs::Image>("stereo/matches_image", 1, changed, changed);
    pub_rect_l_ = nh.advertise<sensor_msgs::Image>("stereo/left/image_rect", 2, changed, changed);
    pub_rect_r_ = nh.advertise<sensor_msgs::Image>("stereo/right/image_rect", 2, changed, changed);
    attached_ = true;
  }
  connectionChanged();
  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  diagnostics_->setHardwareID("skin3d " + node_name);
  diagnostics_->add("stereo front end", this, &FrontEndRunner::diagnose);
  diag_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_->update(); });
  const auto& o = front_end_.options();
  log_.info(stereo::featureTypeName(o.features.type) + " features, ratio " + std::to_string(o.features.ratio) +
            ", row tolerance " + std::to_string(o.features.max_row_diff) + " px; queue " + std::to_string(queue_size) +
            (approximate_sync ? ", approximate sync" : ", exact sync"));
}

std::unique_ptr<FrontEndRunner> startFrontEndRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name,
                                                    RunLog log) {
  std::vector<std::string> errors;
  stereo::FrontEndOptions opt;
  std::string config;
  if (pnh.getParam("config", config) && !config.empty()) {
    try {
      stereo::applyFrontEndOptions(&opt, config);
    } catch (const std::exception& e) {
      errors.push_back(std::string("~config: ") + e.what());
    }
  }
  ros_conv::loadOptionParams(
      pnh, stereo::frontEndOptionKeys(),
      [&](const std::string& k, const std::string& v) { stereo::setFrontEndOption(&opt, k, v); },
      [&](const std::string& k) { return stereo::getFrontEndOption(opt, k); }, &errors);
  int queue = 5;
  bool approximate = false;
  pnh.param("queue_size", queue, queue);
  pnh.param("approximate_sync", approximate, approximate);
  if (queue < 1) errors.push_back("~queue_size = " + std::to_string(queue) + " must be >= 1");
  try {
    ros_conv::imageTransportParam(pnh);
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
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
  auto runner = std::make_unique<FrontEndRunner>(opt, std::move(log));
  runner->attach(nh, pnh, name, queue, approximate);
  return runner;
}

}  // namespace ros_run
}  // namespace skin3d
