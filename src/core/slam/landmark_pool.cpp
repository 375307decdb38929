// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/slam/landmark_pool.h"

#include "../common/text.h"

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace skin3d {
namespace slam {

namespace {

using common::num;

[[noreturn]] void badOption(const std::string& field, double value, const std::string& rule) {
  throw std::invalid_argument("landmark pool options: " + field + " = " + num(value) + ": " + rule);
}

/** Squared L2 distance of two n-float arrays; stops early (returning a value > bound) once the partial sum
 *  exceeds `bound`. Blocks of 16 through fixed-size Eigen maps are SIMD-vectorised; for random 64-float
 *  descriptors the first block usually exceeds the bound already. */
inline float squaredDistanceBounded(const float* a, const float* b, int n, float bound) {
  using Block = Eigen::Map<const Eigen::Matrix<float, 16, 1>>;
  float sum = 0.0f;
  int i = 0;
  for (; i + 16 <= n; i += 16) {
    sum += (Block(a + i) - Block(b + i)).squaredNorm();
    if (sum > bound) return sum;
  }
  for (; i < n; ++i) {
    const float d = a[i] - b[i];
    sum += d * d;
  }
  return sum;
}

struct Candidate {
  int slot;
  float dist_sq;
  double maha_sq;
};

}  // namespace

void LandmarkPoolOptions::validate() const {
  if (initial_capacity < 1) badOption("initial_capacity", initial_capacity, "must be >= 1");
  if (growth != PoolGrowth::ADD_100 && growth != PoolGrowth::GROW_50_PERCENT)
    badOption("growth", static_cast<int>(growth), "unknown growth policy (ADD_100, GROW_50_PERCENT)");
  if (max_capacity < initial_capacity)
    badOption("max_capacity", max_capacity, "must be >= initial_capacity = " + num(initial_capacity));
  if (deletion != DeletionPolicy::BY_AGE && deletion != DeletionPolicy::BY_RUN_LENGTH)
    badOption("deletion", static_cast<int>(deletion), "unknown deletion policy (BY_AGE, BY_RUN_LENGTH)");
  if (max_unseen_frames < 0) badOption("max_unseen_frames", max_unseen_frames, "must be >= 0");
  if (min_observations < 1) badOption("min_observations", min_observations, "must be >= 1");
  if (!(max_descriptor_distance > 0))
    badOption("max_descriptor_distance", max_descriptor_distance, "must be > 0 (L2; binary: sqrt(Hamming))");
  if (!(ratio == 0.0 || (ratio > 0.0 && ratio <= 1.0)))
    badOption("ratio", ratio, "must be in (0, 1], or 0 to switch the ratio test off");
  if (!(mahalanobis_gate > 0))
    badOption("mahalanobis_gate", mahalanobis_gate, "must be > 0 (squared Mahalanobis distance, chi^2 3 dof)");
  if (fork != ForkPolicy::LONGEST_RUN && fork != ForkPolicy::FIRST_SEEN)
    badOption("fork", static_cast<int>(fork), "unknown fork policy (LONGEST_RUN, FIRST_SEEN)");
  if (descriptor_update != DescriptorUpdate::KEEP_FIRST && descriptor_update != DescriptorUpdate::RUNNING_AVERAGE)
    badOption("descriptor_update", static_cast<int>(descriptor_update),
              "unknown descriptor update (KEEP_FIRST, RUNNING_AVERAGE)");
}

LandmarkPool::LandmarkPool(int rig_dim, const LandmarkPoolOptions& options) : options_(options), rig_dim_(rig_dim) {
  options_.validate();
  if (rig_dim < 0) throw std::invalid_argument("landmark pool: rig_dim = " + num(rig_dim) + ": must be >= 0");
  records_.resize(static_cast<size_t>(options_.initial_capacity));
  for (int s = 0; s < capacity(); ++s) {
    records_[s].slot = s;
    records_[s].state_index = stateIndex(s);
  }
}

// ---------------------------------------------------------------- checks

void LandmarkPool::requireFrame(const char* who) const {
  if (frame_ == 0) throw std::logic_error(std::string("landmark pool: ") + who + " before the first beginFrame()");
}

void LandmarkPool::checkSlot(int slot, const char* who) const {
  if (slot < 0 || slot >= capacity())
    throw std::out_of_range(std::string("landmark pool: ") + who + ": slot " + std::to_string(slot) +
                            " outside [0, " + std::to_string(capacity()) + ")");
}

void LandmarkPool::checkDescriptor(const std::vector<float>& d, const char* who) const {
  if (d.empty()) throw std::invalid_argument(std::string("landmark pool: ") + who + ": descriptor is empty");
  if (descriptor_size_ > 0 && static_cast<int>(d.size()) != descriptor_size_)
    throw std::invalid_argument(std::string("landmark pool: ") + who + ": descriptor has " +
                                std::to_string(d.size()) + " elements, the pool's have " +
                                std::to_string(descriptor_size_));
  for (float v : d)
    if (!std::isfinite(v))
      throw std::invalid_argument(std::string("landmark pool: ") + who + ": descriptor has a NaN or Inf element");
}

bool LandmarkPool::inUse(int slot) const {
  checkSlot(slot, "inUse");
  return records_[slot].in_use;
}

const LandmarkRecord& LandmarkPool::record(int slot) const {
  checkSlot(slot, "record");
  return records_[slot];
}

std::vector<int> LandmarkPool::slotsInUse() const {
  std::vector<int> out;
  out.reserve(static_cast<size_t>(used_));
  for (int s = 0; s < capacity(); ++s)
    if (records_[s].in_use) out.push_back(s);
  return out;
}

int LandmarkPool::slotOf(std::int64_t id) const {
  for (int s = 0; s < capacity(); ++s)
    if (records_[s].in_use && records_[s].id == id) return s;
  return -1;
}

// ---------------------------------------------------------------- frames

PoolChanges LandmarkPool::beginFrame(double time) {
  if (!std::isfinite(time) || time < time_)
    throw std::invalid_argument("landmark pool: beginFrame: time = " + num(time) +
                                ": must be finite and >= the previous frame's time " + num(time_));
  PoolChanges changes;
  const std::int64_t closed = frame_;  // the frame that ends now (0: none)
  ++frame_;
  time_ = time;
  for (int s = 0; s < capacity(); ++s) {
    LandmarkRecord& r = records_[s];
    if (!r.in_use) continue;
    if (r.last_seen_frame != closed) r.run_length = 0;
    const std::int64_t unseen = closed - r.last_seen_frame;  // completed frames without an observation
    if (options_.prune_stale && unseen > options_.max_unseen_frames &&
        r.times_observed < options_.min_observations) {
      freeSlot(s);
      changes.freed_slots.push_back(s);
    }
  }
  return changes;
}

// ---------------------------------------------------------------- association

AssociationResult LandmarkPool::associate(const std::vector<std::vector<float>>& measurement_descriptors,
                                          const MahalanobisGate& gate) const {
  AssociationResult result;
  const int n_meas = static_cast<int>(measurement_descriptors.size());
  const int D = descriptor_size_;
  for (int m = 0; m < n_meas; ++m) {
    const std::vector<float>& d = measurement_descriptors[m];
    if (D > 0 && static_cast<int>(d.size()) != D)
      throw std::invalid_argument("landmark pool: associate: measurement " + std::to_string(m) + " descriptor has " +
                                  std::to_string(d.size()) + " elements, the pool's have " + std::to_string(D));
    for (float v : d)
      if (!std::isfinite(v))
        throw std::invalid_argument("landmark pool: associate: measurement " + std::to_string(m) +
                                    " descriptor has a NaN or Inf element");
  }
  if (used_ > 0 && n_meas > 0 && !gate) throw std::invalid_argument("landmark pool: associate: empty gate function");

  std::vector<int> active;
  active.reserve(static_cast<size_t>(used_));
  for (int s = 0; s < capacity(); ++s)
    if (records_[s].in_use) active.push_back(s);

  const double max_d = options_.max_descriptor_distance;
  const bool ratio_on = options_.ratio > 0.0;
  const float max_sq = static_cast<float>(max_d * max_d);
  // With the ratio test, non-candidate distances matter up to max_d / ratio (beyond, d1 < ratio d2 holds).
  const float bound_sq = ratio_on ? static_cast<float>((max_d / options_.ratio) * (max_d / options_.ratio)) : max_sq;
  const double gate_sq = options_.mahalanobis_gate;

  // A is preferred over B as the survivor of a fork.
  auto forkPrefers = [this](int a, int b) {
    const LandmarkRecord& ra = records_[a];
    const LandmarkRecord& rb = records_[b];
    if (options_.fork == ForkPolicy::LONGEST_RUN && ra.max_run_length != rb.max_run_length)
      return ra.max_run_length > rb.max_run_length;
    if (ra.birth_time != rb.birth_time) return ra.birth_time < rb.birth_time;
    return ra.id < rb.id;
  };

  std::vector<Candidate> proposal(static_cast<size_t>(n_meas), Candidate{-1, 0.0f, 0.0});
  std::vector<Association> fork_losers;
  std::vector<Candidate> cands;
  cands.reserve(64);
  const float* base = descriptors_.data();

  for (int m = 0; m < n_meas && !active.empty(); ++m) {
    const float* q = measurement_descriptors[m].data();
    cands.clear();
    float other_min_sq = std::numeric_limits<float>::infinity();  // best non-candidate (ratio test)
    for (int s : active) {
      const float dsq = squaredDistanceBounded(q, base + static_cast<size_t>(s) * D, D, bound_sq);
      if (dsq > bound_sq) continue;
      if (dsq <= max_sq) {
        const double g = gate(s, m);
        ++result.gate_calls;
        if (g <= gate_sq) {
          cands.push_back(Candidate{s, dsq, g});
          continue;
        }
      }
      if (dsq < other_min_sq) other_min_sq = dsq;
    }
    if (cands.empty()) continue;
    if (ratio_on) {
      float best_sq = cands[0].dist_sq;
      for (const Candidate& c : cands) best_sq = std::min(best_sq, c.dist_sq);
      if (!(std::sqrt(static_cast<double>(best_sq)) < options_.ratio * std::sqrt(static_cast<double>(other_min_sq)))) {
        result.ratio_rejected.push_back(m);
        continue;
      }
    }
    size_t win = 0;
    for (size_t i = 1; i < cands.size(); ++i)
      if (forkPrefers(cands[i].slot, cands[win].slot)) win = i;
    proposal[m] = cands[win];
    for (size_t i = 0; i < cands.size(); ++i)
      if (i != win)
        fork_losers.push_back(Association{m, cands[i].slot, std::sqrt(static_cast<double>(cands[i].dist_sq)),
                                          cands[i].maha_sq});
  }

  // One landmark, several measurements: the smallest Mahalanobis distance wins (ties: descriptor distance,
  // then the lower measurement index).
  std::vector<int> owner(static_cast<size_t>(capacity()), -1);
  for (int m = 0; m < n_meas; ++m) {
    const Candidate& p = proposal[m];
    if (p.slot < 0) continue;
    int& o = owner[p.slot];
    if (o < 0) {
      o = m;
      continue;
    }
    const Candidate& q = proposal[o];
    if (p.maha_sq < q.maha_sq || (p.maha_sq == q.maha_sq && p.dist_sq < q.dist_sq)) o = m;
  }

  result.matches.reserve(static_cast<size_t>(n_meas));
  std::vector<char> accepted(static_cast<size_t>(n_meas), 0);
  for (int m = 0; m < n_meas; ++m) {
    const Candidate& p = proposal[m];
    if (p.slot >= 0 && owner[p.slot] == m) {
      accepted[m] = 1;
      result.matches.push_back(Association{m, p.slot, std::sqrt(static_cast<double>(p.dist_sq)), p.maha_sq});
    } else {
      if (p.slot >= 0) result.contested.push_back(m);
      result.unassociated.push_back(m);
    }
  }
  for (const Association& f : fork_losers) {
    if (!accepted[f.measurement] || owner[f.slot] >= 0) continue;  // lost measurement, or slot associated
    result.forks.push_back(f);
    result.duplicate_slots.push_back(f.slot);
  }
  std::sort(result.duplicate_slots.begin(), result.duplicate_slots.end());
  result.duplicate_slots.erase(std::unique(result.duplicate_slots.begin(), result.duplicate_slots.end()),
                               result.duplicate_slots.end());
  return result;
}

// ---------------------------------------------------------------- updates

void LandmarkPool::markObserved(int slot, const std::vector<float>& descriptor, float strength) {
  requireFrame("markObserved");
  checkSlot(slot, "markObserved");
  LandmarkRecord& r = records_[slot];
  if (!r.in_use) throw std::invalid_argument("landmark pool: markObserved: slot " + std::to_string(slot) + " is free");
  if (r.last_seen_frame == frame_)
    throw std::invalid_argument("landmark pool: markObserved: slot " + std::to_string(slot) +
                                " is already observed in this frame");
  checkDescriptor(descriptor, "markObserved");
  if (!std::isfinite(strength))
    throw std::invalid_argument("landmark pool: markObserved: strength = " + num(strength) + ": must be finite");

  r.run_length = r.last_seen_frame == frame_ - 1 ? r.run_length + 1 : 1;
  r.max_run_length = std::max(r.max_run_length, r.run_length);
  ++r.times_observed;
  r.last_seen_frame = frame_;
  r.last_seen_time = time_;
  const float w = 1.0f / static_cast<float>(r.times_observed);
  r.strength += (strength - r.strength) * w;
  if (options_.descriptor_update == DescriptorUpdate::RUNNING_AVERAGE) {
    float* flat = descriptors_.data() + static_cast<size_t>(slot) * descriptor_size_;
    for (int i = 0; i < descriptor_size_; ++i) {
      r.descriptor[i] += (descriptor[i] - r.descriptor[i]) * w;
      flat[i] = r.descriptor[i];
    }
  }
}

PoolChanges LandmarkPool::commit(const AssociationResult& result,
                                 const std::vector<std::vector<float>>& measurement_descriptors,
                                 const std::vector<float>& measurement_strengths) {
  requireFrame("commit");
  const int n_meas = static_cast<int>(measurement_descriptors.size());
  if (!measurement_strengths.empty() && static_cast<int>(measurement_strengths.size()) != n_meas)
    throw std::invalid_argument("landmark pool: commit: " + std::to_string(measurement_strengths.size()) +
                                " strengths for " + std::to_string(n_meas) + " measurements");
  // Validate everything before changing anything.
  std::vector<char> matched(static_cast<size_t>(capacity()), 0);
  for (const Association& a : result.matches) {
    if (a.measurement < 0 || a.measurement >= n_meas)
      throw std::invalid_argument("landmark pool: commit: measurement " + std::to_string(a.measurement) +
                                  " outside [0, " + std::to_string(n_meas) + ")");
    checkSlot(a.slot, "commit");
    const LandmarkRecord& r = records_[a.slot];
    if (!r.in_use) throw std::invalid_argument("landmark pool: commit: slot " + std::to_string(a.slot) + " is free");
    if (matched[a.slot] || r.last_seen_frame == frame_)
      throw std::invalid_argument("landmark pool: commit: slot " + std::to_string(a.slot) +
                                  " is observed twice in this frame");
    matched[a.slot] = 1;
    checkDescriptor(measurement_descriptors[a.measurement], "commit");
    if (!measurement_strengths.empty() && !std::isfinite(measurement_strengths[a.measurement]))
      throw std::invalid_argument("landmark pool: commit: strength of measurement " + std::to_string(a.measurement) +
                                  " is not finite");
  }
  for (int s : result.duplicate_slots) {
    checkSlot(s, "commit");
    if (matched[s])
      throw std::invalid_argument("landmark pool: commit: slot " + std::to_string(s) +
                                  " is both matched and a duplicate");
  }

  for (const Association& a : result.matches) {
    const float strength =
        measurement_strengths.empty() ? records_[a.slot].strength : measurement_strengths[a.measurement];
    markObserved(a.slot, measurement_descriptors[a.measurement], strength);
  }
  PoolChanges changes;
  for (int s : result.duplicate_slots) {
    if (!records_[s].in_use) continue;  // the caller already released it
    freeSlot(s);
    changes.freed_slots.push_back(s);
  }
  std::sort(changes.freed_slots.begin(), changes.freed_slots.end());
  changes.freed_slots.erase(std::unique(changes.freed_slots.begin(), changes.freed_slots.end()),
                            changes.freed_slots.end());
  return changes;
}

// ---------------------------------------------------------------- allocation and deletion

void LandmarkPool::freeSlot(int slot) {
  LandmarkRecord& r = records_[slot];
  r = LandmarkRecord();
  r.slot = slot;
  r.state_index = stateIndex(slot);
  --used_;
}

void LandmarkPool::release(int slot) {
  checkSlot(slot, "release");
  if (!records_[slot].in_use)
    throw std::invalid_argument("landmark pool: release: slot " + std::to_string(slot) + " is not in use");
  freeSlot(slot);
}

int LandmarkPool::growTo() const {
  const int cap = capacity();
  const int step = options_.growth == PoolGrowth::ADD_100 ? 100 : (cap + 1) / 2;  // 50 %, rounded up
  return static_cast<int>(std::min<long>(options_.max_capacity, static_cast<long>(cap) + step));
}

int LandmarkPool::evictionVictim() const {
  int victim = -1;
  for (int s = 0; s < capacity(); ++s) {
    const LandmarkRecord& r = records_[s];
    if (!r.in_use || r.last_seen_frame == frame_) continue;  // never one observed in the current frame
    if (victim < 0) {
      victim = s;
      continue;
    }
    const LandmarkRecord& v = records_[victim];
    bool better;
    if (options_.deletion == DeletionPolicy::BY_AGE) {
      better = r.birth_time < v.birth_time || (r.birth_time == v.birth_time && r.id < v.id);
    } else {
      better = r.max_run_length < v.max_run_length ||
               (r.max_run_length == v.max_run_length &&
                (r.last_seen_frame < v.last_seen_frame || (r.last_seen_frame == v.last_seen_frame && r.id < v.id)));
    }
    if (better) victim = s;
  }
  return victim;
}

Allocation LandmarkPool::allocate(const std::vector<float>& descriptor, float strength) {
  requireFrame("allocate");
  checkDescriptor(descriptor, "allocate");
  if (!std::isfinite(strength))
    throw std::invalid_argument("landmark pool: allocate: strength = " + num(strength) + ": must be finite");

  Allocation out;
  if (descriptor_size_ == 0) {
    descriptor_size_ = static_cast<int>(descriptor.size());
    descriptors_.assign(static_cast<size_t>(capacity()) * descriptor_size_, 0.0f);
  }
  int slot = -1;
  if (used_ < capacity()) {
    for (int s = 0; s < capacity(); ++s)
      if (!records_[s].in_use) {
        slot = s;
        break;
      }
  } else if (capacity() < options_.max_capacity) {
    const int old_cap = capacity();
    const int new_cap = growTo();
    records_.resize(static_cast<size_t>(new_cap));
    for (int s = old_cap; s < new_cap; ++s) {
      records_[s].slot = s;
      records_[s].state_index = stateIndex(s);
    }
    descriptors_.resize(static_cast<size_t>(new_cap) * descriptor_size_, 0.0f);
    out.changes.new_capacity = new_cap;
    slot = old_cap;
  } else {
    slot = evictionVictim();
    if (slot < 0) return out;
    freeSlot(slot);
    out.changes.freed_slots.push_back(slot);
  }

  LandmarkRecord& r = records_[slot];
  r.id = next_id_++;
  r.in_use = true;
  r.descriptor = descriptor;
  r.strength = strength;
  r.times_observed = 1;
  r.run_length = 1;
  r.max_run_length = 1;
  r.birth_time = time_;
  r.last_seen_time = time_;
  r.birth_frame = frame_;
  r.last_seen_frame = frame_;
  std::copy(descriptor.begin(), descriptor.end(), descriptors_.begin() + static_cast<std::ptrdiff_t>(slot) * descriptor_size_);
  ++used_;
  out.slot = slot;
  return out;
}

}  // namespace slam
}  // namespace skin3d
