// SPDX-License-Identifier: BSD-3-Clause
// The site scan's pose graph: every fused frame's pose refined jointly against every other frame it overlaps
// (site_fusion.h, 2.), then the site fused again from the refined poses. Ceres is used here only.
#include <ceres/ceres.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <vector>

#include "site_detail.h"

namespace skin3d {
namespace site {
namespace site_detail {

namespace {

/** The pose graph's weak prior on each frame's pose as given (rad, m): a hand-held recording's poses, from whatever
 *  source, are that good. The skin's relief cannot hold a frame's slide along or turn about a limb's axis; the prior
 *  holds those, and yields wherever the surface speaks (thousands of blocks of ~50 um fix a pose to micrometres). */
constexpr double kPriorRotation = 5e-3, kPriorTranslation = 1e-3;
/** At most this many passes of summaries, solve and fusion (SiteFusion::refine). */
constexpr int kGraphPasses = 3;
/** Every this many samples go into the block summaries: a 2 mm block still holds tens of them at the thesis rig's
 *  footprint (0.09 mm), enough for its plaque ramps to hold a frame's slide along the skin (every 16th, the
 *  registration's sampling, left frames a quarter millimetre off along the skin in the unit test). */
constexpr int kGraphSampleStride = 4;

/** Two frames' offsets from the fused surface over one block, each a linear function of its pose (BlockSummary):
 *  their difference over its sigma. The fused surface is common to both and cancels. */
struct BlockPairCost {
  BlockPairCost(const BlockSummary& a, const BlockSummary& b) : a_(a), b_(b), inv_sigma_(1.0 / std::sqrt(a.var + b.var)) {}
  template <typename T>
  bool operator()(const T* qa, const T* ta, const T* qb, const T* tb, T* r) const {
    r[0] = (offset(a_, qa, ta) - offset(b_, qb, tb)) * T(inv_sigma_);
    return true;
  }
  template <typename T>
  static T offset(const BlockSummary& s, const T* q, const T* t) {
    const Eigen::Matrix<T, 3, 3> R = Eigen::Map<const Eigen::Quaternion<T>>(q).toRotationMatrix();
    return (R * s.M.cast<T>()).trace() + s.n.cast<T>().dot(Eigen::Map<const Eigen::Matrix<T, 3, 1>>(t)) - T(s.c);
  }
  BlockSummary a_, b_;
  double inv_sigma_;
};

/** A weak prior on a frame's pose as given: (rotation vector of R_given^T R) / sigma_r, (t - t_given) / sigma_t. */
struct PosePrior {
  PosePrior(const Eigen::Isometry3d& given, double sigma_r, double sigma_t)
      : q_(Eigen::Quaterniond(given.linear()).normalized()), t_(given.translation()), ir_(1.0 / sigma_r), it_(1.0 / sigma_t) {}
  template <typename T>
  bool operator()(const T* q, const T* t, T* r) const {
    const Eigen::Quaternion<T> e = q_.conjugate().cast<T>() * Eigen::Map<const Eigen::Quaternion<T>>(q);
    const T s = e.w() < T(0) ? T(-2) : T(2);  // small angles: the rotation vector is 2 vec(e), e.w() > 0
    for (int k = 0; k < 3; ++k) {
      r[k] = s * e.vec()[k] * T(ir_);
      r[3 + k] = (t[k] - T(t_[k])) * T(it_);
    }
    return true;
  }
  Eigen::Quaterniond q_;
  Eigen::Vector3d t_;
  double ir_, it_;
};

}  // namespace

ceres::CostFunction* blockPairCost(const BlockSummary& a, const BlockSummary& b) {
  return new ceres::AutoDiffCostFunction<BlockPairCost, 1, 4, 3, 4, 3>(new BlockPairCost(a, b));
}

double blockOffset(const BlockSummary& s, const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  return BlockPairCost::offset(s, q.coeffs().data(), T.translation().data());
}

std::vector<BlockSummary> blockSummaries(const FusionGrid& g, const View& view, const std::vector<Sample>& samples,
                                         const Eigen::Isometry3d& T, double block, int stride, double noise2, double corr) {
  const int B = std::max(1, static_cast<int>(std::lround(block / g.cell)));
  const int nbu = (g.nu + B - 1) / B;
  struct Acc {
    double w = 0, w2v = 0, c = 0;
    int n = 0;
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    Eigen::Vector3d nsum = Eigen::Vector3d::Zero();
  };
  std::map<long, Acc> acc;
  for (std::size_t k = 0; k < samples.size(); k += static_cast<std::size_t>(stride)) {
    const Sample& s = samples[k];
    Eigen::Vector3d Xw, uvw;
    const double ci = incidenceCos(g, view, T, s.X, &Xw, &uvw);
    if (ci < view.cos_max) continue;
    double val, sig, su, sv;
    if (!g.lookup(uvw.x(), uvw.y(), &val, &sig, &su, &sv)) continue;
    int ic, jc;
    g.cellOf(uvw.x(), uvw.y(), &ic, &jc);
    Eigen::Vector3d P;
    const Eigen::Vector3d n = g.tangentPlane(uvw, val, su, sv, &P);
    const double sg2 = static_cast<double>(s.sigma) * s.sigma;
    const double w = ci * ci / sg2, var = std::max(noise2, sg2) * corr;
    Acc& a = acc[static_cast<long>(jc / B) * nbu + ic / B];
    a.w += w;
    a.w2v += w * w * var;
    a.M += w * s.X * n.transpose();
    a.nsum += w * n;
    a.c += w * n.dot(P);
    ++a.n;
  }
  std::vector<BlockSummary> out;
  const int min_samples = std::max(1, B * B / (2 * stride));
  for (const auto& [key, a] : acc) {
    if (a.n < min_samples) continue;
    BlockSummary s;
    s.block = key;
    s.M = a.M / a.w;
    s.n = a.nsum / a.w;
    s.c = a.c / a.w;
    s.var = std::min(a.w2v / (a.w * a.w), std::max(noise2, 1e-18));  // within one correlation area: its noise
    out.push_back(s);
  }
  return out;
}

ceres::CostFunction* posePriorCost(const Eigen::Isometry3d& given, double sigma_r, double sigma_t) {
  return new ceres::AutoDiffCostFunction<PosePrior, 6, 4, 3>(new PosePrior(given, sigma_r, sigma_t));
}

SitePoseGraph solvePoseGraph(const std::vector<std::vector<BlockSummary>>& blocks, int fixed, const std::vector<Eigen::Isometry3d>& given,
                             std::vector<Eigen::Isometry3d>* poses, int max_iterations) {
  const auto t0 = std::chrono::steady_clock::now();
  const int n = static_cast<int>(blocks.size());
  SitePoseGraph rep;
  std::vector<Eigen::Quaterniond> q(n);
  std::vector<Eigen::Vector3d> t(n);
  for (int i = 0; i < n; ++i) {
    q[i] = Eigen::Quaterniond((*poses)[i].linear()).normalized();
    t[i] = (*poses)[i].translation();
  }
  // the blocks each frame has, by block; a pair of frames is an edge where they share blocks
  std::vector<std::map<long, int>> index(n);
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < static_cast<int>(blocks[i].size()); ++k) index[i][blocks[i][k].block] = k;
  ceres::Problem::Options po;
  po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::EigenQuaternionManifold quaternion;
  // every block two frames share, and its difference at the poses as they are (in its sigma)
  struct Edge {
    int i, ki, j, kj;
  };
  std::vector<Edge> edges;
  std::vector<std::pair<int, int>> pairs;
  std::vector<double> z;
  double before2 = 0;
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      int shared = 0;
      for (const auto& [b, k] : index[i]) {
        const auto it = index[j].find(b);
        if (it == index[j].end()) continue;
        const BlockSummary &a = blocks[i][k], &c = blocks[j][it->second];
        const double d = blockOffset(a, (*poses)[i]) - blockOffset(c, (*poses)[j]);
        before2 += d * d;
        z.push_back(std::fabs(d) / std::sqrt(a.var + c.var));
        edges.push_back({i, k, j, it->second});
        ++shared;
      }
      if (shared > 0) pairs.emplace_back(i, j);
      rep.blocks += shared;
    }
  // Huber at twice the differences' robust scale (in sigma; at least 1): differences beyond it (a plaque's ramp seen
  // a little apart, a wrong match) count linearly. The scale follows the data, as in the frame's registration: far
  // from their place the frames disagree by much more than their noise, and their ramps must still pull them home.
  double scale = 1;
  if (!z.empty()) {
    std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
    scale = std::max(1.0, 1.4826 * z[z.size() / 2]);
  }
  rep.pairs = static_cast<int>(pairs.size());
  if (edges.empty()) {
    rep.message = "no two frames share a block: nothing to refine";
    return rep;
  }
  ceres::HuberLoss* loss = new ceres::HuberLoss(2.0 * scale);  // the problem owns it (once, however many blocks share it)
  for (const Edge& e : edges)
    problem.AddResidualBlock(blockPairCost(blocks[e.i][e.ki], blocks[e.j][e.kj]), loss, q[e.i].coeffs().data(), t[e.i].data(),
                             q[e.j].coeffs().data(), t[e.j].data());
  for (int i = 0; i < n; ++i) {
    if (!problem.HasParameterBlock(q[i].coeffs().data())) continue;
    problem.SetManifold(q[i].coeffs().data(), &quaternion);
    problem.AddResidualBlock(posePriorCost(given[i], kPriorRotation, kPriorTranslation), nullptr, q[i].coeffs().data(), t[i].data());
    if (i == fixed) {
      problem.SetParameterBlockConstant(q[i].coeffs().data());
      problem.SetParameterBlockConstant(t[i].data());
    }
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;  // a few frames' poses: a small dense system
  so.max_num_iterations = max_iterations;
  so.num_threads = 2;
  so.function_tolerance = 1e-10;
  so.parameter_tolerance = 1e-12;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  rep.iterations = static_cast<int>(summary.iterations.size()) - 1;
  rep.converged = summary.termination_type == ceres::CONVERGENCE;
  rep.message = summary.message;
  double after2 = 0;
  std::vector<Eigen::Isometry3d> refined(n);
  for (int i = 0; i < n; ++i) {
    refined[i] = Eigen::Isometry3d::Identity();
    refined[i].linear() = q[i].normalized().toRotationMatrix();
    refined[i].translation() = t[i];
  }
  for (const auto& [i, j] : pairs)
    for (const auto& [b, k] : index[i]) {
      const auto it = index[j].find(b);
      if (it == index[j].end()) continue;
      const double d = blockOffset(blocks[i][k], refined[i]) - blockOffset(blocks[j][it->second], refined[j]);
      after2 += d * d;
    }
  rep.rms_before = std::sqrt(before2 / rep.blocks);
  rep.rms_after = std::sqrt(after2 / rep.blocks);
  rep.used = summary.IsSolutionUsable();
  if (rep.used) *poses = refined;
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return rep;
}

}  // namespace site_detail

const SitePoseGraph& SiteFusion::refine() {
  const auto t0 = std::chrono::steady_clock::now();
  graph_ = SitePoseGraph();
  if (!options_.pose_graph || !grid_ || kept_.size() < 2) return graph_;
  site_detail::FusionGrid& g = *grid_;
  const int n = static_cast<int>(kept_.size());
  std::vector<Eigen::Isometry3d> poses(n), given(n);
  for (int i = 0; i < n; ++i) given[i] = frames_[kept_[i]->index].pose_given;
  graph_.run = true;
  graph_.frames = n;
  // passes: the summaries' tangent planes come from the site fused before the pass; fused again from the refined
  // poses, they are sharper, and a further pass gains where the first started far off. It stops when a pass removes
  // less than a tenth of what was left.
  for (int pass = 0; pass < site_detail::kGraphPasses; ++pass) {
    std::vector<std::vector<site_detail::BlockSummary>> blocks(n);
    for (int i = 0; i < n; ++i) {
      const site_detail::KeptFrame& k = *kept_[i];
      poses[i] = frames_[k.index].pose;
      const double corr = std::isfinite(k.noise_correlation_px2) ? std::max(1.0, k.noise_correlation_px2) : 1.0;
      const double noise2 = std::isfinite(k.height_noise) ? k.height_noise * k.height_noise : 0.0;
      blocks[i] = site_detail::blockSummaries(g, k.view, k.samples, poses[i], options_.seam_block, site_detail::kGraphSampleStride, noise2, corr);
    }
    const SitePoseGraph p = site_detail::solvePoseGraph(blocks, 0, given, &poses);
    if (pass == 0) {
      graph_.pairs = p.pairs;
      graph_.blocks = p.blocks;
      graph_.rms_before = p.rms_before;
    }
    graph_.iterations += p.iterations;
    graph_.converged = p.converged;
    graph_.message = p.message;
    graph_.rms_after = p.rms_after;
    graph_.passes = pass + 1;
    if (!p.used) break;
    graph_.used = true;
    refuse(poses);
    if (!(p.rms_after < 0.9 * p.rms_before)) break;
  }
  graph_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return graph_;
}

void SiteFusion::refuse(const std::vector<Eigen::Isometry3d>& poses) {
  // the site fused again, in the same order, from the poses given per kept frame (the seams are measured again)
  site_detail::FusionGrid& g = *grid_;
  std::fill(g.sw.begin(), g.sw.end(), 0.f);
  std::fill(g.swh.begin(), g.swh.end(), 0.0);
  std::fill(g.sw2v.begin(), g.sw2v.end(), 0.f);
  std::fill(g.count.begin(), g.count.end(), 0);
  std::fill(g.best.begin(), g.best.end(), 0);
  std::fill(g.bestw.begin(), g.bestw.end(), 0.f);
  std::fill(g.last.begin(), g.last.end(), -1);
  const std::size_t stride = static_cast<std::size_t>(options_.register_stride * options_.register_stride);
  for (std::size_t i = 0; i < kept_.size(); ++i) {
    const site_detail::KeptFrame& k = *kept_[i];
    SiteFrame& F = frames_[k.index];
    F.pose = poses[i];
    induration::IndurationResult own;  // what the fusion reads of the frame's own measurement
    own.height_noise = k.height_noise;
    own.noise_correlation_px2 = k.noise_correlation_px2;
    long on_old = 0;
    F.samples = site_detail::fuseFrame(g, k.view, k.samples, own, options_, &F, &on_old);
    double c2 = 0;
    long m = 0;
    for (std::size_t q = 0; q < k.samples.size(); q += stride, ++m)
      c2 += (F.pose * k.samples[q].X - F.pose_given * k.samples[q].X).squaredNorm();
    F.correction_rms = m > 0 ? std::sqrt(c2 / m) : 0.0;
  }
}

}  // namespace site
}  // namespace skin3d
