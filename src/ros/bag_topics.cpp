// SPDX-License-Identifier: BSD-3-Clause
// Bag topic names under skin3d's relative names (see skin3d/ros/bag_topics.h).
#include "skin3d/ros/bag_topics.h"

#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <set>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace ros_io {

namespace {
std::string stripLeadingSlash(const std::string& t) {
  std::size_t i = 0;
  while (i < t.size() && t[i] == '/') ++i;
  return t.substr(i);
}

std::string join(const std::vector<std::string>& v, const std::string& sep) {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : sep) + s;
  return out;
}

/** The stored names of each wanted name under namespace `ns` ("" = root). */
std::map<std::string, std::vector<std::string>> under(const std::vector<std::string>& stored,
                                                      const std::vector<std::string>& wanted, const std::string& ns) {
  std::map<std::string, std::vector<std::string>> out;
  for (const auto& w : wanted) {
    const std::string target = ns.empty() ? w : ns + "/" + w;
    for (const auto& s : stored)
      if (stripLeadingSlash(s) == target) out[w].push_back(s);
  }
  return out;
}
}  // namespace

std::string normaliseNamespace(const std::string& ns) {
  std::size_t b = 0, e = ns.size();
  while (b < e && ns[b] == '/') ++b;
  while (e > b && ns[e - 1] == '/') --e;
  return ns.substr(b, e - b);
}

TopicResolution resolveTopics(const std::vector<std::string>& stored, const std::vector<std::string>& wanted,
                              const std::string& ns) {
  TopicResolution r;
  if (!ns.empty()) {
    r.ns = normaliseNamespace(ns);
    r.stored = under(stored, wanted, r.ns);
    if (r.stored.empty())
      r.error = "none of the wanted topics is under the namespace '/" + r.ns + "'";
    return r;
  }
  r.stored = under(stored, wanted, "");
  if (!r.stored.empty()) return r;
  // Not at the root: every namespace that holds a wanted topic.
  std::set<std::string> namespaces;
  for (const auto& s : stored) {
    const std::string t = stripLeadingSlash(s);
    for (const auto& w : wanted)
      if (t.size() > w.size() + 1 && t.compare(t.size() - w.size(), w.size(), w) == 0 && t[t.size() - w.size() - 1] == '/')
        namespaces.insert(t.substr(0, t.size() - w.size() - 1));
  }
  if (namespaces.empty()) {
    r.error = "none of the wanted topics (" + join(wanted, ", ") + ") is in the bag, at the root or under a namespace";
    return r;
  }
  if (namespaces.size() > 1) {
    std::vector<std::string> names;
    for (const auto& n : namespaces) names.push_back("/" + n);
    r.other_namespaces = names;
    r.error = "the wanted topics are under several namespaces (" + join(names, ", ") + "): choose one with --ns";
    return r;
  }
  r.ns = *namespaces.begin();
  r.ns_guessed = true;
  r.stored = under(stored, wanted, r.ns);
  return r;
}

std::string describeBagError(const std::string& path, const std::string& what) {
  std::error_code ec;
  const std::filesystem::path p(path);
  if (!std::filesystem::exists(p, ec)) return "no such file";
  if (std::filesystem::is_directory(p, ec)) return "it is a directory";
  const auto size = std::filesystem::file_size(p, ec);
  if (!ec && size == 0) return "the file is empty (0 bytes)";
  std::string lower = what;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  std::string out = what;
  const bool truncated = lower.find("unindexed") != std::string::npos || lower.find("index") != std::string::npos ||
                         lower.find("reading") != std::string::npos || lower.find("read ") != std::string::npos ||
                         lower.find("chunk") != std::string::npos || lower.find("truncat") != std::string::npos ||
                         lower.find("eof") != std::string::npos || lower.find("end of file") != std::string::npos;
  if (lower.find("version") != std::string::npos && lower.find("unsupported") == std::string::npos &&
      lower.find("index") == std::string::npos)
    out += " (not a ROS 1 bag?)";
  if (truncated && lower.find("version") == std::string::npos)  // a version-line error: not a bag at all
    out += ". A recording that was cut off (killed recorder, full disk, partial copy) has no index: `rosbag reindex " +
           path + "` rebuilds it (keeping the original as " + p.stem().string() + ".orig.bag), then run again";
  return out;
}

void openForReading(rosbag::Bag* bag, const std::string& path) {
  try {
    bag->open(path, rosbag::bagmode::Read);
  } catch (const std::exception& e) {
    throw std::invalid_argument("cannot open bag '" + path + "': " + describeBagError(path, e.what()));
  }
}

std::vector<BagTopic> listTopics(const rosbag::Bag& bag) {
  rosbag::View view(bag);
  std::map<std::string, BagTopic> by_name;
  for (const rosbag::ConnectionInfo* c : view.getConnections()) {
    BagTopic& t = by_name[c->topic];
    t.name = c->topic;
    t.datatype = c->datatype;
  }
  for (auto& kv : by_name) kv.second.messages = rosbag::View(bag, rosbag::TopicQuery(kv.first)).size();
  std::vector<BagTopic> out;
  for (auto& kv : by_name) out.push_back(kv.second);
  return out;
}

std::string describeTopics(const std::vector<BagTopic>& topics) {
  if (topics.empty()) return "  (the bag has no topics)\n";
  std::ostringstream s;
  for (const auto& t : topics) s << "  " << t.name << "  " << t.datatype << "  " << t.messages << " msgs\n";
  return s.str();
}

BagTopics::BagTopics(const rosbag::Bag& bag, const std::string& bag_name, const std::vector<std::string>& wanted,
                     const std::string& ns)
    : all_(listTopics(bag)) {
  std::vector<std::string> names;
  for (const auto& t : all_) names.push_back(t.name);
  resolution_ = resolveTopics(names, wanted, ns);
  if (!resolution_.error.empty())
    throw std::invalid_argument("'" + bag_name + "': " + resolution_.error + ". Its topics:\n" + describeTopics(all_) +
                                "(skin3d reads " + join(wanted, ", ") +
                                "; absolute names and a namespace are accepted: --ns NAMESPACE)");
  for (const auto& kv : resolution_.stored)
    for (const auto& s : kv.second) relative_of_[s] = kv.first;
}

std::vector<std::string> BagTopics::stored() const {
  std::vector<std::string> out;
  for (const auto& kv : resolution_.stored) out.insert(out.end(), kv.second.begin(), kv.second.end());
  return out;
}

std::vector<std::string> BagTopics::stored(const std::string& relative) const {
  const auto it = resolution_.stored.find(relative);
  return it == resolution_.stored.end() ? std::vector<std::string>{} : it->second;
}

std::string BagTopics::relative(const std::string& stored) const {
  const auto it = relative_of_.find(stored);
  return it == relative_of_.end() ? std::string() : it->second;
}

std::uint64_t BagTopics::count(const std::string& relative) const {
  std::uint64_t n = 0;
  for (const auto& s : stored(relative))
    for (const auto& t : all_)
      if (t.name == s) n += t.messages;
  return n;
}

std::string BagTopics::summary() const {
  std::ostringstream s;
  s << "namespace " << nsLabel() << (resolution_.ns_guessed ? " (found)" : "") << ":";
  for (const auto& kv : resolution_.stored) s << ' ' << kv.first << " (" << count(kv.first) << ")";
  return s.str();
}

}  // namespace ros_io
}  // namespace skin3d
