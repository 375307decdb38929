// SPDX-License-Identifier: BSD-3-Clause
// Bag topic names: skin3d's relative names, absolute names (rosbag record -a), a namespace (found
// or given), several namespaces (an error naming them), and nothing matching (an error listing the bag's
// topics); on real bags written here (no ROS master needed).
#include <gtest/gtest.h>
#include <iterator>
#include <fstream>
#include <rosbag/bag.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/String.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/ros/bag_topics.h"

using skin3d::ros_io::BagTopics;
using skin3d::ros_io::resolveTopics;

namespace {

const std::vector<std::string> kWanted = {"stereo/left/image_raw", "stereo/right/image_raw", "stereo/landmarks"};

std::string writeBag(const std::string& name, const std::vector<std::string>& topics) {
  const std::string path = ::testing::TempDir() + name;
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  sensor_msgs::Image img;
  img.header.stamp = ros::Time(1700000000, 100000000);
  for (const auto& t : topics)
    for (int k = 0; k < 3; ++k) bag.write(t, img.header.stamp + ros::Duration(0.1 * k), img);
  std_msgs::String s;
  bag.write("/rosout_like", ros::Time(1700000000, 0), s);
  bag.close();
  return path;
}

}  // namespace

TEST(ResolveTopics, RelativeAbsoluteAndNamespaced) {
  auto r = resolveTopics({"stereo/left/image_raw", "/stereo/right/image_raw", "/tf"}, kWanted, "");
  EXPECT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(r.ns, "");
  EXPECT_EQ(r.stored.at("stereo/left/image_raw"), std::vector<std::string>{"stereo/left/image_raw"});
  EXPECT_EQ(r.stored.at("stereo/right/image_raw"), std::vector<std::string>{"/stereo/right/image_raw"});
  EXPECT_EQ(r.stored.count("stereo/landmarks"), 0u);

  r = resolveTopics({"/rig1/stereo/landmarks", "/rig1/slam/odometry", "/rosout"}, kWanted, "");
  EXPECT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(r.ns, "rig1");
  EXPECT_TRUE(r.ns_guessed);
  EXPECT_EQ(r.stored.at("stereo/landmarks"), std::vector<std::string>{"/rig1/stereo/landmarks"});

  r = resolveTopics({"/a/b/stereo/landmarks"}, kWanted, "/a/b/");  // nested, given with slashes
  EXPECT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(r.ns, "a/b");
  EXPECT_FALSE(r.ns_guessed);
}

TEST(ResolveTopics, AmbiguousOrMissingIsAnError) {
  auto r = resolveTopics({"/rig1/stereo/landmarks", "/rig2/stereo/landmarks"}, kWanted, "");
  EXPECT_NE(r.error.find("/rig1"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("/rig2"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("--ns"), std::string::npos) << r.error;
  r = resolveTopics({"/rig1/stereo/landmarks", "/rig2/stereo/landmarks"}, kWanted, "rig2");
  EXPECT_TRUE(r.error.empty());
  EXPECT_EQ(r.stored.at("stereo/landmarks"), std::vector<std::string>{"/rig2/stereo/landmarks"});
  // the root is chosen when it holds the topics, even if a namespace does too; '/' asks for the root only
  r = resolveTopics({"/stereo/landmarks", "/rig1/stereo/landmarks"}, kWanted, "");
  EXPECT_EQ(r.ns, "");
  r = resolveTopics({"/rig1/stereo/landmarks"}, kWanted, "/");
  EXPECT_FALSE(r.error.empty());
  // a name that only ends like a wanted one is not a namespace match
  r = resolveTopics({"/mystereo/landmarks"}, kWanted, "");
  EXPECT_FALSE(r.error.empty());
}

TEST(BagTopics, ReadsRecordedBags) {
  const std::string path = writeBag("skin3d_abs.bag", {"/stereo/left/image_raw", "/stereo/right/image_raw"});
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  const BagTopics t(bag, path, kWanted);
  EXPECT_TRUE(t.has("stereo/left/image_raw"));
  EXPECT_FALSE(t.has("stereo/landmarks"));
  EXPECT_EQ(t.count("stereo/left/image_raw"), 3u);
  EXPECT_EQ(t.relative("/stereo/right/image_raw"), "stereo/right/image_raw");
  EXPECT_EQ(t.relative("/rosout_like"), "");
  EXPECT_EQ(t.stored().size(), 2u);
  EXPECT_NE(t.summary().find("namespace /:"), std::string::npos) << t.summary();
}

TEST(BagTopics, NothingMatchingListsTheTopics) {
  const std::string path = writeBag("skin3d_other.bag", {"/camera/left/image", "/camera/right/image"});
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  try {
    BagTopics t(bag, path, kWanted);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("/camera/left/image  sensor_msgs/Image  3 msgs"), std::string::npos) << m;
    EXPECT_NE(m.find("/rosout_like  std_msgs/String  1 msgs"), std::string::npos) << m;
    EXPECT_NE(m.find("--ns"), std::string::npos) << m;
  }
  const std::string ns = writeBag("skin3d_ns.bag", {"/rig1/stereo/left/image_raw"});
  rosbag::Bag nbag(ns, rosbag::bagmode::Read);
  EXPECT_THROW(BagTopics(nbag, ns, kWanted, "rig2"), std::invalid_argument);
  const BagTopics found(nbag, ns, kWanted);
  EXPECT_EQ(found.nsLabel(), "/rig1");
  EXPECT_EQ(found.relative("/rig1/stereo/left/image_raw"), "stereo/left/image_raw");
}

TEST(OpenForReading, NamesTheBagItCannotOpen) {
  rosbag::Bag bag;
  const std::string missing = ::testing::TempDir() + "skin3d_no_such.bag";
  try {
    skin3d::ros_io::openForReading(&bag, missing);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open bag '" + missing + "'"), std::string::npos) << e.what();
  }
  const std::string path = writeBag("skin3d_open.bag", {"/stereo/left/image_raw"});
  rosbag::Bag good;
  skin3d::ros_io::openForReading(&good, path);
  EXPECT_EQ(BagTopics(good, path, kWanted).count("stereo/left/image_raw"), 3u);
}

TEST(OpenForReading, ATruncatedBagGetsTheReindexAdviceAndAnEmptyFileIsSaidToBeEmpty) {
  const std::string path = writeBag("skin3d_truncated_src.bag", {"/stereo/left/image_raw"});
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string cut = ::testing::TempDir() + "skin3d_truncated.bag";
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() * 6 / 10);
  auto messageOf = [](const std::string& p) {
    rosbag::Bag bag;
    try {
      skin3d::ros_io::openForReading(&bag, p);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string m = messageOf(cut);
  EXPECT_NE(m.find("`rosbag reindex " + cut + "`"), std::string::npos) << m;
  const std::string empty = ::testing::TempDir() + "skin3d_empty.bag";
  std::ofstream(empty, std::ios::binary).close();
  EXPECT_NE(messageOf(empty).find("the file is empty"), std::string::npos) << messageOf(empty);
  const std::string text = ::testing::TempDir() + "skin3d_text.bag";
  std::ofstream(text) << "not a bag at all\n";
  EXPECT_EQ(messageOf(text).find("reindex"), std::string::npos) << messageOf(text);
}
