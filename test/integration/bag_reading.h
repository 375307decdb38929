// SPDX-License-Identifier: BSD-3-Clause
// Test helper: every message of one topic of a bag, in order.
#pragma once

#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <string>
#include <vector>

namespace skin3d {
namespace test {

template <class M>
std::vector<M> readTopic(const std::string& bag_path, const std::string& topic) {
  rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
  rosbag::View view(bag, rosbag::TopicQuery(topic));
  std::vector<M> out;
  for (const auto& m : view) out.push_back(*m.instantiate<M>());
  return out;
}

}  // namespace test
}  // namespace skin3d
