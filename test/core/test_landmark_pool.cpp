// SPDX-License-Identifier: BSD-3-Clause
// Tests of the landmark pool (thesis §6.2.7, §6.2.8): growth, eviction, ids, run lengths, association,
// forking, claims, stale pruning and input validation. All scenarios are scripted; expected values follow
// from the script.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/slam/landmark_pool.h"

using skin3d::slam::Allocation;
using skin3d::slam::AssociationResult;
using skin3d::slam::DeletionPolicy;
using skin3d::slam::DescriptorUpdate;
using skin3d::slam::ForkPolicy;
using skin3d::slam::LandmarkPool;
using skin3d::slam::LandmarkPoolOptions;
using skin3d::slam::PoolChanges;
using skin3d::slam::PoolGrowth;

namespace {

constexpr int kD = 8;  // descriptor length of the small scripted scenarios
const double kInf = std::numeric_limits<double>::infinity();

/** Unit vector e_k (kD floats), optionally plus `eps` on element (k + 1) % kD. */
std::vector<float> unit(int k, float eps = 0.0f) {
  std::vector<float> d(kD, 0.0f);
  d[k] = 1.0f;
  d[(k + 1) % kD] += eps;
  return d;
}

std::vector<float> randomUnit(std::mt19937& rng, int n) {
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::vector<float> d(n);
  double n2 = 0.0;
  for (float& v : d) {
    v = nd(rng);
    n2 += static_cast<double>(v) * v;
  }
  for (float& v : d) v = static_cast<float>(v / std::sqrt(n2));
  return d;
}

LandmarkPoolOptions noPruning() {
  LandmarkPoolOptions o;
  o.prune_stale = false;
  return o;
}

/** Gate accepting every pair with squared Mahalanobis distance 1. */
double gateAll(int, int) { return 1.0; }

template <class F>
void expectInvalidNaming(F f, const std::string& field) {
  try {
    f();
    ADD_FAILURE() << "no exception, expected one naming " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

}  // namespace

// ---------------------------------------------------------------- growth

TEST(LandmarkPool, GrowsBy100UpToMax) {
  LandmarkPool pool(13, noPruning());  // defaults: 100 initial, +100, max 1000
  EXPECT_EQ(pool.capacity(), 100);
  pool.beginFrame(0.0);
  std::mt19937 rng(1);
  std::vector<int> grown;
  for (int i = 0; i < 1000; ++i) {
    const Allocation a = pool.allocate(randomUnit(rng, 16), 1.0f);
    ASSERT_EQ(a.slot, i);  // lowest free slot; after growth the first new one
    EXPECT_TRUE(a.changes.freed_slots.empty());
    if (a.changes.new_capacity > 0) grown.push_back(a.changes.new_capacity);
  }
  EXPECT_EQ(grown, (std::vector<int>{200, 300, 400, 500, 600, 700, 800, 900, 1000}));
  EXPECT_EQ(pool.capacity(), 1000);
  EXPECT_EQ(pool.used(), 1000);
  EXPECT_EQ(pool.record(999).state_index, 13 + 3 * 999);
  EXPECT_EQ(pool.stateIndex(7), 13 + 21);
  EXPECT_EQ(pool.record(5).state_dim, 3);
  // Full at max and every landmark observed in this frame: nothing may be deleted.
  const Allocation full = pool.allocate(randomUnit(rng, 16), 1.0f);
  EXPECT_EQ(full.slot, -1);
  EXPECT_TRUE(full.changes.empty());
  EXPECT_EQ(pool.everSeen(), 1000);
}

TEST(LandmarkPool, Grows50PercentUpToMax) {
  LandmarkPoolOptions o = noPruning();
  o.growth = PoolGrowth::GROW_50_PERCENT;
  LandmarkPool pool(0, o);
  pool.beginFrame(0.0);
  std::vector<int> grown;
  for (int i = 0; i < 1000; ++i) {
    const Allocation a = pool.allocate(unit(i % kD), 1.0f);
    ASSERT_EQ(a.slot, i);
    if (a.changes.new_capacity > 0) grown.push_back(a.changes.new_capacity);
  }
  // 100 -> +50 -> +75 -> +113 (ceil) -> +169 -> +254 -> +381 capped at 1000
  EXPECT_EQ(grown, (std::vector<int>{150, 225, 338, 507, 761, 1000}));
}

// ---------------------------------------------------------------- eviction

TEST(LandmarkPool, EvictsOldestWhenFullByAge) {
  LandmarkPoolOptions o = noPruning();
  o.initial_capacity = 4;
  o.max_capacity = 4;
  o.deletion = DeletionPolicy::BY_AGE;
  LandmarkPool pool(0, o);
  for (int f = 1; f <= 4; ++f) {  // A, B, C, D born at t = 1..4 in slots 0..3
    pool.beginFrame(f);
    EXPECT_EQ(pool.allocate(unit(f - 1), 1.0f).slot, f - 1);
  }
  pool.beginFrame(5.0);
  pool.markObserved(0, unit(0), 1.0f);  // A (oldest) is observed in this frame: protected
  Allocation e = pool.allocate(unit(4), 1.0f);
  EXPECT_EQ(e.slot, 1);  // B, the oldest unobserved
  EXPECT_EQ(e.changes.freed_slots, std::vector<int>{1});
  EXPECT_EQ(e.changes.new_capacity, 0);
  EXPECT_EQ(pool.record(1).id, 4);
  EXPECT_EQ(pool.record(1).birth_time, 5.0);
  EXPECT_EQ(pool.allocate(unit(5), 1.0f).slot, 2);  // C
  EXPECT_EQ(pool.allocate(unit(6), 1.0f).slot, 3);  // D
  // Left: A (observed now) and E, F, G (born now): nothing deletable.
  const Allocation none = pool.allocate(unit(7), 1.0f);
  EXPECT_EQ(none.slot, -1);
  EXPECT_TRUE(none.changes.empty());
  EXPECT_EQ(pool.used(), 4);
  EXPECT_EQ(pool.record(0).id, 0);
}

TEST(LandmarkPool, EvictsShortestMaxRunWhenFullByRunLength) {
  LandmarkPoolOptions o = noPruning();
  o.initial_capacity = 3;
  o.max_capacity = 3;
  o.deletion = DeletionPolicy::BY_RUN_LENGTH;
  LandmarkPool pool(0, o);
  pool.beginFrame(1.0);  // A, B, C in slots 0, 1, 2
  for (int k = 0; k < 3; ++k) ASSERT_EQ(pool.allocate(unit(k), 1.0f).slot, k);
  pool.beginFrame(2.0);
  pool.markObserved(0, unit(0), 1.0f);
  pool.markObserved(1, unit(1), 1.0f);
  pool.beginFrame(3.0);
  pool.markObserved(0, unit(0), 1.0f);  // max runs: A 3, B 2, C 1
  EXPECT_EQ(pool.record(0).max_run_length, 3);
  EXPECT_EQ(pool.record(1).max_run_length, 2);
  EXPECT_EQ(pool.record(2).max_run_length, 1);
  pool.beginFrame(4.0);
  pool.markObserved(2, unit(2), 1.0f);  // C has the shortest max run but is observed now
  Allocation d = pool.allocate(unit(3), 1.0f);
  EXPECT_EQ(d.slot, 1);  // B (max run 2) rather than protected C (1)
  EXPECT_EQ(d.changes.freed_slots, std::vector<int>{1});
  pool.beginFrame(5.0);
  pool.markObserved(1, unit(3), 1.0f);  // D: max run 2
  Allocation e = pool.allocate(unit(4), 1.0f);
  EXPECT_EQ(e.slot, 2);  // C (max run 1) rather than A (3)
  EXPECT_EQ(pool.record(0).id, 0);
  EXPECT_EQ(pool.record(1).id, 3);
  EXPECT_EQ(pool.record(2).id, 4);
}

// ---------------------------------------------------------------- ids and run lengths

TEST(LandmarkPool, IdsAreUniqueAndNeverReused) {
  LandmarkPoolOptions o = noPruning();
  o.initial_capacity = 2;
  o.max_capacity = 2;
  LandmarkPool pool(0, o);
  std::set<std::int64_t> ids;
  int allocations = 0;
  for (int f = 1; f <= 6; ++f) {
    pool.beginFrame(f);
    if (f == 3) pool.release(0);
    const Allocation a = pool.allocate(unit(f % kD), 1.0f);  // frames >= 3: releases or evictions reuse slots
    ASSERT_GE(a.slot, 0);
    ++allocations;
    const std::int64_t id = pool.record(a.slot).id;
    EXPECT_TRUE(ids.insert(id).second) << "id " << id << " reused";
    EXPECT_EQ(id, allocations - 1);
    EXPECT_EQ(pool.slotOf(id), a.slot);
  }
  EXPECT_EQ(pool.everSeen(), 6);
  EXPECT_EQ(pool.used(), 2);
  EXPECT_EQ(pool.slotOf(0), -1);  // long gone
  EXPECT_EQ(pool.slotOf(4), 0);   // frames 4..6 evict the oldest: ids 1, 2, 3 in turn
  EXPECT_EQ(pool.slotOf(5), 1);
}

TEST(LandmarkPool, RunLengthBookkeeping) {
  LandmarkPool pool(0, noPruning());
  // Observation script of landmark A for frames 1..10 (frame 1: birth); other frames not observed.
  const std::vector<bool> seen = {true, true, true, false, true, true, true, true, false, false};
  // Expected (run, max run) at the end of each frame (before the next beginFrame()).
  const std::vector<std::pair<int, int>> expected = {{1, 1}, {2, 2}, {3, 3}, {3, 3}, {1, 3},
                                                     {2, 3}, {3, 3}, {4, 4}, {4, 4}, {0, 4}};
  int slot = -1;
  for (int f = 1; f <= 10; ++f) {
    pool.beginFrame(0.1 * f);
    if (f == 1) {
      slot = pool.allocate(unit(0), 0.5f).slot;
    } else {
      if (f == 5) {
        EXPECT_EQ(pool.record(slot).run_length, 0);  // frame 4 missed: run reset on closing it
      }
      if (seen[f - 1]) pool.markObserved(slot, unit(0), 0.5f);
    }
    EXPECT_EQ(pool.record(slot).run_length, expected[f - 1].first) << "frame " << f;
    EXPECT_EQ(pool.record(slot).max_run_length, expected[f - 1].second) << "frame " << f;
  }
  EXPECT_EQ(pool.record(slot).times_observed, 7);
  EXPECT_DOUBLE_EQ(pool.record(slot).last_seen_time, 0.8);
  EXPECT_DOUBLE_EQ(pool.record(slot).birth_time, 0.1);
  EXPECT_EQ(pool.record(slot).last_seen_frame, 8);
  pool.markObserved(slot, unit(0), 0.5f);  // frame 10 is still open: allowed once
  EXPECT_THROW(pool.markObserved(slot, unit(0), 0.5f), std::invalid_argument);  // twice in one frame
}

TEST(LandmarkPool, DescriptorAndStrengthUpdate) {
  for (DescriptorUpdate mode : {DescriptorUpdate::KEEP_FIRST, DescriptorUpdate::RUNNING_AVERAGE}) {
    LandmarkPoolOptions o = noPruning();
    o.descriptor_update = mode;
    LandmarkPool pool(0, o);
    pool.beginFrame(1.0);
    const int s = pool.allocate(unit(0), 0.2f).slot;
    pool.beginFrame(2.0);
    pool.markObserved(s, unit(1), 0.6f);
    EXPECT_FLOAT_EQ(pool.record(s).strength, 0.4f);  // mean of 0.2 and 0.6
    const std::vector<float>& d = pool.record(s).descriptor;
    if (mode == DescriptorUpdate::KEEP_FIRST) {
      EXPECT_EQ(d, unit(0));
    } else {
      EXPECT_FLOAT_EQ(d[0], 0.5f);
      EXPECT_FLOAT_EQ(d[1], 0.5f);
      // The averaged descriptor is what association uses: (0.5, 0.5, 0, ...) is 0.1 from (0.5, 0.6, 0, ...).
      std::vector<float> q(kD, 0.0f);
      q[0] = 0.5f;
      q[1] = 0.6f;
      const AssociationResult r = pool.associate({q}, gateAll);
      ASSERT_EQ(r.matches.size(), 1u);
      EXPECT_NEAR(r.matches[0].descriptor_distance, 0.1, 1e-6);
    }
  }
}

// ---------------------------------------------------------------- association

namespace {
/** Pool of landmarks with descriptors e_0 .. e_{n-1}, born in frame 1 (t = 1) in slots 0 .. n-1. */
LandmarkPool distinctPool(int n, LandmarkPoolOptions o = noPruning()) {
  LandmarkPool pool(0, o);
  pool.beginFrame(1.0);
  for (int k = 0; k < n; ++k) EXPECT_EQ(pool.allocate(unit(k), 1.0f).slot, k);
  return pool;
}
}  // namespace

TEST(LandmarkPool, AssociatesDistinctDescriptors) {
  LandmarkPool pool = distinctPool(5);
  pool.beginFrame(2.0);
  const std::vector<std::vector<float>> meas = {unit(3, 0.05f), unit(6), unit(1, -0.1f)};
  const AssociationResult r = pool.associate(meas, gateAll);
  ASSERT_EQ(r.matches.size(), 2u);
  EXPECT_EQ(r.matches[0].measurement, 0);
  EXPECT_EQ(r.matches[0].slot, 3);
  EXPECT_NEAR(r.matches[0].descriptor_distance, 0.05, 1e-6);
  EXPECT_EQ(r.matches[0].mahalanobis_sq, 1.0);
  EXPECT_EQ(r.matches[1].measurement, 2);
  EXPECT_EQ(r.matches[1].slot, 1);
  EXPECT_NEAR(r.matches[1].descriptor_distance, 0.1, 1e-6);
  EXPECT_EQ(r.unassociated, std::vector<int>{1});
  EXPECT_TRUE(r.contested.empty());
  EXPECT_TRUE(r.duplicate_slots.empty());
  EXPECT_EQ(r.gate_calls, 2);  // only the two descriptor-passing pairs (the others are sqrt(2) apart)

  const std::vector<float> strengths = {0.5f, 0.9f, 0.7f};
  const PoolChanges c = pool.commit(r, meas, strengths);
  EXPECT_TRUE(c.empty());
  EXPECT_EQ(pool.record(3).times_observed, 2);
  EXPECT_EQ(pool.record(3).run_length, 2);
  EXPECT_DOUBLE_EQ(pool.record(3).last_seen_time, 2.0);
  EXPECT_FLOAT_EQ(pool.record(1).strength, 0.85f);  // mean of 1.0 and 0.7
  EXPECT_EQ(pool.record(0).times_observed, 1);
  EXPECT_EQ(pool.allocate(meas[1], strengths[1]).slot, 5);
  // Committing the same frame again would observe slot 3 twice.
  EXPECT_THROW(pool.commit(r, meas, strengths), std::invalid_argument);
}

TEST(LandmarkPool, GateRejects) {
  LandmarkPool pool = distinctPool(4);
  pool.beginFrame(2.0);
  const std::vector<std::vector<float>> meas = {unit(0, 0.02f), unit(1, 0.02f), unit(2, 0.02f), unit(3, 0.02f)};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto gate = [nan](int slot, int) {
    switch (slot) {
      case 0: return 11.0;   // inside the 99 % gate (11.34)
      case 1: return 11.5;   // outside
      case 2: return kInf;   // not visible
      default: return nan;   // not computable
    }
  };
  const AssociationResult r = pool.associate(meas, gate);
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_EQ(r.matches[0].slot, 0);
  EXPECT_EQ(r.matches[0].mahalanobis_sq, 11.0);
  EXPECT_EQ(r.unassociated, (std::vector<int>{1, 2, 3}));
  EXPECT_TRUE(r.contested.empty());

  LandmarkPoolOptions o = noPruning();
  o.mahalanobis_gate = 12.0;
  LandmarkPool wide = distinctPool(4, o);
  EXPECT_EQ(wide.associate(meas, gate).matches.size(), 2u);

  // Descriptor bound: 0.25 from e_0 is accepted with the default 0.3, 0.35 is not (and the gate is not asked).
  const AssociationResult near = pool.associate({unit(0, 0.25f)}, gateAll);
  EXPECT_EQ(near.matches.size(), 1u);
  const AssociationResult far = pool.associate({unit(0, 0.35f)}, gateAll);
  EXPECT_TRUE(far.matches.empty());
  EXPECT_EQ(far.gate_calls, 0);
}

namespace {
/** Fork script: X (slot 0, e_0) born at t = 1 and seen at t = 2; the same point enters again as Y
 *  (slot 2, e_0 + 0.05 e_1) at t = 3 and is seen at t = 3..6 (max run 4 > X's 2). Z (slot 1, e_5) unrelated. */
LandmarkPool forkPool(ForkPolicy policy) {
  LandmarkPoolOptions o = noPruning();
  o.fork = policy;
  LandmarkPool pool(0, o);
  pool.beginFrame(1.0);
  EXPECT_EQ(pool.allocate(unit(0), 1.0f).slot, 0);  // X
  EXPECT_EQ(pool.allocate(unit(5), 1.0f).slot, 1);  // Z
  pool.beginFrame(2.0);
  pool.markObserved(0, unit(0), 1.0f);
  pool.beginFrame(3.0);
  EXPECT_EQ(pool.allocate(unit(0, 0.05f), 1.0f).slot, 2);  // Y
  for (int f = 4; f <= 6; ++f) {
    pool.beginFrame(f);
    pool.markObserved(2, unit(0, 0.05f), 1.0f);
  }
  EXPECT_EQ(pool.record(0).max_run_length, 2);
  EXPECT_EQ(pool.record(2).max_run_length, 4);
  pool.beginFrame(7.0);
  return pool;
}
}  // namespace

TEST(LandmarkPool, ForkLongestRunKeepsTheLongerRun) {
  LandmarkPool pool = forkPool(ForkPolicy::LONGEST_RUN);
  const std::vector<std::vector<float>> meas = {unit(5, 0.01f), unit(0, 0.02f)};
  const AssociationResult r = pool.associate(meas, gateAll);  // meas 1 matches X and Y
  ASSERT_EQ(r.matches.size(), 2u);
  EXPECT_EQ(r.matches[0].slot, 1);  // Z
  EXPECT_EQ(r.matches[1].measurement, 1);
  EXPECT_EQ(r.matches[1].slot, 2);  // Y: max run 4
  EXPECT_EQ(r.duplicate_slots, std::vector<int>{0});
  ASSERT_EQ(r.forks.size(), 1u);
  EXPECT_EQ(r.forks[0].measurement, 1);
  EXPECT_EQ(r.forks[0].slot, 0);
  const PoolChanges c = pool.commit(r, meas);
  EXPECT_EQ(c.freed_slots, std::vector<int>{0});
  EXPECT_FALSE(pool.inUse(0));
  EXPECT_EQ(pool.record(2).run_length, 5);
  EXPECT_EQ(pool.used(), 2);
}

TEST(LandmarkPool, ForkFirstSeenKeepsTheOlder) {
  LandmarkPool pool = forkPool(ForkPolicy::FIRST_SEEN);
  const std::vector<std::vector<float>> meas = {unit(0, 0.04f)};  // closer to Y (0.01) than to X (0.04)
  const AssociationResult r = pool.associate(meas, gateAll);
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_EQ(r.matches[0].slot, 0);  // X: born at t = 1
  EXPECT_EQ(r.duplicate_slots, std::vector<int>{2});
  const PoolChanges c = pool.commit(r, meas);
  EXPECT_EQ(c.freed_slots, std::vector<int>{2});
  EXPECT_TRUE(pool.inUse(0));
  EXPECT_FALSE(pool.inUse(2));
  EXPECT_EQ(pool.record(0).times_observed, 3);
  EXPECT_EQ(pool.record(0).run_length, 1);  // X was not seen at t = 3..6
}

TEST(LandmarkPool, ForkLoserKeptWhenAnotherMeasurementOwnsIt) {
  LandmarkPool pool = forkPool(ForkPolicy::FIRST_SEEN);
  // meas 0 sees X and Y (keeps X); meas 1 only passes the gate with Y: Y is associated, not a duplicate.
  const std::vector<std::vector<float>> meas = {unit(0, 0.03f), unit(0, 0.05f)};
  const auto gate = [](int slot, int m) { return (m == 1 && slot == 0) ? kInf : 1.0; };
  const AssociationResult r = pool.associate(meas, gate);
  ASSERT_EQ(r.matches.size(), 2u);
  EXPECT_EQ(r.matches[0].slot, 0);
  EXPECT_EQ(r.matches[1].slot, 2);
  EXPECT_TRUE(r.duplicate_slots.empty());
  EXPECT_TRUE(r.forks.empty());
}

TEST(LandmarkPool, LandmarkClaimedByTwoMeasurements) {
  LandmarkPool pool = distinctPool(3);
  pool.beginFrame(2.0);
  const std::vector<std::vector<float>> meas = {unit(1, 0.02f), unit(1, 0.08f)};
  // Smaller Mahalanobis distance wins even with the larger descriptor distance.
  AssociationResult r = pool.associate(meas, [](int, int m) { return m == 0 ? 5.0 : 2.0; });
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_EQ(r.matches[0].measurement, 1);
  EXPECT_EQ(r.matches[0].slot, 1);
  EXPECT_EQ(r.unassociated, std::vector<int>{0});
  EXPECT_EQ(r.contested, std::vector<int>{0});
  // Equal Mahalanobis distances: the smaller descriptor distance wins.
  r = pool.associate(meas, [](int, int) { return 3.0; });
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_EQ(r.matches[0].measurement, 0);
  EXPECT_EQ(r.contested, std::vector<int>{1});
}

TEST(LandmarkPool, RatioTest) {
  LandmarkPoolOptions o = noPruning();
  o.ratio = 0.8;
  LandmarkPool pool(0, o);
  pool.beginFrame(1.0);
  std::vector<float> a(kD, 0.0f), b(kD, 0.0f);
  a[0] = 1.0f;
  b[0] = 1.0f;
  b[1] = 0.2f;                                // look-alike 0.2 from A, elsewhere in the scene
  ASSERT_EQ(pool.allocate(a, 1.0f).slot, 0);
  ASSERT_EQ(pool.allocate(b, 1.0f).slot, 1);
  pool.beginFrame(2.0);
  std::vector<float> q1 = a, q2 = a;
  q1[1] = 0.05f;                              // 0.05 from A, 0.15 from B: 0.05 < 0.8 * 0.15
  q2[1] = 0.09f;                              // 0.09 from A, 0.11 from B: 0.09 > 0.8 * 0.11
  const auto onlyA = [](int slot, int) { return slot == 0 ? 1.0 : 50.0; };
  AssociationResult r = pool.associate({q1, q2}, onlyA);
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_EQ(r.matches[0].measurement, 0);
  EXPECT_EQ(r.ratio_rejected, std::vector<int>{1});
  EXPECT_EQ(r.unassociated, std::vector<int>{1});
  // When the geometry accepts both, they are one point (a fork), not an ambiguity.
  r = pool.associate({q2}, gateAll);
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_TRUE(r.ratio_rejected.empty());
  EXPECT_EQ(r.duplicate_slots.size(), 1u);
  // Ratio test off: q2 is accepted.
  LandmarkPool plain(0, noPruning());
  plain.beginFrame(1.0);
  plain.allocate(a, 1.0f);
  plain.allocate(b, 1.0f);
  EXPECT_EQ(plain.associate({q2}, onlyA).matches.size(), 1u);
}

// ---------------------------------------------------------------- stale pruning

TEST(LandmarkPool, PrunesStaleRarelySeenLandmarks) {
  LandmarkPoolOptions o;  // defaults: prune, max_unseen_frames 5, min_observations 3
  LandmarkPool pool(0, o);
  pool.beginFrame(1.0);
  const int s = pool.allocate(unit(0), 1.0f).slot;  // seen once (a one-frame mismatch)
  const int t = pool.allocate(unit(1), 1.0f).slot;  // seen in frames 1..3
  for (int f = 2; f <= 3; ++f) {
    EXPECT_TRUE(pool.beginFrame(f).empty());
    pool.markObserved(t, unit(1), 1.0f);
  }
  // S last seen in frame 1: frames 2..7 complete without it at beginFrame(8) -> 6 > 5.
  for (int f = 4; f <= 7; ++f) EXPECT_TRUE(pool.beginFrame(f).empty()) << "frame " << f;
  EXPECT_TRUE(pool.inUse(s));
  const PoolChanges c = pool.beginFrame(8.0);
  EXPECT_EQ(c.freed_slots, std::vector<int>{s});
  EXPECT_FALSE(pool.inUse(s));
  for (int f = 9; f <= 30; ++f) EXPECT_TRUE(pool.beginFrame(f).empty());
  EXPECT_TRUE(pool.inUse(t));  // observed 3 times: never pruned

  LandmarkPool keep(0, noPruning());
  keep.beginFrame(1.0);
  keep.allocate(unit(0), 1.0f);
  for (int f = 2; f <= 30; ++f) EXPECT_TRUE(keep.beginFrame(f).empty());
  EXPECT_EQ(keep.used(), 1);
}

// ---------------------------------------------------------------- validation

TEST(LandmarkPool, BadOptionsThrowNamingTheField) {
  const auto with = [](auto set) {
    return [set]() {
      LandmarkPoolOptions o;
      set(o);
      LandmarkPool p(0, o);
    };
  };
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.initial_capacity = 0; }), "initial_capacity");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.max_capacity = 50; }), "max_capacity");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.growth = static_cast<PoolGrowth>(7); }), "growth");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.deletion = static_cast<DeletionPolicy>(7); }), "deletion");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.fork = static_cast<ForkPolicy>(7); }), "fork");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.max_unseen_frames = -1; }), "max_unseen_frames");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.min_observations = 0; }), "min_observations");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.max_descriptor_distance = 0.0; }),
                      "max_descriptor_distance");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.max_descriptor_distance = std::nan(""); }),
                      "max_descriptor_distance");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.ratio = 1.5; }), "ratio");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.ratio = -0.1; }), "ratio");
  expectInvalidNaming(with([](LandmarkPoolOptions& o) { o.mahalanobis_gate = 0.0; }), "mahalanobis_gate");
  expectInvalidNaming([]() { LandmarkPool p(-1); }, "rig_dim");
}

TEST(LandmarkPool, BadInputsThrow) {
  LandmarkPool pool(0, noPruning());
  EXPECT_THROW(pool.allocate(unit(0), 1.0f), std::logic_error);  // no frame yet
  expectInvalidNaming([&]() { pool.beginFrame(std::nan("")); }, "time");
  pool.beginFrame(2.0);
  expectInvalidNaming([&]() { pool.beginFrame(1.0); }, "time");  // back in time
  expectInvalidNaming([&]() { pool.allocate({}, 1.0f); }, "descriptor");
  ASSERT_EQ(pool.allocate(unit(0), 1.0f).slot, 0);  // fixes the descriptor length to kD
  expectInvalidNaming([&]() { pool.allocate(std::vector<float>(kD + 1, 0.0f), 1.0f); }, "descriptor");
  std::vector<float> bad = unit(1);
  bad[2] = std::numeric_limits<float>::quiet_NaN();
  expectInvalidNaming([&]() { pool.allocate(bad, 1.0f); }, "descriptor");
  expectInvalidNaming([&]() { pool.allocate(unit(1), std::numeric_limits<float>::infinity()); }, "strength");
  expectInvalidNaming([&]() { pool.associate({unit(0), std::vector<float>(3, 0.0f)}, gateAll); }, "measurement 1");
  expectInvalidNaming([&]() { pool.associate({bad}, gateAll); }, "measurement 0");
  EXPECT_THROW(pool.release(100), std::out_of_range);
  EXPECT_THROW(pool.record(-1), std::out_of_range);
  expectInvalidNaming([&]() { pool.release(1); }, "slot 1");  // free
  AssociationResult forged;
  forged.matches.push_back({0, 1, 0.0, 0.0});  // slot 1 is free
  expectInvalidNaming([&]() { pool.commit(forged, {unit(1)}); }, "slot 1");
  forged.matches[0] = {3, 0, 0.0, 0.0};        // measurement out of range
  expectInvalidNaming([&]() { pool.commit(forged, {unit(0)}); }, "measurement 3");
  EXPECT_EQ(pool.record(0).times_observed, 1);  // failed commits change nothing
}

// ---------------------------------------------------------------- scale (informative timing only)

TEST(LandmarkPool, FullSizeFrame) {
  constexpr int kDesc = 64, kPool = 1000, kReseen = 650, kMeas = 1300;
  std::mt19937 rng(42);
  LandmarkPool pool(16, noPruning());
  pool.beginFrame(0.0);
  std::vector<std::vector<float>> stored;
  for (int i = 0; i < kPool; ++i) {
    stored.push_back(randomUnit(rng, kDesc));
    ASSERT_EQ(pool.allocate(stored.back(), 1.0f).slot, i);
  }
  pool.beginFrame(0.1);
  // Measurements: re-observations of 650 distinct landmarks with 0.01 per-element noise (~0.08 away), then new
  // points. Random unit vectors in 64-D are ~1.4 apart, far beyond the 0.3 bound.
  std::normal_distribution<float> noise(0.0f, 0.01f);
  std::vector<std::vector<float>> meas;
  for (int i = 0; i < kReseen; ++i) {
    std::vector<float> d = stored[(3 * i) % kPool];  // 3 and 1000 coprime: distinct
    for (float& v : d) v += noise(rng);
    meas.push_back(d);
  }
  while (static_cast<int>(meas.size()) < kMeas) meas.push_back(randomUnit(rng, kDesc));
  const auto t0 = std::chrono::steady_clock::now();
  const AssociationResult r = pool.associate(meas, gateAll);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::cout << "  associate " << kMeas << " x " << kPool << " x " << kDesc << ": " << ms << " ms\n";
  RecordProperty("associate_ms", std::to_string(ms));
  ASSERT_EQ(static_cast<int>(r.matches.size()), kReseen);
  for (int i = 0; i < kReseen; ++i) EXPECT_EQ(r.matches[i].slot, (3 * i) % kPool);
  EXPECT_EQ(r.gate_calls, kReseen);
  EXPECT_EQ(static_cast<int>(r.unassociated.size()), kMeas - kReseen);
  EXPECT_TRUE(pool.commit(r, meas).empty());
}
