// SPDX-License-Identifier: BSD-3-Clause
// SLAM parameters by name (see slam_config.h).
#include "skin3d/slam/slam_config.h"

#include "../common/option_table.h"

#include <functional>
#include <map>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace slam {

namespace {
using Table = common::OptionTable<SlamOptions>;
using Field = Table::Field;
const common::OptionText kText("slam");

#define SKIN3D_DOUBLE(key, member) \
  {key, {[](const SlamOptions& o) { return common::exactNum(o.member); }, [](SlamOptions* o, const std::string& v) { o->member = kText.toDouble(key, v); }}}
#define SKIN3D_INT(key, member) \
  {key, {[](const SlamOptions& o) { return std::to_string(o.member); }, [](SlamOptions* o, const std::string& v) { o->member = kText.toInt(key, v); }}}
#define SKIN3D_BOOL(key, member)                                                    \
  {key, {[](const SlamOptions& o) { return std::string(o.member ? "true" : "false"); }, \
         [](SlamOptions* o, const std::string& v) { o->member = kText.toBool(key, v); }}}

template <class E>
Field enumField(const char* key, E SlamOptions::*, std::vector<std::pair<std::string, E>> names,
                std::function<E&(SlamOptions*)> ref, std::function<E(const SlamOptions&)> val) {
  return {[names, val](const SlamOptions& o) {
            for (const auto& n : names)
              if (n.second == val(o)) return n.first;
            return std::string("?");
          },
          [names, ref, key](SlamOptions* o, const std::string& v) {
            std::string known;
            for (const auto& n : names) {
              if (n.first == v) {
                ref(o) = n.second;
                return;
              }
              known += (known.empty() ? "" : ", ") + n.first;
            }
            kText.bad(key, "'" + v + "' is not one of " + known);
          }};
}

const Table& table() {
  static const Table t(kText, {
      SKIN3D_BOOL("use_gyro", use_gyro),
      SKIN3D_DOUBLE("gyro_noise", gyro_noise),
      SKIN3D_INT("max_updates_per_frame", max_updates_per_frame),
      SKIN3D_INT("max_new_per_frame", max_new_per_frame),
      SKIN3D_INT("min_tracked_for_no_new", min_tracked_for_no_new),
      SKIN3D_DOUBLE("max_depth", max_depth),
      SKIN3D_INT("consensus_iterations", consensus_iterations),
      SKIN3D_DOUBLE("consensus_gate", consensus_gate),
      SKIN3D_DOUBLE("measurement_white_fraction", measurement_white_fraction),
      {"smoother", {[](const SlamOptions& o) { return o.smoother; },
                    [](SlamOptions* o, const std::string& v) {
                      // YAML 1.1 (rosparam) reads an unquoted off as the boolean false
                      const std::string w = v == "false" ? "off" : v;
                      if (w != "off" && w != "batch") kText.bad("smoother", "'" + v + "' is not one of off, batch");
                      o->smoother = w;
                    }}},
      SKIN3D_DOUBLE("smoother_huber", smoother_huber),
      SKIN3D_INT("smoother_iterations", smoother_iterations),
      SKIN3D_DOUBLE("smoother_loop_radius", smoother_loop_radius),
      SKIN3D_DOUBLE("gamma", filter.gamma),
      SKIN3D_DOUBLE("lambda", filter.lambda),
      SKIN3D_DOUBLE("velocity_noise", filter.velocity_noise),
      SKIN3D_DOUBLE("angular_rate_noise", filter.angular_rate_noise),
      SKIN3D_BOOL("estimate_gyro_bias", filter.estimate_gyro_bias),
      SKIN3D_DOUBLE("gyro_bias_walk", filter.gyro_bias_walk),
      SKIN3D_DOUBLE("initial_velocity_std", filter.initial_velocity_std),
      SKIN3D_DOUBLE("initial_angular_rate_std", filter.initial_angular_rate_std),
      SKIN3D_DOUBLE("initial_gyro_bias_std", filter.initial_gyro_bias_std),
      SKIN3D_DOUBLE("initial_gyro_bias_x", filter.initial_gyro_bias.x()),
      SKIN3D_DOUBLE("initial_gyro_bias_y", filter.initial_gyro_bias.y()),
      SKIN3D_DOUBLE("initial_gyro_bias_z", filter.initial_gyro_bias.z()),
      SKIN3D_DOUBLE("landmark_walk_x", filter.landmark_walk.x()),
      SKIN3D_DOUBLE("landmark_walk_y", filter.landmark_walk.y()),
      SKIN3D_DOUBLE("landmark_walk_z", filter.landmark_walk.z()),
      SKIN3D_DOUBLE("landmark_walk_reference_distance", filter.landmark_walk_reference_distance),
      SKIN3D_INT("threads", filter.threads),
      SKIN3D_BOOL("blas_downdate", filter.blas_downdate),
      SKIN3D_INT("pool_initial_capacity", pool.initial_capacity),
      {"pool_growth", enumField<PoolGrowth>("pool_growth", nullptr,
                                            {{"add_100", PoolGrowth::ADD_100}, {"grow_50_percent", PoolGrowth::GROW_50_PERCENT}},
                                            [](SlamOptions* o) -> PoolGrowth& { return o->pool.growth; },
                                            [](const SlamOptions& o) { return o.pool.growth; })},
      SKIN3D_INT("pool_max_capacity", pool.max_capacity),
      {"pool_deletion", enumField<DeletionPolicy>("pool_deletion", nullptr,
                                                  {{"age", DeletionPolicy::BY_AGE}, {"run_length", DeletionPolicy::BY_RUN_LENGTH}},
                                                  [](SlamOptions* o) -> DeletionPolicy& { return o->pool.deletion; },
                                                  [](const SlamOptions& o) { return o.pool.deletion; })},
      SKIN3D_BOOL("prune_stale", pool.prune_stale),
      SKIN3D_INT("max_unseen_frames", pool.max_unseen_frames),
      SKIN3D_INT("min_observations", pool.min_observations),
      SKIN3D_DOUBLE("max_descriptor_distance", pool.max_descriptor_distance),
      SKIN3D_DOUBLE("ratio", pool.ratio),
      SKIN3D_DOUBLE("mahalanobis_gate", pool.mahalanobis_gate),
      {"fork_policy", enumField<ForkPolicy>("fork_policy", nullptr,
                                            {{"longest_run", ForkPolicy::LONGEST_RUN}, {"first_seen", ForkPolicy::FIRST_SEEN}},
                                            [](SlamOptions* o) -> ForkPolicy& { return o->pool.fork; },
                                            [](const SlamOptions& o) { return o.pool.fork; })},
  });
  return t;
}

}  // namespace

const std::vector<std::string>& slamOptionKeys() { return table().keys(); }

std::string getSlamOption(const SlamOptions& options, const std::string& key) { return table().get(options, key); }

void setSlamOption(SlamOptions* options, const std::string& key, const std::string& value) {
  table().set(options, key, value);
}

void applySlamOptions(SlamOptions* o, const std::string& yaml_path) { table().applyYaml(o, yaml_path); }

std::vector<std::pair<std::string, std::string>> imageInputOptions(const std::string& features) {
  std::vector<std::pair<std::string, std::string>> kv = {{"measurement_white_fraction", "0.1"},
                                                         {"landmark_walk_x", "3.5e-5"},
                                                         {"landmark_walk_y", "6.3e-5"},
                                                         {"landmark_walk_z", "1.8e-4"}};
  if (features != "kaze") kv.emplace_back("max_descriptor_distance", "5.5");
  return kv;
}

SlamOptions loadSlamOptions(const std::string& yaml_path) {
  SlamOptions o;
  applySlamOptions(&o, yaml_path);
  try {
    o.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument("'" + yaml_path + "': " + e.what());
  }
  return o;
}

}  // namespace slam
}  // namespace skin3d
