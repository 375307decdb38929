// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/site_fusion: a hand-held sweep over a body site measured as one site: each raw stereo pair measured on its
 * own, fused with the rig's pose into one height field over the body, the plaques measured once on it. All of it is
 * ros_run::SiteRunner (include/skin3d/ros/site_runner.h), which `process_bag --site` runs too; topics, services and
 * parameters: docs/nodes.md.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/common/large_buffers.h"
#include "skin3d/ros/site_runner.h"

namespace skin3d {

class SiteFusionNodelet : public nodelet::Nodelet {
  void onInit() override {
    keepLargeBuffers();  // process-wide: full-resolution buffers from the heap, not fresh mmap()s
    try {
      runner_ = ros_run::startSiteRunner(getNodeHandle(), getPrivateNodeHandle(), getName(), ros_run::rosLog("site_fusion"));
    } catch (const std::exception& e) {
      NODELET_FATAL("site_fusion: refusing to start, bad configuration: %s", e.what());
    }
  }
  std::unique_ptr<ros_run::SiteRunner> runner_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::SiteFusionNodelet, nodelet::Nodelet)
