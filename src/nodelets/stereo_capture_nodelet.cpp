// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/stereo_capture: the rig's two cameras (or one side-by-side device, a video file or an image
 * sequence per camera) through OpenCV, one stamp for both images, camera_info from calibration files.
 *
 * Publishes:  stereo/{left,right}/image_raw (bgr8 or mono8), stereo/{left,right}/camera_info
 *             (services stereo/{left,right}/set_camera_info from camera_info_manager).
 * Parameters: ~left_source, ~right_source (string): a device index ("0"), a device path (/dev/video0),
 *             a video file or an image-sequence pattern (/data/left_%03d.png);
 *             ~side_by_side_source (string, ""): one device delivering both views side by side (left half =
 *             left camera) instead of the two sources;
 *             ~width, ~height (int, 0 = device default), ~fps (double, 10), ~exposure (double, -1 = auto);
 *             ~loop (bool, false): restart files at their end;
 *             ~left_camera_info_url, ~right_camera_info_url (string, ""): camera_info_manager URLs
 *             (file:///path/left.yaml as written by calibrate_stereo);
 *             ~left_frame_id (stereo_left_optical_frame), ~right_frame_id (stereo_right_optical_frame),
 *             ~left_camera_name (left), ~right_camera_name (right).
 * A source that cannot be opened or read logs a throttled error and the node keeps retrying.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/ros/capture_node.h"

namespace skin3d {

class StereoCaptureNodelet : public nodelet::Nodelet {
  void onInit() override { node_ = ros_run::startStereoCapture(getNodeHandle(), getPrivateNodeHandle()); }
  std::shared_ptr<void> node_;  // ros_run::StereoCaptureNode
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::StereoCaptureNodelet, nodelet::Nodelet)
