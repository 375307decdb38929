// SPDX-License-Identifier: BSD-3-Clause
// ES-EKF SLAM (skin3d::slam::Eskf): every Jacobian against central differences of the true nonlinear
// functions (perturbing in the error state), the structure-aware filter against the textbook dense
// one, symmetry / positive definiteness over long random runs, a Monte Carlo NEES / NIS consistency
// check on the test's own small simulation (never the project's simulator), and bad inputs.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <iostream>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/slam/eskf.h"

using namespace skin3d::slam;
using skin3d::geometry::quatExp;
using skin3d::geometry::quatLog;
using skin3d::geometry::skew;
using skin3d::geometry::so3LeftJacobian;
using skin3d::geometry::toRotationMatrix;

namespace {

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;

Eigen::Vector3d gauss3(std::mt19937& rng, double sigma) {
  std::normal_distribution<double> n(0.0, sigma);
  return Eigen::Vector3d(n(rng), n(rng), n(rng));
}

Eigen::Vector3d uniform3(std::mt19937& rng, double a) {
  std::uniform_real_distribution<double> u(-a, a);
  return Eigen::Vector3d(u(rng), u(rng), u(rng));
}

// A non-trivial rig state: random attitude (up to ~pi), non-zero velocity, turn rate ~1 rad/s and bias.
RigState randomState(std::mt19937& rng) {
  RigState x;
  x.p = uniform3(rng, 0.3);
  Eigen::Vector3d axis = gauss3(rng, 1.0).normalized();
  x.q = quatExp(axis * std::uniform_real_distribution<double>(0.5, 3.0)(rng));
  x.v = uniform3(rng, 0.2);
  x.w = uniform3(rng, 1.0);
  x.gyro_bias = uniform3(rng, 0.05);
  return x;
}

// Random symmetric positive definite matrix with eigenvalues in about [lo, lo + hi].
Mat randomSpd(std::mt19937& rng, int n, double lo, double hi) {
  std::normal_distribution<double> g(0.0, 1.0);
  const Mat A = Mat::NullaryExpr(n, n, [&]() { return g(rng); });
  const Mat P = (hi / (4.0 * n)) * A * A.transpose() + lo * Mat::Identity(n, n);
  return 0.5 * (P + P.transpose());
}

Eigen::Matrix3d stereoCov(std::mt19937& rng) {
  // A stereo-like covariance: ~1 mm laterally, ~3 mm in depth, random orientation.
  const Eigen::Matrix3d Rr = quatExp(uniform3(rng, 0.3)).toRotationMatrix();
  return Rr * Eigen::Vector3d(1e-6, 1.2e-6, 9e-6).asDiagonal() * Rr.transpose();
}

// Central differences of f: R^in -> R^out around 0.
Mat numericJacobian(const std::function<Vec(const Vec&)>& f, int in_dim, double h = 1e-6) {
  Vec e = Vec::Zero(in_dim);
  const Vec f0 = f(e);
  Mat J(f0.size(), in_dim);
  for (int j = 0; j < in_dim; ++j) {
    e.setZero();
    e(j) = h;
    const Vec fp = f(e);
    e(j) = -h;
    const Vec fm = f(e);
    J.col(j) = (fp - fm) / (2.0 * h);
  }
  return J;
}

double maxAbs(const Mat& A) { return A.size() ? A.cwiseAbs().maxCoeff() : 0.0; }
double relDiff(const Mat& A, const Mat& B) { return maxAbs(A - B) / std::max(maxAbs(B), 1e-300); }

// Wilson-Hilferty approximation of the chi-square quantile (k dof, probability p); accurate to
// < 0.1 % for the k >= 100 used here. z = standard normal quantile of p.
double chi2Quantile(double k, double z) {
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3);
}
constexpr double kZ975 = 1.959963985;

EskfOptions testOptions(bool bias) {
  EskfOptions o;
  o.gamma = 0.95;
  o.lambda = 0.9;
  o.velocity_noise = 0.02;
  o.angular_rate_noise = 0.05;
  o.estimate_gyro_bias = bias;
  o.gyro_bias_walk = 1e-3;
  o.threads = 2;
  return o;
}

// Snapshot of everything a failed call must leave unchanged.
struct Snapshot {
  RigState x;
  Mat C;
  std::vector<int> active;
  std::vector<Eigen::Vector3d> lm;
  explicit Snapshot(const Eskf& f) : x(f.state()), C(f.covariance()) {
    for (int j = 0; j < f.capacity(); ++j) {
      active.push_back(f.isActive(j));
      lm.push_back(f.isActive(j) ? f.landmark(j) : Eigen::Vector3d::Zero());
    }
  }
  bool operator==(const Snapshot& o) const {
    return x.p == o.x.p && x.q.coeffs() == o.x.q.coeffs() && x.v == o.x.v && x.w == o.x.w &&
           x.gyro_bias == o.x.gyro_bias && C.rows() == o.C.rows() && C == o.C && active == o.active && lm == o.lm;
  }
};

// A filter reset at a random state with a random (PD) rig covariance and `k` landmarks near the rig.
Eskf makeFilter(std::mt19937& rng, bool bias, int capacity, int k, EskfOptions opt) {
  opt.estimate_gyro_bias = bias;
  Eskf f(opt);
  f.setCapacity(capacity);
  f.reset(randomState(rng), randomSpd(rng, f.rigDim(), 1e-6, 1e-2));
  for (int j = 0; j < k; ++j) f.addLandmark(j, Eigen::Vector3d(0, 0, 1.0) + uniform3(rng, 0.3), stereoCov(rng));
  return f;
}

}  // namespace

// ============================================================================ Jacobians

TEST(EskfJacobians, TransitionMatchesNumericalAndNotesApproximationDoesNot) {
  std::mt19937 rng(11);
  for (bool bias : {false, true}) {
    for (int trial = 0; trial < 5; ++trial) {
      const Eskf f = makeFilter(rng, bias, 0, 0, testOptions(bias));
      const RigState x = f.state();
      const int rd = f.rigDim();
      const double dt = 0.1;
      const auto& o = f.options();
      const RigState x1 = propagateNominal(x, dt, o.gamma, o.lambda);
      const Mat Fn = numericJacobian(
          [&](const Vec& e) { return rigDifference(propagateNominal(retract(x, e), dt, o.gamma, o.lambda), x1, rd); },
          rd);
      const Mat F = f.transitionJacobian(dt);
      EXPECT_LT(maxAbs(F - Fn), 1e-8) << "bias " << bias << "\nF\n" << F << "\nnumerical\n" << Fn;
      // ESKF_NOTES' approximation R dt (instead of R Jl(w dt) dt) in the dtheta-dw block is off by
      // about |w| dt^2 / 2 here: far outside the tolerance, so the filter uses the exact form.
      const Eigen::Matrix3d R = toRotationMatrix(x.q);
      EXPECT_GT(maxAbs(R * dt - Fn.block(3, 9, 3, 3)), 1e-4);
      EXPECT_LT(maxAbs(R * so3LeftJacobian(x.w * dt) * dt - Fn.block(3, 9, 3, 3)), 1e-8);
    }
  }
}

TEST(EskfJacobians, MeasurementMatchesNumerical) {
  std::mt19937 rng(12);
  for (bool bias : {false, true}) {
    for (int trial = 0; trial < 5; ++trial) {
      const Eskf f = makeFilter(rng, bias, 4, 3, testOptions(bias));
      const RigState x = f.state();
      const int rd = f.rigDim(), slot = 1, s = f.slotIndex(slot);
      const Eigen::Vector3d m = f.landmark(slot);
      // Perturb [rig error, landmark error]: h = R^T (m - p) at retract(x, e_rig), m + e_m.
      const Mat Hn = numericJacobian(
          [&](const Vec& e) -> Vec { return observeLandmark(retract(x, e.head(rd)), m + e.tail<3>()); }, rd + 3);
      const Eskf::Observation ob{slot, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity()};
      const Mat H = f.measurementJacobian(ob);
      ASSERT_EQ(H.rows(), 3);
      ASSERT_EQ(H.cols(), f.dim());
      EXPECT_LT(maxAbs(H.leftCols(rd) - Hn.leftCols(rd)), 1e-8);
      EXPECT_LT(maxAbs(H.middleCols(s, 3) - Hn.rightCols(3)), 1e-8);
      // Every other column is zero (v, w, bias and the other slots).
      EXPECT_EQ(maxAbs(H.middleCols(6, rd - 6)), 0.0);
      EXPECT_EQ(maxAbs(H.middleCols(rd, s - rd)), 0.0);
      EXPECT_EQ(maxAbs(H.rightCols(f.dim() - s - 3)), 0.0);
      Eigen::Matrix<double, 3, 6> Hp;
      Eigen::Matrix3d Hm;
      f.measurementJacobianBlocks(slot, &Hp, &Hm);
      EXPECT_EQ(Mat(Hp), Mat(H.leftCols(6)));
      EXPECT_EQ(Mat(Hm), Mat(H.middleCols(s, 3)));
      EXPECT_LT((f.predictObservation(slot) - observeLandmark(x, m)).norm(), 1e-15);
    }
  }
}

TEST(EskfJacobians, KnownPointMeasurementMatchesNumerical) {
  std::mt19937 rng(17);
  for (bool bias : {false, true}) {
    Eskf f = makeFilter(rng, bias, 2, 2, testOptions(bias));
    f.predict(0.1);
    const RigState x = f.state();
    const int rd = f.rigDim();
    const Eigen::Vector3d m = x.p + toRotationMatrix(x.q) * Eigen::Vector3d(0.1, -0.05, 0.6);
    const Mat Hn = numericJacobian([&](const Vec& e) -> Vec { return observeLandmark(retract(x, e), m); }, rd);
    const Eskf::KnownObservation ko{m, observeLandmark(x, m) + Eigen::Vector3d(1e-3, 2e-3, -1e-3), stereoCov(rng)};
    const Eskf::Innovation in = f.innovationKnown(ko);
    const Mat S = Hn * f.rigCovariance() * Hn.transpose() + ko.C;
    EXPECT_LT(relDiff(in.S, S), 1e-7);
    EXPECT_LT((in.y - (ko.z - observeLandmark(x, m))).norm(), 1e-15);
    EXPECT_NEAR(in.d2, in.y.dot(S.llt().solve(in.y)), 1e-6 * in.d2);
    const Eskf::UpdateResult r = f.updateKnown({ko});
    EXPECT_NEAR(r.nis, in.d2, 1e-9 * in.d2);
  }
}

TEST(EskfJacobians, AugmentationMatchesNumericalAndAddLandmarkUsesIt) {
  std::mt19937 rng(13);
  for (bool bias : {false, true}) {
    for (int trial = 0; trial < 5; ++trial) {
      Eskf f = makeFilter(rng, bias, 5, 2, testOptions(bias));
      f.predict(0.1);  // rig-landmark correlations
      const RigState x = f.state();
      const int rd = f.rigDim();
      const Eigen::Vector3d z = Eigen::Vector3d(0.05, -0.02, 0.4) + uniform3(rng, 0.05);
      const Mat Jn = numericJacobian(
          [&](const Vec& e) -> Vec { return landmarkFromObservation(retract(x, e.head(rd)), z + e.tail<3>()); },
          rd + 3);
      const Eskf::AugmentationJacobians J = f.augmentationJacobians(z);
      ASSERT_EQ(J.Jx.rows(), 3);
      ASSERT_EQ(J.Jx.cols(), rd);
      EXPECT_LT(maxAbs(J.Jx - Jn.leftCols(rd)), 1e-8);
      EXPECT_LT(maxAbs(Mat(J.Jz) - Jn.rightCols(3)), 1e-8);

      // addLandmark: m = p + R z, C_mm = Jx C_xx Jx^T + R Cz R^T, C_m. = Jx C_x. (whole row).
      const Eigen::Matrix3d Cz = stereoCov(rng);
      const Mat C0 = f.covariance();
      const int slot = 3, s = f.slotIndex(slot);
      f.addLandmark(slot, z, Cz);
      EXPECT_LT((f.landmark(slot) - landmarkFromObservation(x, z)).norm(), 1e-15);
      const Mat Cxx = C0.topLeftCorner(rd, rd);
      const Mat Cmm = J.Jx * Cxx * J.Jx.transpose() + J.Jz * Cz * J.Jz.transpose();
      EXPECT_LT(relDiff(f.landmarkCovariance(slot), Cmm), 1e-12);
      Mat Jfull = Mat::Zero(3, f.dim());
      Jfull.leftCols(rd) = J.Jx;
      Mat Cmx = Jfull * C0;
      Cmx.middleCols(s, 3) = Cmm;
      EXPECT_LT(relDiff(f.covariance().middleRows(s, 3), Cmx), 1e-12);
      EXPECT_EQ(f.covariance(), Mat(f.covariance().transpose()));
    }
  }
}

TEST(EskfJacobians, ResetMatchesNumericalAndFirstOrderFormIsOnlyApproximate) {
  std::mt19937 rng(14);
  for (bool bias : {false, true}) {
    const int rd = bias ? 15 : 12;
    for (int trial = 0; trial < 5; ++trial) {
      const RigState x = randomState(rng);
      Vec dhat = Vec::Zero(rd);
      dhat.head(rd) = gauss3(rng, 0.1).replicate(rd / 3, 1);
      dhat.segment<3>(3) = gauss3(rng, 0.2);  // a large injected angle makes the difference visible
      const RigState xn = retract(x, dhat);
      // The true reset: the error of a truth retract(x, dx_old) relative to the injected state xn.
      const Mat Gn = numericJacobian([&](const Vec& e) { return rigDifference(retract(x, dhat + e), xn, rd); }, rd);
      Mat G = Mat::Identity(rd, rd);
      G.block(3, 3, 3, 3) = Eskf::resetJacobian(dhat.segment<3>(3));
      EXPECT_LT(maxAbs(G - Gn), 1e-8) << "G\n" << G << "\nnumerical\n" << Gn;
      // ESKF_NOTES / Sola's first-order G_theta = I + 1/2 [dtheta]x is off by O(|dtheta|^2).
      const Eigen::Matrix3d G1 = Eigen::Matrix3d::Identity() + 0.5 * skew(dhat.segment<3>(3));
      EXPECT_GT(maxAbs(Mat(G1) - Gn.block(3, 3, 3, 3)), 1e-4);
    }
  }
}

TEST(EskfJacobians, GyroMatchesNumerical) {
  std::mt19937 rng(15);
  for (bool bias : {false, true}) {
    const Eskf f = makeFilter(rng, bias, 3, 2, testOptions(bias));
    const RigState x = f.state();
    const int rd = f.rigDim();
    const Mat Hn = numericJacobian([&](const Vec& e) -> Vec { return predictGyro(retract(x, e)); }, rd);
    const Mat H = f.gyroJacobian();
    ASSERT_EQ(H.cols(), f.dim());
    EXPECT_LT(maxAbs(H.leftCols(rd) - Hn), 1e-9);
    EXPECT_EQ(maxAbs(H.rightCols(f.dim() - rd)), 0.0);
    EXPECT_EQ(H.block(0, 9, 3, 3), Mat(Eigen::Matrix3d::Identity()));
    if (bias) {
      EXPECT_EQ(H.block(0, 12, 3, 3), Mat(Eigen::Matrix3d::Identity()));
    }
  }
}

TEST(EskfJacobians, InjectIsTheRetraction) {
  std::mt19937 rng(16);
  Eskf f = makeFilter(rng, true, 4, 3, testOptions(true));
  const RigState x = f.state();
  const Eigen::Vector3d m0 = f.landmark(0), m2 = f.landmark(2);
  Vec dx = Vec::Zero(f.dim());
  for (int i = 0; i < f.dim(); ++i) dx(i) = 0.01 * (i + 1);
  f.inject(dx);
  const RigState xr = retract(x, dx.head(15));
  EXPECT_LT((f.state().p - xr.p).norm(), 1e-15);
  EXPECT_LT(quatLog(f.state().q * xr.q.conjugate()).norm(), 1e-15);
  EXPECT_LT((f.state().gyro_bias - xr.gyro_bias).norm(), 1e-15);
  EXPECT_LT((f.landmark(0) - (m0 + dx.segment<3>(f.slotIndex(0)))).norm(), 1e-15);
  EXPECT_LT((f.landmark(2) - (m2 + dx.segment<3>(f.slotIndex(2)))).norm(), 1e-15);
  EXPECT_FALSE(f.isActive(3));
  // rigDifference inverts retract.
  EXPECT_LT((rigDifference(xr, x, 15) - dx.head(15)).norm(), 1e-12);
}

// ============================================================================ fast vs dense

namespace {

// The test's own little world: fixed landmarks and a rig following the filter's motion model.
struct World {
  std::vector<Eigen::Vector3d> pts;
  RigState truth;
  std::mt19937 rng;
  EskfOptions opt;
  World(unsigned seed, int n_points, const EskfOptions& o) : rng(seed), opt(o) {
    std::uniform_real_distribution<double> u(-0.5, 0.5), d(0.8, 1.5);
    for (int i = 0; i < n_points; ++i) pts.emplace_back(u(rng), u(rng), d(rng));
    truth.v = Eigen::Vector3d(0.03, 0.01, 0.02);
    truth.w = Eigen::Vector3d(0.02, -0.05, 0.03);
  }
  // Truth motion: the filter's own model with its process noise (v, w, bias random walks); with
  // opt.landmark_walk the points random-walk along the camera's axes as the filter's model says.
  void step(double dt) {
    if (!(opt.landmark_walk.array() == 0.0).all()) {
      const Eigen::Matrix3d R = skin3d::geometry::toRotationMatrix(truth.q);
      for (auto& m : pts) m += R * opt.landmark_walk.cwiseProduct(gauss3(rng, std::sqrt(dt)));
    }
    truth = propagateNominal(truth, dt, opt.gamma, opt.lambda);
    truth.v += gauss3(rng, opt.velocity_noise * std::sqrt(dt));
    truth.w += gauss3(rng, opt.angular_rate_noise * std::sqrt(dt));
    if (opt.estimate_gyro_bias) truth.gyro_bias += gauss3(rng, opt.gyro_bias_walk * std::sqrt(dt));
  }
  bool visible(int j) const {
    const Eigen::Vector3d c = observeLandmark(truth, pts[j]);
    return c.z() > 0.2 && std::abs(c.x()) < 0.8 * c.z() && std::abs(c.y()) < 0.8 * c.z();
  }
  // A measurement of landmark j with covariance C: z = R^T (m - p) + n, n ~ N(0, C).
  Eigen::Vector3d measure(int j, const Eigen::Matrix3d& C) {
    const Eigen::Matrix3d L = C.llt().matrixL();
    return observeLandmark(truth, pts[j]) + L * gauss3(rng, 1.0);
  }
  Eigen::Vector3d measureGyro(const Eigen::Matrix3d& C) {
    const Eigen::Matrix3d L = C.llt().matrixL();
    return predictGyro(truth) + L * gauss3(rng, 1.0);
  }
};

void expectSameFilter(const Eskf& a, const Eskf& b, double tol, const std::string& where) {
  ASSERT_EQ(a.dim(), b.dim()) << where;
  EXPECT_LT(relDiff(a.covariance(), b.covariance()), tol) << where;
  EXPECT_LT((a.state().p - b.state().p).norm(), tol * (1.0 + b.state().p.norm())) << where;
  EXPECT_LT(quatLog(a.state().q * b.state().q.conjugate()).norm(), tol) << where;
  EXPECT_LT((a.state().v - b.state().v).norm(), tol * (1.0 + b.state().v.norm())) << where;
  EXPECT_LT((a.state().w - b.state().w).norm(), tol * (1.0 + b.state().w.norm())) << where;
  EXPECT_LT((a.state().gyro_bias - b.state().gyro_bias).norm(), tol) << where;
  for (int j = 0; j < a.capacity(); ++j) {
    ASSERT_EQ(a.isActive(j), b.isActive(j)) << where;
    if (a.isActive(j)) {
      EXPECT_LT((a.landmark(j) - b.landmark(j)).norm(), tol * (1.0 + b.landmark(j).norm())) << where;
    }
  }
}

// The same random sequence of predict / update / gyro / add / remove / grow on the fast and the dense filter.
void runFastVsDense(unsigned seed, bool bias, int n_points, bool explicit_gain, int steps,
                    const Eigen::Vector3d& walk = Eigen::Vector3d::Zero()) {
  EskfOptions opt = testOptions(bias);
  opt.landmark_walk = walk;
  opt.joseph_explicit_gain = explicit_gain;
  World w(seed, n_points, opt);
  Eskf fast(opt), dense(opt);
  const int cap0 = n_points - 5;
  Mat P0 = Mat::Zero(fast.rigDim(), fast.rigDim());
  P0.diagonal().setConstant(1e-6);
  P0.block(6, 6, 6, 6).diagonal().setConstant(1e-3);
  for (Eskf* f : {&fast, &dense}) {
    f->setCapacity(cap0);
    f->reset(w.truth, P0);
  }
  std::mt19937 rng(seed + 1000);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double max_rel = 0.0;
  for (int k = 0; k < steps; ++k) {
    const std::string where = "seed " + std::to_string(seed) + " step " + std::to_string(k);
    const double dt = 0.05 + 0.1 * u(rng);
    w.step(dt);
    fast.predict(dt);
    dense.predictDense(dt);
    if (k == steps / 3) {  // grow: the new slots are free
      fast.setCapacity(n_points);
      dense.setCapacity(n_points);
    }
    std::vector<Eskf::Observation> obs;
    for (int j = 0; j < fast.capacity(); ++j)
      if (fast.isActive(j) && u(rng) < 0.6) {
        const Eigen::Matrix3d C = stereoCov(w.rng);
        obs.push_back({j, w.measure(j, C), C});
      }
    std::shuffle(obs.begin(), obs.end(), rng);
    const Eskf::UpdateResult ra = fast.update(obs), rb = dense.updateDense(obs);
    EXPECT_EQ(ra.used, rb.used);
    EXPECT_EQ(ra.dof, rb.dof);
    EXPECT_NEAR(ra.nis, rb.nis, 1e-8 * (1.0 + rb.nis)) << where;
    if (u(rng) < 0.3) {  // observations of known world points (thesis experiment 1)
      std::vector<Eskf::KnownObservation> known;
      for (int j = 0; j < 3; ++j) {
        const Eigen::Matrix3d C = stereoCov(w.rng);
        known.push_back({w.pts[j], w.measure(j, C), C});
      }
      const Eskf::UpdateResult ka = fast.updateKnown(known), kb = dense.updateKnownDense(known);
      EXPECT_EQ(ka.dof, 9);
      EXPECT_NEAR(ka.nis, kb.nis, 1e-8 * (1.0 + kb.nis)) << where;
    }
    if (u(rng) < 0.3) {
      const Eigen::Matrix3d Cg = Eigen::Matrix3d::Identity() * 1e-4;
      const Eigen::Vector3d zg = w.measureGyro(Cg);
      fast.updateGyro(zg, Cg);
      dense.updateGyroDense(zg, Cg);
    }
    for (int j = 0; j < fast.capacity(); ++j)
      if (!fast.isActive(j) && u(rng) < 0.15) {
        const Eigen::Matrix3d C = stereoCov(w.rng);
        const Eigen::Vector3d z = w.measure(j, C);
        fast.addLandmark(j, z, C);
        dense.addLandmark(j, z, C);
      }
    if (fast.activeCount() > 5 && u(rng) < 0.2) {
      int j;
      do j = std::uniform_int_distribution<int>(0, fast.capacity() - 1)(rng);
      while (!fast.isActive(j));
      fast.removeLandmark(j);
      dense.removeLandmark(j);
    }
    max_rel = std::max(max_rel, relDiff(fast.covariance(), dense.covariance()));
    expectSameFilter(fast, dense, 1e-9, where);
    if (::testing::Test::HasFailure()) return;
  }
  std::cout << "fast vs dense (seed " << seed << ", n = " << fast.dim() << ", explicit gain " << explicit_gain
            << "): max relative covariance difference " << max_rel << "\n";
}

}  // namespace

TEST(EskfFastVsDense, SmallRandomSequences) {
  runFastVsDense(21, false, 30, false, 150);
  runFastVsDense(22, true, 30, false, 150);
  runFastVsDense(23, true, 30, true, 150);
  runFastVsDense(26, false, 30, false, 150, Eigen::Vector3d(1e-3, 1e-3, 3e-3));  // landmark walk on
}

TEST(EskfFastVsDense, BlasAndEigenDowndatesAgree) {
  // n = 12 + 3 * 200 = 612: the downdate runs in 2 parts (OpenBLAS dsyrk + dgemm each, or Eigen's products).
  std::cout << "this build's downdate: " << (Eskf::blasAvailable() ? "OpenBLAS" : "Eigen only") << "\n";
  for (int threads : {1, 2}) {
    EskfOptions o = testOptions(false);
    o.threads = threads;
    std::mt19937 ra(77 + threads), rb(77 + threads);
    Eskf a = makeFilter(ra, false, 200, 200, o);  // set up by addLandmark only: no downdate yet
    o.blas_downdate = false;
    Eskf b = makeFilter(rb, false, 200, 200, o);
    ASSERT_EQ(a.covariance(), b.covariance());
    for (int frame = 0; frame < 3; ++frame) {
      std::vector<Eskf::Observation> obs;
      for (int j = frame; j < 200; j += 3) {
        const Eigen::Matrix3d C = stereoCov(ra);
        obs.push_back({j, a.predictObservation(j) + uniform3(ra, 1e-3), C});
      }
      a.predict(0.1);
      b.predict(0.1);
      a.update(obs);
      b.update(obs);
    }
    EXPECT_LT(relDiff(a.covariance(), b.covariance()), 1e-12) << threads << " threads";
    EXPECT_LT((a.state().p - b.state().p).norm(), 1e-12) << threads << " threads";
    EXPECT_EQ(a.covariance(), Mat(a.covariance().transpose()));
  }
}

TEST(EskfFastVsDense, ThreadedSizes) {
  // n = 15 + 3 * 130 = 405 >= 384: the covariance update and the mirror run split over 2 threads.
  runFastVsDense(24, true, 130, false, 25);
  runFastVsDense(25, false, 130, true, 25);
}

// ============================================================================ gyro interval

namespace {

// k gyro samples between two frames: propagateWithGyro() against the same steps one by one on the fast
// filter (predict + updateGyro) and on the dense reference (predictDense + updateGyroDense).
void runGyroInterval(unsigned seed, bool bias, int slots, int samples, const Eigen::Vector3d& walk,
                     double walk_reference_distance = 0.0) {
  EskfOptions opt = testOptions(bias);
  opt.landmark_walk = walk;
  opt.landmark_walk_reference_distance = walk_reference_distance;
  std::mt19937 rng(seed);
  const Eskf start = makeFilter(rng, bias, slots, slots - 3, opt);  // 3 free slots stay free
  Eskf batch = start, seq = start, dense = start;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eskf::GyroStep> steps;
  for (int i = 0; i < samples; ++i) {
    Eskf::GyroStep st;
    st.dt = (i == 0) ? 0.0 : 0.005 + 0.01 * u(rng);  // the first sample at the filter's own time
    st.C = randomSpd(rng, 3, 1e-6, 1e-4);
    st.z = start.state().w + start.state().gyro_bias + uniform3(rng, 0.05);
    steps.push_back(st);
  }
  const Eskf::UpdateResult rb = batch.propagateWithGyro(steps);
  double nis_seq = 0.0, nis_dense = 0.0;
  for (const Eskf::GyroStep& st : steps) {
    if (st.dt > 0.0) {
      seq.predict(st.dt);
      dense.predictDense(st.dt);
    }
    nis_seq += seq.updateGyro(st.z, st.C).nis;
    nis_dense += dense.updateGyroDense(st.z, st.C).nis;
  }
  const std::string where = "seed " + std::to_string(seed) + ", " + std::to_string(samples) + " samples";
  EXPECT_EQ(rb.used, samples) << where;
  EXPECT_EQ(rb.dof, 3 * samples) << where;
  EXPECT_NEAR(rb.nis, nis_seq, 1e-8 * (1.0 + nis_seq)) << where;
  EXPECT_NEAR(rb.nis, nis_dense, 1e-8 * (1.0 + nis_dense)) << where;
  expectSameFilter(batch, seq, 1e-9, where + " (batch vs one by one)");
  expectSameFilter(batch, dense, 1e-9, where + " (batch vs dense)");
  // The landmarks moved (the rig-landmark correlations carry the gyro's information) and free slots stayed zero.
  double moved = 0.0;
  for (int j = 0; j < slots - 3; ++j) moved = std::max(moved, (batch.landmark(j) - start.landmark(j)).norm());
  if (samples > 0) {
    EXPECT_GT(moved, 1e-9) << where;
  }
  const int n = batch.dim(), free0 = batch.slotIndex(slots - 3);
  EXPECT_EQ(batch.covariance().block(free0, 0, n - free0, n).cwiseAbs().maxCoeff(), 0.0) << where;
  EXPECT_EQ(batch.covariance(), Mat(batch.covariance().transpose())) << where;
}

}  // namespace

TEST(EskfGyroInterval, SameAsTheStepsOneByOneAndAsTheDenseForm) {
  runGyroInterval(31, false, 12, 10, Eigen::Vector3d::Zero());
  runGyroInterval(32, true, 12, 10, Eigen::Vector3d::Zero());
  runGyroInterval(33, true, 12, 1, Eigen::Vector3d::Zero());
  runGyroInterval(34, true, 12, 25, Eigen::Vector3d(1e-3, 1e-3, 3e-3));  // landmark walk on
  runGyroInterval(37, true, 12, 10, Eigen::Vector3d(1e-3, 1e-3, 3e-3), 0.45);  // per-landmark walk
  runGyroInterval(35, true, 140, 10, Eigen::Vector3d::Zero());           // n >= 384: two threads
  runGyroInterval(36, false, 12, 0, Eigen::Vector3d::Zero());            // no sample: nothing changes
}

// ============================================================================ symmetric positive definite

TEST(EskfCovariance, StaysSymmetricPositiveDefiniteOverALongRandomRun) {
  EskfOptions opt = testOptions(true);
  World w(31, 60, opt);
  Eskf f(opt);
  f.setCapacity(40);
  Mat P0 = Mat::Zero(15, 15);
  P0.diagonal().setConstant(1e-8);
  P0.block(6, 6, 9, 9).diagonal().setConstant(1e-4);
  f.reset(w.truth, P0);
  std::mt19937 rng(32);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double worst_rcond = 1e300;
  for (int k = 0; k < 2000; ++k) {
    const double dt = 0.02 + 0.1 * u(rng);
    f.predict(dt);
    w.step(dt);
    std::vector<Eskf::Observation> obs;
    for (int j = 0; j < f.capacity(); ++j)
      if (f.isActive(j) && u(rng) < 0.5) {
        const Eigen::Matrix3d C = stereoCov(w.rng);
        obs.push_back({j, w.measure(j, C), C});
      }
    f.update(obs);
    if (u(rng) < 0.5) f.updateGyro(w.measureGyro(Eigen::Matrix3d::Identity() * 1e-6), Eigen::Matrix3d::Identity() * 1e-6);
    for (int j = 0; j < f.capacity(); ++j)
      if (!f.isActive(j) && u(rng) < 0.1) {
        const Eigen::Matrix3d C = stereoCov(w.rng);
        f.addLandmark(j, w.measure(j, C), C);
      }
    if (f.activeCount() > 10 && u(rng) < 0.3) {
      int j;
      do j = std::uniform_int_distribution<int>(0, f.capacity() - 1)(rng);
      while (!f.isActive(j));
      f.removeLandmark(j);
    }
    if (k % 50 == 49) {
      const Mat& C = f.covariance();
      ASSERT_EQ(C, Mat(C.transpose())) << "step " << k;  // exactly symmetric
      // Principal submatrix over the rig and the active slots is positive definite; free slots are zero.
      std::vector<int> idx;
      for (int i = 0; i < f.rigDim(); ++i) idx.push_back(i);
      for (int j = 0; j < f.capacity(); ++j) {
        const int s = f.slotIndex(j);
        if (f.isActive(j)) {
          for (int i = 0; i < 3; ++i) idx.push_back(s + i);
        } else {
          ASSERT_EQ(maxAbs(C.middleCols(s, 3)), 0.0) << "free slot " << j << " step " << k;
        }
      }
      Mat Ca(idx.size(), idx.size());
      for (size_t a = 0; a < idx.size(); ++a)
        for (size_t b = 0; b < idx.size(); ++b) Ca(a, b) = C(idx[a], idx[b]);
      const Eigen::LLT<Mat> llt(Ca);
      ASSERT_EQ(llt.info(), Eigen::Success) << "step " << k;
      worst_rcond = std::min(worst_rcond, llt.rcond());
      ASSERT_GT(llt.rcond(), 0.0) << "step " << k;
    }
  }
  std::cout << "smallest reciprocal condition number (rig + active slots) over the run: " << worst_rcond << "\n";
}

// ============================================================================ consistency (Monte Carlo)

namespace {

struct McStats {
  std::vector<double> nees;      // per step: mean over runs of the pose NEES (6 dof)
  std::vector<double> nis_sum;   // per step: sum over runs of the stacked NIS
  std::vector<double> dof_sum;   // per step: sum over runs of its dof
};

// `runs` independent runs of `steps` steps at 10 Hz among `n_points` fixed landmarks. The rig follows
// the filter's own motion model (nearly constant velocity: the v, w random walks of the options);
// the initial estimate is drawn from the initial covariance around the truth.
// With `walk` the landmarks random-walk (m per sqrt(s), camera axes); the filter models it when filter_walks.
McStats monteCarlo(bool gyro, int runs, int steps, int n_points, const Eigen::Vector3d& walk = Eigen::Vector3d::Zero(),
                   bool filter_walks = true) {
  EskfOptions opt;
  opt.landmark_walk = walk;
  opt.velocity_noise = 0.01;
  opt.angular_rate_noise = 0.02;
  opt.estimate_gyro_bias = gyro;
  opt.gyro_bias_walk = 1e-4;
  opt.threads = 1;
  const double dt = 0.1;
  const Eigen::Matrix3d Cz = Eigen::Vector3d(1e-6, 1e-6, 9e-6).asDiagonal();  // 1 / 1 / 3 mm
  const Eigen::Matrix3d Cg = Eigen::Matrix3d::Identity() * 25e-6;             // 5 mrad/s gyro noise
  McStats st;
  st.nees.assign(steps, 0.0);
  st.nis_sum.assign(steps, 0.0);
  st.dof_sum.assign(steps, 0.0);
  for (int r = 0; r < runs; ++r) {
    World w(1000 + r, n_points, opt);
    EskfOptions fopt = opt;
    if (!filter_walks) fopt.landmark_walk.setZero();
    Eskf f(fopt);
    const int rd = f.rigDim();
    Vec sd = Vec::Constant(rd, 0.01);  // bias: 0.01 rad/s
    sd.segment<6>(0).setConstant(1e-3);  // p: 1 mm, theta: 1 mrad
    sd.segment<3>(6).setConstant(0.02);  // v: 2 cm/s
    sd.segment<3>(9).setConstant(0.05);  // w: 0.05 rad/s
    const Mat P0 = sd.cwiseAbs2().asDiagonal();
    if (gyro) w.truth.gyro_bias = gauss3(w.rng, 0.01);
    Vec e0(rd);
    for (int i = 0; i < rd; ++i) e0(i) = std::normal_distribution<double>(0.0, sd(i))(w.rng);
    f.setCapacity(n_points);
    f.reset(retract(w.truth, e0), P0);
    for (int k = 0; k < steps; ++k) {
      if (k > 0) {
        w.step(dt);
        f.predict(dt);
      }
      if (gyro) f.updateGyro(w.measureGyro(Cg), Cg);
      std::vector<Eskf::Observation> obs;
      std::vector<int> fresh;
      for (int j = 0; j < n_points; ++j) {
        if (!w.visible(j)) continue;
        if (f.isActive(j))
          obs.push_back({j, w.measure(j, Cz), Cz});
        else
          fresh.push_back(j);
      }
      const Eskf::UpdateResult ur = f.update(obs);
      st.nis_sum[k] += ur.nis;
      st.dof_sum[k] += ur.dof;
      for (int j : fresh) f.addLandmark(j, w.measure(j, Cz), Cz);
      const Vec e = rigDifference(w.truth, f.state(), rd).head(6);
      st.nees[k] += e.dot(f.poseCovariance().llt().solve(e)) / runs;
    }
  }
  return st;
}

void checkConsistency(const McStats& st, int runs, const char* name) {
  // Mean pose NEES over N runs: N * mean ~ chi^2(6 N). 95 % two-sided bounds:
  // [chi2(6N, 0.025), chi2(6N, 0.975)] / N; for N = 50: [253.9, 349.9] / 50 = [5.08, 7.00].
  const double lo = chi2Quantile(6.0 * runs, -kZ975) / runs, hi = chi2Quantile(6.0 * runs, kZ975) / runs;
  const int steps = static_cast<int>(st.nees.size());
  int nees_in = 0, nis_in = 0, nis_steps = 0;
  double nees_mean = 0, nis_total = 0, dof_total = 0;
  for (int k = 0; k < steps; ++k) {
    nees_in += (st.nees[k] >= lo && st.nees[k] <= hi);
    nees_mean += st.nees[k] / steps;
    if (st.dof_sum[k] > 0) {
      // Sum of the stacked NIS over the runs ~ chi^2(sum of their dof): 95 % bounds of that chi^2.
      const double d = st.dof_sum[k];
      nis_in += (st.nis_sum[k] >= chi2Quantile(d, -kZ975) && st.nis_sum[k] <= chi2Quantile(d, kZ975));
      ++nis_steps;
      nis_total += st.nis_sum[k];
      dof_total += d;
    }
  }
  const double nees_frac = static_cast<double>(nees_in) / steps, nis_frac = static_cast<double>(nis_in) / nis_steps;
  std::cout << name << ": mean pose NEES " << nees_mean << " (6 expected; per-step 95 % bounds [" << lo << ", " << hi
            << "], " << 100.0 * nees_frac << " % of steps inside); NIS / dof " << nis_total / dof_total << " ("
            << 100.0 * nis_frac << " % of steps inside their 95 % bounds)\n";
  // 95 % bounds: about 5 % of the (correlated) steps may fall outside by chance; require 90 %.
  EXPECT_GE(nees_frac, 0.90) << name;
  EXPECT_GE(nis_frac, 0.90) << name;
  // The averages over all steps lie well inside the per-step bounds.
  EXPECT_GT(nees_mean, lo) << name;
  EXPECT_LT(nees_mean, hi) << name;
  const double nis_lo = chi2Quantile(dof_total, -kZ975) / dof_total, nis_hi = chi2Quantile(dof_total, kZ975) / dof_total;
  EXPECT_GT(nis_total / dof_total, nis_lo - 0.02) << name;  // 0.02 slack: steps are correlated
  EXPECT_LT(nis_total / dof_total, nis_hi + 0.02) << name;
}

}  // namespace

TEST(EskfConsistency, MonteCarloNeesAndNisStereoOnly) {
  const int runs = 50;
  checkConsistency(monteCarlo(false, runs, 100, 50), runs, "stereo only");
}

TEST(EskfConsistency, MonteCarloNeesAndNisWithGyroAndBias) {
  const int runs = 50;
  checkConsistency(monteCarlo(true, runs, 100, 50), runs, "stereo + gyro, bias estimated");
}

TEST(EskfConsistency, MonteCarloNeesAndNisWithWalkingLandmarks) {
  // Landmarks that random-walk by (2, 2, 6) mm per sqrt(s) along the camera axes (an image front end's
  // measurement errors correlated over frames, modelled as moving landmarks), 1 / 1 / 3 mm white noise.
  const int runs = 50;
  const Eigen::Vector3d walk(2e-3, 2e-3, 6e-3);
  checkConsistency(monteCarlo(false, runs, 100, 50, walk, true), runs, "walking landmarks, modelled");
  // The same data through a filter that takes the landmarks as fixed: overconfident (the check above can fail).
  const McStats blind = monteCarlo(false, runs, 100, 50, walk, false);
  double nees_mean = 0;
  for (double v : blind.nees) nees_mean += v / blind.nees.size();
  const double hi = chi2Quantile(6.0 * runs, kZ975) / runs;
  std::cout << "walking landmarks, not modelled: mean pose NEES " << nees_mean << " (95 % bound " << hi << ")\n";
  EXPECT_GT(nees_mean, 2 * hi);
}

// ============================================================================ API behaviour

TEST(EskfApi, CapacityAddRemoveAndTraces) {
  std::mt19937 rng(41);
  Eskf f = makeFilter(rng, false, 3, 3, testOptions(false));
  f.predict(0.1);
  const Mat C = f.covariance();
  f.setCapacity(10);
  EXPECT_EQ(f.capacity(), 10);
  EXPECT_EQ(f.dim(), 12 + 30);
  EXPECT_EQ(Mat(f.covariance().topLeftCorner(C.rows(), C.cols())), C);
  EXPECT_EQ(maxAbs(f.covariance().rightCols(21)), 0.0);
  f.setCapacity(3);  // shrink over free trailing slots
  EXPECT_EQ(f.covariance(), C);
  EXPECT_EQ(f.activeCount(), 3);
  f.removeLandmark(1);
  EXPECT_FALSE(f.isActive(1));
  EXPECT_EQ(f.activeCount(), 2);
  EXPECT_EQ(maxAbs(f.covariance().middleCols(f.slotIndex(1), 3)), 0.0);
  EXPECT_EQ(maxAbs(f.covariance().middleRows(f.slotIndex(1), 3)), 0.0);
  EXPECT_NEAR(f.totalTrace(), f.rigTrace() + f.landmarksTrace(), 1e-15);
  EXPECT_NEAR(f.landmarksTrace(), f.landmarkCovariance(0).trace() + f.landmarkCovariance(2).trace(), 1e-15);
  // reset drops the landmarks and keeps the capacity.
  f.reset(RigState());
  EXPECT_EQ(f.capacity(), 3);
  EXPECT_EQ(f.activeCount(), 0);
  EXPECT_EQ(f.rigCovariance(), f.defaultRigCovariance());
  EXPECT_EQ(maxAbs(f.covariance().rightCols(9)), 0.0);
  // An exactly known initial pose (the default: zero std of p, theta) is accepted.
  EXPECT_EQ(f.rigCovariance().topLeftCorner(6, 6), Mat::Zero(6, 6));
  f.addLandmark(0, Eigen::Vector3d(0.1, 0, 0.5), stereoCov(rng));
  f.addLandmark(1, Eigen::Vector3d(-0.1, 0.05, 0.6), stereoCov(rng));
  f.predict(0.1);
  const Eskf::UpdateResult r = f.update({{0, f.predictObservation(0) + Eigen::Vector3d(1e-3, 0, 0), stereoCov(rng)},
                                         {1, f.predictObservation(1), stereoCov(rng)}});
  EXPECT_EQ(r.used, 2);
  EXPECT_TRUE(std::isfinite(r.nis));
  EXPECT_EQ(f.covariance(), Mat(f.covariance().transpose()));
  EXPECT_GT(f.rigCovariance().diagonal().minCoeff(), 0.0);
}

TEST(EskfApi, PredictLeavesLandmarkBlocksUntouched) {
  std::mt19937 rng(42);
  Eskf f = makeFilter(rng, true, 6, 5, testOptions(true));
  f.predict(0.1);
  const Mat C0 = f.covariance();
  f.predict(0.07);
  const int rd = f.rigDim();
  EXPECT_EQ(Mat(f.covariance().bottomRightCorner(f.dim() - rd, f.dim() - rd)),
            Mat(C0.bottomRightCorner(f.dim() - rd, f.dim() - rd)));
  EXPECT_EQ(f.covariance(), Mat(f.covariance().transpose()));
}

// With a reference distance, a landmark's walk is (|z| / reference)^4 times the common one, z its latest
// measurement: set when it is added, renewed by every update that observes it (fast and dense alike).
TEST(EskfApi, LandmarkWalkScalesWithTheSquareOfTheLandmarksDistance) {
  EskfOptions opt = testOptions(false);
  opt.landmark_walk = Eigen::Vector3d(1e-3, 2e-3, 5e-3);
  opt.landmark_walk_reference_distance = 0.45;
  Eskf f(opt);
  f.setCapacity(3);
  RigState x0;
  x0.q = skin3d::geometry::Quat(Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1.0, 0.1).normalized()));
  x0.p = Eigen::Vector3d(0.01, -0.02, 0.03);
  f.reset(x0);
  const Eigen::Vector3d z0(0.0, 0.0, 0.3), z1(0.1, -0.2, 0.55);
  const Eigen::Matrix3d Cz = Eigen::Vector3d(1e-8, 1e-8, 1e-7).asDiagonal();
  f.addLandmark(0, z0, Cz);
  f.addLandmark(1, z1, Cz);
  const auto expected = [](const Eigen::Vector3d& z) { return std::pow(z.norm() / 0.45, 4); };
  EXPECT_NEAR(f.landmarkWalkScale(0), expected(z0), 1e-12);
  EXPECT_NEAR(f.landmarkWalkScale(1), expected(z1), 1e-12);
  EXPECT_THROW(f.landmarkWalkScale(2), std::invalid_argument);  // free slot
  const double dt = 0.1;
  const Mat C0 = f.covariance();
  const Eigen::Matrix3d Q = f.landmarkProcessNoise(dt);
  Eskf g = f;
  f.predict(dt);
  g.predictDense(dt);
  expectSameFilter(f, g, 1e-12, "scaled walk");
  for (int j : {0, 1}) {
    const Mat d = f.covariance().block<3, 3>(f.slotIndex(j), f.slotIndex(j)) - C0.block<3, 3>(f.slotIndex(j), f.slotIndex(j));
    EXPECT_LT((d - expected(j == 0 ? z0 : z1) * Q).norm(), 1e-15 + 1e-12 * Q.norm()) << "slot " << j;
  }
  // An observation of slot 0 from 0.9 m: its walk becomes 16x the reference's; slot 1 keeps its own.
  const Eigen::Vector3d z0b = Eigen::Vector3d(0.2, 0.1, 0.87).normalized() * 0.9;
  Eskf h = f;
  f.update({Eskf::Observation{0, z0b, Cz}});
  h.updateDense({Eskf::Observation{0, z0b, Cz}});
  EXPECT_NEAR(f.landmarkWalkScale(0), 16.0, 1e-9);
  EXPECT_NEAR(h.landmarkWalkScale(0), 16.0, 1e-9);
  EXPECT_NEAR(f.landmarkWalkScale(1), expected(z1), 1e-12);
  f.predict(dt);
  h.predictDense(dt);
  expectSameFilter(f, h, 1e-10, "scaled walk after an update");
  // The reference distance must be finite and >= 0.
  for (double bad : {-0.1, std::nan("")}) {
    opt.landmark_walk_reference_distance = bad;
    EXPECT_THROW(Eskf{opt}, std::invalid_argument) << bad;
  }
}

TEST(EskfApi, LandmarkWalkAddsItsProcessNoiseToEachActiveLandmark) {
  std::mt19937 rng(43);
  EskfOptions opt = testOptions(false);
  opt.landmark_walk = Eigen::Vector3d(1e-3, 2e-3, 5e-3);
  Eskf f = makeFilter(rng, false, 6, 5, opt);
  const Mat C0 = f.covariance();
  const Eigen::Matrix3d R = skin3d::geometry::toRotationMatrix(f.state().q);
  const double dt = 0.07;
  const Eigen::Matrix3d Q = f.landmarkProcessNoise(dt);
  // In the camera's axes the walk is diagonal: q^2 dt.
  const Eigen::Matrix3d Qc = R.transpose() * Q * R;
  EXPECT_LT((Qc - Eigen::Vector3d(1e-6 * dt, 4e-6 * dt, 25e-6 * dt).asDiagonal().toDenseMatrix()).norm(), 1e-18);
  Eskf g = f;
  f.predict(dt);
  g.predictDense(dt);
  expectSameFilter(f, g, 1e-12, "walk");
  for (int a = 0; a < f.capacity(); ++a)
    for (int b = 0; b < f.capacity(); ++b) {
      const Mat d = f.covariance().block<3, 3>(f.slotIndex(a), f.slotIndex(b)) - C0.block<3, 3>(f.slotIndex(a), f.slotIndex(b));
      if (a == b && f.isActive(a))
        EXPECT_LT((d - Q).norm(), 1e-15) << "slot " << a;  // only the walk: F is I on the landmarks
      else
        EXPECT_EQ(maxAbs(d), 0.0) << "slots " << a << ", " << b;  // free slots stay zero, no cross terms
    }
  EXPECT_EQ(f.covariance(), Mat(f.covariance().transpose()));
  opt.landmark_walk.z() = -1e-3;
  EXPECT_THROW(Eskf{opt}, std::invalid_argument);
}

TEST(EskfApi, MahalanobisMatchesDenseInnovationAndSingleUpdateNis) {
  std::mt19937 rng(43);
  Eskf f = makeFilter(rng, false, 4, 4, testOptions(false));
  f.predict(0.1);
  const Eskf::Observation ob{2, f.predictObservation(2) + Eigen::Vector3d(1e-3, -2e-3, 4e-3), stereoCov(rng)};
  const Mat H = f.measurementJacobian(ob);
  const Mat S = H * f.covariance() * H.transpose() + ob.C;
  const Eigen::Vector3d y = ob.z - f.predictObservation(2);
  const double d2 = y.dot(S.llt().solve(y));
  const Eskf::Innovation in = f.innovation(ob);
  EXPECT_LT((in.y - y).norm(), 1e-15);
  EXPECT_LT(relDiff(in.S, S), 1e-12);
  EXPECT_NEAR(f.mahalanobis(ob), d2, 1e-9 * d2);
  const Eskf::UpdateResult r = f.update({ob});
  EXPECT_EQ(r.used, 1);
  EXPECT_EQ(r.dof, 3);
  EXPECT_NEAR(r.nis, d2, 1e-9 * d2);
  // An update pulls the prediction towards the measurement.
  EXPECT_LT((ob.z - f.predictObservation(2)).norm(), y.norm());
  // An empty batch is a no-op.
  const Snapshot before(f);
  const Eskf::UpdateResult e = f.update({});
  EXPECT_EQ(e.used, 0);
  EXPECT_TRUE(Snapshot(f) == before);
}

TEST(EskfApi, GyroUpdateWithBiasSeparatesRateAndBias) {
  // Only the sum w + b is observed by the gyro; the stereo landmarks observe w through the motion.
  std::mt19937 rng(44);
  Eskf f = makeFilter(rng, true, 2, 2, testOptions(true));
  const Mat C0 = f.rigCovariance();
  const Eigen::Matrix3d Cg = Eigen::Matrix3d::Identity() * 1e-6;
  const Eigen::Vector3d zg = predictGyro(f.state()) + Eigen::Vector3d(0.01, 0, 0);
  f.updateGyro(zg, Cg);
  EXPECT_LT((zg - predictGyro(f.state())).norm(), 1e-3);  // w + b moves (almost all the way) to z
  // The variance of the observed combination w + b drops to about the gyro noise.
  Mat Hs = Mat::Zero(3, 15);
  Hs.block(0, 9, 3, 3).setIdentity();
  Hs.block(0, 12, 3, 3).setIdentity();
  const Mat Vsum = Hs * f.rigCovariance() * Hs.transpose();
  EXPECT_LT(Vsum.trace(), 3.0 * 1e-6 * 1.01);
  EXPECT_LT(f.rigCovariance().trace(), C0.trace());
}

// ============================================================================ bad inputs

namespace {

template <typename F>
void expectThrowsUnchanged(Eskf& f, const F& call, const std::string& needle, const char* what) {
  const Snapshot before(f);
  try {
    call();
    ADD_FAILURE() << what << ": did not throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos)
        << what << ": message \"" << e.what() << "\" does not mention \"" << needle << "\"";
  } catch (const std::exception& e) {
    ADD_FAILURE() << what << ": threw something else: " << e.what();
  }
  EXPECT_TRUE(Snapshot(f) == before) << what << ": the filter changed";
}

}  // namespace

TEST(EskfBadInputs, ThrowWithAClearMessageAndLeaveTheFilterUnchanged) {
  std::mt19937 rng(51);
  Eskf f = makeFilter(rng, true, 6, 4, testOptions(true));
  f.predict(0.1);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const Eigen::Matrix3d good = stereoCov(rng);
  const Eigen::Vector3d z = f.predictObservation(1);
  Eigen::Matrix3d asym = good;
  asym(0, 1) += 1e-7;
  const Eigen::Matrix3d indef = Eigen::Vector3d(1e-6, -1e-6, 1e-6).asDiagonal();
  Eigen::Matrix3d cnan = good;
  cnan(2, 2) = nan;
  const Eskf::Observation ok{1, z, good};

  expectThrowsUnchanged(f, [&] { f.predict(0.0); }, "dt", "predict(0)");
  expectThrowsUnchanged(f, [&] { f.predict(-0.1); }, "dt", "predict(-0.1)");
  expectThrowsUnchanged(f, [&] { f.predict(nan); }, "dt", "predict(nan)");
  expectThrowsUnchanged(f, [&] { f.predict(inf); }, "dt", "predict(inf)");
  expectThrowsUnchanged(f, [&] { f.predictDense(0.0); }, "dt", "predictDense(0)");

  // A bad observation anywhere in the batch (after good ones) rejects the whole batch.
  expectThrowsUnchanged(f, [&] { f.update({ok, {-1, z, good}}); }, "out of range", "slot -1");
  expectThrowsUnchanged(f, [&] { f.update({ok, {6, z, good}}); }, "out of range", "slot = capacity");
  expectThrowsUnchanged(f, [&] { f.update({ok, {5, z, good}}); }, "not active", "inactive slot");
  expectThrowsUnchanged(f, [&] { f.update({ok, {2, z, good}, {1, z, good}}); }, "twice", "duplicate slot");
  expectThrowsUnchanged(f, [&] { f.update({ok, {2, Eigen::Vector3d(0, nan, 1), good}}); }, "not finite", "z nan");
  expectThrowsUnchanged(f, [&] { f.update({ok, {2, z, cnan}}); }, "not finite", "C nan");
  expectThrowsUnchanged(f, [&] { f.update({ok, {2, z, asym}}); }, "not symmetric", "C asymmetric");
  expectThrowsUnchanged(f, [&] { f.update({ok, {2, z, indef}}); }, "positive definite", "C indefinite");
  expectThrowsUnchanged(f, [&] { f.update({ok, {2, z, Eigen::Matrix3d::Zero()}}); }, "positive definite", "C zero");
  expectThrowsUnchanged(f, [&] { f.updateDense({ok, {2, z, indef}}); }, "positive definite", "updateDense");
  expectThrowsUnchanged(f, [&] { f.mahalanobis({5, z, good}); }, "not active", "mahalanobis inactive");
  expectThrowsUnchanged(f, [&] { f.innovation({1, z, indef}); }, "positive definite", "innovation indefinite");

  expectThrowsUnchanged(f, [&] { f.updateKnown({{Eigen::Vector3d(0, 0, 1), z, good}, {Eigen::Vector3d(nan, 0, 1), z, good}}); },
                        "known position m is not finite", "known m nan");
  expectThrowsUnchanged(f, [&] { f.updateKnown({{Eigen::Vector3d(0, 0, 1), z, indef}}); }, "positive definite",
                        "known C indefinite");
  expectThrowsUnchanged(f, [&] { f.innovationKnown({Eigen::Vector3d(0, 0, 1), z, asym}); }, "not symmetric",
                        "innovationKnown asymmetric");
  expectThrowsUnchanged(f, [&] { f.updateGyro(Eigen::Vector3d(inf, 0, 0), good); }, "not finite", "gyro z inf");
  expectThrowsUnchanged(f, [&] { f.updateGyro(Eigen::Vector3d::Zero(), indef); }, "positive definite", "gyro C");
  {
    std::vector<Eskf::GyroStep> steps(3);
    steps[1].dt = 0.01;
    steps[2].dt = -0.01;
    expectThrowsUnchanged(f, [&] { f.propagateWithGyro(steps); }, "step 2: dt", "gyro interval dt");
    steps[2].dt = 0.01;
    steps[1].C = indef;
    expectThrowsUnchanged(f, [&] { f.propagateWithGyro(steps); }, "positive definite", "gyro interval C");
  }

  expectThrowsUnchanged(f, [&] { f.addLandmark(1, z, good); }, "already active", "add to active slot");
  expectThrowsUnchanged(f, [&] { f.addLandmark(6, z, good); }, "out of range", "add out of range");
  expectThrowsUnchanged(f, [&] { f.addLandmark(5, Eigen::Vector3d(nan, 0, 1), good); }, "not finite", "add z nan");
  expectThrowsUnchanged(f, [&] { f.addLandmark(5, z, indef); }, "positive definite", "add Cz indefinite");
  expectThrowsUnchanged(f, [&] { f.removeLandmark(5); }, "not active", "remove free slot");
  expectThrowsUnchanged(f, [&] { f.removeLandmark(-2); }, "out of range", "remove -2");
  expectThrowsUnchanged(f, [&] { f.landmark(4); }, "not active", "landmark(free)");

  expectThrowsUnchanged(f, [&] { f.setCapacity(-1); }, "slots", "setCapacity(-1)");
  expectThrowsUnchanged(f, [&] { f.setCapacity(3); }, "slot 3 is active", "shrink over an active slot");

  expectThrowsUnchanged(f, [&] { f.reset(RigState(), Mat::Identity(12, 12)); }, "15x15", "reset wrong size");
  Mat Pa = Mat::Identity(15, 15);
  Pa(0, 1) = 0.5;
  expectThrowsUnchanged(f, [&] { f.reset(RigState(), Pa); }, "not symmetric", "reset asymmetric");
  Mat Pn = Mat::Identity(15, 15);
  Pn(4, 4) = -1e-3;
  expectThrowsUnchanged(f, [&] { f.reset(RigState(), Pn); }, "semi-definite", "reset indefinite");
  RigState bad;
  bad.v.x() = nan;
  expectThrowsUnchanged(f, [&] { f.reset(bad); }, "not finite", "reset nan state");

  expectThrowsUnchanged(f, [&] { f.inject(Vec::Zero(5)); }, "size", "inject wrong size");
  expectThrowsUnchanged(f, [&] { f.inject(Vec::Constant(f.dim(), nan)); }, "not finite", "inject nan");

  // Still fully usable afterwards.
  EXPECT_NO_THROW(f.update({ok}));
}

TEST(EskfBadInputs, OptionsValidationNamesTheField) {
  auto expectField = [](EskfOptions o, const std::string& field) {
    try {
      o.validate();
      ADD_FAILURE() << field << ": no throw";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
    EXPECT_THROW(Eskf{o}, std::invalid_argument);
  };
  EskfOptions o;
  EXPECT_NO_THROW(o.validate());
  o.gamma = 1.5;
  expectField(o, "gamma");
  o = EskfOptions();
  o.lambda = -0.1;
  expectField(o, "lambda");
  o = EskfOptions();
  o.velocity_noise = std::numeric_limits<double>::quiet_NaN();
  expectField(o, "velocity_noise");
  o = EskfOptions();
  o.angular_rate_noise = -1;
  expectField(o, "angular_rate_noise");
  o = EskfOptions();
  o.gyro_bias_walk = -1;
  expectField(o, "gyro_bias_walk");
  o = EskfOptions();
  o.initial_velocity_std = std::numeric_limits<double>::infinity();
  expectField(o, "initial_velocity_std");
  o = EskfOptions();
  o.threads = 0;
  expectField(o, "threads");
}

// ============================================================================ benchmark (not run by default)

// Run with --gtest_also_run_disabled_tests: 1000 active landmarks (n = 3012), 30 observations/frame.
TEST(EskfBenchmark, DISABLED_ThousandLandmarks) {
  for (int variant = 0; variant < 3; ++variant) {
    EskfOptions opt;
    opt.threads = variant == 0 ? 1 : 2;
    opt.joseph_explicit_gain = variant == 2;
    std::mt19937 rng(61);
    Eskf f(opt);
    f.setCapacity(1000);
    RigState x;
    x.v = Eigen::Vector3d(0.05, 0, 0);
    Mat P0 = Mat::Identity(12, 12) * 1e-6;
    f.reset(x, P0);
    for (int j = 0; j < 1000; ++j) f.addLandmark(j, Eigen::Vector3d(0, 0, 0.5) + uniform3(rng, 0.3), stereoCov(rng));
    const int frames = 20;
    double t_pred = 0, t_upd = 0;
    for (int k = 0; k < frames; ++k) {
      auto t0 = std::chrono::steady_clock::now();
      f.predict(0.1);
      auto t1 = std::chrono::steady_clock::now();
      std::vector<Eskf::Observation> obs;
      std::vector<int> slots(1000);
      std::iota(slots.begin(), slots.end(), 0);
      std::shuffle(slots.begin(), slots.end(), rng);
      for (int i = 0; i < 30; ++i) {
        const Eigen::Matrix3d C = stereoCov(rng);
        obs.push_back({slots[i], f.predictObservation(slots[i]) + gauss3(rng, 1e-3), C});
      }
      auto t2 = std::chrono::steady_clock::now();
      f.update(obs);
      auto t3 = std::chrono::steady_clock::now();
      t_pred += std::chrono::duration<double>(t1 - t0).count();
      t_upd += std::chrono::duration<double>(t3 - t2).count();
    }
    std::cout << "n = " << f.dim() << ", threads " << opt.threads << ", explicit-gain Joseph "
              << opt.joseph_explicit_gain << ": predict " << 1e3 * t_pred / frames << " ms, update (90-dim) "
              << 1e3 * t_upd / frames << " ms -> " << frames / (t_pred + t_upd) << " Hz\n";
  }
}
