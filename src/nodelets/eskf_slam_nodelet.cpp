// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/eskf_slam: the ES-EKF SLAM (core: slam/slam_system.h) on the stereo landmarks of each frame.
 *
 * Subscribes: stereo/landmarks (skin3d/LandmarkArray, left optical frame), imu/data (sensor_msgs/Imu, angular
 *             velocity in the camera frame; only with ~use_gyro).
 * Publishes:  TF ~world_frame -> ~camera_frame; slam/odometry (nav_msgs/Odometry: pose with the 6x6 [p, theta]
 *             covariance in the world, twist in the camera frame with the [v, omega] covariance);
 *             slam/path (nav_msgs/Path); slam/map (sensor_msgs/PointCloud2 of the landmarks in the world, fields
 *             x y z std id, every ~map_every frames); slam/state (skin3d/SlamState).
 * Services:   ~reset (std_srvs/Empty): forget everything, the next frame defines the world again;
 *             ~save_results (skin3d/SaveResults): write the results directory now.
 * Parameters: every SLAM key of config/slam.yaml (same names, same defaults, private namespace); ~world_frame
 *             (world), ~camera_frame (stereo_left_optical_frame: the frame the landmarks must come in),
 *             ~results (directory written on shutdown; empty = none), ~fit_sphere (true: sphere_fit.yaml),
 *             ~known_map (make_dataset's FILE.map.csv: localisation in a known map, thesis experiment 1; empty =
 *             SLAM), ~map_every (10 frames), ~reset_on_jump_back (1.0 s: a stamp this much older than the last frame is a
 *             restarted bag: reset with a warning; smaller steps back are dropped frames), ~queue_size (10).
 * Bad input never stops the node: NaN/Inf or non-positive-definite landmark covariances and points behind the
 * camera are dropped (counted, throttled warning); out-of-order or repeated stamps drop the frame; a frame with
 * no landmarks is a prediction step; gyro messages in another frame, or with NaN, are dropped with a warning.
 */
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

#include <cmath>
#include <memory>
#include <mutex>
#include <pluginlib/class_list_macros.hpp>
#include <sstream>

#include "conversions.h"
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
    sub_landmarks_ = nh.subscribe("stereo/landmarks", queue, &EskfSlamNodelet::onLandmarks, this);
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
    run_.trajectory.push_back({t, x.p, x.q});
    run_.rows.push_back(slam::stateRow(*slam_, st));
    publish(msg->header.stamp, st);
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
    od.pose.pose.position.x = x.p.x();
    od.pose.pose.position.y = x.p.y();
    od.pose.pose.position.z = x.p.z();
    od.pose.pose.orientation = tf.transform.rotation;
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
    if (pub_path_.getNumSubscribers() > 0) pub_path_.publish(path_);

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

    if (map_every_ > 0 && run_.rows.size() % map_every_ == 1 && pub_map_.getNumSubscribers() > 0)
      pub_map_.publish(mapCloud(stamp));
  }

  sensor_msgs::PointCloud2 mapCloud(const ros::Time& stamp) const {
    const auto map = slam_->map();
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
  }

  bool save(const std::string& dir, std::string* message) {
    try {
      run_.map = slam_->map();
      run_.fit_sphere = fit_sphere_;
      run_.info = {{"source", "eskf_slam nodelet"}, {"world_frame", world_frame_}, {"camera_frame", camera_frame_}};
      slam::writeResults(dir, run_);
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
  ros::Publisher pub_odom_, pub_path_, pub_map_, pub_state_;
  ros::Subscriber sub_landmarks_, sub_imu_;
  ros::ServiceServer srv_reset_, srv_save_;
  tf2_ros::TransformBroadcaster tf_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::EskfSlamNodelet, nodelet::Nodelet)
