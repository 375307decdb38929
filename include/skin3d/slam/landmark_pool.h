/**
 * @file landmark_pool.h
 * @brief Landmark pool: slot bookkeeping, data association and forking for the ES-EKF SLAM
 *        (thesis §5.2.2, §6.2.7, §6.2.8).
 *
 * The ES-EKF keeps landmark states in numbered SLOTS 0..capacity()-1; slot j occupies the error-state
 * entries [rig_dim + 3 j, rig_dim + 3 j + 3). The pool decides which slot holds which landmark. It never
 * touches the filter: every call that changes the slot layout returns a PoolChanges (grow to a new
 * capacity, slots freed) that the caller applies to the filter, in this order: grow, then remove the
 * freed slots, then insert the new landmark (an evicted slot is handed out again at once).
 *
 * Per landmark (§6.2.7): a unique id (never reused; ids are 0, 1, 2, ... in order of birth, so
 * everSeen() = next id), the in-use flag, the descriptor, the match strength, times observed, current
 * and maximum run length (consecutive frames observed), the slot and thus the error-state index, the
 * error-state dimension (3), birth and last-seen time (s, the caller's clock).
 *
 * Frames. The caller brackets each camera frame with beginFrame(time):
 *   pool.beginFrame(t);                 // closes the previous frame: run lengths, stale pruning -> changes
 *   auto a = pool.associate(descs, gate);   // const: proposes matches, duplicates (forks), new landmarks
 *   ... filter update with a.matches (drop from a.matches what the innovation check rejects) ...
 *   pool.commit(a, descs, strengths);   // marks matches observed, frees fork duplicates -> changes
 *   for (int m : a.unassociated) pool.allocate(descs[m], strengths[m]);   // -> slot + changes
 * commit() must precede allocate() in a frame so that eviction never hits a landmark observed in it.
 *
 * Capacity. The pool starts with initial_capacity slots. When no slot is free it grows by 100 slots or by
 * 50 % (rounded up), never beyond max_capacity (thesis: "100 or 50 % upon pool exhaustion", max 1000).
 * Full at max_capacity, one landmark NOT observed in the current frame is evicted: BY_AGE the earliest
 * birth (ties: smallest id), BY_RUN_LENGTH the smallest maximum run length (ties: least recently seen,
 * then smallest id). If every landmark was observed in this frame, allocate() returns slot -1.
 * Stale pruning (optional, on by default; not in the thesis): at beginFrame(), a landmark not observed
 * for more than max_unseen_frames completed frames AND observed fewer than min_observations times is
 * deleted, so that one-frame mismatches do not fill the pool until the thesis' exhaustion policy acts.
 *
 * Association (descriptor + Mahalanobis gate, §5.2.2). Descriptor distance is L2 for all descriptor types;
 * binary descriptors come as one float (0/1) per bit, for which L2 = sqrt(Hamming), so a Hamming threshold
 * h becomes max_descriptor_distance = sqrt(h). A (measurement m, landmark in slot s) pair is a CANDIDATE
 * when its descriptor distance <= max_descriptor_distance and the caller's gate(s, m), the squared
 * Mahalanobis distance of the innovation (+inf when s is not visible or not computable), is
 * <= mahalanobis_gate (chi^2, 3 dof; 11.34 = 99 %). The gate is only called for pairs that pass the
 * descriptor test (squared distances with early exit, on a contiguous descriptor array).
 * Optional ratio test (ratio > 0): the best candidate distance d1 must satisfy d1 < ratio * d2, where d2 is
 * the smallest descriptor distance to a pool landmark that is NOT a candidate of the measurement (too far in
 * descriptor space or rejected by the gate). Candidates are the same physical point seen through the
 * geometry (a fork), so they do not count as ambiguity; the test rejects measurements whose appearance is
 * not distinctive with respect to the rest of the pool. Off by default: the gate disambiguates look-alikes.
 * Forking (§6.2.8): a measurement with several candidates is associated with one of them by the fork policy
 * (LONGEST_RUN: largest max run length, ties: earliest birth, smallest id; FIRST_SEEN: earliest birth,
 * ties: smallest id); the other candidates are duplicates of the same point and are reported in
 * duplicate_slots for deletion (unless another measurement is associated with them). A landmark claimed
 * by several measurements keeps the one with the smallest Mahalanobis distance (ties: descriptor distance,
 * then measurement index); the losers are unassociated (also listed in `contested`). Duplicates are only
 * reported from measurements whose association survived.
 *
 * Descriptor update on re-observation: KEEP_FIRST (default: a slipped wrong association cannot drag the
 * signature away) or RUNNING_AVERAGE (mean of all observed descriptors). Match strength: mean of the
 * observed strengths.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

namespace skin3d {
namespace slam {

/** Error-state dimension of one landmark (a 3D point). */
constexpr int kLandmarkStateDim = 3;

enum class PoolGrowth { ADD_100, GROW_50_PERCENT };
enum class DeletionPolicy { BY_AGE, BY_RUN_LENGTH };
enum class ForkPolicy { LONGEST_RUN, FIRST_SEEN };
enum class DescriptorUpdate { KEEP_FIRST, RUNNING_AVERAGE };

struct LandmarkPoolOptions {
  int initial_capacity = 100;                     //!< slots at construction, >= 1
  PoolGrowth growth = PoolGrowth::ADD_100;        //!< growth step when no slot is free
  int max_capacity = 1000;                        //!< >= initial_capacity
  DeletionPolicy deletion = DeletionPolicy::BY_AGE;  //!< eviction when full at max_capacity

  bool prune_stale = true;     //!< delete stale, rarely observed landmarks at beginFrame()
  int max_unseen_frames = 5;   //!< stale: not observed for more than this many completed frames (>= 0)
  int min_observations = 3;    //!< ... and observed fewer than this many times (>= 1)

  /** L2 descriptor distance bound (> 0). 0.3 suits unit-norm KAZE (64 floats); binary: sqrt(Hamming). */
  double max_descriptor_distance = 0.3;
  double ratio = 0.0;               //!< Lowe-style ratio test, in (0, 1]; 0 = off
  double mahalanobis_gate = 11.34;  //!< squared Mahalanobis bound (chi^2 3 dof 99 %), > 0
  ForkPolicy fork = ForkPolicy::LONGEST_RUN;
  DescriptorUpdate descriptor_update = DescriptorUpdate::KEEP_FIRST;

  /** @throws std::invalid_argument naming a bad field and its value. */
  void validate() const;
};

/** @brief Bookkeeping of one landmark (one slot). Free slots hold id -1 and in_use false. */
struct LandmarkRecord {
  std::int64_t id = -1;             //!< unique, never reused (0, 1, 2, ... in order of birth)
  bool in_use = false;
  std::vector<float> descriptor;
  float strength = 0.0f;            //!< mean match strength of the observations
  int times_observed = 0;           //!< frames in which it was observed (birth included)
  int run_length = 0;               //!< consecutive frames observed, up to the last/current frame
  int max_run_length = 0;
  int slot = -1;
  int state_index = -1;             //!< rig_dim + 3 * slot
  int state_dim = kLandmarkStateDim;
  double birth_time = 0.0;          //!< s
  double last_seen_time = 0.0;      //!< s
  std::int64_t birth_frame = -1;    //!< frame number (1 = first beginFrame())
  std::int64_t last_seen_frame = -1;
};

/** @brief Slot-layout decisions the caller must apply to the filter (grow first, then remove freed slots). */
struct PoolChanges {
  int new_capacity = 0;            //!< > 0: the pool grew to this many slots; 0: capacity unchanged
  std::vector<int> freed_slots;    //!< slots whose landmark was deleted (ascending)
  bool empty() const { return new_capacity == 0 && freed_slots.empty(); }
};

/** @brief Result of allocate(): the slot of the new landmark (-1: full, nothing deletable) and the changes. */
struct Allocation {
  int slot = -1;
  PoolChanges changes;
};

/** @brief One (measurement, pool landmark) pair. */
struct Association {
  int measurement = -1;
  int slot = -1;
  double descriptor_distance = 0.0;  //!< L2
  double mahalanobis_sq = 0.0;       //!< squared Mahalanobis distance returned by the gate
};

struct AssociationResult {
  std::vector<Association> matches;    //!< accepted associations, ascending measurement, distinct slots
  std::vector<int> unassociated;       //!< measurements without a match (candidates for new landmarks)
  std::vector<int> contested;          //!< subset of unassociated: lost their landmark to another measurement
  std::vector<int> ratio_rejected;     //!< subset of unassociated: had candidates but failed the ratio test
  std::vector<Association> forks;      //!< fork losers: duplicates of the measurement's associated landmark
  std::vector<int> duplicate_slots;    //!< slots of the fork losers to delete (ascending, unique)
  long gate_calls = 0;                 //!< diagnostics: calls of the gate function
};

/** gate(slot, measurement) -> squared Mahalanobis distance of the innovation, +inf if not computable. */
using MahalanobisGate = std::function<double(int slot, int measurement)>;

class LandmarkPool {
 public:
  /** @param rig_dim error-state dimension before the first landmark (>= 0).
   *  @throws std::invalid_argument for bad options or rig_dim. */
  explicit LandmarkPool(int rig_dim, const LandmarkPoolOptions& options = LandmarkPoolOptions());

  /** @brief Starts a frame at `time` (s, finite, >= the previous frame's time). Closes the previous frame:
   *  landmarks not observed in it get run length 0; stale landmarks are pruned (returned as freed). */
  PoolChanges beginFrame(double time);

  /** @brief Proposes associations of this frame's measurements with the pool (does not modify the pool).
   *  @throws std::invalid_argument if a descriptor's length differs from the pool's or is not finite. */
  AssociationResult associate(const std::vector<std::vector<float>>& measurement_descriptors,
                              const MahalanobisGate& gate) const;

  /** @brief Applies an association result in the current frame: each match is marked observed with its
   *  measurement's descriptor and strength (strengths may be empty: strength unchanged), and the
   *  duplicate_slots still in use are freed. The caller may drop entries of result.matches beforehand.
   *  @throws std::logic_error before the first beginFrame(); std::invalid_argument for bad indices,
   *  free slots, a slot matched twice or already observed in this frame, or a duplicate also matched. */
  PoolChanges commit(const AssociationResult& result,
                     const std::vector<std::vector<float>>& measurement_descriptors,
                     const std::vector<float>& measurement_strengths = std::vector<float>());

  /** @brief Marks the landmark in `slot` observed in the current frame (run length, counts, descriptor,
   *  strength, last seen). @throws as commit(). */
  void markObserved(int slot, const std::vector<float>& descriptor, float strength);

  /** @brief A slot for a new landmark observed in the current frame (lowest free slot; grows or evicts
   *  when none is free). slot -1: full at max_capacity and every landmark observed in this frame.
   *  @throws std::logic_error before the first beginFrame(); std::invalid_argument for an empty, non-finite
   *  or wrongly sized descriptor or a non-finite strength. */
  Allocation allocate(const std::vector<float>& descriptor, float strength);

  /** @brief Deletes the landmark in `slot` (decided by the caller, e.g. a failed innovation check).
   *  @throws std::out_of_range for a slot outside [0, capacity()), std::invalid_argument for a free slot. */
  void release(int slot);

  // ---- accessors
  int capacity() const { return static_cast<int>(records_.size()); }
  int used() const { return used_; }
  std::int64_t everSeen() const { return next_id_; }
  bool inUse(int slot) const;                            //!< @throws std::out_of_range
  const LandmarkRecord& record(int slot) const;          //!< @throws std::out_of_range
  std::vector<int> slotsInUse() const;                   //!< ascending
  int slotOf(std::int64_t id) const;                     //!< -1 if no landmark in use has this id
  int stateIndex(int slot) const { return rig_dim_ + kLandmarkStateDim * slot; }
  int rigDim() const { return rig_dim_; }
  int descriptorSize() const { return descriptor_size_; }  //!< 0 until the first allocate()
  std::int64_t frame() const { return frame_; }            //!< 0 before the first beginFrame()
  double time() const { return time_; }
  const LandmarkPoolOptions& options() const { return options_; }

 private:
  void requireFrame(const char* who) const;
  void checkSlot(int slot, const char* who) const;
  void checkDescriptor(const std::vector<float>& d, const char* who) const;
  void freeSlot(int slot);
  int growTo() const;           // next capacity, or capacity() at max
  int evictionVictim() const;   // -1 if nothing is deletable

  LandmarkPoolOptions options_;
  int rig_dim_ = 0;
  std::vector<LandmarkRecord> records_;
  std::vector<float> descriptors_;  // capacity x descriptor_size_, contiguous (association inner loop)
  int descriptor_size_ = 0;
  int used_ = 0;
  std::int64_t next_id_ = 0;
  std::int64_t frame_ = 0;
  double time_ = -std::numeric_limits<double>::infinity();
};

}  // namespace slam
}  // namespace skin3d
