// SPDX-License-Identifier: BSD-3-Clause
// The ES-EKF SLAM frame loop (see slam_system.h).
#include "skin3d/slam/slam_system.h"

#include <Eigen/Cholesky>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <unordered_map>

namespace skin3d {
namespace slam {

namespace {
bool validMeasurement(const Measurement& m) {
  if (!m.z.allFinite() || !m.C.allFinite() || !(m.z.z() > 0.0)) return false;
  if ((m.C - m.C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * std::max(1e-30, m.C.cwiseAbs().maxCoeff())) return false;
  Eigen::LLT<Eigen::Matrix3d> llt(m.C);
  if (llt.info() != Eigen::Success) return false;
  for (float d : m.descriptor)
    if (!std::isfinite(d)) return false;
  return std::isfinite(m.strength);
}

double descriptorDistance(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return std::numeric_limits<double>::infinity();
  double s = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double d = static_cast<double>(a[i]) - b[i];
    s += d * d;
  }
  return std::sqrt(s);
}
}  // namespace

void SlamOptions::validate() const {
  filter.validate();
  pool.validate();
  auto bad = [](const std::string& field, double v) {
    throw std::invalid_argument("slam option '" + field + "' has a bad value (" + std::to_string(v) + ")");
  };
  if (!(gyro_noise > 0.0) || !std::isfinite(gyro_noise)) bad("gyro_noise", gyro_noise);
  if (max_updates_per_frame < 1) bad("max_updates_per_frame (>= 1)", max_updates_per_frame);
  if (max_new_per_frame < 0) bad("max_new_per_frame (>= 0)", max_new_per_frame);
  if (min_tracked_for_no_new < 0) bad("min_tracked_for_no_new (>= 0)", min_tracked_for_no_new);
  if (!(max_depth > 0.0)) bad("max_depth (> 0)", max_depth);
  if (consensus_iterations < 0) bad("consensus_iterations (>= 0)", consensus_iterations);
  if (!(consensus_gate > 0.0)) bad("consensus_gate (> 0)", consensus_gate);
  if (smoother != "off" && smoother != "batch")
    throw std::invalid_argument("slam option 'smoother' is '" + smoother + "', not one of off, batch");
  if (!(smoother_huber > 0.0) || !std::isfinite(smoother_huber)) bad("smoother_huber (> 0)", smoother_huber);
  if (smoother_iterations < 1) bad("smoother_iterations (>= 1)", smoother_iterations);
  if (!(smoother_loop_radius >= 0.0) || !std::isfinite(smoother_loop_radius)) bad("smoother_loop_radius (>= 0)", smoother_loop_radius);
  if (!(measurement_white_fraction > 0.0 && measurement_white_fraction <= 1.0))
    bad("measurement_white_fraction (in (0, 1])", measurement_white_fraction);
}

SlamSystem::SlamSystem(const SlamOptions& options)
    : opt_((options.validate(), options)), filter_(options.filter), pool_(filter_.rigDim(), options.pool) {
  filter_.setCapacity(pool_.capacity());
}

void SlamSystem::reset() {
  filter_ = Eskf(opt_.filter);
  pool_ = LandmarkPool(filter_.rigDim(), opt_.pool);
  filter_.setCapacity(pool_.capacity());
  initialised_ = false;
  time_ = 0.0;
  gyro_.clear();
}

void SlamSystem::setInitialTwist(const Eigen::Vector3d& v, const Eigen::Vector3d& w) {
  if (!v.allFinite() || !w.allFinite()) throw std::invalid_argument("initial twist: velocities must be finite");
  initial_v_ = v;
  initial_w_ = w;
}

void SlamSystem::setKnownMap(const std::vector<Eigen::Vector3d>& positions,
                             const std::vector<std::vector<float>>& descriptors) {
  if (positions.size() != descriptors.size())
    throw std::invalid_argument("known map: " + std::to_string(positions.size()) + " positions but " +
                                std::to_string(descriptors.size()) + " descriptors");
  for (size_t i = 0; i < positions.size(); ++i)
    if (!positions[i].allFinite()) throw std::invalid_argument("known map: position " + std::to_string(i) + " is not finite");
  known_positions_ = positions;
  known_descriptors_ = descriptors;
}

void SlamSystem::addGyro(double time, const Eigen::Vector3d& omega, const Eigen::Matrix3d& covariance) {
  if (!opt_.use_gyro) return;  // ignored, bad or not: without use_gyro a gyro sample never stops a run
  if (!std::isfinite(time) || !omega.allFinite() || !covariance.allFinite())
    throw std::invalid_argument("gyro sample: time, angular velocity and covariance must be finite");
  Eigen::Matrix3d C = covariance;
  if (C.isZero(0.0)) C = opt_.gyro_noise * opt_.gyro_noise * Eigen::Matrix3d::Identity();
  Eigen::LLT<Eigen::Matrix3d> llt(C);
  if (llt.info() != Eigen::Success) throw std::invalid_argument("gyro sample: covariance is not positive definite");
  // Keep the buffer sorted by time (samples normally arrive in order).
  auto it = gyro_.end();
  while (it != gyro_.begin() && std::prev(it)->first > time) --it;
  gyro_.insert(it, {time, {omega, C}});
}

void SlamSystem::predictTo(double t, FrameStats* stats) {
  // Predict to each gyro sample and fuse it, in one call: the filter carries the steps on the rig block
  // and updates the landmark blocks once (Eskf::propagateWithGyro).
  std::vector<Eskf::GyroStep> steps;
  while (!gyro_.empty() && gyro_.front().first <= t) {
    const auto g = gyro_.front();
    gyro_.pop_front();
    if (g.first < time_) {
      ++stats->gyro_dropped;
      continue;
    }
    steps.push_back({g.first - time_, g.second.first, g.second.second});
    time_ = g.first;
    ++stats->gyro_used;
  }
  filter_.propagateWithGyro(steps);
  if (t > time_) {
    filter_.predict(t - time_);
    time_ = t;
  }
}

void SlamSystem::applyChanges(const PoolChanges& changes, FrameStats* stats) {
  if (changes.new_capacity > filter_.capacity()) filter_.setCapacity(changes.new_capacity);
  for (int s : changes.freed_slots) {
    if (filter_.isActive(s)) filter_.removeLandmark(s);
    if (stats) ++stats->pruned;
  }
}

FrameStats SlamSystem::processFrame(double time, const std::vector<Measurement>& input) {
  if (!std::isfinite(time)) throw std::invalid_argument("frame time is not finite");
  if (initialised_ && !(time > time_))
    throw std::invalid_argument("frame time " + std::to_string(time) + " s is not after the previous frame (" +
                                std::to_string(time_) + " s)");
  FrameStats stats;
  stats.time = time;
  stats.measurements = static_cast<int>(input.size());
  std::vector<Measurement> meas;
  std::vector<int> input_index;  // meas[i] is input[input_index[i]]
  meas.reserve(input.size());
  last_ids_.assign(input.size(), -1);
  for (std::size_t i = 0; i < input.size(); ++i) {
    const Measurement& m = input[i];
    if (validMeasurement(m) && (meas.empty() || m.descriptor.size() == meas.front().descriptor.size())) {
      meas.push_back(m);
      input_index.push_back(static_cast<int>(i));
    } else {
      ++stats.rejected_invalid;
    }
  }

  if (!initialised_) {
    RigState x0;
    x0.v = initial_v_;
    x0.w = initial_w_;
    x0.gyro_bias = opt_.filter.initial_gyro_bias;
    filter_.reset(x0);
    // Gyro samples before the first frame cannot be used (no state yet).
    while (!gyro_.empty() && gyro_.front().first <= time) {
      gyro_.pop_front();
      ++stats.gyro_dropped;
    }
    time_ = time;
    initialised_ = true;
  } else {
    predictTo(time, &stats);
  }
  if (!known_positions_.empty()) return knownMapFrame(time, meas, stats);
  // Mapped landmarks are gated, checked and updated with the white part of each covariance (options);
  // new landmarks are placed with the whole of it.
  std::vector<Eigen::Matrix3d> white(meas.size());
  for (size_t i = 0; i < meas.size(); ++i) white[i] = opt_.measurement_white_fraction * meas[i].C;

  applyChanges(pool_.beginFrame(time), &stats);

  // Association: descriptor + Mahalanobis gate through the filter.
  std::vector<std::vector<float>> descs(meas.size());
  std::vector<float> strengths(meas.size());
  for (size_t i = 0; i < meas.size(); ++i) {
    descs[i] = meas[i].descriptor;
    strengths[i] = meas[i].strength;
  }
  const RigState& x = filter_.state();
  const Eigen::Matrix3d Rt = x.q.toRotationMatrix().transpose();
  const MahalanobisGate gate = [&](int slot, int mi) {
    if (!filter_.isActive(slot)) return std::numeric_limits<double>::infinity();
    const Eigen::Vector3d zc = Rt * (filter_.landmark(slot) - x.p);
    if (!(zc.z() > 0.0) || zc.z() > opt_.max_depth) return std::numeric_limits<double>::infinity();
    return filter_.mahalanobis(Eskf::Observation{slot, meas[mi].z, white[mi]});
  };
  AssociationResult a = meas.empty() ? AssociationResult() : pool_.associate(descs, gate);
  stats.associated = static_cast<int>(a.matches.size());
  if (opt_.consensus_iterations > 0 && a.matches.size() >= 4) {
    const std::vector<bool> ok = consensus(a.matches, meas, white);
    std::vector<Association> kept;
    for (size_t i = 0; i < a.matches.size(); ++i) {
      if (ok[i]) {
        kept.push_back(a.matches[i]);
      } else {
        a.unassociated.push_back(a.matches[i].measurement);
        ++stats.rejected_consensus;
      }
    }
    // A fork duplicate only counts if its measurement's association survived.
    std::vector<int> dup;
    for (const auto& f : a.forks) {
      const bool survived = std::any_of(kept.begin(), kept.end(), [&](const Association& k) { return k.measurement == f.measurement; });
      if (survived) dup.push_back(f.slot);
    }
    std::sort(dup.begin(), dup.end());
    dup.erase(std::unique(dup.begin(), dup.end()), dup.end());
    a.duplicate_slots = dup;
    a.matches.swap(kept);
    std::sort(a.unassociated.begin(), a.unassociated.end());
    stats.associated = static_cast<int>(a.matches.size());
  }

  // Update with the strongest associated measurements.
  std::vector<Association> use = a.matches;
  std::stable_sort(use.begin(), use.end(), [&](const Association& l, const Association& r) {
    return meas[l.measurement].strength > meas[r.measurement].strength;
  });
  if (static_cast<int>(use.size()) > opt_.max_updates_per_frame) use.resize(opt_.max_updates_per_frame);
  std::vector<Eskf::Observation> obs;
  obs.reserve(use.size());
  for (const auto& u : use) obs.push_back({u.slot, meas[u.measurement].z, white[u.measurement]});
  if (!obs.empty()) {
    const Eskf::UpdateResult r = filter_.update(obs);
    stats.used = r.used;
    stats.nis = r.nis;
    stats.nis_dof = r.dof;
  }
  for (const auto& u : a.matches) last_ids_[input_index[u.measurement]] = pool_.record(u.slot).id;
  const int before_forks = pool_.used();
  const PoolChanges fork_changes = pool_.commit(a, descs, strengths);
  stats.forks_deleted = before_forks - pool_.used();
  for (int s : fork_changes.freed_slots)
    if (filter_.isActive(s)) filter_.removeLandmark(s);

  // New landmarks from the strongest unassociated measurements.
  if (opt_.min_tracked_for_no_new == 0 || stats.associated < opt_.min_tracked_for_no_new) {
    std::vector<int> fresh = a.unassociated;
    std::stable_sort(fresh.begin(), fresh.end(), [&](int l, int r) { return meas[l].strength > meas[r].strength; });
    for (int mi : fresh) {
      if (stats.initialised >= opt_.max_new_per_frame) break;
      const Allocation al = pool_.allocate(descs[mi], strengths[mi]);
      applyChanges(al.changes, &stats);
      if (al.slot < 0) break;  // full, every landmark observed in this frame
      filter_.addLandmark(al.slot, meas[mi].z, meas[mi].C);
      last_ids_[input_index[mi]] = pool_.record(al.slot).id;
      ++stats.initialised;
    }
  }
  return stats;
}

std::vector<bool> SlamSystem::consensus(const std::vector<Association>& matches, const std::vector<Measurement>& meas,
                                        const std::vector<Eigen::Matrix3d>& covariances) const {
  // Rigid motion world <- camera from 3 pairs (Kabsch), inliers by the Mahalanobis distance of
  // R z + t - m under C_m + R C_z R^T; the hypothesis with most inliers wins (ties: smaller sum of d^2).
  const size_t n = matches.size();
  std::vector<Eigen::Vector3d> m(n), z(n);
  std::vector<Eigen::Matrix3d> Cm(n), Cz(n);
  for (size_t i = 0; i < n; ++i) {
    m[i] = filter_.landmark(matches[i].slot);
    Cm[i] = filter_.landmarkCovariance(matches[i].slot);
    z[i] = meas[matches[i].measurement].z;
    Cz[i] = covariances[matches[i].measurement];
  }
  auto inliers = [&](const Eigen::Matrix3d& R, const Eigen::Vector3d& t, std::vector<bool>* in, double* cost) {
    int count = 0;
    *cost = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d e = R * z[i] + t - m[i];
      const Eigen::Matrix3d S = Cm[i] + R * Cz[i] * R.transpose();
      const double d2 = e.dot(S.ldlt().solve(e));
      const bool ok = d2 <= opt_.consensus_gate;
      (*in)[i] = ok;
      count += ok;
      *cost += std::min(d2, opt_.consensus_gate);
    }
    return count;
  };
  auto kabsch = [&](const std::vector<size_t>& idx, Eigen::Matrix3d* R, Eigen::Vector3d* t) {
    Eigen::Vector3d cz = Eigen::Vector3d::Zero(), cm = Eigen::Vector3d::Zero();
    for (size_t i : idx) cz += z[i], cm += m[i];
    cz /= idx.size();
    cm /= idx.size();
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    for (size_t i : idx) H += (z[i] - cz) * (m[i] - cm).transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
    *R = svd.matrixV() * D * svd.matrixU().transpose();
    *t = cm - *R * cz;
  };
  // The current estimate is the first hypothesis (usually right: then the sampling only has to beat it).
  const RigState& x = filter_.state();
  std::vector<bool> best(n), cur(n);
  double best_cost = 0.0, cost = 0.0;
  int best_count = inliers(x.q.toRotationMatrix(), x.p, &best, &best_cost);
  std::uint64_t state = opt_.consensus_seed * 6364136223846793005ull + 1442695040888963407ull;
  auto next = [&state](size_t k) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<size_t>((state >> 33) % k);
  };
  for (int it = 0; it < opt_.consensus_iterations && best_count < static_cast<int>(n); ++it) {
    std::vector<size_t> idx = {next(n), next(n), next(n)};
    if (idx[0] == idx[1] || idx[0] == idx[2] || idx[1] == idx[2]) continue;
    // Degenerate (nearly collinear) samples give no rotation.
    if ((z[idx[1]] - z[idx[0]]).cross(z[idx[2]] - z[idx[0]]).norm() < 1e-6) continue;
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    kabsch(idx, &R, &t);
    const int c = inliers(R, t, &cur, &cost);
    if (c > best_count || (c == best_count && cost < best_cost)) {
      // Refit on the consensus set, then keep whichever labelling is better.
      std::vector<size_t> all;
      for (size_t i = 0; i < n; ++i)
        if (cur[i]) all.push_back(i);
      if (all.size() >= 3) {
        Eigen::Matrix3d R2;
        Eigen::Vector3d t2;
        kabsch(all, &R2, &t2);
        std::vector<bool> cur2(n);
        double cost2 = 0.0;
        const int c2 = inliers(R2, t2, &cur2, &cost2);
        if (c2 > c || (c2 == c && cost2 < cost)) {
          cur.swap(cur2);
          cost = cost2;
        }
      }
      best_count = static_cast<int>(std::count(cur.begin(), cur.end(), true));
      best.swap(cur);
      best_cost = cost;
    }
  }
  return best;
}

FrameStats SlamSystem::knownMapFrame(double, const std::vector<Measurement>& meas, FrameStats stats) {
  // Candidates: known landmarks whose predicted camera-frame position lies near a measurement (voxel hash),
  // within the Mahalanobis gate, then the closest descriptor.
  const RigState& x = filter_.state();
  const Eigen::Matrix3d Rt = x.q.toRotationMatrix().transpose();
  // Grid cell = the search radius: 3 sigma of the predicted pose error at the largest depth plus 1 cm.
  double max_depth_seen = 0.0;
  for (const auto& m : meas) max_depth_seen = std::max(max_depth_seen, m.z.norm());
  const Eigen::Matrix<double, 6, 6> Pp = filter_.poseCovariance();
  const double sp = std::sqrt(std::max(0.0, Pp.topLeftCorner<3, 3>().trace()));
  const double st = std::sqrt(std::max(0.0, Pp.bottomRightCorner<3, 3>().trace()));
  const double cell = std::max(0.01, 3.0 * (sp + st * max_depth_seen) + 0.01);
  auto key = [cell](const Eigen::Vector3d& p) {
    const auto i = static_cast<std::int64_t>(std::floor(p.x() / cell)) & 0x1FFFFF;
    const auto j = static_cast<std::int64_t>(std::floor(p.y() / cell)) & 0x1FFFFF;
    const auto k = static_cast<std::int64_t>(std::floor(p.z() / cell)) & 0x1FFFFF;
    return (i << 42) | (j << 21) | k;
  };
  std::unordered_multimap<std::int64_t, int> grid;
  std::vector<Eigen::Vector3d> zc(known_positions_.size());
  for (size_t i = 0; i < known_positions_.size(); ++i) {
    zc[i] = Rt * (known_positions_[i] - x.p);
    if (zc[i].z() > 0.0 && zc[i].z() < opt_.max_depth) grid.emplace(key(zc[i]), static_cast<int>(i));
  }
  std::vector<Eskf::KnownObservation> obs;
  std::vector<float> strength;
  std::vector<int> taken(known_positions_.size(), 0);
  for (const auto& m : meas) {
    // Candidates pass the gate (and the descriptor bound when the map has descriptors); the smallest
    // Mahalanobis distance wins.
    int best = -1;
    double best_d2 = opt_.pool.mahalanobis_gate;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto range = grid.equal_range(key(m.z + cell * Eigen::Vector3d(dx, dy, dz)));
          for (auto it = range.first; it != range.second; ++it) {
            const int k = it->second;
            if (taken[k]) continue;
            if (!known_descriptors_[k].empty() &&
                !(descriptorDistance(m.descriptor, known_descriptors_[k]) <= opt_.pool.max_descriptor_distance))
              continue;
            const double d2 = filter_.innovationKnown(Eskf::KnownObservation{known_positions_[k], m.z, m.C}).d2;
            if (d2 <= best_d2) {
              best_d2 = d2;
              best = k;
            }
          }
        }
    if (best < 0) continue;
    taken[best] = 1;
    obs.push_back({known_positions_[best], m.z, m.C});
    strength.push_back(m.strength);
  }
  stats.associated = static_cast<int>(obs.size());
  if (static_cast<int>(obs.size()) > opt_.max_updates_per_frame) {
    std::vector<size_t> order(obs.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](size_t l, size_t r) { return strength[l] > strength[r]; });
    std::vector<Eskf::KnownObservation> keep;
    for (int i = 0; i < opt_.max_updates_per_frame; ++i) keep.push_back(obs[order[i]]);
    obs.swap(keep);
  }
  if (!obs.empty()) {
    const Eskf::UpdateResult r = filter_.updateKnown(obs);
    stats.used = r.used;
    stats.nis = r.nis;
    stats.nis_dof = r.dof;
  }
  return stats;
}

std::vector<MapPoint> SlamSystem::map() const {
  std::vector<MapPoint> out;
  if (!known_positions_.empty()) {
    for (size_t i = 0; i < known_positions_.size(); ++i) out.push_back({static_cast<std::int64_t>(i), known_positions_[i], Eigen::Matrix3d::Zero(), 0});
    return out;
  }
  for (int s : pool_.slotsInUse()) {
    if (!filter_.isActive(s)) continue;
    const LandmarkRecord& r = pool_.record(s);
    out.push_back({r.id, filter_.landmark(s), filter_.landmarkCovariance(s), r.times_observed});
  }
  return out;
}

double SlamSystem::correlationVxWy() const {
  const Eigen::MatrixXd& C = filter_.covariance();
  const double vx = C(6, 6), wy = C(10, 10);
  if (!(vx > 0.0) || !(wy > 0.0)) return 0.0;
  return C(6, 10) / std::sqrt(vx * wy);
}

}  // namespace slam
}  // namespace skin3d
