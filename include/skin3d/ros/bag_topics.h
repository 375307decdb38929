// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file
 * @brief The topics of a recorded bag under the relative names skin3d uses (docs/design.md "Topics").
 *
 * skin3d's own datasets store relative names (`stereo/left/image_raw`); bags recorded by others store absolute
 * ones (`rosbag record -a` writes `/stereo/left/image_raw`), possibly under a namespace
 * (`/rig1/stereo/left/image_raw`). Every tool that reads a bag resolves the names it wants through this, so that
 * all three read the same, and says which topics the bag has when none of them match.
 *
 * Namespace rule: an explicit namespace (`--ns rig1`, `--ns /rig1`; `--ns /` = the root only) is used as given.
 * Without one, the root is used when it holds any wanted topic; otherwise the one namespace that holds wanted
 * topics; several such namespaces are an error that names them (choose with --ns).
 */
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace rosbag {
class Bag;
}

namespace skin3d {
namespace ros_io {

/** @brief One topic of a bag, as stored. */
struct BagTopic {
  std::string name;      //!< as stored ("/rig1/stereo/left/image_raw")
  std::string datatype;  //!< e.g. "sensor_msgs/Image"
  std::uint64_t messages = 0;
};

/** @brief How the wanted relative names map onto a bag's stored names (resolveTopics). */
struct TopicResolution {
  std::string ns;  //!< the namespace used, without slashes ("" = the root)
  bool ns_guessed = false;  //!< true when the namespace was found, not given
  /** relative name -> stored names (a bag may hold both "x" and "/x"); only the wanted names that were found */
  std::map<std::string, std::vector<std::string>> stored;
  std::vector<std::string> other_namespaces;  //!< namespaces that also hold wanted topics (auto: empty)
  std::string error;  //!< non-empty when nothing could be resolved (names the namespaces or says none match)
};

/** @brief `ns` without leading/trailing slashes ("/" and "" -> ""). */
std::string normaliseNamespace(const std::string& ns);

/**
 * @brief Resolves `wanted` relative names (e.g. "stereo/left/image_raw") against the stored topic names of a bag.
 * @param ns "" = automatic (see the file comment); "/" = the root only; otherwise that namespace.
 */
TopicResolution resolveTopics(const std::vector<std::string>& stored, const std::vector<std::string>& wanted,
                              const std::string& ns);

/**
 * @brief Opens a bag for reading; throws std::invalid_argument "cannot open bag 'PATH': why" when it cannot
 * (missing, a directory, empty, not a bag, unindexed; why = describeBagError).
 */
void openForReading(rosbag::Bag* bag, const std::string& path);

/**
 * @brief rosbag's error `what` about the bag `path` in words a user can act on: "no such file", "the file is empty
 * (0 bytes)", or `what` followed, when it is about a missing index or a read past the data (a truncated or
 * unindexed bag), by the advice to run `rosbag reindex PATH`. Use it also for a rosbag::BagException thrown while
 * iterating a view (a bag cut off inside a chunk): the runner then writes the results of the frames read so far.
 */
std::string describeBagError(const std::string& path, const std::string& what);

/** @brief Every topic of an open bag (name, type, message count), sorted by name. */
std::vector<BagTopic> listTopics(const rosbag::Bag& bag);

/** @brief A listing for error messages: one indented line per topic ("  /a/b  sensor_msgs/Image  10 msgs"). */
std::string describeTopics(const std::vector<BagTopic>& topics);

/**
 * @brief The wanted topics of one open bag under their relative names.
 *
 * Throws std::invalid_argument naming the bag's topics when none of `wanted` is found (or the namespace is
 * ambiguous). Use stored() for a rosbag::TopicQuery and relative() on each MessageInstance's getTopic().
 */
class BagTopics {
 public:
  BagTopics(const rosbag::Bag& bag, const std::string& bag_name, const std::vector<std::string>& wanted,
            const std::string& ns = "");

  /** @brief The stored names of every wanted topic found (for rosbag::TopicQuery). */
  std::vector<std::string> stored() const;
  /** @brief The stored names of one relative name (empty when the bag does not have it). */
  std::vector<std::string> stored(const std::string& relative) const;
  /** @brief The relative name of a stored topic ("" when it is not one of the wanted ones). */
  std::string relative(const std::string& stored) const;
  bool has(const std::string& relative) const { return resolution_.stored.count(relative) > 0; }
  /** @brief Messages on one relative name. */
  std::uint64_t count(const std::string& relative) const;
  /** @brief "/" for the root, else "/ns". */
  std::string nsLabel() const { return "/" + resolution_.ns; }
  const TopicResolution& resolution() const { return resolution_; }
  const std::vector<BagTopic>& all() const { return all_; }
  /** @brief One line for logs: the namespace and which wanted topics were found, and how many messages. */
  std::string summary() const;

 private:
  TopicResolution resolution_;
  std::vector<BagTopic> all_;
  std::map<std::string, std::string> relative_of_;
};

}  // namespace ros_io
}  // namespace skin3d
