// SPDX-License-Identifier: BSD-3-Clause
/**
 * skin3d/induration: plaque heights above the healthy-skin reference in each raw stereo pair (rectify -> dense
 * disparity -> cloud -> reference and plaques) and the results directory of the run. All of it is
 * ros_run::IndurationRunner (include/skin3d/ros/induration_runner.h), which `process_bag --induration` runs too;
 * topics, services and parameters: docs/nodes.md.
 */
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "skin3d/common/large_buffers.h"
#include "skin3d/ros/induration_runner.h"

namespace skin3d {

class IndurationNodelet : public nodelet::Nodelet {
  void onInit() override {
    keepLargeBuffers();  // process-wide: full-resolution buffers from the heap, not fresh mmap()s
    try {
      runner_ = ros_run::startIndurationRunner(getNodeHandle(), getPrivateNodeHandle(), getName(),
                                               ros_run::rosLog("induration"));
    } catch (const std::exception& e) {
      NODELET_FATAL("induration: refusing to start, bad configuration: %s", e.what());
    }
  }
  std::unique_ptr<ros_run::IndurationRunner> runner_;
};

}  // namespace skin3d

PLUGINLIB_EXPORT_CLASS(skin3d::IndurationNodelet, nodelet::Nodelet)
