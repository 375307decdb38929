// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file site_runner.h
 * @brief skin3d_ros: the site scan's runner (see runner.h): each raw stereo pair measured on its own (an
 * IndurationRunner: its induration.yaml comes with the site's results), then fused into one site
 * (site::SiteFusion) with the rig's pose at the pair's stamp. The site_fusion nodelet constructs it and calls
 * attach(); `process_bag --site` constructs it, hands it every pose of the bag (onPose) and calls onStereo() with the
 * bag's pairs, so both write the same site.yaml.
 *
 * Poses: from a topic (geometry_msgs/PoseStamped or nav_msgs/Odometry: world <- the left optical frame; the ES-EKF's
 * slam/odometry by default), from TF (world_frame <- the left image's frame_id), or from the images themselves
 * ("images": each pair's stereo features matched with those of the last pair fused, site/pair_odometry.h; the pose
 * is that pair's registered pose times the motion between them, and the registration refines it). A measured pair waits up to
 * `pose_wait` s (wall) for its pose (a pose within `pose_tolerance` s of its stamp), then is left out and named;
 * pairs are fused in the order they were taken.
 *
 * Live topics: subscribes stereo/{left,right}/image_raw + camera_info and the poses; publishes site/frame (one
 * SiteFrameReport per pair), site/coverage (latched: the site unrolled, frames per cell; never covered is dark
 * grey) and, only while subscribed, site/points (the site so far: x y z height sigma frames, in world_frame).
 */
#pragma once

#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <Eigen/Geometry>
#include <chrono>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "skin3d/ros/induration_runner.h"
#include "skin3d/site/pair_odometry.h"
#include "skin3d/site/site_fusion.h"
#include "skin3d/stereo/front_end.h"

namespace tf2_ros {
class Buffer;
class TransformListener;
}  // namespace tf2_ros

namespace skin3d {
namespace ros_run {

struct SiteRunOptions {
  std::string poses = "slam/odometry";  //!< pose topic (PoseStamped or Odometry), "tf", or "images"
  std::string world_frame = "world";    //!< the site's frame (TF: the frame looked up; also the outputs' frame_id)
  double pose_tolerance = 0.01;         //!< s, a pose belongs to a pair when its stamp is this close
  double pose_wait = 5.0;               //!< s (wall) a measured pair waits for its pose (0: none, it is left out at once)
  int preview_cells = 250000;           //!< at most about this many points in site/points and cells in site/coverage
  void validate() const;                //!< throws std::invalid_argument naming the option
};

class SiteRunner {
 public:
  /** @param results directory written on save_results and when the runner goes (empty: none)
   *  @throws std::invalid_argument for bad options. */
  SiteRunner(const induration::PipelineOptions& options, const site::SiteOptions& site, const SiteRunOptions& run,
             const std::string& results, RunLog log);
  /** Leaves the pairs still waiting for a pose out (named) and writes the results (when ~results is set and
   *  something was fused or left out since the last save). */
  ~SiteRunner();

  /** @brief Live: subscriptions (images: queue `queue_size`), outputs, ~save_results, diagnostics. */
  void attach(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& node_name, int queue_size,
              bool approximate_sync);

  /** @brief One raw stereo pair (both doors): measured on its own (a bad pair is dropped and named, and the site
   *  records it as left out), then fused when its pose is known, else held for it. @return whether it was measured. */
  bool onStereo(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                const sensor_msgs::Image& right, const sensor_msgs::CameraInfo& right_info);
  /** @brief A pair matched (and its features found), not yet measured: onStereo()'s first half. */
  struct Prepared {
    std_msgs::Header header;
    std::unique_ptr<induration::FrameMeasurement> measurement;  // nullptr: the pair could not be matched
    std::vector<stereo::StereoLandmark> landmarks;
  };
  /** @brief onStereo() in two halves, for a pipeline that matches one pair while it measures and fuses the one
   *  before (process_bag): prepare() one pair at a time, complete() in the order the pairs came (the same site). */
  Prepared prepare(const sensor_msgs::Image& left, const sensor_msgs::CameraInfo& left_info,
                   const sensor_msgs::Image& right, const sensor_msgs::CameraInfo& right_info);
  bool complete(Prepared prepared);
  /** @brief The rig's pose at `stamp`: world <- the left optical frame. Fuses the pairs that waited for it. */
  void onPose(double stamp, const Eigen::Isometry3d& T_W_C);
  /** @brief Fuses what can be, leaves the pairs still waiting for a pose out (named). */
  void finish();

  /** @brief Writes the site's results (site::writeSiteResults) and the frames' induration results into `dir`;
   *  `result` (optional) receives the site measured. @return false with the reason in `message`. */
  bool save(const std::string& dir, std::string* message, const std::vector<std::string>& command_line = {},
            const std::string& source = "", const InputLedger* upstream = nullptr, site::SiteResult* result = nullptr);

  /** @brief Called with each pair's site record as it is fused or left out (process_bag prints it). */
  void onFrame(std::function<void(const site::SiteFrame&)> callback) { on_frame_ = std::move(callback); }
  /** @brief The per-pair measurement (frames measured, the last one's maps, its drops). */
  IndurationRunner& measurer() { return measurer_; }

 private:
  struct Pending {
    geometry::DenseCloud cloud;
    induration::IndurationResult own;
    double stamp = 0;
    std::string frame_id;
    std::string failed;  // why the pair could not be measured (then it is only recorded, in its turn)
    std::vector<stereo::StereoLandmark> landmarks;  // "images": its triangulated features
    std::chrono::steady_clock::time_point measured;
  };
  bool poseAt(double stamp, const std::string& frame_id, Eigen::Isometry3d* T);
  /** "images": the pose of a pair from its features and the last pair fused; false with *why when they do not match */
  bool poseFromImages(const Pending& p, Eigen::Isometry3d* T, std::string* why);
  void drainLocked(bool give_up);  // fuses the waiting pairs in order while their poses are known
  void recordLocked(const site::SiteFrame& f);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  void publishLocked(const site::SiteFrame& f);
  bool saveLocked(const std::string& dir, std::string* message, const std::vector<std::string>& command_line,
                  const std::string& source, const InputLedger* upstream, site::SiteResult* result);

  std::mutex serial_mutex_;  // onStereo(): one pair after the other, in order
  mutable std::mutex mutex_;        // the fusion and the waiting pairs (held while a pair is fused)
  std::mutex prepare_mutex_;        // prepare(): the front end's rectification, one pair at a time
  mutable std::mutex pose_mutex_;   // the pose buffer (poses come while a pair is measured)
  RunLog log_;
  SiteRunOptions run_;
  IndurationRunner measurer_;
  site::SiteFusion fusion_;
  std::deque<Pending> waiting_;
  std::unique_ptr<stereo::FrontEnd> front_end_;             // "images"
  std::vector<stereo::StereoLandmark> last_fused_landmarks_;  // "images": those of the last pair fused
  Eigen::Isometry3d last_fused_pose_ = Eigen::Isometry3d::Identity();
  std::map<double, Eigen::Isometry3d> poses_;
  std::string results_, node_name_ = "site_fusion";
  std::vector<std::string> pair_frame_ids_;
  bool unsaved_ = false;
  std::function<void(const site::SiteFrame&)> on_frame_;

  // live only
  bool attached_ = false;
  std::unique_ptr<ros_conv::StereoSync> sync_;
  std::unique_ptr<tf2_ros::Buffer> tf_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Subscriber sub_pose_;
  ros::Publisher pub_frame_, pub_points_, pub_coverage_;
  ros::ServiceServer srv_save_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::Timer diag_timer_;
  ros::WallTimer wait_timer_;
};

/**
 * @brief The live runner of the site_fusion nodelet: the induration options from `pnh` as the induration nodelet
 * reads them (~config, then every key of config/induration.yaml as a private parameter), the site options as
 * those (~site_config, then every key of config/site.yaml), ~poses, ~world_frame, ~pose_tolerance, ~pose_wait, ~preview_cells, ~results,
 * ~queue_size (2), ~approximate_sync (false), then attach().
 * @throws std::invalid_argument naming every bad parameter.
 */
std::unique_ptr<SiteRunner> startSiteRunner(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name, RunLog log);

}  // namespace ros_run
}  // namespace skin3d
