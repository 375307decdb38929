// SPDX-License-Identifier: BSD-3-Clause
/**
 * observability [--landmarks K] [--steps N] [--experiment 1|2|3|all] [--unweighted]
 *
 * Observability analysis of the ES-EKF SLAM's linearised error system (thesis §5.3) for the thesis'
 * experiments 1-3 on a globe-like orbit generated here (slam/observability.h): rank, rank deficiency,
 * smallest singular values and the unobservable directions of the observability matrix over N frames,
 * then the v_x - w_y ambiguity over short windows (marginal information of (v, w)) and the filter's
 * own correlation of the two. Needs no ROS master. Exit codes: 0 ok, 1 internal error, 2 bad command line.
 */
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include <Eigen/SVD>

#include "skin3d/slam/eskf.h"
#include "skin3d/slam/observability.h"

using namespace skin3d::slam;

namespace {

const char* kUsage =
    "usage: observability [--landmarks K] [--steps N] [--experiment 1|2|3|all] [--unweighted]\n"
    "  --landmarks K   landmarks on the sphere's visible cap, 1..100 (default 10)\n"
    "  --steps N       frames at 10 Hz, 1..200 (default 20)\n"
    "  --experiment E  1 = known landmarks, 2 = SLAM, 3 = SLAM + gyroscope (with and without a\n"
    "                  gyro-bias state), all (default)\n"
    "  --unweighted    W_k = I instead of the measurement information (stereo / gyro noise)\n";

constexpr double kRelTol = 1e-9;
constexpr int kShown = 8;

bool parseInt(const std::string& s, int lo, int hi, int* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(s.c_str(), &end, 10);
  if (errno != 0 || end == s.c_str() || *end != '\0' || v < lo || v > hi) return false;
  *out = static_cast<int>(v);
  return true;
}

std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.2e", v);
  return buf;
}

std::string fix(double v, int prec = 3) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.*f", prec, v);
  return buf;
}

std::string vec(const Eigen::Vector3d& v, int prec = 3) {
  return "(" + fix(v.x(), prec) + ", " + fix(v.y(), prec) + ", " + fix(v.z(), prec) + ")";
}

// The smallest `count` singular values, smallest first.
std::string smallest(const Eigen::VectorXd& s, int count) {
  std::string out;
  const int n = static_cast<int>(s.size());
  for (int i = 0; i < std::min(count, n); ++i) out += (i ? " " : "") + sci(s(n - 1 - i));
  return out;
}

// Orthonormal basis of the span of the (independent) columns of A: Gram-Schmidt, orthogonalised twice.
Eigen::MatrixXd orthonormalise(const Eigen::MatrixXd& A) {
  Eigen::MatrixXd Q = A;
  for (Eigen::Index j = 0; j < Q.cols(); ++j) {
    for (int pass = 0; pass < 2; ++pass)
      for (Eigen::Index i = 0; i < j; ++i) Q.col(j) -= Q.col(i).dot(Q.col(j)) * Q.col(i);
    Q.col(j).normalize();
  }
  return Q;
}

Eigen::MatrixXd dropColumns(const Eigen::MatrixXd& M, int first, int count) {
  Eigen::MatrixXd out(M.rows(), M.cols() - count);
  out << M.leftCols(first), M.rightCols(M.cols() - first - count);
  return out;
}

void reportExperiment(Experiment e, const OrbitTrajectory& traj, const OrbitScenario& sc) {
  const int K = sc.landmarks, N = sc.steps;
  const LinearizedSystem sys = buildExperiment(traj, sc, e);
  ObservabilityOptions opt;
  opt.relative_tolerance = kRelTol;
  opt.weakest_count = kShown;
  const Eigen::MatrixXd R = observabilityFactor(sys);
  const ObservabilityReport rep = analyseMatrix(R, opt);
  const int rd = experimentRigDim(e);
  const std::vector<StateBlock> blocks = errorStateBlocks(rd, e == Experiment::KnownLandmarks ? 0 : K);
  const bool slam = e != Experiment::KnownLandmarks;

  std::cout << "\n== " << experimentName(e) << "\n";
  std::cout << "  state: " << rep.dim << " = " << (slam ? std::to_string(rd) + " (rig) + 3 x " + std::to_string(K) + " (landmarks)" : std::string("12 (rig: p, theta, v, w)"))
            << "; measurements: " << (slam ? "z = R^T (m_j - p), m_j estimated" : "z = R^T (m_j - p), m_j known")
            << (e == Experiment::SlamGyro ? " + gyro z_g = w" : "") << (e == Experiment::SlamGyroBias ? " + gyro z_g = w + b_g" : "")
            << "\n";
  // Theory (K >= 3 landmarks not on one line, every landmark seen, N >= 2 frames).
  std::string theory = "n/a (needs N >= 2 frames and K >= 3 landmarks)";
  if (N >= 2 && K >= 3) {
    const int expect = slam ? 6 + 3 * traj.neverSeen() : 0;
    theory = std::to_string(expect) + (slam ? " (6 gauge" + (traj.neverSeen() ? " + 3 x " + std::to_string(traj.neverSeen()) + " never-seen landmarks" : std::string()) + ")" : " (full rank)");
  }
  std::cout << "  rank " << rep.rank << " of " << rep.dim << ", deficiency " << rep.deficiency() << "   [theory: " << theory
            << "]\n";
  std::cout << "  smallest singular values (smallest first): " << smallest(rep.singular_values, kShown) << "\n";
  std::cout << "  sigma_max " << sci(rep.singular_values(0)) << ", rank threshold " << sci(rep.tolerance);
  if (rep.rank > 0 && rep.rank < rep.dim)
    std::cout << ", gap sigma_" << rep.rank << " / sigma_" << rep.rank + 1 << " = "
              << sci(rep.singular_values(rep.rank - 1) / std::max(rep.singular_values(rep.rank), 1e-300));
  std::cout << ", condition of the observable part " << sci(rep.observableCondition()) << "\n";

  if (!slam || rep.deficiency() == 0) {
    std::cout << "  weakest direction (sigma " << sci(rep.singular_values(rep.dim - 1))
              << "): " << describeDirection(rep.weakest.col(0), blocks) << "\n";
    return;
  }
  // The gauge: analytic directions vs the numerical null space.
  const Eigen::MatrixXd gauge = slamGaugeBasis(traj.states[0], traj.landmarks, rd);
  const Eigen::MatrixXd N0 = rep.nullSpace();
  const Eigen::MatrixXd Q = orthonormalise(gauge);
  const double gauge_out = subspaceResidual(gauge, N0), null_out = subspaceResidual(N0, Q);
  std::cout << "  unobservable directions: the " << rep.deficiency() << "-dim null space vs the 6 analytic gauge vectors:\n"
            << "    largest distance of a gauge vector from the null space " << sci(gauge_out)
            << ", of a null vector from the gauge span " << sci(null_out) << "\n";
  if (rep.deficiency() == 6 && gauge_out < 1e-6 && null_out < 1e-6)
    std::cout << "    => exactly the world frame's gauge freedom:\n";
  else
    std::cout << "    => NOT (only) the gauge: see the directions below\n";
  const char* names[6] = {"global translation x (p and every m shifted together)",
                          "global translation y (p and every m shifted together)",
                          "global translation z (p and every m shifted together)",
                          "global rotation about world x (theta, p and every m turned together about the origin)",
                          "global rotation about world y (theta, p and every m turned together about the origin)",
                          "global rotation about world z (theta, p and every m turned together about the origin)"};
  for (int i = 0; i < 6; ++i) {
    const Eigen::VectorXd proj = N0 * (N0.transpose() * gauge.col(i));
    std::cout << "    " << names[i] << "\n      null vector closest to it: " << describeDirection(proj, blocks) << "\n";
  }
  if (rep.deficiency() != 6)
    for (int i = 0; i < rep.deficiency(); ++i)
      std::cout << "    null vector " << i << ": " << describeDirection(rep.weakest.col(i), blocks) << "\n";
  // skin3d's anchor: the first pose (p, theta) is known exactly (zero initial covariance).
  const ObservabilityReport anchored = analyseMatrix(dropColumns(R, 0, 6), opt);
  std::cout << "  skin3d removes the gauge by fixing the first pose (p_0, theta_0) with zero covariance\n"
            << "  (EskfOptions::initial_position_std = initial_attitude_std = 0): without those 6 columns rank "
            << anchored.rank << " of " << anchored.dim << " (" << (anchored.fullRank() ? "full" : "deficient") << "), smallest sigma "
            << sci(anchored.singular_values(anchored.dim - 1)) << "\n";
}

// The v_x - w_y ambiguity: marginal information of (v, w) over windows of w frames.
void reportAmbiguity(const std::vector<Experiment>& exps, const OrbitTrajectory& traj, const OrbitScenario& sc) {
  std::vector<int> windows;
  for (int w : {2, 3, 5, 10, 20})
    if (w <= sc.steps) windows.push_back(w);
  if (sc.steps >= 2 && (windows.empty() || windows.back() != sc.steps)) windows.push_back(sc.steps);
  std::cout << "\n== v_x - w_y ambiguity (thesis §7.4): observability restricted to (v, w) over the first w frames\n"
            << "  J = marginal information of (v, w): their columns of the whitened O projected off the other states'\n"
            << "  columns (landmarks estimated; first pose anchored in SLAM, as in skin3d) = Schur complement of the\n"
            << "  Gramian; noise-free constant-velocity model, no prior. sigma_min/max: sqrt of eig J (v in m/s, w in\n"
            << "  rad/s). From J^-1 (Cramer-Rao bound): corr(v_x, w_y); beta = cov(v_x, w_y) / var(w_y) in m (an error\n"
            << "  d w_y comes with d v_x ~ beta d w_y; orbiting a point at depth d ahead is beta = -d); the twin pair\n"
            << "  corr(v_y, w_x); std of v_x (mm/s) and w_y (mrad/s); smallest eigenvalue of the 6x6 correlation\n"
            << "  matrix (unit-free, -> 0 when two estimates are nearly collinear: an ambiguity).\n";
  if (windows.empty()) {
    std::cout << "  (needs at least 2 frames)\n";
    return;
  }
  for (Experiment e : exps) {
    const LinearizedSystem sys = buildExperiment(traj, sc, e);
    const bool slam = e != Experiment::KnownLandmarks;
    std::cout << "  " << experimentName(e) << "\n"
              << "    w  sigma_min  sigma_max  corr(vx,wy)  beta(m)  corr(vy,wx)  std vx  std wy  min eig corr\n";
    const std::vector<int> kept = {6, 7, 8, 9, 10, 11};
    const std::vector<int> known = slam ? std::vector<int>{0, 1, 2, 3, 4, 5} : std::vector<int>{};
    for (int w : windows) {
      const RestrictedObservability r = restrictObservability(observabilityFactor(sys, w), kept, known, kRelTol);
      char line[256];
      if (r.rank < 6) {
        std::snprintf(line, sizeof(line), "   %2d  %.2e   %.2e   (rank %d of 6: not observable)\n", w,
                      r.singular_values(5), r.singular_values(0), r.rank);
        std::cout << line;
        continue;
      }
      const Eigen::MatrixXd& C = r.covariance;
      const double corr = r.correlation(0, 4), beta = C(0, 4) / C(4, 4);
      // The correlation matrix is symmetric positive definite: its SVD is its eigen-decomposition.
      const Eigen::JacobiSVD<Eigen::MatrixXd, Eigen::NoQRPreconditioner> es(r.correlation);
      std::snprintf(line, sizeof(line), "   %2d  %.2e   %.2e   %+.4f     %+.3f    %+.4f     %6.2f  %6.2f   %.2e\n", w,
                    r.singular_values(5), r.singular_values(0), corr, beta, r.correlation(1, 3), 1e3 * std::sqrt(C(0, 0)),
                    1e3 * std::sqrt(C(4, 4)), es.singularValues()(5));
      std::cout << line;
    }
  }
  // The filter itself (its own prior and process noise), as the thesis' correlation plot (Fig. 7.4).
  std::cout << "  The ES-EKF itself (skin3d::slam::Eskf, default EskfOptions: initial std v 0.1 m/s, w 0.2 rad/s, process\n"
            << "  noise 0.05 m/s/sqrt(s), 0.1 rad/s/sqrt(s)) run with noise-free measurements along the same trajectory:\n"
            << "  corr(v_x, w_y) of its covariance after frame k (0-based; the thesis' Fig. 7.4 is at time instant 8)\n";
  std::vector<int> frames;
  for (int k : {1, 2, 3, 5, 8, 10, 20, 50, 100, 200})
    if (k < sc.steps - 1) frames.push_back(k);
  if (sc.steps >= 2) frames.push_back(sc.steps - 1);
  std::cout << "    k     ";
  for (int k : frames) {
    char b[16];
    std::snprintf(b, sizeof(b), " %8d", k);
    std::cout << b;
  }
  std::cout << "\n";
  for (Experiment e : exps) {
    const FilterCorrelation fc = runFilterCorrelation(traj, sc, e);
    std::cout << "    exp " << (e == Experiment::SlamGyroBias ? "3b" : std::to_string(static_cast<int>(e))) << (e == Experiment::SlamGyroBias ? " " : "  ");
    for (int k : frames) {
      char b[16];
      std::snprintf(b, sizeof(b), " %+8.4f", fc.corr_vx_wy[k]);
      std::cout << b;
    }
    std::cout << "\n";
  }
}

}  // namespace

int main(int argc, char** argv) {
  int K = 10, N = 20;
  std::string which = "all";
  bool weighted = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](std::string* out) {
      if (i + 1 >= argc) return false;
      *out = argv[++i];
      return true;
    };
    std::string v;
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--landmarks") {
      if (!value(&v) || !parseInt(v, 1, 100, &K)) {
        std::cerr << "observability: --landmarks needs an integer in [1, 100]" << (v.empty() ? "" : ", got '" + v + "'") << "\n" << kUsage;
        return 2;
      }
    } else if (a == "--steps") {
      if (!value(&v) || !parseInt(v, 1, 200, &N)) {
        std::cerr << "observability: --steps needs an integer in [1, 200]" << (v.empty() ? "" : ", got '" + v + "'") << "\n" << kUsage;
        return 2;
      }
    } else if (a == "--experiment") {
      if (!value(&v) || (v != "1" && v != "2" && v != "3" && v != "all")) {
        std::cerr << "observability: --experiment needs 1, 2, 3 or all" << (v.empty() ? "" : ", got '" + v + "'") << "\n" << kUsage;
        return 2;
      }
      which = v;
    } else if (a == "--unweighted") {
      weighted = false;
    } else {
      std::cerr << "observability: unknown argument '" << a << "'\n" << kUsage;
      return 2;
    }
  }

  try {
    OrbitScenario sc;
    sc.landmarks = K;
    sc.steps = N;
    sc.information_weighting = weighted;
    const OrbitTrajectory traj = makeOrbitTrajectory(sc);
    std::vector<Experiment> exps;
    if (which == "1" || which == "all") exps.push_back(Experiment::KnownLandmarks);
    if (which == "2" || which == "all") exps.push_back(Experiment::Slam);
    if (which == "3" || which == "all") {
      exps.push_back(Experiment::SlamGyro);
      exps.push_back(Experiment::SlamGyroBias);
    }

    int measured = 0;
    for (const auto& v : traj.visible) measured += static_cast<int>(v.size());
    const double deg = 180.0 / 3.14159265358979323846;
    std::cout << "skin3d observability analysis (thesis §5.3): linearised ES-EKF error system, observability matrix\n"
              << "O = [H_0; H_1 F_0; H_2 F_1 F_0; ...] of the state at frame 0, F_k and H_k from skin3d::slam::Eskf.\n";
    std::cout << "scenario (generated here, SI units): sphere radius " << fix(sc.sphere_radius) << " m, centre "
              << fix(sc.distance) << " m ahead of the first camera, orbit " << fix(sc.rate) << " rad/s (latitude "
              << fix(sc.latitude * deg, 0) << " deg, tilt " << fix(sc.tilt * deg, 0) << " deg), " << fix(sc.fps, 0)
              << " Hz, N = " << N << " frames (" << fix((N - 1) / sc.fps, 1) << " s)\n"
              << "  rig frame, constant: v = " << vec(traj.states[0].v) << " m/s, w = " << vec(traj.states[0].w)
              << " rad/s; poses propagated with the filter's model\n"
              << "  K = " << K << " landmarks (Fibonacci cap, " << fix(sc.cap_half_angle * deg, 0)
              << " deg half angle seen from the centre, facing the mid-window pose); " << measured
              << " landmark measurements (" << traj.neverSeen() << " landmarks never seen)\n";
    double dmin = 1e9, dmax = 0.0;
    for (const Eigen::Vector3d& m : traj.landmarks) {
      const double d = observeLandmark(traj.states[0], m).z();
      dmin = std::min(dmin, d);
      dmax = std::max(dmax, d);
    }
    std::cout << "  landmark depth in the first frame " << fix(dmin) << " .. " << fix(dmax) << " m\n";
    if (weighted)
      std::cout << "  weighting W_k = measurement information: stereo point covariance (sigma " << fix(sc.pixel_sigma, 1)
                << " px per coordinate, f " << fix(sc.focal_px, 1) << " px, baseline " << fix(sc.baseline) << " m), gyro "
                << sc.gyro_sigma << " rad/s per axis and frame\n";
    else
      std::cout << "  weighting W_k = I (unweighted, SI units)\n";
    std::cout << "  rank = #{sigma_i > " << sci(kRelTol) << " sigma_max}; singular values of " << (weighted ? "the whitened O" : "O")
              << " = sqrt of the Gramian's\n  eigenvalues, in " << (weighted ? "(whitened measurement)" : "(measurement unit: m, rad/s)")
              << " per state unit (m, rad, m/s, rad/s).\n";

    for (Experiment e : exps) reportExperiment(e, traj, sc);

    if (which == "2" || which == "all") {
      OrbitScenario exact = sc;
      exact.model_consistent_trajectory = false;
      const OrbitTrajectory tx = makeOrbitTrajectory(exact);
      ObservabilityOptions o;
      o.relative_tolerance = kRelTol;
      const ObservabilityReport r = analyseObservability(buildExperiment(tx, exact, Experiment::Slam), o);
      std::cout << "\n  note (experiment 2 linearised on the exact circular orbit instead of a trajectory of the model:\n"
                << "  the Euler step p+ = p + R v dt misses it by O(|w||v| dt^2)): rank " << r.rank << " of " << r.dim
                << ", smallest singular values " << smallest(r.singular_values, 7) << "\n"
                << "  -> a linearisation that is not a trajectory of the model makes part of the gauge look observable\n"
                << "     (spurious information: the EKF-SLAM inconsistency of linearising at changing estimates).\n";
    }

    std::vector<Experiment> amb;
    for (Experiment e : exps)
      if (e != Experiment::SlamGyroBias) amb.push_back(e);
    reportAmbiguity(amb, traj, sc);
  } catch (const std::exception& ex) {
    std::cerr << "observability: " << ex.what() << "\n";
    return 1;
  }
  return 0;
}
