// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the site scan's runner (see include/skin3d/ros/site_runner.h).
#include "skin3d/ros/site_runner.h"

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/PoseStamped.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <skin3d/SaveResults.h>
#include <skin3d/SiteFrameReport.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <topic_tools/shape_shifter.h>

#include <cmath>
#include <cstdio>
#include <limits>

#include "skin3d/induration/induration_config.h"
#include "skin3d/ros/conversions.h"

namespace skin3d {
namespace ros_run {

namespace {

std::string num1(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.1f", v);
  return b;
}

Eigen::Isometry3d fromPoseMsg(const geometry_msgs::Pose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z)
                   .normalized()
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  return T;
}

/** The site so far as a cloud in `frame`: x y z height sigma frames (float32), the known preview cells only. */
sensor_msgs::PointCloud2Ptr previewCloud(const site::SitePreview& p, const std::string& frame, const ros::Time& t) {
  sensor_msgs::PointCloud2Ptr pc(new sensor_msgs::PointCloud2);
  pc->header.frame_id = frame;
  pc->header.stamp = t;
  sensor_msgs::PointCloud2Modifier mod(*pc);
  const auto F = sensor_msgs::PointField::FLOAT32;
  mod.setPointCloud2Fields(6, "x", 1, F, "y", 1, F, "z", 1, F, "height", 1, F, "sigma", 1, F, "frames", 1, F);
  std::size_t n = 0;
  for (int j = 0; j < p.height.rows; ++j)
    for (int i = 0; i < p.height.cols; ++i) n += std::isfinite(p.height.at<float>(j, i));
  mod.resize(n);
  pc->height = 1;
  pc->width = static_cast<std::uint32_t>(n);
  pc->is_dense = true;
  float* out = reinterpret_cast<float*>(pc->data.data());
  for (int j = 0; j < p.height.rows; ++j)
    for (int i = 0; i < p.height.cols; ++i) {
      const float h = p.height.at<float>(j, i);
      if (!std::isfinite(h)) continue;
      const cv::Vec3f& X = p.world_xyz.at<cv::Vec3f>(j, i);
      const float v[6] = {X[0], X[1], X[2], h, p.sigma.at<float>(j, i), static_cast<float>(p.frames.at<uchar>(j, i))};
      std::memcpy(out, v, sizeof(v));
      out += pc->point_step / sizeof(float);
    }
  return pc;
}

}  // namespace

void SiteRunOptions::validate() const {
  std::string bad;
  if (poses.empty()) bad += "poses must name a pose topic or be 'tf' or 'images'; ";
  if (world_frame.empty()) bad += "world_frame must not be empty; ";
  if (!(pose_tolerance > 0) || pose_tolerance > 1) bad += "pose_tolerance = " + std::to_string(pose_tolerance) + " s must be in (0, 1]; ";
  if (!(pose_wait >= 0)) bad += "pose_wait = " + std::to_string(pose_wait) + " s must be >= 0; ";
  if (preview_cells < 100) bad += "preview_cells = " + std::to_string(preview_cells) + " must be >= 100; ";
  if (!bad.empty()) throw std::invalid_argument(bad.substr(0, bad.size() - 2));
}

SiteRunner::SiteRunner(const induration::PipelineOptions& options, const site::SiteOptions& site,
                       const SiteRunOptions& run, const std::string& results, RunLog log)
    : log_(std::move(log)), run_(run), measurer_(options, "", log_), fusion_(site, options.induration), results_(results) {
  run_.validate();
  if (run_.poses == "images") front_end_ = std::make_unique<stereo::FrontEnd>(site::odometryFrontEndOptions());
}

SiteRunner::~SiteRunner() {
  std::lock_guard<std::mutex> lock(mutex_);
  sync_.reset();
  drainLocked(true);
  if (!results_.empty() && unsaved_) {  // no data is lost
    std::string message;
    saveLocked(results_, &message, {node_name_ + " nodelet"}, "", nullptr, nullptr);
    std::fprintf(stderr, "%s: %s\n", node_name_.c_str(), message.c_str());
  }
}

bool SiteRunner::onStereo(const sensor_msgs::Image& li, const sensor_msgs::CameraInfo& lc,
                          const sensor_msgs::Image& ri, const sensor_msgs::CameraInfo& rc) {
  std::lock_guard<std::mutex> serial(serial_mutex_);  // live callbacks on several threads: one pair after the other
  return complete(prepare(li, lc, ri, rc));
}

SiteRunner::Prepared SiteRunner::prepare(const sensor_msgs::Image& li, const sensor_msgs::CameraInfo& lc,
                                         const sensor_msgs::Image& ri, const sensor_msgs::CameraInfo& rc) {
  std::lock_guard<std::mutex> order(prepare_mutex_);  // the front end's rectification: one pair at a time
  Prepared p;
  p.header = li.header;
  p.measurement = measurer_.match(li, lc, ri, rc);
  if (p.measurement && front_end_) {  // its features, for its pose
    try {
      p.landmarks = site::odometryFeatures(front_end_.get(), ros_conv::toMono8(li), ros_conv::toMono8(ri),
                                           ros_conv::fromMsg(lc), ros_conv::fromMsg(rc));
    } catch (const std::exception& e) {
      log_.warnThrottled("features", std::string("the pair's features could not be found: ") + e.what());
    }
  }
  return p;
}

bool SiteRunner::complete(Prepared pr) {
  const int before = measurer_.frames();
  const bool ok = measurer_.complete(std::move(pr.measurement), pr.header);
  std::lock_guard<std::mutex> lock(mutex_);
  if (!ok || measurer_.frames() == before || !measurer_.last()) {
    Pending p;  // recorded as left out in its turn
    p.stamp = pr.header.stamp.toSec();
    p.failed = "the pair could not be measured (the log says why)";
    p.measured = std::chrono::steady_clock::now();
    waiting_.push_back(std::move(p));
    drainLocked(run_.pose_wait <= 0);
    return false;
  }
  const induration::FrameMeasurement& m = *measurer_.last();
  Pending p;
  p.landmarks = std::move(pr.landmarks);
  p.cloud = m.cloud;  // shares the pixels (and the maps below): the measurer makes new ones for the next pair
  p.own = m.record.result;  // with its height map: the fusion takes only what it measured as skin
  p.stamp = m.record.stamp;
  p.frame_id = pr.header.frame_id;
  p.measured = std::chrono::steady_clock::now();
  waiting_.push_back(std::move(p));
  unsaved_ = true;
  drainLocked(run_.pose_wait <= 0);
  return true;
}

void SiteRunner::onPose(double stamp, const Eigen::Isometry3d& T_W_C) {
  {
    std::lock_guard<std::mutex> lock(pose_mutex_);
    poses_[stamp] = T_W_C;
    while (poses_.size() > 100000) poses_.erase(poses_.begin());
  }
  // the pairs waiting for it are fused by the next onStereo (offline: the poses come first) or the live timer
  // (not here: a pair being measured holds mutex_ for seconds, and the pose subscription must not wait for it)
}

void SiteRunner::finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  drainLocked(true);
}

bool SiteRunner::poseAt(double stamp, const std::string& frame_id, Eigen::Isometry3d* T) {
  if (run_.poses == "tf") {
    if (!tf_) return false;
    const ros::Time t(stamp);
    std::string error;
    if (!tf_->canTransform(run_.world_frame, frame_id, t, &error)) return false;
    const geometry_msgs::TransformStamped ts = tf_->lookupTransform(run_.world_frame, frame_id, t);
    *T = Eigen::Isometry3d::Identity();
    const auto& q = ts.transform.rotation;
    T->linear() = Eigen::Quaterniond(q.w, q.x, q.y, q.z).normalized().toRotationMatrix();
    T->translation() = Eigen::Vector3d(ts.transform.translation.x, ts.transform.translation.y, ts.transform.translation.z);
    return true;
  }
  std::lock_guard<std::mutex> lock(pose_mutex_);
  auto it = poses_.lower_bound(stamp - run_.pose_tolerance);
  if (it == poses_.end() || it->first > stamp + run_.pose_tolerance) return false;
  auto best = it;
  for (auto q = it; q != poses_.end() && q->first <= stamp + run_.pose_tolerance; ++q)
    if (std::fabs(q->first - stamp) < std::fabs(best->first - stamp)) best = q;
  *T = best->second;
  return true;
}

bool SiteRunner::poseFromImages(const Pending& p, Eigen::Isometry3d* T, std::string* why) {
  bool any_fused = false;
  for (const auto& f : fusion_.frames()) any_fused |= f.fused;
  if (!any_fused) {  // the first pair placed defines the world
    *T = Eigen::Isometry3d::Identity();
    return true;
  }
  const site::RelativeMotion m = site::relativeMotion(last_fused_landmarks_, p.landmarks, site::OdometryOptions());
  if (!m.ok) {
    *why = "no pose from the images: its features and those of the last pair fused do not give one motion (" + m.why + ")";
    return false;
  }
  *T = last_fused_pose_ * m.T_a_b;
  return true;
}

void SiteRunner::drainLocked(bool give_up) {
  const auto now = std::chrono::steady_clock::now();
  while (!waiting_.empty()) {
    Pending& p = waiting_.front();
    Eigen::Isometry3d T;
    if (!p.failed.empty()) {
      fusion_.skip(p.stamp, p.failed);
      recordLocked(fusion_.frames().back());
    } else if (front_end_) {
      std::string why;
      if (poseFromImages(p, &T, &why)) {
        const site::SiteFrame& f = fusion_.add(p.cloud, p.own, T, p.stamp);
        if (f.fused) {
          last_fused_landmarks_ = p.landmarks;
          last_fused_pose_ = f.pose;
        }
        recordLocked(f);
      } else {
        fusion_.skip(p.stamp, why);
        recordLocked(fusion_.frames().back());
      }
    } else if (poseAt(p.stamp, p.frame_id, &T)) {
      recordLocked(fusion_.add(p.cloud, p.own, T, p.stamp));
    } else if (give_up || std::chrono::duration<double>(now - p.measured).count() > run_.pose_wait) {
      const std::string where = run_.poses == "tf" ? "TF " + run_.world_frame + " <- " + p.frame_id : run_.poses;
      char text[160];
      std::snprintf(text, sizeof(text), "no pose on %s within %.0f ms of its stamp", where.c_str(), 1e3 * run_.pose_tolerance);
      fusion_.skip(p.stamp, text);
      recordLocked(fusion_.frames().back());
    } else {
      return;  // it waits, and those after it with it: pairs are fused in order
    }
    waiting_.pop_front();
  }
}

void SiteRunner::recordLocked(const site::SiteFrame& f) {
  unsaved_ = true;
  if (!f.fused) log_.warnThrottled("left out", "frame " + std::to_string(f.index) + " (t = " + std::to_string(f.stamp) + " s) left out: " + f.reason);
  if (on_frame_) on_frame_(f);
  if (attached_) publishLocked(f);
}

void SiteRunner::publishLocked(const site::SiteFrame& f) {
  skin3d::SiteFrameReport r;
  r.header.stamp = ros::Time(f.stamp);
  r.header.frame_id = run_.world_frame;
  r.index = f.index;
  r.fused = f.fused;
  r.reason = f.reason;
  r.overlap = f.overlap;
  r.seam_rms = f.seam_rms;
  r.seam_rigid = f.seam_rigid;
  r.correction_rms = f.correction_rms;
  r.samples = f.samples;
  for (const auto& g : fusion_.frames()) (g.fused ? r.frames_fused : r.frames_left_out) += 1;
  pub_frame_.publish(r);
  if (!f.fused) return;
  const site::SitePreview p = fusion_.preview(run_.preview_cells);
  if (p.height.empty()) return;
  if (pub_points_.getNumSubscribers() > 0) pub_points_.publish(previewCloud(p, run_.world_frame, r.header.stamp));
  std_msgs::Header h = r.header;
  pub_coverage_.publish(cv_bridge::CvImage(h, sensor_msgs::image_encodings::BGR8, site::coverageImage(p.frames, 1200)).toImageMsg());
}

bool SiteRunner::save(const std::string& dir, std::string* message, const std::vector<std::string>& command_line,
                      const std::string& source, const InputLedger* upstream, site::SiteResult* result) {
  std::lock_guard<std::mutex> lock(mutex_);
  return saveLocked(dir, message, command_line, source, upstream, result);
}

bool SiteRunner::saveLocked(const std::string& dir, std::string* message, const std::vector<std::string>& command_line,
                            const std::string& source, const InputLedger* upstream, site::SiteResult* result) {
  if (fusion_.frames().empty()) {
    *message = "no pair has reached the site yet: no results written";
    return false;
  }
  std::string measured;
  if (measurer_.frames() > 0 && !measurer_.save(dir, &measured, command_line, source, upstream)) {
    *message = measured;
    return false;
  }
  try {
    const site::SitePoseGraph& graph = fusion_.refine();  // the whole sweep's poses jointly, then the site again
    const site::SiteResult r = fusion_.measure();
    const std::string src = source.empty() ? "stereo/{left,right}/image_raw with poses from " +
                                                 (run_.poses == "tf" ? "TF (" + run_.world_frame + ")" : run_.poses)
                                           : source;
    site::writeSiteResults(dir, r, fusion_.frames(), src, command_line.empty() ? std::vector<std::string>{node_name_} : command_line,
                            run_.world_frame);
    if (dir == results_) unsaved_ = false;
    *message = "site of " + std::to_string(r.frames_fused) + " fused frames (" + std::to_string(r.frames_left_out) +
               " left out, " + std::to_string(r.plaques.size()) + " plaques) written to " + dir +
               (waiting_.empty() ? "" : "; " + std::to_string(waiting_.size()) + " measured pairs still wait for their pose") +
               (graph.run ? "; pose graph over " + std::to_string(graph.frames) + " pairs: block differences " +
                                num1(graph.rms_before * 1e6) + " -> " + num1(graph.rms_after * 1e6) + " um RMS" +
                                (graph.used ? "" : " (not used: " + graph.message + ")")
                          : "");
    if (result) *result = r;
    return true;
  } catch (const std::exception& e) {
    *message = "cannot write the site to '" + dir + "': " + e.what();
    return false;
  }
}

}  // namespace ros_run
}  // namespace skin3d

namespace skin3d {
namespace ros_run {

void SiteRunner::diagnose(diagnostic_updater::DiagnosticStatusWrapper& s) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto& frames = fusion_.frames();
  int fused = 0;
  for (const auto& f : frames) fused += f.fused;
  const int out = static_cast<int>(frames.size()) - fused;
  if (!frames.empty() && !frames.back().fused)
    s.summary(diagnostic_msgs::DiagnosticStatus::WARN, "the last pair was left out: " + frames.back().reason);
  else if (frames.empty())
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, waiting_.empty() ? "waiting for stereo pairs" : "waiting for the first pose");
  else
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "fusing");
  s.add("pairs measured", measurer_.frames());
  s.add("frames fused", fused);
  s.add("frames left out", out);
  s.add("pairs waiting for their pose", static_cast<int>(waiting_.size()));
  if (!frames.empty() && frames.back().fused) {
    s.add("seam RMS of the last frame (um)", 1e6 * frames.back().seam_rms);
    s.add("rigid part of it (um)", 1e6 * frames.back().seam_rigid);
    s.add("registration correction of the last frame (mm)", 1e3 * frames.back().correction_rms);
  }
  s.add("poses from", run_.poses == "tf" ? "TF " + run_.world_frame : run_.poses);
}

void SiteRunner::attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name, int queue_size,
                        bool approximate_sync) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    node_name_ = node_name;
    pub_frame_ = nh.advertise<skin3d::SiteFrameReport>("site/frame", 100);
    pub_points_ = nh.advertise<sensor_msgs::PointCloud2>("site/points", 1, true);
    pub_coverage_ = nh.advertise<sensor_msgs::Image>("site/coverage", 1, true);
    attached_ = true;
  }
  if (run_.poses == "images") {
    // the pairs' own features place them
  } else if (run_.poses == "tf") {
    tf_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(120.0));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_, nh);
  } else {
    // PoseStamped or Odometry, whichever the topic carries
    sub_pose_ = nh.subscribe<topic_tools::ShapeShifter>(
        run_.poses, 1000, [this](const topic_tools::ShapeShifter::ConstPtr& m) {
          if (m->getDataType() == "geometry_msgs/PoseStamped") {
            const auto p = m->instantiate<geometry_msgs::PoseStamped>();
            onPose(p->header.stamp.toSec(), fromPoseMsg(p->pose));
          } else if (m->getDataType() == "nav_msgs/Odometry") {
            const auto o = m->instantiate<nav_msgs::Odometry>();
            onPose(o->header.stamp.toSec(), fromPoseMsg(o->pose.pose));
          } else {
            log_.warnThrottled("pose type", "'" + run_.poses + "' carries " + m->getDataType() +
                                                ", not geometry_msgs/PoseStamped or nav_msgs/Odometry: no pose from it");
          }
        });
  }
  // the pairs that wait for a pose are fused when it comes (or left out after ~pose_wait)
  wait_timer_ = nh.createWallTimer(ros::WallDuration(0.1), [this](const ros::WallTimerEvent&) {
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);  // a pair being measured: next time
    if (lock.owns_lock() && !waiting_.empty()) drainLocked(false);
  });
  srv_save_ = pnh.advertiseService<skin3d::SaveResults::Request, skin3d::SaveResults::Response>(
      "save_results", saveResultsHandler<skin3d::SaveResults::Request, skin3d::SaveResults::Response>(
                          results_, [this](const std::string& dir, std::string* message) { return save(dir, message); },
                          &log_));
  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  diagnostics_->setHardwareID("skin3d " + node_name);
  diagnostics_->add("site", this, &SiteRunner::diagnose);
  diag_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_->update(); });
  const std::string transport = ros_conv::imageTransportParam(pnh);
  sync_ = std::make_unique<ros_conv::StereoSync>();
  sync_->subscribe(nh, "image_raw", queue_size, approximate_sync,
                   [this](const sensor_msgs::Image::ConstPtr& li, const sensor_msgs::CameraInfo::ConstPtr& lc,
                          const sensor_msgs::Image::ConstPtr& ri,
                          const sensor_msgs::CameraInfo::ConstPtr& rc) { onStereo(*li, *lc, *ri, *rc); },
                   transport);
  log_.info("poses from " + (run_.poses == "tf" ? "TF (" + run_.world_frame + " <- the left image's frame)" : run_.poses) +
            ", a pair waits " + std::to_string(run_.pose_wait) + " s for its pose" +
            (results_.empty() ? "" : "; results on shutdown to " + results_));
}

std::unique_ptr<SiteRunner> startSiteRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name, RunLog log) {
  std::vector<std::string> errors;
  induration::PipelineOptions opt;  // as the induration nodelet reads them: ~config, then the keys
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
  try {
    opt.validate();
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  site::SiteOptions so;
  std::string site_config;
  if (pnh.getParam("site_config", site_config) && !site_config.empty()) {
    try {
      site::applySiteOptions(&so, site_config);
    } catch (const std::exception& e) {
      errors.push_back(std::string("~site_config: ") + e.what());
    }
  }
  ros_conv::loadOptionParams(
      pnh, site::siteOptionKeys(), [&](const std::string& k, const std::string& v) { site::setSiteOption(&so, k, v); },
      [&](const std::string& k) { return site::getSiteOption(so, k); }, &errors);
  try {
    so.validate();
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  SiteRunOptions ro;
  pnh.param<std::string>("poses", ro.poses, ro.poses);
  pnh.param<std::string>("world_frame", ro.world_frame, ro.world_frame);
  pnh.param("pose_tolerance", ro.pose_tolerance, ro.pose_tolerance);
  pnh.param("pose_wait", ro.pose_wait, ro.pose_wait);
  pnh.param("preview_cells", ro.preview_cells, ro.preview_cells);
  try {
    ro.validate();
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  std::string results;
  int queue = 2;
  bool approximate = false;
  pnh.param<std::string>("results", results, results);
  pnh.param("queue_size", queue, queue);
  pnh.param("approximate_sync", approximate, approximate);
  if (queue < 1) errors.push_back("~queue_size = " + std::to_string(queue) + " must be >= 1");
  try {
    ros_conv::imageTransportParam(pnh);
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  if (!errors.empty()) {
    std::string all;
    for (const auto& e : errors) all += (all.empty() ? "" : "; ") + e;
    throw std::invalid_argument(all);
  }
  auto runner = std::make_unique<SiteRunner>(opt, so, ro, results, std::move(log));
  runner->attach(nh, pnh, name, queue, approximate);
  return runner;
}

}  // namespace ros_run
}  // namespace skin3d
