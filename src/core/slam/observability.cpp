// SPDX-License-Identifier: BSD-3-Clause
//
// Observability analysis of the linearised ES-EKF error system: see include/skin3d/slam/observability.h.
// ROS-free; uses only the filter (slam/eskf.h) and the SO(3) helpers, never skin3d/sim.
#include "skin3d/slam/observability.h"

#include "../common/text.h"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include "skin3d/geometry/quaternion.h"

namespace skin3d {
namespace slam {

namespace {

[[noreturn]] void fail(const std::string& message) { throw std::invalid_argument(message); }

std::string str(double v) { return common::num(v); }

std::string shape(const Eigen::MatrixXd& M) {
  return std::to_string(M.rows()) + "x" + std::to_string(M.cols());
}

bool finite(const Eigen::MatrixXd& M) { return M.size() == 0 || M.allFinite(); }

int effectiveSteps(const LinearizedSystem& sys, int steps) {
  if (steps < 0) return sys.steps();
  if (steps > sys.steps())
    fail("observability: steps = " + std::to_string(steps) + " exceeds the system's " + std::to_string(sys.steps()));
  return steps;
}

// Rows L_k^T H_k Phi_k (W_k = L_k L_k^T) of step k, or H_k Phi_k.
Eigen::MatrixXd stepRows(const LinearizedSystem& sys, int k, const Eigen::MatrixXd& Phi, bool weighted) {
  Eigen::MatrixXd rows = sys.H[k] * Phi;
  if (weighted && !sys.W.empty() && rows.rows() > 0) {
    const Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (sys.W[k] + sys.W[k].transpose()));
    rows = llt.matrixU() * rows;  // U = L^T
  }
  return rows;
}

// An n x n matrix S with S^T S = M^T M (M: rows x n): M itself, M padded with zero rows, or, for
// rows > n, the triangular factor of M's column-pivoted Householder QR, M P = Q R, with its columns put
// back in order, S = R P^T. (Column-pivoted, unblocked QR: accurate, and free of the spurious
// -Wmaybe-uninitialized that GCC 12 reports inside Eigen's blocked HouseholderQR and BDCSVD.)
Eigen::MatrixXd squareFactor(const Eigen::MatrixXd& M) {
  const Eigen::Index n = M.cols();
  if (M.rows() == n) return M;
  if (M.rows() < n) {
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(n, n);
    S.topRows(M.rows()) = M;
    return S;
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(M);
  const Eigen::MatrixXd R = qr.matrixR().topRows(n).triangularView<Eigen::Upper>();
  return R * qr.colsPermutation().transpose();
}

// All n singular values (descending; zeros when M has fewer rows) and the full right singular vectors.
// One-sided Jacobi on the square factor: accurate for the small singular values relative to the norm.
void svdRight(const Eigen::MatrixXd& M, Eigen::VectorXd* sigma, Eigen::MatrixXd* V) {
  const Eigen::JacobiSVD<Eigen::MatrixXd, Eigen::NoQRPreconditioner> svd(squareFactor(M), Eigen::ComputeFullV);
  *sigma = svd.singularValues();
  *V = svd.matrixV();
}

// Orthonormal basis (columns) of the range of A (rows x c) to the relative tolerance; sets *rank.
Eigen::MatrixXd rangeBasis(const Eigen::MatrixXd& A, double relative_tolerance, int* rank) {
  // Square A by zero columns (range unchanged), then its left singular vectors.
  const Eigen::Index m = std::max(A.rows(), A.cols());
  Eigen::MatrixXd Sq = Eigen::MatrixXd::Zero(m, m);
  Sq.topLeftCorner(A.rows(), A.cols()) = A;
  const Eigen::JacobiSVD<Eigen::MatrixXd, Eigen::NoQRPreconditioner> svd(Sq, Eigen::ComputeFullU);
  const Eigen::VectorXd& s = svd.singularValues();
  const double tol = relative_tolerance * (s.size() > 0 ? s(0) : 0.0);
  int r = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i)
    if (s(i) > tol) ++r;
  *rank = r;
  return svd.matrixU().topLeftCorner(A.rows(), r);
}

void checkTolerance(double tol, const char* who) {
  if (!(tol > 0.0 && tol < 1.0)) fail(std::string(who) + ": relative_tolerance = " + str(tol) + " must be in (0, 1)");
}

const char* axisName(int i) {
  static const char* kAxes[3] = {"x", "y", "z"};
  return kAxes[i];
}

bool isLandmarkBlock(const std::string& name) {
  if (name.size() < 2 || name[0] != 'm') return false;
  return std::all_of(name.begin() + 1, name.end(), [](char c) { return c >= '0' && c <= '9'; });
}

std::string vec3(const Eigen::Vector3d& v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "[%+.2f %+.2f %+.2f]", v.x(), v.y(), v.z());
  return buf;
}

}  // namespace

// ======================================================================================= LinearizedSystem

int LinearizedSystem::dim() const {
  if (!H.empty()) return static_cast<int>(H[0].cols());
  if (!F.empty()) return static_cast<int>(F[0].rows());
  return 0;
}

void LinearizedSystem::validate() const {
  const int N = steps();
  if (N < 1) fail("LinearizedSystem: no measurement step (H is empty)");
  const int n = dim();
  if (n < 1) fail("LinearizedSystem: state dimension is 0");
  if (static_cast<int>(F.size()) < N - 1)
    fail("LinearizedSystem: " + std::to_string(F.size()) + " transition matrices for " + std::to_string(N) +
         " steps (need at least " + std::to_string(N - 1) + ")");
  for (int k = 0; k < N - 1; ++k) {
    if (F[k].rows() != n || F[k].cols() != n)
      fail("LinearizedSystem: F[" + std::to_string(k) + "] is " + shape(F[k]) + ", expected " + std::to_string(n) +
           "x" + std::to_string(n));
    if (!finite(F[k])) fail("LinearizedSystem: F[" + std::to_string(k) + "] is not finite");
  }
  for (int k = 0; k < N; ++k) {
    if (H[k].cols() != n)
      fail("LinearizedSystem: H[" + std::to_string(k) + "] is " + shape(H[k]) + ", expected " + std::to_string(n) +
           " columns");
    if (!finite(H[k])) fail("LinearizedSystem: H[" + std::to_string(k) + "] is not finite");
  }
  if (W.empty()) return;
  if (static_cast<int>(W.size()) != N)
    fail("LinearizedSystem: " + std::to_string(W.size()) + " weight matrices for " + std::to_string(N) +
         " steps (need none or one per step)");
  for (int k = 0; k < N; ++k) {
    const std::string tag = "LinearizedSystem: W[" + std::to_string(k) + "]";
    const Eigen::Index m = H[k].rows();
    if (W[k].rows() != m || W[k].cols() != m)
      fail(tag + " is " + shape(W[k]) + ", expected " + std::to_string(m) + "x" + std::to_string(m));
    if (m == 0) continue;
    if (!finite(W[k])) fail(tag + " is not finite");
    const double scale = W[k].cwiseAbs().maxCoeff();
    if ((W[k] - W[k].transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) fail(tag + " is not symmetric");
    const Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (W[k] + W[k].transpose()));
    if (!(scale > 0.0) || llt.info() != Eigen::Success) fail(tag + " is not positive definite");
  }
}

// ============================================================================== matrix, Gramian, factor

Eigen::MatrixXd observabilityMatrix(const LinearizedSystem& sys, bool weighted, int steps) {
  sys.validate();
  const int N = effectiveSteps(sys, steps), n = sys.dim();
  Eigen::Index rows = 0;
  for (int k = 0; k < N; ++k) rows += sys.H[k].rows();
  Eigen::MatrixXd O(rows, n);
  Eigen::MatrixXd Phi = Eigen::MatrixXd::Identity(n, n);
  Eigen::Index r = 0;
  for (int k = 0; k < N; ++k) {
    const Eigen::MatrixXd block = stepRows(sys, k, Phi, weighted);
    O.middleRows(r, block.rows()) = block;
    r += block.rows();
    if (k + 1 < N) Phi = (sys.F[k] * Phi).eval();
  }
  return O;
}

Eigen::MatrixXd observabilityGramian(const LinearizedSystem& sys, int steps) {
  sys.validate();
  const int N = effectiveSteps(sys, steps), n = sys.dim();
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, n);
  Eigen::MatrixXd Phi = Eigen::MatrixXd::Identity(n, n);
  for (int k = 0; k < N; ++k) {
    const Eigen::MatrixXd HP = sys.H[k] * Phi;
    if (HP.rows() > 0) {
      if (sys.W.empty())
        G.noalias() += HP.transpose() * HP;
      else
        G.noalias() += HP.transpose() * (0.5 * (sys.W[k] + sys.W[k].transpose())) * HP;
    }
    if (k + 1 < N) Phi = (sys.F[k] * Phi).eval();
  }
  return 0.5 * (G + G.transpose());
}

Eigen::MatrixXd observabilityFactor(const LinearizedSystem& sys, int steps) {
  sys.validate();
  const int N = effectiveSteps(sys, steps), n = sys.dim();
  Eigen::MatrixXd R = Eigen::MatrixXd::Zero(n, n);  // R^T R = the Gramian so far
  Eigen::MatrixXd Phi = Eigen::MatrixXd::Identity(n, n);
  for (int k = 0; k < N; ++k) {
    const Eigen::MatrixXd block = stepRows(sys, k, Phi, true);
    if (block.rows() > 0) {
      Eigen::MatrixXd stacked(n + block.rows(), n);
      stacked << R, block;
      R = squareFactor(stacked);
    }
    if (k + 1 < N) Phi = (sys.F[k] * Phi).eval();
  }
  return R;
}

// ================================================================================================ analysis

double ObservabilityReport::observableCondition() const {
  if (rank <= 0) return std::numeric_limits<double>::infinity();
  return singular_values(0) / singular_values(rank - 1);
}

ObservabilityReport analyseMatrix(const Eigen::MatrixXd& M, const ObservabilityOptions& options) {
  checkTolerance(options.relative_tolerance, "analyseMatrix");
  if (options.weakest_count < 0)
    fail("analyseMatrix: weakest_count = " + std::to_string(options.weakest_count) + " must be >= 0");
  if (M.cols() == 0) fail("analyseMatrix: the matrix has no column");
  if (!finite(M)) fail("analyseMatrix: the matrix is not finite");
  ObservabilityReport rep;
  rep.dim = static_cast<int>(M.cols());
  Eigen::MatrixXd V;
  svdRight(M, &rep.singular_values, &V);
  const double smax = rep.singular_values.size() > 0 ? rep.singular_values(0) : 0.0;
  rep.tolerance = options.relative_tolerance * smax;
  rep.rank = 0;
  for (Eigen::Index i = 0; i < rep.singular_values.size(); ++i)
    if (rep.singular_values(i) > rep.tolerance) ++rep.rank;
  const int c = std::min(rep.dim, std::max(rep.deficiency(), options.weakest_count));
  rep.weakest.resize(rep.dim, c);
  for (int i = 0; i < c; ++i) {
    rep.weakest.col(i) = V.col(rep.dim - 1 - i);
    Eigen::Index imax = 0;  // sign convention: the largest-magnitude component is positive
    rep.weakest.col(i).cwiseAbs().maxCoeff(&imax);
    if (rep.weakest(imax, i) < 0.0) rep.weakest.col(i) *= -1.0;
  }
  return rep;
}

ObservabilityReport analyseObservability(const LinearizedSystem& sys, const ObservabilityOptions& options, int steps) {
  return analyseMatrix(observabilityFactor(sys, steps), options);
}

double subspaceResidual(const Eigen::MatrixXd& directions, const Eigen::MatrixXd& basis) {
  if (directions.rows() != basis.rows())
    fail("subspaceResidual: directions are " + shape(directions) + ", basis " + shape(basis));
  double worst = 0.0;
  for (Eigen::Index j = 0; j < directions.cols(); ++j) {
    const double nrm = directions.col(j).norm();
    if (!(nrm > 0.0)) fail("subspaceResidual: direction " + std::to_string(j) + " is zero");
    const Eigen::VectorXd d = directions.col(j) / nrm;
    const Eigen::VectorXd r = basis.cols() > 0 ? Eigen::VectorXd(d - basis * (basis.transpose() * d)) : d;
    worst = std::max(worst, r.norm());
  }
  return worst;
}

RestrictedObservability restrictObservability(const Eigen::MatrixXd& M_in, const std::vector<int>& kept,
                                              const std::vector<int>& known, double relative_tolerance) {
  checkTolerance(relative_tolerance, "restrictObservability");
  const int n = static_cast<int>(M_in.cols());
  if (!finite(M_in)) fail("restrictObservability: the matrix is not finite");
  // Everything below depends on M^T M only: work on an n x n factor of it when M is tall.
  const Eigen::MatrixXd M = M_in.rows() > n ? squareFactor(M_in) : M_in;
  if (kept.empty()) fail("restrictObservability: no state kept");
  std::vector<int> role(n, 0);  // 0 nuisance, 1 kept, 2 known
  auto mark = [&](const std::vector<int>& idx, int r, const char* what) {
    for (int i : idx) {
      if (i < 0 || i >= n)
        fail(std::string("restrictObservability: ") + what + " index " + std::to_string(i) + " is out of [0, " +
             std::to_string(n) + ")");
      if (role[i] != 0) fail(std::string("restrictObservability: index ") + std::to_string(i) + " is listed twice");
      role[i] = r;
    }
  };
  mark(kept, 1, "kept");
  mark(known, 2, "known");
  std::vector<int> nuisance;
  for (int i = 0; i < n; ++i)
    if (role[i] == 0) nuisance.push_back(i);

  RestrictedObservability out;
  out.kept = kept;
  Eigen::MatrixXd K(M.rows(), static_cast<Eigen::Index>(kept.size()));
  for (size_t j = 0; j < kept.size(); ++j) K.col(j) = M.col(kept[j]);
  // Scale of the rank decision: the kept columns BEFORE the projection (a column that the projection
  // reduces to rounding noise must count as unobservable).
  double kept_scale = 0.0;
  {
    Eigen::VectorXd s0;
    Eigen::MatrixXd V0;
    svdRight(K, &s0, &V0);
    kept_scale = s0.size() > 0 ? s0(0) : 0.0;
  }
  if (!nuisance.empty() && M.rows() > 0) {
    Eigen::MatrixXd A(M.rows(), static_cast<Eigen::Index>(nuisance.size()));
    for (size_t j = 0; j < nuisance.size(); ++j) A.col(j) = M.col(nuisance[j]);
    int r = 0;
    const Eigen::MatrixXd U = rangeBasis(A, relative_tolerance, &r);
    out.nuisance_rank = r;
    if (r > 0) K -= U * (U.transpose() * K);
  }
  const Eigen::Index c = K.cols();
  Eigen::MatrixXd V;
  svdRight(K, &out.singular_values, &V);
  out.singular_values = out.singular_values.head(c).eval();
  out.directions = V;
  const double tol = relative_tolerance * kept_scale;
  for (Eigen::Index i = 0; i < c; ++i)
    if (out.singular_values(i) > tol) ++out.rank;
  out.information = K.transpose() * K;
  out.information = (0.5 * (out.information + out.information.transpose())).eval();
  if (out.rank == c) {
    const Eigen::VectorXd inv2 = out.singular_values.array().square().inverse();
    out.covariance = V * inv2.asDiagonal() * V.transpose();
    const Eigen::VectorXd sd = out.covariance.diagonal().cwiseSqrt();
    out.correlation = sd.cwiseInverse().asDiagonal() * out.covariance * sd.cwiseInverse().asDiagonal();
  }
  return out;
}

// ============================================================================================ state layout

std::vector<StateBlock> errorStateBlocks(int rig_dim, int landmarks) {
  if (rig_dim != 12 && rig_dim != 15) fail("errorStateBlocks: rig_dim = " + std::to_string(rig_dim) + " must be 12 or 15");
  if (landmarks < 0) fail("errorStateBlocks: landmarks = " + std::to_string(landmarks) + " must be >= 0");
  std::vector<StateBlock> b = {{"p", 0, 3}, {"theta", 3, 3}, {"v", 6, 3}, {"w", 9, 3}};
  if (rig_dim == 15) b.push_back({"b_g", 12, 3});
  for (int j = 0; j < landmarks; ++j) b.push_back({"m" + std::to_string(j), rig_dim + 3 * j, 3});
  return b;
}

std::vector<std::string> componentLabels(const std::vector<StateBlock>& blocks) {
  std::vector<std::string> labels;
  for (const StateBlock& b : blocks)
    for (int i = 0; i < b.size; ++i)
      labels.push_back(b.name + "_" + (b.size == 3 ? std::string(axisName(i)) : std::to_string(i)));
  return labels;
}

std::string describeDirection(const Eigen::VectorXd& direction, const std::vector<StateBlock>& blocks,
                              double min_share) {
  const double nrm = direction.norm();
  if (!(nrm > 0.0)) return "(zero vector)";
  const Eigen::VectorXd d = direction / nrm;
  struct Term {
    double share;
    std::string text;
  };
  std::vector<Term> terms;
  double lm_energy = 0.0;
  int lm_count = 0;
  Eigen::Vector3d lm_sum = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> lm_vecs;
  for (const StateBlock& b : blocks) {
    if (b.start < 0 || b.size < 0 || b.start + b.size > d.size()) fail("describeDirection: block " + b.name + " is out of range");
    const Eigen::VectorXd seg = d.segment(b.start, b.size);
    if (isLandmarkBlock(b.name) && b.size == 3) {
      lm_energy += seg.squaredNorm();
      lm_sum += Eigen::Vector3d(seg);
      lm_vecs.push_back(Eigen::Vector3d(seg));
      ++lm_count;
      continue;
    }
    const double share = seg.norm();
    if (share < min_share) continue;
    std::ostringstream os;
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.2f", share);
    os << b.name << " " << buf;
    if (b.size == 3) os << " " << vec3(Eigen::Vector3d(seg));
    terms.push_back({share, os.str()});
  }
  if (lm_count > 0) {
    const double share = std::sqrt(lm_energy);
    if (share >= min_share) {
      const Eigen::Vector3d mean = lm_sum / lm_count;
      double spread = 0.0;
      for (const Eigen::Vector3d& v : lm_vecs) spread = std::max(spread, (v - mean).norm());
      char buf[128];
      std::snprintf(buf, sizeof(buf), "m* %.2f (%d landmarks, mean %s, max deviation %.2f)", share, lm_count,
                    vec3(mean).c_str(), spread);
      terms.push_back({share, buf});
    }
  }
  std::stable_sort(terms.begin(), terms.end(), [](const Term& a, const Term& b) { return a.share > b.share; });
  std::string out;
  for (size_t i = 0; i < terms.size(); ++i) out += (i ? "; " : "") + terms[i].text;
  return out.empty() ? "(spread thinly over all components)" : out;
}

Eigen::MatrixXd slamGaugeBasis(const RigState& x0, const std::vector<Eigen::Vector3d>& landmarks, int rig_dim) {
  if (rig_dim != 12 && rig_dim != 15) fail("slamGaugeBasis: rig_dim = " + std::to_string(rig_dim) + " must be 12 or 15");
  const int K = static_cast<int>(landmarks.size());
  const int n = rig_dim + 3 * K;
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, 6);
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d e = Eigen::Vector3d::Unit(i);
    // translation: every world point (p, m_j) shifted by e; attitude, v, w unchanged
    G.block<3, 1>(0, i) = e;
    for (int j = 0; j < K; ++j) G.block<3, 1>(rig_dim + 3 * j, i) = e;
    // rotation Exp(phi e) about the world origin: R <- Exp(phi e) R (global error dtheta = e),
    // p <- Exp(phi e) p (dp = e x p), m_j likewise; v, w, b_g are rig-frame quantities: unchanged
    G.block<3, 1>(0, 3 + i) = e.cross(x0.p);
    G.block<3, 1>(3, 3 + i) = e;
    for (int j = 0; j < K; ++j) G.block<3, 1>(rig_dim + 3 * j, 3 + i) = e.cross(landmarks[j]);
  }
  for (int c = 0; c < 6; ++c) G.col(c).normalize();
  return G;
}

// ============================================================================================== scenario

void OrbitScenario::validate() const {
  auto bad = [](const char* field, double v, const char* why) {
    fail(std::string("OrbitScenario: ") + field + " = " + str(v) + " " + why);
  };
  const double half_pi = 0.5 * 3.14159265358979323846;
  if (!(sphere_radius > 0.0 && std::isfinite(sphere_radius))) bad("sphere_radius", sphere_radius, "must be > 0 (m)");
  if (!(distance > sphere_radius && std::isfinite(distance))) bad("distance", distance, "must exceed sphere_radius (m)");
  if (!(std::isfinite(rate) && std::abs(rate) < 100.0)) bad("rate", rate, "must be finite, |rate| < 100 rad/s");
  if (!(std::abs(latitude) < half_pi)) bad("latitude", latitude, "must be in (-pi/2, pi/2) rad");
  if (!(std::abs(tilt) < half_pi)) bad("tilt", tilt, "must be in (-pi/2, pi/2) rad");
  if (!(fps > 0.0 && std::isfinite(fps))) bad("fps", fps, "must be > 0 (Hz)");
  if (landmarks < 1 || landmarks > 10000) bad("landmarks", landmarks, "must be in [1, 10000]");
  if (steps < 1 || steps > 100000) bad("steps", steps, "must be in [1, 100000]");
  const double horizon = std::acos(sphere_radius / distance);
  if (!(cap_half_angle > 0.0 && cap_half_angle < horizon))
    bad("cap_half_angle", cap_half_angle, "must be in (0, acos(radius / distance)) rad (the visible cap)");
  if (!(focal_px > 0.0 && std::isfinite(focal_px))) bad("focal_px", focal_px, "must be > 0");
  if (image_width < 1 || image_height < 1) bad("image_width/height", std::min(image_width, image_height), "must be >= 1");
  if (!(baseline > 0.0 && std::isfinite(baseline))) bad("baseline", baseline, "must be > 0 (m)");
  if (!(pixel_sigma > 0.0 && std::isfinite(pixel_sigma))) bad("pixel_sigma", pixel_sigma, "must be > 0 (px)");
  if (!(gyro_sigma > 0.0 && std::isfinite(gyro_sigma))) bad("gyro_sigma", gyro_sigma, "must be > 0 (rad/s)");
}

int OrbitTrajectory::neverSeen() const {
  std::vector<char> seen(landmarks.size(), 0);
  for (const auto& v : visible)
    for (int j : v) seen[j] = 1;
  return static_cast<int>(std::count(seen.begin(), seen.end(), 0));
}

OrbitTrajectory makeOrbitTrajectory(const OrbitScenario& sc) {
  sc.validate();
  OrbitTrajectory t;
  t.dt = 1.0 / sc.fps;
  // Globe frame G (spin axis z_G): the rig starts at latitude `latitude`, longitude 0, looking at the
  // centre; its image x axis is horizontal in a lab whose "up" is tilted by `tilt` from z_G.
  const double phi = sc.latitude, tau = sc.tilt;
  const Eigen::Vector3d z_G = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d e_r(std::cos(phi), 0.0, std::sin(phi));
  const Eigen::Vector3d e_east = z_G.cross(e_r).normalized();
  const Eigen::Vector3d up = std::cos(tau) * z_G - std::sin(tau) * e_east;
  const Eigen::Vector3d z_L = -e_r;
  const Eigen::Vector3d x_L = z_L.cross(up).normalized();
  const Eigen::Vector3d y_L = z_L.cross(x_L);
  Eigen::Matrix3d R_GL;
  R_GL << x_L, y_L, z_L;
  // World = the rig frame at t = 0, fixed to the globe; the rig orbits the centre at -rate about z_G,
  // so in the rig frame w = -rate R_GL^T z_G and v = w x (rig - centre) = -w x c_L: both constant.
  const Eigen::Vector3d c_L(0.0, 0.0, sc.distance);
  t.centre = c_L;
  const Eigen::Vector3d w = -sc.rate * R_GL.transpose() * z_G;
  const Eigen::Vector3d v = -w.cross(c_L);

  auto exactState = [&](double time) {
    RigState x;
    x.q = geometry::quatExp(w * time);
    x.p = t.centre - geometry::toRotationMatrix(x.q) * c_L;
    x.v = v;
    x.w = w;
    return x;
  };
  t.states.resize(sc.steps);
  t.states[0] = exactState(0.0);
  t.states[0].p.setZero();
  t.states[0].q = geometry::Quat::Identity();
  for (int k = 1; k < sc.steps; ++k)
    t.states[k] = sc.model_consistent_trajectory ? propagateNominal(t.states[k - 1], t.dt, 1.0, 1.0)
                                                 : exactState(k * t.dt);

  // Landmarks: Fibonacci pattern on the cap (half angle cap_half_angle, seen from the centre) around the
  // direction of the rig at mid-window (exact orbit, so the pattern does not depend on the flag).
  const Eigen::Vector3d u = (exactState(0.5 * (sc.steps - 1) * t.dt).p - t.centre).normalized();
  const Eigen::Vector3d a = u.unitOrthogonal();
  const Eigen::Vector3d b = u.cross(a);
  const double golden = 3.14159265358979323846 * (3.0 - std::sqrt(5.0));
  t.landmarks.resize(sc.landmarks);
  for (int j = 0; j < sc.landmarks; ++j) {
    const double cb = 1.0 - (1.0 - std::cos(sc.cap_half_angle)) * (j + 0.5) / sc.landmarks;
    const double sb = std::sqrt(std::max(0.0, 1.0 - cb * cb));
    const double al = golden * j;
    t.landmarks[j] = t.centre + sc.sphere_radius * (sb * std::cos(al) * a + sb * std::sin(al) * b + cb * u);
  }

  // Measured: in front of the left camera, inside its image, surface facing the rig.
  const double cx = 0.5 * (sc.image_width - 1), cy = 0.5 * (sc.image_height - 1);
  t.visible.resize(sc.steps);
  for (int k = 0; k < sc.steps; ++k) {
    const RigState& x = t.states[k];
    for (int j = 0; j < sc.landmarks; ++j) {
      const Eigen::Vector3d& m = t.landmarks[j];
      const Eigen::Vector3d pc = observeLandmark(x, m);
      if (!(pc.z() > 1e-3)) continue;
      const double px = sc.focal_px * pc.x() / pc.z() + cx, py = sc.focal_px * pc.y() / pc.z() + cy;
      if (px < 0.0 || px > sc.image_width - 1 || py < 0.0 || py > sc.image_height - 1) continue;
      if ((m - t.centre).dot(x.p - m) <= 0.0) continue;
      t.visible[k].push_back(j);
    }
  }
  return t;
}

Eigen::Matrix3d stereoPointCovariance(const Eigen::Vector3d& pc, const OrbitScenario& sc) {
  if (!(pc.z() > 0.0)) fail("stereoPointCovariance: point depth " + str(pc.z()) + " must be > 0");
  const double f = sc.focal_px, Z = pc.z();
  const double disparity = f * sc.baseline / Z;  // px
  Eigen::Matrix3d J;  // d(X, Y, Z) / d(u, v, disparity)
  J << Z / f, 0.0, -pc.x() / disparity,  //
      0.0, Z / f, -pc.y() / disparity,   //
      0.0, 0.0, -Z / disparity;
  const double s2 = sc.pixel_sigma * sc.pixel_sigma;
  const Eigen::Vector3d var(s2, s2, 2.0 * s2);
  return J * var.asDiagonal() * J.transpose();
}

// ============================================================================================ experiments

const char* experimentName(Experiment e) {
  switch (e) {
    case Experiment::KnownLandmarks: return "experiment 1: ES-EKF with known landmarks";
    case Experiment::Slam: return "experiment 2: SLAM without gyroscope";
    case Experiment::SlamGyro: return "experiment 3: SLAM with gyroscope (no bias state)";
    case Experiment::SlamGyroBias: return "experiment 3b: SLAM with gyroscope and gyro-bias state";
  }
  return "?";
}

int experimentRigDim(Experiment e) { return e == Experiment::SlamGyroBias ? 15 : 12; }

int experimentDim(Experiment e, int landmarks) {
  return e == Experiment::KnownLandmarks ? 12 : experimentRigDim(e) + 3 * landmarks;
}

LinearizedSystem buildExperiment(const OrbitTrajectory& traj, const OrbitScenario& sc, Experiment e) {
  sc.validate();
  const int K = static_cast<int>(traj.landmarks.size());
  const int N = static_cast<int>(traj.states.size());
  if (N < 1 || static_cast<int>(traj.visible.size()) != N) fail("buildExperiment: inconsistent trajectory");
  const int rd = experimentRigDim(e), n = experimentDim(e, K);
  const bool slam = e != Experiment::KnownLandmarks;
  const bool gyro = e == Experiment::SlamGyro || e == Experiment::SlamGyroBias;

  EskfOptions opt;
  opt.gamma = 1.0;
  opt.lambda = 1.0;
  opt.estimate_gyro_bias = (rd == 15);
  opt.threads = 1;
  Eskf f(opt);
  f.setCapacity(K);

  LinearizedSystem sys;
  sys.F.reserve(N > 1 ? N - 1 : 0);
  sys.H.reserve(N);
  if (sc.information_weighting) sys.W.reserve(N);
  for (int k = 0; k < N; ++k) {
    f.reset(traj.states[k]);  // the Jacobians depend on the state only, not on the covariance
    if (k + 1 < N) {
      Eigen::MatrixXd F = Eigen::MatrixXd::Identity(n, n);
      F.topLeftCorner(rd, rd) = f.transitionJacobian(traj.dt);  // landmarks: identity
      sys.F.push_back(F);
    }
    const std::vector<int>& vis = traj.visible[k];
    const int m = 3 * static_cast<int>(vis.size()) + (gyro ? 3 : 0);
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(m, n);
    Eigen::MatrixXd W = Eigen::MatrixXd::Zero(m, m);
    for (size_t i = 0; i < vis.size(); ++i) {
      const int j = vis[i];
      const Eigen::Vector3d z = observeLandmark(traj.states[k], traj.landmarks[j]);
      const Eigen::Matrix3d Cz = stereoPointCovariance(z, sc);
      f.addLandmark(j, z, Cz);  // m = p + R z: the landmark, to rounding
      Eigen::Matrix<double, 3, 6> P;
      Eigen::Matrix3d M;
      f.measurementJacobianBlocks(j, &P, &M);
      const int r = 3 * static_cast<int>(i);
      H.block<3, 6>(r, 0) = P;                             // dp, dtheta
      if (slam) H.block<3, 3>(r, rd + 3 * j) = M;          // dm_j (experiment 1: m is known)
      W.block<3, 3>(r, r) = Cz.inverse();
    }
    if (gyro) {
      const int r = 3 * static_cast<int>(vis.size());
      H.middleRows(r, 3) = f.gyroJacobian();  // dw (and db_g)
      W.block<3, 3>(r, r) = Eigen::Matrix3d::Identity() / (sc.gyro_sigma * sc.gyro_sigma);
    }
    sys.H.push_back(H);
    if (sc.information_weighting) sys.W.push_back(0.5 * (W + W.transpose()));
  }
  sys.validate();
  return sys;
}

FilterCorrelation runFilterCorrelation(const OrbitTrajectory& traj, const OrbitScenario& sc, Experiment e,
                                       const EskfOptions& options) {
  sc.validate();
  const int K = static_cast<int>(traj.landmarks.size());
  const int N = static_cast<int>(traj.states.size());
  if (N < 1 || static_cast<int>(traj.visible.size()) != N) fail("runFilterCorrelation: inconsistent trajectory");
  const bool slam = e != Experiment::KnownLandmarks;
  const bool gyro = e == Experiment::SlamGyro || e == Experiment::SlamGyroBias;
  EskfOptions opt = options;
  opt.estimate_gyro_bias = (e == Experiment::SlamGyroBias);
  Eskf f(opt);
  f.setCapacity(slam ? K : 0);
  f.reset(traj.states[0]);
  const Eigen::Matrix3d Cg = Eigen::Matrix3d::Identity() * (sc.gyro_sigma * sc.gyro_sigma);
  FilterCorrelation out;
  for (int k = 0; k < N; ++k) {
    const RigState& truth = traj.states[k];
    if (k > 0) f.predict(traj.dt);
    if (slam) {
      std::vector<Eskf::Observation> obs;
      std::vector<int> fresh;
      for (int j : traj.visible[k]) {
        const Eigen::Vector3d z = observeLandmark(truth, traj.landmarks[j]);
        if (f.isActive(j)) {
          Eskf::Observation o;
          o.slot = j;
          o.z = z;
          o.C = stereoPointCovariance(z, sc);
          obs.push_back(o);
        } else {
          fresh.push_back(j);
        }
      }
      f.update(obs);
      for (int j : fresh) {
        const Eigen::Vector3d z = observeLandmark(truth, traj.landmarks[j]);
        f.addLandmark(j, z, stereoPointCovariance(z, sc));
      }
    } else {
      std::vector<Eskf::KnownObservation> obs;
      for (int j : traj.visible[k]) {
        Eskf::KnownObservation o;
        o.m = traj.landmarks[j];
        o.z = observeLandmark(truth, o.m);
        o.C = stereoPointCovariance(o.z, sc);
        obs.push_back(o);
      }
      f.updateKnown(obs);
    }
    if (gyro) f.updateGyro(truth.w + truth.gyro_bias, Cg);
    const Eigen::MatrixXd& C = f.covariance();
    const double svx = std::sqrt(std::max(0.0, C(6, 6))), swy = std::sqrt(std::max(0.0, C(10, 10)));
    out.std_vx.push_back(svx);
    out.std_wy.push_back(swy);
    out.corr_vx_wy.push_back(svx > 0.0 && swy > 0.0 ? C(6, 10) / (svx * swy) : 0.0);
  }
  return out;
}

}  // namespace slam
}  // namespace skin3d
