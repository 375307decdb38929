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
#include <nav_msgs/Path.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <skin3d/LandmarkArray.h>
#include <skin3d/SaveResults.h>
#include <std_srvs/Empty.h>

#include <cmath>
#include <memory>
#include <mutex>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/common/run_info.h"  // writeParameters
#include "skin3d/ros/conversions.h"
#include "skin3d/ros/slam_messages.h"
#include "skin3d/ros/ground_truth_path.h"
#include "skin3d/slam/results.h"
#include "skin3d/slam/slam_system.h"

namespace skin3d {

class EskfSlamNodelet : public nodelet::Nodelet {
 public:
  ~EskfSlamNodelet() override {
    // No data is lost: the results are written when the node goes down.
    std::lock_guard<std::mutex> lock(mutex_);
    if (!par_.results.empty() && slam_ && !run_.trajectory.empty()) {
      std::string message;
      save(par_.results, &message);
      std::fprintf(stderr, "eskf_slam: %s\n", message.c_str());
    }
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::vector<std::string> errors;
    const slam::SlamOptions opt = ros_conv::loadSlamOptions(pnh, &errors);
    par_ = ros_conv::loadSlamNodeParams(pnh, &errors);
    for (const auto& e : errors) NODELET_ERROR("eskf_slam: %s", e.c_str());
    slam_ = std::make_unique<slam::SlamSystem>(opt);
    const std::string& known_map = par_.known_map;
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

    pub_.advertise(nh, par_);
    sub_landmarks_ = nh.subscribe("stereo/landmarks", par_.queue_size, &EskfSlamNodelet::onLandmarks, this);
    if (!par_.ground_truth_topic.empty()) {
      truth_.advertise(nh, "slam/ground_truth_path", par_.world_frame);
      sub_truth_ = nh.subscribe(par_.ground_truth_topic, 50, &EskfSlamNodelet::onGroundTruth, this);
    }
    if (opt.use_gyro) sub_imu_ = nh.subscribe("imu/data", 200, &EskfSlamNodelet::onImu, this);
    srv_reset_ = pnh.advertiseService("reset", &EskfSlamNodelet::onReset, this);
    srv_save_ = pnh.advertiseService("save_results", &EskfSlamNodelet::onSave, this);
    NODELET_INFO("eskf_slam: %s, pool up to %d landmarks, %d updates per frame; world '%s', camera '%s'%s%s",
                 opt.use_gyro ? "with gyroscope" : "without gyroscope", opt.pool.max_capacity,
                 opt.max_updates_per_frame, par_.world_frame.c_str(), par_.camera_frame.c_str(),
                 par_.results.empty() ? "" : "; results on shutdown to ", par_.results.c_str());
  }

  void onImu(const sensor_msgs::Imu::ConstPtr& imu) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (imu->header.frame_id != par_.camera_frame) {
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping imu/data in frame '%s': the gyro must be expressed in '%s'",
                            imu->header.frame_id.c_str(), par_.camera_frame.c_str());
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
    if (msg->header.frame_id != par_.camera_frame) {
      NODELET_WARN_THROTTLE(2.0, "eskf_slam: dropping stereo/landmarks in frame '%s' (expected '%s')",
                            msg->header.frame_id.c_str(), par_.camera_frame.c_str());
      return;
    }
    const double t = msg->header.stamp.toSec();
    if (slam_->initialised() && t < slam_->time() - par_.jump_back) {
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
    const std::string warning = pub_.publish(msg->header.stamp, *slam_, run_.rows.back(), st, run_.rows.size());
    if (!warning.empty()) NODELET_WARN_THROTTLE(10.0, "eskf_slam: %s", warning.c_str());
    if (run_.trajectory.size() == 1) truth_.anchor(run_.trajectory.front());
  }

  /** Ground truth, for display: buffered until the SLAM's first frame fixes how its world sits in ours. */
  void onGroundTruth(const geometry_msgs::PoseStamped::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string problem = truth_.add(*msg, par_.jump_back, run_.trajectory.empty() ? nullptr : &run_.trajectory.front());
    if (!problem.empty()) NODELET_WARN_THROTTLE(2.0, "eskf_slam: %s", problem.c_str());
  }

  void resetLocked() {
    if (!par_.results.empty() && !run_.trajectory.empty()) {
      std::string message;
      save(par_.results, &message);
      NODELET_INFO("eskf_slam: before the reset: %s", message.c_str());
    }
    slam_->reset();
    run_ = slam::RunRecord();
    pub_.clearPath();
    truth_.clear();
  }

  bool save(const std::string& dir, std::string* message) {
    try {
      run_.map = slam_->map();
      run_.ground_truth = truth_.aligned();
      run_.fit_sphere = par_.fit_sphere;
      run_.info = {{"source", "eskf_slam nodelet"}, {"world_frame", par_.world_frame}, {"camera_frame", par_.camera_frame}};
      run_.ground_truth_alignment =
          "ground_truth/pose moved rigidly onto the SLAM's pose at its first frame (identity on a whole dataset bag)";
      slam::writeResults(dir, run_);
      const slam::SlamOptions& o = slam_->options();
      common::writeParameters(dir + "/parameters.yaml", "ES-EKF SLAM, keys of config/slam.yaml",
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
    const std::string dir = req.directory.empty() ? par_.results : req.directory;
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
  ros_conv::SlamNodeParams par_;
  ros_conv::GroundTruthPath truth_;  // ground truth for display, moved onto the SLAM's first pose
  ros_conv::SlamPublisher pub_;
  ros::Subscriber sub_landmarks_, sub_imu_, sub_truth_;
  ros::ServiceServer srv_reset_, srv_save_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::EskfSlamNodelet, nodelet::Nodelet)
