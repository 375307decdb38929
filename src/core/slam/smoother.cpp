// SPDX-License-Identifier: BSD-3-Clause
// Batch smoother over a recording (see smoother.h): Ceres, landmarks eliminated by the Schur complement.
#include "skin3d/slam/smoother.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>

namespace skin3d {
namespace slam {

void SmootherOptions::validate() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument("smoother: " + what); };
  if (!(huber > 0)) bad("smoother_huber must be > 0");
  if (min_observations < 2) bad("smoother_min_observations must be >= 2");
  if (max_iterations < 1) bad("smoother_max_iterations must be >= 1");
  if (!(gyro_noise > 0)) bad("gyro_noise must be > 0");
  if (!(gyro_bias_walk > 0)) bad("gyro_bias_walk must be > 0");
  if (!(initial_gyro_bias_std > 0)) bad("initial_gyro_bias_std must be > 0");
  if (!(velocity_noise > 0)) bad("velocity_noise must be > 0");
  if (!initial_gyro_bias.allFinite()) bad("initial_gyro_bias must be finite");
  if (threads < 1) bad("threads must be >= 1");
  if (!(loop_radius >= 0) || !std::isfinite(loop_radius)) bad("smoother_loop_radius must be >= 0");
  if (!(loop_descriptor_distance > 0)) bad("the loop's descriptor distance must be > 0");
}

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}
Eigen::Matrix3d expSO3(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  if (a < 1e-12) return Eigen::Matrix3d::Identity() + skew(phi);
  return Eigen::AngleAxisd(a, phi / a).toRotationMatrix();
}
// Right Jacobian of SO(3): Exp(phi + d) ~ Exp(phi) Exp(Jr(phi) d).
Eigen::Matrix3d rightJacobian(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  const Eigen::Matrix3d K = skew(phi);
  if (a < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * K + K * K / 6.0;
  return Eigen::Matrix3d::Identity() - (1 - std::cos(a)) / (a * a) * K + (a - std::sin(a)) / (a * a * a) * K * K;
}

// Rotation of an Eigen-ordered quaternion (x, y, z, w) applied to a point.
template <typename T>
Eigen::Matrix<T, 3, 1> rotate(const T* q, const Eigen::Matrix<T, 3, 1>& v) {
  const T wxyz[4] = {q[3], q[0], q[1], q[2]};
  Eigen::Matrix<T, 3, 1> out;
  ceres::UnitQuaternionRotatePoint(wxyz, v.data(), out.data());
  return out;
}

// Landmark factor: L^-1 (R^T (m - p) - z).
struct LandmarkCost {
  LandmarkCost(const Eigen::Vector3d& z, const Eigen::Matrix3d& Linv, const double* scale)
      : z_(z), Linv_(Linv), scale_(scale) {}
  template <typename T>
  bool operator()(const T* q, const T* p, const T* m, T* r) const {
    const T qinv[4] = {-q[0], -q[1], -q[2], q[3]};
    const Eigen::Matrix<T, 3, 1> d(m[0] - p[0], m[1] - p[1], m[2] - p[2]);
    const Eigen::Matrix<T, 3, 1> c = rotate(qinv, d);
    const Eigen::Matrix<T, 3, 1> e = c - z_.cast<T>();
    Eigen::Map<Eigen::Matrix<T, 3, 1>> out(r);
    out = (*scale_ * Linv_).cast<T>() * e;
    return true;
  }
  Eigen::Vector3d z_;
  Eigen::Matrix3d Linv_;
  const double* scale_;  // 1 / sigma_0: the measurements' variance factor, estimated (smooth())
};

// Gyro factor: W Log((dR Exp(J (b - b_lin)))^T R_i^T R_j).
struct GyroCost {
  GyroCost(const GyroDelta& g, const Eigen::Matrix3d& W) : g_(g), W_(W), dq_(g.dR) {}
  template <typename T>
  bool operator()(const T* qi, const T* qj, const T* b, T* r) const {
    Eigen::Matrix<T, 3, 1> db(b[0] - T(g_.bias_lin.x()), b[1] - T(g_.bias_lin.y()), b[2] - T(g_.bias_lin.z()));
    const Eigen::Matrix<T, 3, 1> corr = g_.J_bias.cast<T>() * db;
    T cq[4];  // w, x, y, z
    ceres::AngleAxisToQuaternion(corr.data(), cq);
    const Eigen::Quaternion<T> c(cq[0], cq[1], cq[2], cq[3]);
    const Eigen::Quaternion<T> pred = dq_.cast<T>() * c;
    const Eigen::Quaternion<T> Qi(qi[3], qi[0], qi[1], qi[2]), Qj(qj[3], qj[0], qj[1], qj[2]);
    const Eigen::Quaternion<T> err = pred.conjugate() * (Qi.conjugate() * Qj);
    const T ewxyz[4] = {err.w(), err.x(), err.y(), err.z()};
    Eigen::Matrix<T, 3, 1> phi;
    ceres::QuaternionToAngleAxis(ewxyz, phi.data());
    Eigen::Map<Eigen::Matrix<T, 3, 1>> out(r);
    out = W_.cast<T>() * phi;
    return true;
  }
  GyroDelta g_;
  Eigen::Matrix3d W_;
  Eigen::Quaterniond dq_;
};

struct BiasWalkCost {
  explicit BiasWalkCost(double inv_sigma) : w_(inv_sigma) {}
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    for (int i = 0; i < 3; ++i) r[i] = T(w_) * (b[i] - a[i]);
    return true;
  }
  double w_;
};

struct BiasPriorCost {
  BiasPriorCost(const Eigen::Vector3d& mean, double inv_sigma) : mean_(mean), w_(inv_sigma) {}
  template <typename T>
  bool operator()(const T* b, T* r) const {
    for (int i = 0; i < 3; ++i) r[i] = T(w_) * (b[i] - T(mean_[i]));
    return true;
  }
  Eigen::Vector3d mean_;
  double w_;
};

// The filter's motion model: the velocity in the rig's frame, v_k = R_k^T (p_k+1 - p_k) / dt_k, changes from frame
// to frame by its random walk (velocity_noise sqrt(dt)). (In the world's frame a turning rig's velocity turns too.)
struct MotionCost {
  MotionCost(double dt1, double dt2, double sigma_v) : dt1_(dt1), dt2_(dt2) {
    w_ = 1.0 / (sigma_v * std::sqrt(0.5 * (dt1 + dt2)));
  }
  template <typename T>
  bool operator()(const T* qa, const T* qb, const T* a, const T* b, const T* c, T* r) const {
    const T qai[4] = {-qa[0], -qa[1], -qa[2], qa[3]}, qbi[4] = {-qb[0], -qb[1], -qb[2], qb[3]};
    const Eigen::Matrix<T, 3, 1> va = rotate(qai, Eigen::Matrix<T, 3, 1>(b[0] - a[0], b[1] - a[1], b[2] - a[2])) / T(dt1_);
    const Eigen::Matrix<T, 3, 1> vb = rotate(qbi, Eigen::Matrix<T, 3, 1>(c[0] - b[0], c[1] - b[1], c[2] - b[2])) / T(dt2_);
    for (int i = 0; i < 3; ++i) r[i] = T(w_) * (vb[i] - va[i]);
    return true;
  }
  double dt1_, dt2_, w_;
};

// The marginal covariances of the solution, from J^T J of the whitened (and robustified) residuals at it, the
// landmarks, the poses after the first (held fixed: it defines the world) and the estimated biases its
// variables: a sparse LDL^T (AMD ordering), solved for the bias columns and forward-substituted for each pose's, a
// few frames at a time. Poses come out as [p, theta] (m, rad; theta the world-frame rotation error: the manifold
// perturbs on the left); zero where the factorisation failed or a block is not positive definite.
void marginalCovariances(ceres::Problem& problem, std::map<std::int64_t, Eigen::Vector3d>& m,
                         std::vector<Eigen::Vector4d>& q, std::vector<Eigen::Vector3d>& p,
                         std::vector<Eigen::Vector3d>* b, int threads, std::vector<Matrix6d>* poses,
                         Eigen::Matrix3d* last_bias, Eigen::Matrix3d* mean_bias) {
  const std::size_t n = q.size();
  poses->assign(n, Matrix6d::Zero());
  last_bias->setZero();
  mean_bias->setZero();
  ceres::Problem::EvaluateOptions eo;
  for (auto& kv : m) eo.parameter_blocks.push_back(kv.second.data());
  const int first_pose = 3 * static_cast<int>(m.size());
  for (std::size_t k = 1; k < n; ++k) {
    eo.parameter_blocks.push_back(q[k].data());  // columns first_pose + 6 (k - 1): theta, then p
    eo.parameter_blocks.push_back(p[k].data());
  }
  if (b)
    for (auto& x : *b) eo.parameter_blocks.push_back(x.data());  // the last bias: the last 3 columns
  eo.num_threads = threads;
  ceres::CRSMatrix J;
  double cost = 0;
  if (!problem.Evaluate(eo, &cost, nullptr, nullptr, &J)) return;
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(J.values.size());
  for (int r = 0; r < J.num_rows; ++r)
    for (int i = J.rows[r]; i < J.rows[r + 1]; ++i) t.emplace_back(r, J.cols[i], J.values[i]);
  Eigen::SparseMatrix<double> Js(J.num_rows, J.num_cols);
  Js.setFromTriplets(t.begin(), t.end());
  const Eigen::SparseMatrix<double> H = Eigen::SparseMatrix<double>(Js.transpose()) * Js;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(H);
  if (ldlt.info() != Eigen::Success) return;
  auto positive = [](const Eigen::MatrixXd& C) {
    return C.allFinite() && Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(C).eigenvalues().minCoeff() > 0;
  };
  if (b) {  // the last bias (columns 0-2) and the mean of all (3-5): a^T H^-1 a, a the averaging vector
    const int nb = static_cast<int>(b->size()), b0 = J.num_cols - 3 * nb;
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(J.num_cols, 6);
    for (int i = 0; i < 3; ++i) {
      E(J.num_cols - 3 + i, i) = 1.0;
      for (int k = 0; k < nb; ++k) E(b0 + 3 * k + i, 3 + i) = 1.0 / nb;
    }
    const Eigen::MatrixXd X = ldlt.solve(E);
    Eigen::Matrix3d C = X.bottomLeftCorner(3, 3), M = E.rightCols(3).transpose() * X.rightCols(3);
    C = 0.5 * (C + C.transpose());
    M = 0.5 * (M + M.transpose());
    if (ldlt.info() == Eigen::Success && positive(C)) *last_bias = C;
    if (ldlt.info() == Eigen::Success && positive(M)) *mean_bias = M;
  }
  // A pose's block of H^-1 = P^T L^-T D^-1 L^-1 P is Y^T D^-1 Y with Y = L^-1 P E (E its 6 unit columns): the
  // forward substitution alone, which skips the zeros of the right-hand side (the poses come late in the
  // elimination order, so Y is short), instead of a whole solve
  const Eigen::VectorXd Dinv = ldlt.vectorD().cwiseInverse();
  const int chunk = 8;  // frames per substitution: 48 right-hand sides
  for (std::size_t k0 = 1; k0 < n; k0 += chunk) {
    const int frames = static_cast<int>(std::min<std::size_t>(chunk, n - k0));
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(J.num_cols, 6 * frames);
    const int c0 = first_pose + 6 * static_cast<int>(k0 - 1);
    for (int i = 0; i < 6 * frames; ++i) E(c0 + i, i) = 1.0;
    Eigen::MatrixXd Y = ldlt.permutationP() * E;
    ldlt.matrixL().solveInPlace(Y);
    if (!Y.allFinite() || !Dinv.allFinite()) return;
    for (int f = 0; f < frames; ++f) {
      const auto Yf = Y.middleCols(6 * f, 6);
      const Eigen::Matrix<double, 6, 6> B = Yf.transpose() * Dinv.asDiagonal() * Yf;
      // [delta, p]: Ceres' quaternion tangent delta is half the rotation vector (Plus(q, delta) = [cos|delta|,
      // sin|delta| delta / |delta|] q), theta = 2 delta
      Matrix6d C;
      C << B.block<3, 3>(3, 3), 2.0 * B.block<3, 3>(3, 0), 2.0 * B.block<3, 3>(0, 3), 4.0 * B.block<3, 3>(0, 0);
      C = 0.5 * (C + C.transpose());
      if (positive(C)) (*poses)[k0 + f] = C;
    }
  }
}

}  // namespace

GyroDelta preintegrate(const std::vector<GyroSample>& s, double t0, double t1, const Eigen::Vector3d& bias,
                       double default_noise) {
  GyroDelta g;
  g.bias_lin = bias;
  g.covariance = Eigen::Matrix3d::Identity() * std::numeric_limits<double>::infinity();
  if (s.empty() || !(t1 > t0)) return g;
  // the sample active at t0: the last with stamp <= t0, else the first
  auto it = std::upper_bound(s.begin(), s.end(), t0, [](double t, const GyroSample& x) { return t < x.t; });
  std::size_t k = it == s.begin() ? 0 : static_cast<std::size_t>(it - s.begin()) - 1;
  if (s[k].t > t1) return g;  // no sample in or before the interval
  double t = t0;
  g.covariance.setZero();
  while (t < t1) {
    const double t_next = (k + 1 < s.size()) ? std::min(t1, std::max(t, s[k + 1].t)) : t1;
    const double dt = t_next - t;
    if (dt > 0) {
      const Eigen::Matrix3d Cn = s[k].C.isZero() ? Eigen::Matrix3d(default_noise * default_noise * Eigen::Matrix3d::Identity()) : s[k].C;
      const Eigen::Vector3d phi = (s[k].omega - bias) * dt;
      const Eigen::Matrix3d E = expSO3(phi), Jr = rightJacobian(phi);
      g.J_bias = E.transpose() * g.J_bias - Jr * dt;
      g.covariance = E.transpose() * g.covariance * E + Jr * Cn * Jr.transpose() * dt * dt;
      g.dR = g.dR * E;
    }
    t = t_next;
    if (k + 1 < s.size() && s[k + 1].t <= t) ++k;
  }
  g.dt = t1 - t0;
  return g;
}

namespace {

// The gyro's factors: the bias blocks (held when not estimated), their prior and random walk, and the rotation
// between consecutive frames. Returns the number of rotation factors.
int addGyroFactors(ceres::Problem* problem, const std::vector<SmootherFrame>& frames, const std::vector<GyroSample>& gyro,
                   const SmootherOptions& o, std::vector<Eigen::Vector4d>* q, std::vector<Eigen::Vector3d>* b) {
  const std::size_t n = frames.size();
  int factors = 0;
  for (std::size_t k = 0; k < n; ++k) problem->AddParameterBlock((*b)[k].data(), 3);
  if (!o.estimate_gyro_bias)
    for (std::size_t k = 0; k < n; ++k) problem->SetParameterBlockConstant((*b)[k].data());
  problem->AddResidualBlock(new ceres::AutoDiffCostFunction<BiasPriorCost, 3, 3>(
                               new BiasPriorCost(o.initial_gyro_bias, 1.0 / o.initial_gyro_bias_std)),
                           nullptr, (*b)[0].data());
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const double dt = frames[k + 1].t - frames[k].t;
    problem->AddResidualBlock(new ceres::AutoDiffCostFunction<BiasWalkCost, 3, 3, 3>(
                                 new BiasWalkCost(1.0 / (o.gyro_bias_walk * std::sqrt(dt)))),
                             nullptr, (*b)[k].data(), (*b)[k + 1].data());
    const GyroDelta g = preintegrate(gyro, frames[k].t, frames[k + 1].t, o.initial_gyro_bias, o.gyro_noise);
    if (!(g.dt > 0)) continue;
    Eigen::LLT<Eigen::Matrix3d> llt(g.covariance);
    if (llt.info() != Eigen::Success) continue;
    const Eigen::Matrix3d W = Eigen::Matrix3d(llt.matrixL()).inverse();
    problem->AddResidualBlock(new ceres::AutoDiffCostFunction<GyroCost, 3, 4, 4, 3>(new GyroCost(g, W)), nullptr,
                             (*q)[k].data(), (*q)[k + 1].data(), (*b)[k].data());
    ++factors;
  }
  return factors;
}

// The landmark measurements' sigma factor from a solution: the inliers' chi^2 over the degrees of freedom,
// corrected for the Huber cut (only the inliers are counted: a chi^2 (3 dof) cut at c = huber^2 has the mean
// 3 P5(c) / P3(c), Pk the chi^2 distribution function with k dof, P5(c) = P3(c) - (c/2)^1.5 e^(-c/2) / Gamma(5/2)).
// 0 when there are too few degrees of freedom.
double varianceFactor(ceres::Problem& problem, const std::vector<std::pair<ceres::ResidualBlockId, double>>& blocks,
                      double huber, std::size_t landmarks, std::size_t frames) {
  double chi2 = 0;
  int inliers = 0;
  for (auto& lb : blocks) {
    double r[3], c = 0;
    problem.EvaluateResidualBlock(lb.first, false, &c, r, nullptr);
    const double d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    if (d2 <= huber * huber) {
      chi2 += d2;
      ++inliers;
    }
  }
  const double dof = 3.0 * inliers - 3.0 * static_cast<double>(landmarks) - 6.0 * static_cast<double>(frames - 1);
  if (!(dof > 10 && chi2 > 0)) return 0.0;
  const double c = huber * huber;
  const double p3 = std::erf(std::sqrt(0.5 * c)) - std::sqrt(2.0 * c / M_PI) * std::exp(-0.5 * c);
  const double p5 = p3 - std::pow(0.5 * c, 1.5) * std::exp(-0.5 * c) / std::tgamma(2.5);
  return std::sqrt(chi2 / (dof * p5 / p3));
}

// One solve of the batch problem. bias_start: per-frame starting biases (empty: the options' initial bias);
// sigma0 > 0: the measurements' sigma factor, known (else estimated from a first solution and solved again).
SmootherResult solveOnce(const std::vector<SmootherFrame>& frames, const std::vector<GyroSample>& gyro,
                         const SmootherOptions& o, const std::vector<Eigen::Vector3d>& bias_start, double sigma0,
                         bool covariances) {
  const auto t_start = std::chrono::steady_clock::now();
  SmootherResult res;
  const std::size_t n = frames.size();
  if (n < 3) {
    res.message = "fewer than 3 frames: nothing to smooth";
    return res;
  }
  for (std::size_t k = 1; k < n; ++k)
    if (!(frames[k].t > frames[k - 1].t)) {
      res.message = "frames are not in time order";
      return res;
    }
  // parameters
  std::vector<Eigen::Vector4d> q(n);  // x, y, z, w
  std::vector<Eigen::Vector3d> p(n), b(n, o.initial_gyro_bias);
  if (bias_start.size() == n) b = bias_start;
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Quaterniond qq = frames[k].q.normalized();
    q[k] = Eigen::Vector4d(qq.x(), qq.y(), qq.z(), qq.w());
    p[k] = frames[k].p;
  }
  std::map<std::int64_t, int> seen;
  for (const auto& f : frames)
    for (const auto& ob : f.observations)
      if (ob.landmark >= 0) ++seen[ob.landmark];
  std::map<std::int64_t, Eigen::Vector3d> m;
  for (const auto& f : frames) {
    const Eigen::Matrix3d R = f.q.normalized().toRotationMatrix();
    for (const auto& ob : f.observations)
      if (ob.landmark >= 0 && seen[ob.landmark] >= o.min_observations && !m.count(ob.landmark))
        m[ob.landmark] = f.p + R * ob.z;
  }

  ceres::Problem::Options po;
  po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::EigenQuaternionManifold quaternion;
  ceres::HuberLoss huber(o.huber);
  for (std::size_t k = 0; k < n; ++k) {
    problem.AddParameterBlock(q[k].data(), 4, &quaternion);
    problem.AddParameterBlock(p[k].data(), 3);
  }
  problem.SetParameterBlockConstant(q[0].data());
  problem.SetParameterBlockConstant(p[0].data());
  double scale = sigma0 > 0 ? 1.0 / sigma0 : 1.0;  // 1 / sigma_0 of the landmark measurements, see below
  res.sigma0 = sigma0 > 0 ? sigma0 : 1.0;
  std::vector<std::pair<ceres::ResidualBlockId, double>> landmark_blocks;
  for (std::size_t k = 0; k < n; ++k) {
    for (const auto& ob : frames[k].observations) {
      auto mi = m.find(ob.landmark);
      if (mi == m.end()) continue;
      Eigen::LLT<Eigen::Matrix3d> llt(0.5 * (ob.C + ob.C.transpose()));
      if (llt.info() != Eigen::Success || !ob.z.allFinite()) continue;
      const Eigen::Matrix3d Linv = Eigen::Matrix3d(llt.matrixL()).inverse();
      auto* cost = new ceres::AutoDiffCostFunction<LandmarkCost, 3, 4, 3, 3>(new LandmarkCost(ob.z, Linv, &scale));
      landmark_blocks.push_back({problem.AddResidualBlock(cost, &huber, q[k].data(), p[k].data(), mi->second.data()), 0});
    }
  }
  res.observations = static_cast<int>(landmark_blocks.size());
  res.landmarks = static_cast<int>(m.size());
  const int gyro_factors = gyro.empty() ? 0 : addGyroFactors(&problem, frames, gyro, o, &q, &b);
  for (std::size_t k = 1; k + 1 < n; ++k)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<MotionCost, 3, 4, 4, 3, 3, 3>(new MotionCost(
                                 frames[k].t - frames[k - 1].t, frames[k + 1].t - frames[k].t, o.velocity_noise)),
                             nullptr, q[k - 1].data(), q[k].data(), p[k - 1].data(), p[k].data(), p[k + 1].data());

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_SCHUR;
  if (!ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) &&
      !ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::EIGEN_SPARSE))
    so.linear_solver_type = ceres::ITERATIVE_SCHUR;
  auto* order = new ceres::ParameterBlockOrdering;
  for (auto& kv : m) order->AddElementToGroup(kv.second.data(), 0);
  for (std::size_t k = 0; k < n; ++k) {
    order->AddElementToGroup(q[k].data(), 1);
    order->AddElementToGroup(p[k].data(), 1);
    if (!gyro.empty()) order->AddElementToGroup(b[k].data(), 1);
  }
  so.linear_solver_ordering.reset(order);
  so.max_num_iterations = o.max_iterations;
  so.num_threads = o.threads;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  auto now = [] { return std::chrono::steady_clock::now(); };
  auto secs = [](std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  };
  auto t0 = now();
  ceres::Solve(so, &problem, &summary);
  res.solve_seconds = secs(t0, now());
  res.iterations = static_cast<int>(summary.iterations.size());
  // The front end's covariances hold the error a landmark keeps from frame to frame (calibration, its pixel
  // neighbourhood) as well as the white part; here the landmark's position absorbs the first, so the residuals
  // are smaller than C says and the images would be under-weighted against the gyroscope. Their variance
  // factor sigma_0^2 (the a posteriori estimate: the landmark residuals' chi^2 over its degrees of freedom,
  // the inliers' only) is estimated from this recording and the problem solved again with C sigma_0^2.
  if (o.estimate_variance_factor && !(sigma0 > 0) && summary.IsSolutionUsable()) {
    const double f = varianceFactor(problem, landmark_blocks, o.huber, m.size(), n);
    if (f > 0) {
      res.sigma0 = f;
      scale = 1.0 / f;
      ceres::Solver::Summary again;
      t0 = now();
      ceres::Solve(so, &problem, &again);
      res.solve_seconds += secs(t0, now());
      res.iterations += static_cast<int>(again.iterations.size());
      summary.final_cost = again.final_cost;
      if (!again.IsSolutionUsable()) summary = again;
    }
  }
  res.initial_cost = summary.initial_cost;
  res.final_cost = summary.final_cost;
  if (!summary.IsSolutionUsable()) {
    res.message = "the solver failed: " + summary.message;
    return res;
  }
  // outliers at the end
  for (auto& lb : landmark_blocks) {
    double r[3];
    double cost = 0;
    problem.EvaluateResidualBlock(lb.first, false, &cost, r, nullptr);
    if (std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) > o.huber) ++res.outliers;
  }
  // the marginal covariances (poses, last and mean bias); only for the solve whose result is returned
  t0 = now();
  if (covariances)
    marginalCovariances(problem, m, q, p, !gyro.empty() && o.estimate_gyro_bias ? &b : nullptr, o.threads,
                        &res.pose_covariance, &res.final_bias_covariance, &res.mean_bias_covariance);
  res.covariance_seconds = secs(t0, now());
  res.p = p;
  res.q.resize(n);
  for (std::size_t k = 0; k < n; ++k) res.q[k] = Eigen::Quaterniond(q[k][3], q[k][0], q[k][1], q[k][2]).normalized();
  res.gyro_bias = b;
  for (const auto& kv : m) res.landmark_positions.emplace_back(kv.first, kv.second);
  res.ok = true;
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  res.message = std::to_string(n) + " frames, " + std::to_string(res.landmarks) + " landmarks, " +
                std::to_string(res.observations) + " observations (" + std::to_string(res.outliers) +
                " beyond the Huber radius), " + std::to_string(gyro_factors) + " gyro factors; " +
                std::to_string(res.iterations) + " iterations, cost " + std::to_string(summary.initial_cost) +
                " -> " + std::to_string(summary.final_cost) + ", measurement sigma factor " + std::to_string(res.sigma0) +
                "; solved in " + std::to_string(res.solve_seconds) + " s, covariances in " +
                std::to_string(res.covariance_seconds) + " s";
  return res;
}


// Landmarks the filter lost and found again under a new id (a loop: the orbit comes back to skin it saw long
// before): a later landmark is the earlier one when it was first seen after that one was last seen, lies within
// loop_radius of it on the smoothed map, and their descriptors are closer than loop_descriptor_distance and than
// 0.8 of the next candidate's. Rewrites the ids in `frames`; returns how many landmarks were merged.
int closeLoops(const SmootherResult& r, std::vector<SmootherFrame>* frames, const SmootherOptions& o,
               std::map<std::int64_t, std::int64_t>* joined) {
  struct Info {
    Eigen::Vector3d m;
    int first = -1, last = -1;
    const std::vector<float>* descriptor = nullptr;
  };
  std::map<std::int64_t, Info> info;
  for (const auto& kv : r.landmark_positions) info[kv.first].m = kv.second;
  for (int k = 0; k < static_cast<int>(frames->size()); ++k)
    for (const auto& ob : (*frames)[k].observations) {
      auto it = info.find(ob.landmark);
      if (it == info.end()) continue;
      if (it->second.first < 0) it->second.first = k;
      it->second.last = k;
      if (!it->second.descriptor && !ob.descriptor.empty()) it->second.descriptor = &ob.descriptor;
    }
  std::vector<std::pair<std::int64_t, Info*>> byx;
  for (auto& kv : info)
    if (kv.second.descriptor && kv.second.first >= 0) byx.push_back({kv.first, &kv.second});
  std::sort(byx.begin(), byx.end(), [](const auto& a, const auto& b) { return a.second->m.x() < b.second->m.x(); });
  std::vector<std::size_t> order(byx.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return byx[a].second->first < byx[b].second->first; });
  std::map<std::int64_t, std::int64_t> parent;  // merged id -> the id it joins
  std::map<std::int64_t, int> root_last;         // a set's last frame
  auto find = [&](std::int64_t id) {
    while (parent.count(id)) id = parent[id];
    return id;
  };
  auto distance = [](const std::vector<float>& a, const std::vector<float>& b) {
    if (a.size() != b.size()) return std::numeric_limits<double>::infinity();
    double s = 0;
    for (std::size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]) * (a[i] - b[i]);
    return std::sqrt(s);
  };
  int merged = 0;
  for (std::size_t oi : order) {
    const Info& B = *byx[oi].second;
    // candidates: earlier landmarks within the radius (x-sorted scan)
    double best = std::numeric_limits<double>::infinity(), second = best;
    std::int64_t best_id = -1;
    for (int dir = -1; dir <= 1; dir += 2) {
      for (std::ptrdiff_t j = static_cast<std::ptrdiff_t>(oi) + dir; j >= 0 && j < static_cast<std::ptrdiff_t>(byx.size()); j += dir) {
        const Info& A = *byx[j].second;
        if (std::fabs(A.m.x() - B.m.x()) > o.loop_radius) break;
        if ((A.m - B.m).norm() > o.loop_radius) continue;
        const std::int64_t root = find(byx[j].first);
        const int last = root_last.count(root) ? root_last[root] : A.last;
        if (!(std::max(last, A.last) < B.first)) continue;
        const double d = distance(*A.descriptor, *B.descriptor);
        if (d < best) {
          second = best;
          best = d;
          best_id = byx[j].first;
        } else if (d < second) {
          second = d;
        }
      }
    }
    if (best_id < 0 || !(best < o.loop_descriptor_distance) || !(best < 0.8 * second)) continue;
    const std::int64_t root = find(best_id);
    parent[byx[oi].first] = root;
    root_last[root] = std::max(root_last.count(root) ? root_last[root] : info[root].last, B.last);
    ++merged;
  }
  if (merged)
    for (auto& f : *frames)
      for (auto& ob : f.observations)
        if (ob.landmark >= 0) ob.landmark = find(ob.landmark);
  for (const auto& kv : parent) (*joined)[kv.first] = find(kv.first);
  return merged;
}

}  // namespace

SmootherResult smooth(const std::vector<SmootherFrame>& frames, const std::vector<GyroSample>& gyro,
                      const SmootherOptions& o) {
  o.validate();
  const bool loops = o.loop_radius > 0;
  SmootherResult r = solveOnce(frames, gyro, o, {}, 0.0, !loops);  // the covariances of the final solve only
  if (!r.ok || !loops) return r;
  std::vector<SmootherFrame> again = frames;
  std::map<std::int64_t, std::int64_t> joined;
  const int merged = closeLoops(r, &again, o, &joined);
  for (std::size_t k = 0; k < again.size(); ++k) {
    again[k].p = r.p[k];
    again[k].q = r.q[k];
  }
  if (merged == 0) {  // the same problem from its solution: a few iterations, then the covariances
    SmootherResult r2 = solveOnce(again, gyro, o, r.gyro_bias, r.sigma0, true);
    if (!r2.ok) return r;
    r2.sigma0 = r.sigma0;
    r2.seconds += r.seconds;
    r2.solve_seconds += r.solve_seconds;
    r2.iterations += r.iterations;
    r2.message += "; no landmark found again, sigma factor from the first solve";
    return r2;
  }
  SmootherResult r2 = solveOnce(again, gyro, o, r.gyro_bias, r.sigma0, true);
  if (!r2.ok) {
    r.message += "; the solve with " + std::to_string(merged) + " landmarks found again failed (" + r2.message + ")";
    return r;
  }
  r2.loops = merged;
  // a joined id's position is its landmark's
  {
    std::map<std::int64_t, Eigen::Vector3d> pos(r2.landmark_positions.begin(), r2.landmark_positions.end());
    for (const auto& kv : joined) {
      auto it = pos.find(kv.second);
      if (it != pos.end()) pos[kv.first] = it->second;
    }
    r2.landmark_positions.assign(pos.begin(), pos.end());
  }
  r2.seconds += r.seconds;
  r2.solve_seconds += r.solve_seconds;
  r2.covariance_seconds += r.covariance_seconds;
  r2.message += "; " + std::to_string(merged) + " landmarks found again (loop closure), sigma factor from the first solve";
  return r2;
}

}  // namespace slam
}  // namespace skin3d
