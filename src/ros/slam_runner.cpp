// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: the SLAM pipeline's runner (see include/skin3d/ros/slam_runner.h).
#include "skin3d/ros/slam_runner.h"

#include <diagnostic_updater/diagnostic_updater.h>
#include <skin3d/SaveResults.h>
#include <std_srvs/Empty.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include "skin3d/common/run_info.h"
#include "skin3d/ros/conversions.h"
#include "skin3d/ros/ground_truth_path.h"
#include "skin3d/ros/input_checks.h"
#include "skin3d/slam/slam_config.h"

namespace skin3d {
namespace ros_run {

namespace {

slam::StampedPose fromPoseMsg(const geometry_msgs::PoseStamped& m) {
  slam::StampedPose p;
  p.t = m.header.stamp.toSec();
  p.stamp_ns = static_cast<std::int64_t>(m.header.stamp.toNSec());
  p.p = Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z);
  p.q = Eigen::Quaterniond(m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z);
  return p;
}

}  // namespace

slam::SlamOptions slamOptionsFor(const std::string& front_end_features, const std::vector<std::string>& config_files,
                                 const std::vector<std::pair<std::string, std::string>>& sets) {
  slam::SlamOptions opt;
  if (!front_end_features.empty())
    for (const auto& kv : slam::imageInputOptions(front_end_features)) slam::setSlamOption(&opt, kv.first, kv.second);
  for (const auto& c : config_files) slam::applySlamOptions(&opt, c);
  for (const auto& kv : sets) slam::setSlamOption(&opt, kv.first, kv.second);
  opt.validate();
  return opt;
}

void SlamRunnerParams::validate() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument("eskf_slam parameter " + what); };
  if (!front_end.empty() && front_end != "kaze" && front_end != "akaze" && front_end != "orb")
    bad("~front_end = '" + front_end + "': must be kaze, akaze, orb or empty (landmarks with their own model)");
  if (!(gyro_wait >= 0.0) || !std::isfinite(gyro_wait)) bad("~gyro_wait must be a finite number of seconds >= 0");
  if (!(ate_max_dt > 0.0) || !std::isfinite(ate_max_dt)) bad("~ate_max_dt must be a positive number of seconds");
  if (map_every < 1) bad("~map_every must be >= 1");
  if (!(jump_back > 0.0)) bad("~reset_on_jump_back must be > 0 s");
  if (camera_frame.empty() || world_frame.empty()) bad("~world_frame and ~camera_frame must not be empty");
}

SlamRunner::SlamRunner(const slam::SlamOptions& options, const SlamRunnerParams& params, RunLog log)
    : log_(std::move(log)), ledger_(&log_), par_(params) {
  options.validate();
  par_.validate();
  slam_ = std::make_unique<slam::SlamSystem>(options);
  if (!par_.known_map.empty()) {
    const auto km = slam::readLandmarkMap(par_.known_map);  // throws naming the file and line
    slam_->setKnownMap(km.first, km.second);
    log_.info("localisation in the known map '" + par_.known_map + "' (" + std::to_string(km.first.size()) +
              " landmarks): thesis experiment 1");
  }
}

SlamRunner::~SlamRunner() {
  std::lock_guard<std::mutex> lock(mutex_);
  drainLocked(true);
  if (!par_.results.empty() && unsaved_ && !run_.trajectory.empty()) {
    std::string message;
    saveLocked(par_.results, &message, {}, {}, nullptr);
    std::fprintf(stderr, "%s: %s\n", node_name_.c_str(), message.c_str());
  }
}

int SlamRunner::frames() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(run_.trajectory.size());
}

double SlamRunner::slamSecondsPerFrame() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return run_.trajectory.empty() ? 0.0 : slam_seconds_ / run_.trajectory.size();
}

void SlamRunner::onImu(const sensor_msgs::Imu& imu) {
  std::lock_guard<std::mutex> lock(mutex_);
  const double t = imu.header.stamp.toSec();
  if (!slam_->options().use_gyro) return;  // not used: not checked either
  if (imu.header.frame_id != par_.camera_frame) {
    ledger_.drop("imu/data", t, "frame '" + imu.header.frame_id + "' is not '" + par_.camera_frame + "'",
                 "the gyro must be expressed in the camera frame");
    return;
  }
  if (!imu_order_.last().isZero() && t < imu_order_.last().toSec() - par_.jump_back) {
    imu_order_.reset();  // a restarted stream (bag): its frames will reset the SLAM
    last_gyro_ = -1e300;
  }
  ros_conv::InputFault fault = imu_order_.admit(imu.header.stamp);
  if (!fault) fault = ros_conv::checkImu(imu);
  if (fault) {
    ledger_.drop("imu/data", t, fault.fault, fault.detail);
    return;
  }
  try {
    slam_->addGyro(t, Eigen::Vector3d(imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z),
                   ros_conv::gyroCovariance(imu));
  } catch (const std::exception& e) {
    ledger_.drop("imu/data", t, e.what());
    return;
  }
  if (slam_->options().smoother != "off")
    smoother_gyro_.push_back({t, Eigen::Vector3d(imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z),
                              ros_conv::gyroCovariance(imu)});
  last_gyro_ = std::max(last_gyro_, t);
  drainLocked(false);
}

void SlamRunner::onLandmarks(const skin3d::LandmarkArray& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  const double t = msg.header.stamp.toSec();
  if (msg.header.frame_id != par_.camera_frame) {
    ledger_.drop("stereo/landmarks", t, "frame '" + msg.header.frame_id + "' is not '" + par_.camera_frame + "'");
    return;
  }
  if (msg.header.stamp.isZero()) {
    ledger_.drop("stereo/landmarks", t, "zero stamp");
    return;
  }
  const double newest = waiting_.empty() ? last_frame_ : waiting_.back().msg.header.stamp.toSec();
  if (slam_->initialised() && t < newest - par_.jump_back) {
    log_.warn("time jumped back by " + std::to_string(newest - t) + " s (bag restarted?): resetting the SLAM");
    drainLocked(true);
    resetLocked();
  } else if (t <= newest) {
    ledger_.drop("stereo/landmarks", t, t == newest ? "duplicate stamp" : "stamp older than the previous frame's");
    return;
  }
  waiting_.push_back({msg, std::chrono::steady_clock::now()});
  drainLocked(false);
}

void SlamRunner::drainLocked(bool all) {
  const bool gyro = slam_->options().use_gyro;
  const auto now = std::chrono::steady_clock::now();
  while (!waiting_.empty()) {
    const double t = waiting_.front().msg.header.stamp.toSec();
    const double lag = waiting_.back().msg.header.stamp.toSec() - t;
    const double waited = std::chrono::duration<double>(now - waiting_.front().arrived).count();
    const bool ready = all || !gyro || last_gyro_ >= t;
    if (!ready && lag <= par_.gyro_wait && waited <= par_.gyro_wait) return;
    if (!ready)
      log_.warnThrottled("gyro lag", "imu/data lags: the frame at t = " + std::to_string(t) +
                                         " s is processed without the gyro samples up to its stamp (~gyro_wait " +
                                         std::to_string(par_.gyro_wait) + " s)");
    const skin3d::LandmarkArray msg = std::move(waiting_.front().msg);
    waiting_.pop_front();
    processLocked(msg);
  }
}

void SlamRunner::processLocked(const skin3d::LandmarkArray& msg) {
  const double t = msg.header.stamp.toSec();
  const auto t0 = std::chrono::steady_clock::now();
  slam::FrameStats st;
  try {
    const std::vector<slam::Measurement> meas = ros_conv::fromMsg(msg);
    st = slam_->processFrame(t, meas);
    if (slam_->options().smoother != "off") {
      const auto& ids = slam_->lastAssociations();
      slam::SmootherFrame f;
      f.t = t;
      f.p = slam_->filter().state().p;
      f.q = slam_->filter().state().q;
      for (std::size_t i = 0; i < meas.size() && i < ids.size(); ++i)
        if (ids[i] >= 0) f.observations.push_back({ids[i], meas[i].z, meas[i].C, meas[i].descriptor});
      smoother_frames_.push_back(std::move(f));
    }
  } catch (const std::exception& e) {
    ledger_.drop("stereo/landmarks", t, e.what());
    return;
  }
  slam_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  last_frame_ = t;
  if (st.rejected_invalid > 0)
    log_.warnThrottled("invalid landmarks",
                       "dropped " + std::to_string(st.rejected_invalid) + " of " + std::to_string(st.measurements) +
                           " landmarks with a non-finite position or covariance, a covariance that is not symmetric "
                           "positive definite, or a point behind the camera");
  const auto& x = slam_->filter().state();
  run_.trajectory.push_back({t, static_cast<std::int64_t>(msg.header.stamp.toNSec()), x.p, x.q});
  run_.rows.push_back(slam::stateRow(*slam_, st));
  unsaved_ = true;
  status_.frameDone();
  if (pub_) {
    const std::string warning = pub_->publish(msg.header.stamp, *slam_, run_.rows.back(), st, run_.rows.size());
    if (!warning.empty()) log_.warnThrottled("ellipsoids", warning);
  }
  if (truth_path_ && run_.trajectory.size() == 1) truth_path_->anchor(run_.trajectory.front());
}

void SlamRunner::onGroundTruth(const geometry_msgs::PoseStamped& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  const slam::StampedPose g = fromPoseMsg(msg);
  if (!g.p.allFinite() || !g.q.coeffs().allFinite() || g.q.norm() < 1e-9) {
    ledger_.drop(par_.ground_truth_topic, g.t, "non-finite position or zero quaternion");
    return;
  }
  if (!truth_.empty() && g.t < truth_.back().t - par_.jump_back) truth_.clear();  // a restarted bag
  truth_.push_back(g);
  if (truth_path_) {
    const std::string problem =
        truth_path_->add(msg, par_.jump_back, run_.trajectory.empty() ? nullptr : &run_.trajectory.front());
    if (!problem.empty()) log_.warnThrottled("ground truth", problem);
  }
}

void SlamRunner::flush() {
  std::lock_guard<std::mutex> lock(mutex_);
  drainLocked(true);
}

void SlamRunner::resetLocked() {
  if (!par_.results.empty() && !run_.trajectory.empty()) {
    std::string message;
    saveLocked(par_.results, &message, {}, {}, nullptr);
    log_.info("before the reset: " + message);
  }
  slam_->reset();
  run_ = slam::RunRecord();
  smoother_frames_.clear();
  smoother_gyro_.clear();
  truth_.clear();
  waiting_.clear();
  last_frame_ = -1e300;
  last_gyro_ = -1e300;
  unsaved_ = false;
  status_.reset();
  if (pub_) pub_->clearPath();
  if (truth_path_) truth_path_->clear();
}

void SlamRunner::reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  resetLocked();
}

bool SlamRunner::save(const std::string& dir, std::string* message,
                      const std::vector<std::pair<std::string, std::string>>& extra,
                      const std::vector<std::string>& command_line, const InputLedger* upstream) {
  std::lock_guard<std::mutex> lock(mutex_);
  return saveLocked(dir, message, extra, command_line, upstream);
}

void SlamRunner::smoothInto(slam::RunRecord* run) {
  smoothed_ = false;
  const slam::SlamOptions& o = slam_->options();
  if (o.smoother == "off") return;
  run->info.push_back({"trajectory", "filter (the smoother did not run)"});
  const std::size_t line = run->info.size() - 1;
  if (smoother_frames_.size() != run->trajectory.size()) {
    run->info.push_back({"smoother", "not run: its frames do not match the trajectory's"});
    return;
  }
  slam::SmootherOptions so;
  so.huber = o.smoother_huber;
  so.max_iterations = o.smoother_iterations;
  so.gyro_noise = o.gyro_noise;
  so.gyro_bias_walk = o.filter.gyro_bias_walk;
  so.initial_gyro_bias_std = o.filter.initial_gyro_bias_std;
  so.initial_gyro_bias = o.filter.initial_gyro_bias;
  so.velocity_noise = o.filter.velocity_noise;
  // the bias is estimated over the whole recording whether or not the filter estimates it: the prior is
  // initial_gyro_bias with initial_gyro_bias_std (a still recording's, from scripts/gyro_bias.py, or the default 10 mrad/s)
  so.estimate_gyro_bias = true;
  so.threads = o.filter.threads;
  so.loop_radius = o.smoother_loop_radius;
  so.loop_descriptor_distance = o.pool.max_descriptor_distance;
  const std::vector<slam::GyroSample> none;
  const slam::SmootherResult r = slam::smooth(smoother_frames_, o.use_gyro ? smoother_gyro_ : none, so);
  log_.info("smoother: " + r.message);
  if (!r.ok) {
    run->info.push_back({"smoother", "failed: " + r.message});
    return;
  }
  if (!run->ground_truth.empty()) {
    try {
      const slam::TrajectoryError e = slam::trajectoryError(run->trajectory, run->ground_truth, slam::AteAlignment::SE3, run->ate_max_dt);
      run->info.push_back({"filter_ate_se3_rmse_mm", std::to_string(1e3 * e.rmse)});
    } catch (const std::exception&) {
    }
  }
  for (std::size_t k = 0; k < run->trajectory.size(); ++k) {
    run->trajectory[k].p = r.p[k];
    run->trajectory[k].q = r.q[k];
  }
  run->info[line] = {"trajectory", "smoother (batch; the filter's: trajectory_filter.tum)"};
  if (r.pose_covariance.size() == run->trajectory.size()) run->smoother_pose_covariance = r.pose_covariance;
  // the map: the smoothed positions of the landmarks the smoother had (the others as the filter left them)
  for (auto& mp : run->map) {
    auto it = std::lower_bound(r.landmark_positions.begin(), r.landmark_positions.end(), mp.id,
                               [](const std::pair<std::int64_t, Eigen::Vector3d>& a, std::int64_t id) { return a.first < id; });
    if (it != r.landmark_positions.end() && it->first == mp.id) mp.position = it->second;
  }
  run->info.push_back({"smoother", r.message});
  run->info.push_back({"smoother_seconds", std::to_string(r.seconds)});
  if (o.use_gyro && !r.gyro_bias.empty()) {
    run->smoother_bias_valid = true;
    run->smoother_bias = r.gyro_bias.back();
    run->smoother_bias_std = r.final_bias_covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    run->smoother_mean_bias = r.mean_bias();
    run->smoother_mean_bias_std = r.mean_bias_covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  }
  smoothed_ = true;
}

bool SlamRunner::saveLocked(const std::string& dir, std::string* message,
                            const std::vector<std::pair<std::string, std::string>>& extra,
                            const std::vector<std::string>& command_line, const InputLedger* upstream) {
  try {
    if (run_.trajectory.empty()) throw std::runtime_error("no frame was processed");
    run_.map = slam_->map();
    run_.ground_truth = truth_;
    run_.fit_sphere = par_.fit_sphere && par_.known_map.empty();
    run_.ate_alignment = par_.ate_alignment;
    run_.ate_max_dt = par_.ate_max_dt;
    const int n = static_cast<int>(run_.trajectory.size());
    const int dropped = ledger_.dropped() + (upstream ? upstream->dropped() : 0);
    std::string why = upstream && upstream->dropped() ? upstream->summary() : "";
    if (ledger_.dropped() || why.empty()) why += (why.empty() ? "" : "; ") + ledger_.summary();
    run_.info = {{"frames_dropped", std::to_string(dropped)},
                 {"dropped_input", why},
                 {"gyro", slam_->options().use_gyro ? "true" : "false"},
                 {"known_map", par_.known_map.empty() ? "false" : "true"},
                 {"front_end", par_.front_end.empty() ? "none (landmark bag)" : par_.front_end},
                 {"world_frame", par_.world_frame},
                 {"camera_frame", par_.camera_frame},
                 {"slam_ms_per_frame", std::to_string(1e3 * slam_seconds_ / n)}};
    for (const auto& kv : extra) run_.info.push_back(kv);
    slam::RunRecord written = run_;
    smoothInto(&written);
    const std::string text = slam::writeResults(dir, written);
    if (smoothed_)
      slam::writeTum(dir + "/trajectory_filter.tum", run_.trajectory);
    else
      std::remove((dir + "/trajectory_filter.tum").c_str());  // an earlier save's, when this one has no smoother run
    const slam::SlamOptions& o = slam_->options();
    common::writeParameters(dir + "/parameters.yaml", "ES-EKF SLAM, keys of config/slam.yaml",
                            command_line.empty() ? std::vector<std::string>{node_name_} : command_line,
                            slam::slamOptionKeys(), [&](const std::string& k) { return slam::getSlamOption(o, k); });
    unsaved_ = false;
    *message = extra.empty() ? "results of " + std::to_string(n) + " frames written to " + dir : text;
    return true;
  } catch (const std::exception& e) {
    *message = "cannot write the results to '" + dir + "': " + e.what();
    return false;
  }
}

void SlamRunner::diagnose(diagnostic_updater::DiagnosticStatusWrapper& s) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int n = static_cast<int>(run_.trajectory.size());
  if (n == 0)
    s.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no frame yet (waiting for stereo/landmarks)");
  else if (!ledger_.lastError().empty())
    s.summary(diagnostic_msgs::DiagnosticStatus::WARN, ledger_.lastError());
  else
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "tracking");
  s.add("frames", n);
  s.add("frame rate (Hz)", status_.rate());
  s.add("ms per frame (SLAM)", n ? 1e3 * slam_seconds_ / n : 0.0);
  s.add("frames waiting for the gyro", static_cast<int>(waiting_.size()));
  s.add("dropped", ledger_.dropped());
  s.add("dropped by fault", ledger_.summary());
  s.add("landmarks in the pool", slam_->pool().used());
}

void SlamRunner::attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name) {
  std::lock_guard<std::mutex> lock(mutex_);
  node_name_ = node_name;
  pub_ = std::make_unique<ros_conv::SlamPublisher>();
  pub_->advertise(nh, par_);
  sub_landmarks_ = nh.subscribe<skin3d::LandmarkArray>(
      "stereo/landmarks", par_.queue_size, [this](const skin3d::LandmarkArray::ConstPtr& m) { onLandmarks(*m); });
  if (!par_.ground_truth_topic.empty()) {
    truth_path_ = std::make_unique<ros_conv::GroundTruthPath>();
    truth_path_->advertise(nh, "slam/ground_truth_path", par_.world_frame);
    sub_truth_ = nh.subscribe<geometry_msgs::PoseStamped>(
        par_.ground_truth_topic, 50, [this](const geometry_msgs::PoseStamped::ConstPtr& m) { onGroundTruth(*m); });
  }
  // imu/data is read even without the gyro (then ignored): a player that waits for subscribers does not hang
  sub_imu_ = nh.subscribe<sensor_msgs::Imu>("imu/data", std::max(200, 20 * par_.queue_size),
                                            [this](const sensor_msgs::Imu::ConstPtr& m) { onImu(*m); });
  srv_reset_ = pnh.advertiseService<std_srvs::Empty::Request, std_srvs::Empty::Response>(
      "reset", [this](std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
        log_.info("reset requested");
        reset();
        return true;
      });
  srv_save_ = pnh.advertiseService<skin3d::SaveResults::Request, skin3d::SaveResults::Response>(
      "save_results", [this](skin3d::SaveResults::Request& req, skin3d::SaveResults::Response& res) {
        const std::string dir = req.directory.empty() ? par_.results : req.directory;
        if (dir.empty()) {
          res.success = false;
          res.message = "no directory given and ~results is not set";
          return true;
        }
        res.success = save(dir, &res.message);
        return true;
      });
  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh);
  diagnostics_->setHardwareID("skin3d " + node_name);
  diagnostics_->add("SLAM", this, &SlamRunner::diagnose);
  diag_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) { diagnostics_->update(); });
  wait_timer_ = nh.createWallTimer(ros::WallDuration(0.05), [this](const ros::WallTimerEvent&) {
    std::lock_guard<std::mutex> lock(mutex_);
    drainLocked(false);
  });
  const slam::SlamOptions& opt = slam_->options();
  log_.info(std::string(opt.use_gyro ? "with gyroscope" : "without gyroscope") + ", pool up to " +
            std::to_string(opt.pool.max_capacity) + " landmarks, " + std::to_string(opt.max_updates_per_frame) +
            " updates per frame; front end '" + (par_.front_end.empty() ? "none" : par_.front_end) + "'; world '" +
            par_.world_frame + "', camera '" + par_.camera_frame + "'" +
            (par_.results.empty() ? "" : "; results on shutdown to " + par_.results));
}

}  // namespace ros_run
}  // namespace skin3d

namespace skin3d {
namespace ros_run {

std::unique_ptr<SlamRunner> startSlamRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name,
                                            RunLog log) {
  std::vector<std::string> errors;
  SlamRunnerParams par;
  static_cast<ros_conv::SlamNodeParams&>(par) = ros_conv::loadSlamNodeParams(pnh, &errors);
  pnh.param<std::string>("front_end", par.front_end, par.front_end);
  pnh.param("gyro_wait", par.gyro_wait, par.gyro_wait);
  pnh.param("ate_max_dt", par.ate_max_dt, par.ate_max_dt);
  std::string align = "auto";
  pnh.param<std::string>("ate_align", align, align);
  try {
    par.ate_alignment = slam::parseAteAlignment(align);
  } catch (const std::exception& e) {
    errors.push_back(std::string("~ate_align: ") + e.what());
  }
  slam::SlamOptions opt;
  try {
    par.validate();
    if (!par.front_end.empty())
      for (const auto& kv : slam::imageInputOptions(par.front_end)) slam::setSlamOption(&opt, kv.first, kv.second);
  } catch (const std::exception& e) {
    errors.push_back(e.what());
  }
  ros_conv::loadOptionParams(
      pnh, slam::slamOptionKeys(), [&](const std::string& k, const std::string& v) { slam::setSlamOption(&opt, k, v); },
      [&](const std::string& k) { return slam::getSlamOption(opt, k); }, &errors);
  if (!errors.empty()) {
    std::string all;
    for (const auto& e : errors) all += (all.empty() ? "" : "; ") + e;
    throw std::invalid_argument(all);
  }
  auto runner = std::make_unique<SlamRunner>(opt, par, std::move(log));
  runner->attach(nh, pnh, name);
  return runner;
}

}  // namespace ros_run
}  // namespace skin3d
