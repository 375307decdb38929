// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/eskf_slam: the ES-EKF SLAM (core: slam/slam_system.h) on the stereo landmarks of each frame.
 *
 * Subscribes: stereo/landmarks (skin3d/LandmarkArray, left optical frame), imu/data (sensor_msgs/Imu, angular
 *             velocity in the camera frame; only with ~use_gyro), ~ground_truth_topic (geometry_msgs/PoseStamped,
 *             world <- left optical frame, what the dataset bags carry; for display only).
 * Publishes:  TF ~world_frame -> ~camera_frame; slam/odometry (nav_msgs/Odometry: pose with the 6x6 [p, theta]
 *             covariance in the world, twist in the camera frame with the [v, omega] covariance);
 *             slam/path (nav_msgs/Path, latched); slam/map (sensor_msgs/PointCloud2 of the landmarks in the world,
 *             fields x y z std id, every ~map_every frames, latched); slam/landmark_ellipsoids
 *             (visualization_msgs/MarkerArray, latched, with slam/map: a DELETEALL, then one SPHERE per landmark,
 *             its ~ellipsoid_sigma ellipsoid in the world, coloured by its largest 1-sigma semi-axis: green
 *             <= 0.1 mm, yellow 1 mm, red >= 10 mm); slam/ground_truth_path (nav_msgs/Path, latched: the poses of
 *             ~ground_truth_topic, moved rigidly so that the one at the SLAM's first frame coincides with the SLAM's
 *             first pose (a dataset's world already is its first camera frame: then they are unchanged); cleared
 *             on a reset); slam/state (skin3d/SlamState).
 * Services:   ~reset (std_srvs/Empty): forget everything, the next frame defines the world again;
 *             ~save_results (skin3d/SaveResults): write the results directory now.
 * Parameters: every SLAM key of config/slam.yaml (same names, same defaults, private namespace); ~world_frame
 *             (world), ~camera_frame (stereo_left_optical_frame: the frame the landmarks must come in),
 *             ~results (directory written on shutdown; empty = none), ~fit_sphere (true: sphere_fit.yaml),
 *             ~known_map (make_dataset's FILE.map.csv: localisation in a known map, thesis experiment 1; empty =
 *             SLAM), ~map_every (10 frames), ~reset_on_jump_back (1.0 s: a stamp this much older than the last
 *             frame is a restarted bag: reset with a warning; smaller steps back are dropped frames),
 *             ~queue_size (10), ~ellipsoid_sigma (3.0: size of the landmark ellipsoids in standard deviations),
 *             ~max_ellipsoids (2000: at most this many, the most often observed landmarks first; 0 = no
 *             slam/landmark_ellipsoids), ~ground_truth_topic ("ground_truth/pose"; empty = no
 *             slam/ground_truth_path).
 * Bad input never stops the node: NaN/Inf or non-positive-definite landmark covariances and points behind the
 * camera are dropped (counted, throttled warning); out-of-order or repeated stamps drop the frame; a frame with
 * no landmarks is a prediction step; gyro messages in another frame, or with NaN, are dropped with a warning; a
 * landmark whose covariance has no ellipsoid (NaN, not positive definite) is left out of slam/landmark_ellipsoids;
 * ground-truth poses with NaN or a zero quaternion are dropped.
 */
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <skin3d/LandmarkArray.h>
#include <skin3d/SaveResults.h>
#include <skin3d/SlamState.h>
#include <std_srvs/Empty.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <deque>
#include <memory>
#include <mutex>
#include <pluginlib/class_list_macros.hpp>
#include <sstream>

#include "../tools/run_info.h"  // writeParameters
#include "conversions.h"
#include "skin3d/geometry/covariance_ellipsoid.h"
#include "skin3d/slam/results.h"
#include "skin3d/slam/slam_config.h"
#include "skin3d/slam/slam_system.h"

namespace skin3d {

class EskfSlamNodelet : public nodelet::Nodelet {
 public:
  ~EskfSlamNodelet() override {
    // No data is lost: the results are written when the node goes down.
    std::lock_guard<std::mutex> lock(mutex_);
    if (!results_dir_.empty() && slam_ && !run_.trajectory.empty()) {
      std::string message;
      save(results_dir_, &message);
      std::fprintf(stderr, "eskf_slam: %s\n", message.c_str());
    }
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    slam::SlamOptions opt;
    for (const std::string& key : slam::slamOptionKeys()) {
      XmlRpc::XmlRpcValue v;
      if (!pnh.getParam(key, v)) continue;
      std::ostringstream text;
      if (v.getType() == XmlRpc::XmlRpcValue::TypeBoolean) text << (static_cast<bool>(v) ? "true" : "false");
      else if (v.getType() == XmlRpc::XmlRpcValue::TypeInt) text << static_cast<int>(v);
      else if (v.getType() == XmlRpc::XmlRpcValue::TypeDouble) text.precision(17), text << static_cast<double>(v);
      else if (v.getType() == XmlRpc::XmlRpcValue::TypeString) text << static_cast<std::string>(v);
      else {
        NODELET_ERROR("eskf_slam: parameter ~%s must be a single value; keeping its default %s", key.c_str(),
                      slam::getSlamOption(opt, key).c_str());
        continue;
      }
      try {
        slam::setSlamOption(&opt, key, text.str());
      } catch (const std::exception& e) {
        NODELET_ERROR("eskf_slam: %s; keeping the default %s", e.what(), slam::getSlamOption(opt, key).c_str());
      }
    }
    try {
      opt.validate();
    } catch (const std::exception& e) {
      NODELET_ERROR("eskf_slam: %s; using the defaults of config/slam.yaml for every parameter", e.what());
      opt = slam::SlamOptions();
    }
    pnh.param<std::string>("world_frame", world_frame_, "world");
    pnh.param<std::string>("camera_frame", camera_frame_, "stereo_left_optical_frame");
    pnh.param<std::string>("results", results_dir_, "");
    pnh.param("fit_sphere", fit_sphere_, true);
    pnh.param("map_every", map_every_, 10);
    pnh.param("reset_on_jump_back", jump_back_, 1.0);
    int queue = 10;
    pnh.param("queue_size", queue, 10);
    pnh.param("ellipsoid_sigma", ellipsoid_sigma_, 3.0);
    if (!(ellipsoid_sigma_ > 0.0) || !std::isfinite(ellipsoid_sigma_)) {
      NODELET_ERROR("eskf_slam: ~ellipsoid_sigma = %g must be > 0; using 3", ellipsoid_sigma_);
      ellipsoid_sigma_ = 3.0;
    }
    pnh.param("max_ellipsoids", max_ellipsoids_, 2000);
    if (max_ellipsoids_ < 0) {
      NODELET_ERROR("eskf_slam: ~max_ellipsoids = %d must be >= 0 (0: none); using 2000", max_ellipsoids_);
      max_ellipsoids_ = 2000;
    }
    std::string ground_truth_topic;
    pnh.param<std::string>("ground_truth_topic", ground_truth_topic, "ground_truth/pose");
    slam_ = std::make_unique<slam::SlamSystem>(opt);
    std::string known_map;
    pnh.param<std::string>("known_map", known_map, "");
    if (!known_map.empty()) {
      try {
        const auto km = slam::readLandmarkMap(known_map);
        slam_->setKnownMap(km.first, km.second);
        NODELET_INFO("eskf_slam: localisation in the known map '%s' (%zu landmarks): thesis experiment 1",
                     known_map.c_str(), km.first.size());
      } catch (const std::exception& e) {
        NODELET_ERROR("eskf_slam: ~known_map: %s; running SLAM instead", e.what());
      }
    }

    pub_odom_ = nh.advertise<nav_msgs::Odometry>("slam/odometry", 10);
    pub_path_ = nh.advertise<nav_msgs::Path>("slam/path", 2, true);
    pub_map_ = nh.advertise<sensor_msgs::PointCloud2>("slam/map", 2, true);
    pub_state_ = nh.advertise<skin3d::SlamState>("slam/state", 10);
    if (max_ellipsoids_ > 0)
      pub_ellipsoids_ = nh.advertise<visualization_msgs::MarkerArray>("slam/landmark_ellipsoids", 2, true);
    sub_landmarks_ = nh.subscribe("stereo/landmarks", queue, &EskfSlamNodelet::onLandmarks, this);
    if (!ground_truth_topic.empty()) {
      pub_truth_ = nh.advertise<nav_msgs::Path>("slam/ground_truth_path", 2, true);
      sub_truth_ = nh.subscribe(ground_truth_topic, 50, &EskfSlamNodelet::onGroundTruth, this);
    }
    if (opt.use_gyro) sub_imu_ = nh.subscribe("imu/data", 200, &EskfSlamNodelet::onImu, this);
    srv_reset_ = pnh.advertiseService("reset", &EskfSlamNodelet::onReset, this);
    srv_save_ = pnh.advertiseService("save_results", &EskfSlamNodelet::onSave, this);
    NODELET_INFO("eskf_slam: %s, pool up to %d landmarks, %d updates per frame; world '%s', camera '%s'%s%s",
                 opt.use_gyro ? "with gyroscope" : "without gyroscope", opt.pool.max_capacity,
                 opt.max_updates_per_frame, world_frame_.c_str(), camera_frame_.c_str(),
                 results_dir_.empty() ? "" : "; results on shutdown to ", results_dir_.c_str());
  }

  void onImu(const sensor_msgs::Imu::ConstPtr& imu) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (imu->header.frame_id != camera_frame_) {
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping imu/data in frame '%s': the gyro must be expressed in '%s'",
                            imu->header.frame_id.c_str(), camera_frame_.c_str());
      return;
    }
    Eigen::Matrix3d C;
    for (int i = 0; i < 9; ++i) C(i / 3, i % 3) = imu->angular_velocity_covariance[i];
    if (C(0, 0) < 0.0 || C.isZero(0.0)) C.setZero();  // unknown: the configured gyro_noise
    try {
      slam_->addGyro(imu->header.stamp.toSec(),
                     Eigen::Vector3d(imu->angular_velocity.x, imu->angular_velocity.y, imu->angular_velocity.z), C);
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping imu/data: %s", e.what());
    }
  }

  void onLandmarks(const skin3d::LandmarkArray::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (msg->header.frame_id != camera_frame_) {
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping stereo/landmarks in frame '%s' (expected '%s')",
                            msg->header.frame_id.c_str(), camera_frame_.c_str());
      return;
    }
    const double t = msg->header.stamp.toSec();
    if (slam_->initialised() && t < slam_->time() - jump_back_) {
      NODELET_WARN("eskf_slam: time jumped back by %.3f s (bag restarted?): resetting the SLAM", slam_->time() - t);
      resetLocked();
    }
    slam::FrameStats st;
    try {
      st = slam_->processFrame(t, ros_conv::fromMsg(*msg));
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping frame: %s", e.what());
      return;
    }
    if (st.rejected_invalid > 0)
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropped %d of %d landmarks with a non-finite position or covariance, a "
                                 "covariance that is not symmetric positive definite, or a point behind the camera",
                            st.rejected_invalid, st.measurements);
    const auto& x = slam_->filter().state();
    run_.trajectory.push_back({t, static_cast<std::int64_t>(msg->header.stamp.toNSec()), x.p, x.q});
    run_.rows.push_back(slam::stateRow(*slam_, st));
    publish(msg->header.stamp, st);
    if (run_.trajectory.size() == 1) anchorGroundTruth();
  }

  /** Ground truth, for display: buffered until the SLAM's first frame fixes how its world sits in ours. */
  void onGroundTruth(const geometry_msgs::PoseStamped::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto& p = msg->pose.position;
    const auto& o = msg->pose.orientation;
    const Eigen::Quaterniond q(o.w, o.x, o.y, o.z);
    if (!std::isfinite(p.x + p.y + p.z) || !(q.norm() > 1e-6)) {  // NaN-safe: !(NaN > x)
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping a ground-truth pose with NaN or a zero quaternion");
      return;
    }
    const double t = msg->header.stamp.toSec();
    if (!truth_.empty() && t < truth_.back().t - jump_back_) {  // restarted bag: forget the old run
      truth_.clear();
      clearGroundTruthPath();
    }
    slam::StampedPose s;
    s.t = t;
    s.stamp_ns = static_cast<std::int64_t>(msg->header.stamp.toNSec());
    s.p = Eigen::Vector3d(p.x, p.y, p.z);
    s.q = q.normalized();
    truth_.push_back(s);
    if (truth_.size() > kTruthBuffer) truth_.pop_front();
    if (!truth_anchored_) {
      anchorGroundTruth();
    } else if (t >= run_.trajectory.front().t - kTruthMatch) {
      appendGroundTruth(s);
      pub_truth_.publish(truth_path_);
    }
  }

  /** Finds the ground-truth pose at the SLAM's first frame (within kTruthMatch s) and draws the buffer from there. */
  void anchorGroundTruth() {
    if (truth_anchored_ || !pub_truth_ || run_.trajectory.empty() || truth_.empty()) return;
    const slam::StampedPose& s0 = run_.trajectory.front();
    const slam::StampedPose* g0 = nullptr;
    for (const auto& g : truth_)
      if (std::abs(g.t - s0.t) <= kTruthMatch && (!g0 || std::abs(g.t - s0.t) < std::abs(g0->t - s0.t))) g0 = &g;
    if (!g0) return;
    // T_slam_truth = T_slam_camera(t0) * T_truth_camera(t0)^-1
    const Eigen::Quaterniond q = s0.q * g0->q.conjugate();
    truth_q_ = q.normalized();
    truth_p_ = s0.p - truth_q_ * g0->p;
    truth_anchored_ = true;
    truth_path_.poses.clear();
    run_.ground_truth.clear();
    for (const auto& g : truth_)
      if (g.t >= s0.t - kTruthMatch) appendGroundTruth(g);
    pub_truth_.publish(truth_path_);
  }

  void appendGroundTruth(const slam::StampedPose& g) {
    const Eigen::Vector3d p = truth_p_ + truth_q_ * g.p;
    const Eigen::Quaterniond q = (truth_q_ * g.q).normalized();
    geometry_msgs::PoseStamped ps;
    if (g.stamp_ns >= 0) ps.header.stamp.fromNSec(static_cast<std::uint64_t>(g.stamp_ns));
    else ps.header.stamp.fromSec(g.t);
    ps.header.frame_id = world_frame_;
    ps.pose = ros_conv::toPoseMsg(p, q);
    truth_path_.header = ps.header;
    truth_path_.poses.push_back(ps);
    slam::StampedPose aligned;  // for the results: ground_truth.tum and the ATE in summary.yaml
    aligned.t = g.t;
    aligned.stamp_ns = g.stamp_ns;
    aligned.p = p;
    aligned.q = q;
    run_.ground_truth.push_back(aligned);
  }

  void clearGroundTruthPath() {
    truth_anchored_ = false;
    run_.ground_truth.clear();
    if (!pub_truth_ || truth_path_.poses.empty()) return;
    truth_path_.poses.clear();
    truth_path_.header.frame_id = world_frame_;
    pub_truth_.publish(truth_path_);
  }

  void publish(const ros::Time& stamp, const slam::FrameStats& st) {
    const auto& f = slam_->filter();
    const auto& x = f.state();
    geometry_msgs::TransformStamped tf;
    tf.header.stamp = stamp;
    tf.header.frame_id = world_frame_;
    tf.child_frame_id = camera_frame_;
    tf.transform.translation.x = x.p.x();
    tf.transform.translation.y = x.p.y();
    tf.transform.translation.z = x.p.z();
    tf.transform.rotation.w = x.q.w();
    tf.transform.rotation.x = x.q.x();
    tf.transform.rotation.y = x.q.y();
    tf.transform.rotation.z = x.q.z();
    tf_.sendTransform(tf);

    nav_msgs::Odometry od;
    od.header = tf.header;
    od.child_frame_id = camera_frame_;
    od.pose.pose = ros_conv::toPoseMsg(x.p, x.q);
    const Eigen::MatrixXd& C = f.covariance();
    // [dp, dtheta] (global angle = world axes, as ROS wants the pose covariance) and [dv, dw] (camera frame).
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) {
        od.pose.covariance[6 * i + j] = C(i, j);
        od.twist.covariance[6 * i + j] = C(6 + i, 6 + j);
      }
    od.twist.twist.linear.x = x.v.x();
    od.twist.twist.linear.y = x.v.y();
    od.twist.twist.linear.z = x.v.z();
    od.twist.twist.angular.x = x.w.x();
    od.twist.twist.angular.y = x.w.y();
    od.twist.twist.angular.z = x.w.z();
    pub_odom_.publish(od);

    geometry_msgs::PoseStamped ps;
    ps.header = tf.header;
    ps.pose = od.pose.pose;
    path_.header = tf.header;
    path_.poses.push_back(ps);
    pub_path_.publish(path_);  // latched: an rviz started after the end of a bag still gets the whole path

    const slam::StateRow r = run_.rows.back();
    skin3d::SlamState s;
    s.header = tf.header;
    s.linear_velocity.x = x.v.x();
    s.linear_velocity.y = x.v.y();
    s.linear_velocity.z = x.v.z();
    s.angular_velocity.x = x.w.x();
    s.angular_velocity.y = x.w.y();
    s.angular_velocity.z = x.w.z();
    s.trace_state = r.trace_rig;
    s.trace_landmarks = r.trace_landmarks;
    s.trace_all = r.trace_all;
    s.pool_size = r.pool_size;
    s.pool_in_use = r.pool_in_use;
    s.landmarks_ever_seen = static_cast<uint32_t>(r.ever_seen);
    s.measurements = st.measurements;
    s.associated = st.associated;
    s.initialised = st.initialised;
    s.rejected = st.rejected_invalid + (st.associated - st.used);
    pub_state_.publish(s);

    // Latched: published whether or not someone listens, so that an rviz started later sees the latest map.
    if (map_every_ > 0 && run_.rows.size() % map_every_ == 1) {
      const auto map = slam_->map();
      pub_map_.publish(mapCloud(map, stamp));
      if (max_ellipsoids_ > 0) pub_ellipsoids_.publish(ellipsoids(map, stamp));
    }
  }

  /** One SPHERE per landmark (the most often observed ~max_ellipsoids), after a DELETEALL of the last array. */
  visualization_msgs::MarkerArray ellipsoids(std::vector<slam::MapPoint> map, const ros::Time& stamp) const {
    if (static_cast<int>(map.size()) > max_ellipsoids_) {
      std::nth_element(
          map.begin(), map.begin() + max_ellipsoids_, map.end(),
          [](const slam::MapPoint& a, const slam::MapPoint& b) { return a.times_observed > b.times_observed; });
      map.resize(max_ellipsoids_);
    }
    visualization_msgs::MarkerArray out;
    visualization_msgs::Marker m;
    m.header.stamp = stamp;
    m.header.frame_id = world_frame_;
    m.ns = "landmarks";
    m.action = visualization_msgs::Marker::DELETEALL;
    out.markers.push_back(m);
    m.action = visualization_msgs::Marker::ADD;
    m.type = visualization_msgs::Marker::SPHERE;
    int skipped = 0;
    for (const auto& lm : map) {
      geometry::CovarianceEllipsoid e;
      if (!lm.position.allFinite() || !geometry::covarianceEllipsoid(lm.covariance, ellipsoid_sigma_, &e)) {
        ++skipped;
        continue;
      }
      m.id = static_cast<int32_t>(lm.id);
      m.pose = ros_conv::toPoseMsg(lm.position, e.orientation);
      m.scale.x = 2.0 * e.semi_axes[0];  // a SPHERE's scale is its diameter
      m.scale.y = 2.0 * e.semi_axes[1];
      m.scale.z = 2.0 * e.semi_axes[2];
      // largest 1-sigma semi-axis on a log scale: 0.1 mm green, 1 mm yellow, 10 mm red
      const double s = std::clamp((std::log10(e.semi_axes[0] / ellipsoid_sigma_) + 4.0) / 2.0, 0.0, 1.0);
      m.color.r = static_cast<float>(std::min(1.0, 2.0 * s));
      m.color.g = static_cast<float>(std::min(1.0, 2.0 * (1.0 - s)));
      m.color.b = 0.1f;
      m.color.a = 0.8f;
      out.markers.push_back(m);
    }
    if (skipped > 0)
      NODELET_WARN_THROTTLE(10.0,
                            "eskf_slam: %d of %zu landmarks have a covariance with no ellipsoid (NaN or not "
                            "positive definite): left out of slam/landmark_ellipsoids",
                            skipped, map.size());
    return out;
  }

  sensor_msgs::PointCloud2 mapCloud(const std::vector<slam::MapPoint>& map, const ros::Time& stamp) const {
    sensor_msgs::PointCloud2 pc;
    pc.header.stamp = stamp;
    pc.header.frame_id = world_frame_;
    sensor_msgs::PointCloud2Modifier mod(pc);
    mod.setPointCloud2Fields(5, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32,
                             "z", 1, sensor_msgs::PointField::FLOAT32, "std", 1, sensor_msgs::PointField::FLOAT32,
                             "id", 1, sensor_msgs::PointField::FLOAT32);
    mod.resize(map.size());
    sensor_msgs::PointCloud2Iterator<float> px(pc, "x"), py(pc, "y"), pz(pc, "z"), ps(pc, "std"), pid(pc, "id");
    for (const auto& m : map) {
      *px = m.position.x();
      *py = m.position.y();
      *pz = m.position.z();
      *ps = std::sqrt(std::max(0.0, m.covariance.trace()));
      *pid = static_cast<float>(m.id);
      ++px, ++py, ++pz, ++ps, ++pid;
    }
    return pc;
  }

  void resetLocked() {
    if (!results_dir_.empty() && !run_.trajectory.empty()) {
      std::string message;
      save(results_dir_, &message);
      NODELET_INFO("eskf_slam: before the reset: %s", message.c_str());
    }
    slam_->reset();
    run_ = slam::RunRecord();
    path_.poses.clear();
    clearGroundTruthPath();
  }

  bool save(const std::string& dir, std::string* message) {
    try {
      run_.map = slam_->map();
      run_.fit_sphere = fit_sphere_;
      run_.info = {{"source", "eskf_slam nodelet"}, {"world_frame", world_frame_}, {"camera_frame", camera_frame_}};
      run_.ground_truth_alignment =
          "ground_truth/pose moved rigidly onto the SLAM's pose at its first frame (identity on a whole dataset bag)";
      slam::writeResults(dir, run_);
      const slam::SlamOptions& o = slam_->options();
      tools::writeParameters(dir + "/parameters.yaml", "ES-EKF SLAM, keys of config/slam.yaml",
                             {"eskf_slam nodelet (" + getName() + ")"}, slam::slamOptionKeys(),
                             [&](const std::string& k) { return slam::getSlamOption(o, k); });
      *message = "results of " + std::to_string(run_.trajectory.size()) + " frames written to " + dir;
      return true;
    } catch (const std::exception& e) {
      *message = std::string("cannot write the results: ") + e.what();
      return false;
    }
  }

  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
    std::lock_guard<std::mutex> lock(mutex_);
    NODELET_INFO("eskf_slam: reset requested");
    resetLocked();
    return true;
  }

  bool onSave(skin3d::SaveResults::Request& req, skin3d::SaveResults::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string dir = req.directory.empty() ? results_dir_ : req.directory;
    if (dir.empty()) {
      res.success = false;
      res.message = "no directory given and ~results is not set";
      return true;
    }
    res.success = save(dir, &res.message);
    return true;
  }

  std::mutex mutex_;
  std::unique_ptr<slam::SlamSystem> slam_;
  slam::RunRecord run_;
  nav_msgs::Path path_;
  std::string world_frame_, camera_frame_, results_dir_;
  bool fit_sphere_ = true;
  int map_every_ = 10;
  double jump_back_ = 1.0;
  double ellipsoid_sigma_ = 3.0;
  int max_ellipsoids_ = 2000;
  // ground truth for display: raw poses (last kTruthBuffer), and the rigid motion that puts them in the SLAM's world
  static constexpr size_t kTruthBuffer = 5000;
  static constexpr double kTruthMatch = 0.05;  // s: the ground-truth pose of the SLAM's first frame
  std::deque<slam::StampedPose> truth_;
  bool truth_anchored_ = false;
  Eigen::Quaterniond truth_q_ = Eigen::Quaterniond::Identity();
  Eigen::Vector3d truth_p_ = Eigen::Vector3d::Zero();
  nav_msgs::Path truth_path_;
  ros::Publisher pub_odom_, pub_path_, pub_map_, pub_state_, pub_ellipsoids_, pub_truth_;
  ros::Subscriber sub_landmarks_, sub_imu_, sub_truth_;
  ros::ServiceServer srv_reset_, srv_save_;
  tf2_ros::TransformBroadcaster tf_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::EskfSlamNodelet, nodelet::Nodelet)
