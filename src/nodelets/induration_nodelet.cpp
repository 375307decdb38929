// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/induration: plaque heights above the healthy-skin reference in each dense cloud (core:
 * induration/induration.h) and the results directory of the run (induration/induration_io.h).
 *
 * Subscribes: induration/points (sensor_msgs/PointCloud2, organised, from skin3d/dense_stereo: x y z, and when
 *             present sigma, ray_x/y/z and rgb).
 * Publishes:  induration/report (skin3d/IndurationReport, SI units, frame of the cloud; the measurement's
 *             warnings in `warnings`); induration/height_map (sensor_msgs/Image 32FC1, m above the reference,
 *             NaN unknown; not published when the reference could not be fitted).
 * Services:   ~save_results (skin3d/SaveResults): write the results now (directory: the request's, else ~results).
 * Parameters: ~config (YAML file of the keys of config/induration.yaml, applied first), then every key of
 *             config/induration.yaml set as a private parameter (the induration keys are used here; the
 *             matcher's are read but unused); ~results (directory; empty = none): induration.yaml of every
 *             frame, height_map.png and surface.ply of the last one, written on ~save_results and, if anything
 *             new was measured since, on shutdown; ~queue_size (2).
 * Bad input (a cloud that is not organised, lacks x y z or has inconsistent sizes) drops that cloud with a
 * throttled error naming the problem; the nodelet keeps running. Hopeless data (no healthy skin, too few
 * points) is not an error: the report says why in `warnings` (also a throttled warning).
 */
#include <cv_bridge/cv_bridge.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <skin3d/IndurationReport.h>
#include <skin3d/SaveResults.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/conversions.h"
#include "skin3d/common/large_buffers.h"
#include "skin3d/induration/induration.h"
#include "skin3d/induration/induration_config.h"
#include "skin3d/induration/induration_io.h"

namespace skin3d {

class IndurationNodelet : public nodelet::Nodelet {
 public:
  ~IndurationNodelet() override {
    // No data is lost: what was measured since the last save is written when the node goes down.
    std::lock_guard<std::mutex> lock(mutex_);
    if (!results_dir_.empty() && unsaved_ && !frames_.empty()) {
      std::string message;
      save(results_dir_, &message);
      std::fprintf(stderr, "induration: %s\n", message.c_str());
    }
  }

 private:
  void onInit() override {
    keepLargeBuffers();  // process-wide: full-resolution buffers from the heap, not fresh mmap()s
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::vector<std::string> errors;
    options_ = ros_conv::loadPipelineOptions(pnh, &errors).induration;
    for (const auto& e : errors) NODELET_ERROR("induration: %s", e.c_str());
    pnh.param<std::string>("results", results_dir_, "");
    int queue = 2;
    pnh.param("queue_size", queue, 2);
    if (queue < 1) {
      NODELET_ERROR("induration: ~queue_size = %d must be >= 1; using 2", queue);
      queue = 2;
    }
    pub_report_ = nh.advertise<skin3d::IndurationReport>("induration/report", 10);
    pub_height_ = nh.advertise<sensor_msgs::Image>("induration/height_map", 2);
    sub_points_ = nh.subscribe("induration/points", queue, &IndurationNodelet::onPoints, this);
    srv_save_ = pnh.advertiseService("save_results", &IndurationNodelet::onSave, this);
    NODELET_INFO("induration: reference '%s', plaques above %.3f mm and %.1f mm^2%s%s",
                 options_.reference_model.c_str(), options_.min_height * 1e3, options_.min_area * 1e6,
                 results_dir_.empty() ? "" : "; results on shutdown to ", results_dir_.c_str());
  }

  void onPoints(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    induration::FrameRecord rec;
    stereo::DenseCloud cloud;
    cv::Mat colour;
    const std::string problem = ros_conv::fromCloudMsg(*msg, "induration/points", &cloud, &colour);
    if (!problem.empty()) {
      NODELET_ERROR_THROTTLE(2.0, "induration: dropping cloud: %s", problem.c_str());
      return;
    }
    const auto t0 = std::chrono::steady_clock::now();
    try {
      rec.result = induration::measureInduration(cloud, options_);
    } catch (const std::exception& e) {  // IndurationError: options (validated at start-up), cv::Exception
      NODELET_ERROR_THROTTLE(2.0, "induration: dropping cloud: %s", e.what());
      return;
    }
    rec.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rec.stamp = msg->header.stamp.toSec();
    rec.valid_fraction = static_cast<double>(rec.result.known_points) / cloud.xyz.total();  // known / all pixels
    for (const auto& w : rec.result.warnings) NODELET_WARN_THROTTLE(5.0, "induration: %s", w.c_str());
    NODELET_DEBUG("induration: %zu plaques in %.2f s", rec.result.plaques.size(), rec.seconds);

    const skin3d::IndurationReport report = ros_conv::toReportMsg(rec.result, msg->header);
    sensor_msgs::ImagePtr height;
    if (!rec.result.height_map.empty())
      height = cv_bridge::CvImage(msg->header, sensor_msgs::image_encodings::TYPE_32FC1, rec.result.height_map)
                   .toImageMsg();
    {  // stored before it is published: a save_results call that follows a report includes its frame
      std::lock_guard<std::mutex> lock(mutex_);
      if (!frames_.empty()) {  // only the last frame keeps its maps (height_map.png, surface.ply)
        frames_.back().result.height_map.release();
        frames_.back().result.labels.release();
      }
      frames_.push_back(std::move(rec));
      last_cloud_ = std::move(cloud);
      last_colour_ = std::move(colour);
      frame_id_ = msg->header.frame_id;
      unsaved_ = true;
    }
    pub_report_.publish(report);
    if (height) pub_height_.publish(height);
  }

  /** Writes induration.yaml, height_map.png and surface.ply to `dir` (created if needed); mutex held. */
  bool save(const std::string& dir, std::string* message) {
    if (frames_.empty()) {
      *message = "nothing measured yet: no results written";
      return false;
    }
    try {
      std::filesystem::create_directories(dir);
      const std::filesystem::path d(dir);
      induration::writeInduration((d / "induration.yaml").string(), frames_, options_, frame_id_,
                                  "skin3d/induration nodelet (induration/points)");
      const induration::IndurationResult& r = frames_.back().result;
      const std::string png = (d / "height_map.png").string();
      if (!cv::imwrite(png, induration::heightMapImage(r.height_map, r.labels, r.plaques)))
        throw std::runtime_error("cannot write " + png);
      induration::writeSurfacePly((d / "surface.ply").string(), last_cloud_, last_colour_);
      if (dir == results_dir_) unsaved_ = false;
      *message = "results of " + std::to_string(frames_.size()) + " frames written to " + dir;
      return true;
    } catch (const std::exception& e) {
      *message = std::string("cannot write the results: ") + e.what();
      return false;
    }
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
    if (res.success)
      NODELET_INFO("induration: %s", res.message.c_str());
    else
      NODELET_ERROR("induration: %s", res.message.c_str());
    return true;
  }

  induration::IndurationOptions options_;
  std::string results_dir_, frame_id_;
  std::mutex mutex_;
  std::vector<induration::FrameRecord> frames_;  //!< every frame; maps only in the last
  stereo::DenseCloud last_cloud_;
  cv::Mat last_colour_;
  bool unsaved_ = false;
  ros::Publisher pub_report_, pub_height_;
  ros::Subscriber sub_points_;
  ros::ServiceServer srv_save_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::IndurationNodelet, nodelet::Nodelet)
