// SPDX-License-Identifier: BSD-3-Clause
// Observability analysis (skin3d/slam/observability.h): the generic rank / SVD machinery on textbook
// systems with known answers, then the thesis' experiments 1-3 built from the filter's own Jacobians,
// checked against theory (full rank with known landmarks; exactly the 6-dof gauge of the world frame
// in SLAM), and the Gramian against the filter's own covariance (linear-Gaussian: they must agree).
// Every expected value comes from theory, never from the tool's output.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "skin3d/slam/eskf.h"
#include "skin3d/slam/observability.h"

using namespace skin3d::slam;

namespace {

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

// Double integrator x = [position, velocity], x+ = [[1, dt], [0, 1]] x, over N steps.
LinearizedSystem doubleIntegrator(const Mat& H, int N, double dt = 0.1) {
  LinearizedSystem s;
  Mat F(2, 2);
  F << 1.0, dt, 0.0, 1.0;
  for (int k = 0; k < N; ++k) {
    s.H.push_back(H);
    if (k + 1 < N) s.F.push_back(F);
  }
  return s;
}

Mat randomMat(std::mt19937& rng, int r, int c) {
  std::normal_distribution<double> g(0.0, 1.0);
  return Mat::NullaryExpr(r, c, [&]() { return g(rng); });
}

Mat randomSpd(std::mt19937& rng, int n) {
  const Mat A = randomMat(rng, n, n);
  return A * A.transpose() + 0.5 * Mat::Identity(n, n);
}

Mat dropColumns(const Mat& M, int first, int count) {
  Mat out(M.rows(), M.cols() - count);
  out << M.leftCols(first), M.rightCols(M.cols() - first - count);
  return out;
}

// The default scenario of the tool (thesis globe geometry), K landmarks, N frames.
OrbitScenario scenario(int K = 10, int N = 20) {
  OrbitScenario sc;
  sc.landmarks = K;
  sc.steps = N;
  return sc;
}

}  // namespace

// ============================================================================== textbook systems

TEST(ObservabilityGeneric, DoubleIntegratorPositionMeasurementIsObservable) {
  Mat H(1, 2);
  H << 1.0, 0.0;
  // One position sample cannot give the velocity; two can (O = [1 0; 1 dt], det = dt).
  const ObservabilityReport one = analyseObservability(doubleIntegrator(H, 1));
  EXPECT_EQ(one.rank, 1);
  ASSERT_EQ(one.deficiency(), 1);
  EXPECT_NEAR(std::abs(one.nullSpace()(1, 0)), 1.0, 1e-12);  // the velocity is the unobservable direction
  const ObservabilityReport two = analyseObservability(doubleIntegrator(H, 2));
  EXPECT_EQ(two.rank, 2);
  EXPECT_TRUE(two.fullRank());
  const ObservabilityReport many = analyseObservability(doubleIntegrator(H, 10));
  EXPECT_EQ(many.rank, 2);
  EXPECT_EQ(many.dim, 2);
  EXPECT_EQ(many.singular_values.size(), 2);
}

TEST(ObservabilityGeneric, DoubleIntegratorVelocityOnlyMissesThePosition) {
  Mat H(1, 2);
  H << 0.0, 1.0;
  for (int N : {1, 2, 5, 50}) {
    const ObservabilityReport r = analyseObservability(doubleIntegrator(H, N));
    EXPECT_EQ(r.rank, 1) << N;
    ASSERT_EQ(r.deficiency(), 1) << N;
    // The null vector is the position direction (a constant offset of position never shows).
    EXPECT_NEAR(r.nullSpace()(0, 0), 1.0, 1e-12) << N;  // sign convention: largest component positive
    EXPECT_NEAR(r.nullSpace()(1, 0), 0.0, 1e-12) << N;
    EXPECT_LT(r.singular_values(1), 1e-12);
  }
}

TEST(ObservabilityGeneric, ObservabilityMatrixIsTheStackOfHPhi) {
  std::mt19937 rng(7);
  const int n = 4, N = 4;
  LinearizedSystem s;
  for (int k = 0; k < N; ++k) {
    s.H.push_back(randomMat(rng, 1 + k % 2, n));
    if (k + 1 < N) s.F.push_back(randomMat(rng, n, n));
  }
  const Mat O = observabilityMatrix(s);
  Mat expected(s.H[0].rows() + s.H[1].rows() + s.H[2].rows() + s.H[3].rows(), n);
  expected << s.H[0], s.H[1] * s.F[0], s.H[2] * s.F[1] * s.F[0], s.H[3] * s.F[2] * s.F[1] * s.F[0];
  EXPECT_LT((O - expected).norm(), 1e-12 * expected.norm());
  // Prefix of two steps.
  EXPECT_LT((observabilityMatrix(s, false, 2) - expected.topRows(s.H[0].rows() + s.H[1].rows())).norm(), 1e-12);
}

TEST(ObservabilityGeneric, GramianFactorAndWeightsAgree) {
  std::mt19937 rng(11);
  const int n = 6, N = 5;
  LinearizedSystem s;
  for (int k = 0; k < N; ++k) {
    const int m = 1 + k % 3;
    s.H.push_back(randomMat(rng, m, n));
    s.W.push_back(randomSpd(rng, m));
    if (k + 1 < N) s.F.push_back(randomMat(rng, n, n) * 0.5 + Mat::Identity(n, n));
  }
  const Mat Ow = observabilityMatrix(s, true);
  const Mat G = observabilityGramian(s);
  // The Gramian sum Phi^T H^T W H Phi equals O_W^T O_W ...
  EXPECT_LT((G - Ow.transpose() * Ow).norm(), 1e-10 * G.norm());
  // ... and R^T R of the compact factor.
  const Mat R = observabilityFactor(s);
  EXPECT_EQ(R.rows(), n);
  EXPECT_LT((R.transpose() * R - G).norm(), 1e-10 * G.norm());
  // Singular values of the factor are the square roots of the Gramian's eigenvalues.
  const ObservabilityReport a = analyseObservability(s), b = analyseMatrix(Ow);
  EXPECT_LT((a.singular_values - b.singular_values).norm(), 1e-9 * b.singular_values(0));
  // (G is symmetric positive semi-definite: its singular values are its eigenvalues.)
  const Eigen::JacobiSVD<Mat, Eigen::NoQRPreconditioner> eig(G);
  for (int i = 0; i < n; ++i)
    EXPECT_NEAR(a.singular_values(i), std::sqrt(eig.singularValues()(i)), 1e-8 * a.singular_values(0));
  // Weighting never changes the rank.
  LinearizedSystem u = s;
  u.W.clear();
  EXPECT_EQ(analyseObservability(u).rank, a.rank);
}

TEST(ObservabilityGeneric, RankDeficientTimeVaryingSystemNullSpace) {
  // A 5-state system whose last two states never reach a measurement: block diagonal F, H on the
  // first three only. The null space is exactly span(e3, e4).
  std::mt19937 rng(3);
  LinearizedSystem s;
  for (int k = 0; k < 6; ++k) {
    Mat F = Mat::Zero(5, 5);
    F.topLeftCorner(3, 3) = randomMat(rng, 3, 3) + 2.0 * Mat::Identity(3, 3);
    F.bottomRightCorner(2, 2) = randomMat(rng, 2, 2);
    Mat H = Mat::Zero(2, 5);
    H.leftCols(3) = randomMat(rng, 2, 3);
    s.H.push_back(H);
    s.F.push_back(F);
  }
  const ObservabilityReport r = analyseObservability(s);
  EXPECT_EQ(r.rank, 3);
  ASSERT_EQ(r.deficiency(), 2);
  Mat expected = Mat::Zero(5, 2);
  expected(3, 0) = expected(4, 1) = 1.0;
  EXPECT_LT(subspaceResidual(expected, r.nullSpace()), 1e-10);
  EXPECT_LT(subspaceResidual(r.nullSpace(), expected), 1e-10);
  EXPECT_GT(subspaceResidual(Vec::Unit(5, 0), r.nullSpace()), 0.99);
}

TEST(ObservabilityGeneric, AnalyseMatrixWideAndWeakest) {
  Mat M(1, 3);
  M << 0.0, 3.0, 4.0;  // rank 1: sigma = 5, 0, 0
  ObservabilityOptions o;
  o.weakest_count = 3;
  const ObservabilityReport r = analyseMatrix(M, o);
  EXPECT_EQ(r.rank, 1);
  ASSERT_EQ(r.singular_values.size(), 3);
  EXPECT_NEAR(r.singular_values(0), 5.0, 1e-12);
  EXPECT_EQ(r.weakest.cols(), 3);
  // The last column of weakest is the strongest direction (0, 0.6, 0.8).
  EXPECT_NEAR(std::abs(r.weakest(1, 2)), 0.6, 1e-12);
  EXPECT_NEAR(std::abs(r.weakest(2, 2)), 0.8, 1e-12);
  EXPECT_NEAR(r.observableCondition(), 1.0, 1e-12);
  // Tolerance: a singular value just above / below the relative threshold.
  Mat D = Mat::Zero(2, 2);
  D(0, 0) = 1.0;
  D(1, 1) = 1e-8;
  EXPECT_EQ(analyseMatrix(D).rank, 2);  // 1e-8 > 1e-9
  o.relative_tolerance = 1e-7;
  EXPECT_EQ(analyseMatrix(D, o).rank, 1);
}

TEST(ObservabilityGeneric, RestrictionIsTheSchurComplement) {
  std::mt19937 rng(5);
  const Mat M = randomMat(rng, 9, 5);
  const std::vector<int> kept = {1, 3}, known = {4};
  const RestrictedObservability r = restrictObservability(M, kept, known);
  // Marginal information of the kept states: Schur complement of the Gramian over the nuisance {0, 2}.
  const Mat G = M.transpose() * M;
  const std::vector<int> nu = {0, 2};
  Mat Gkk(2, 2), Gkn(2, 2), Gnn(2, 2);
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) {
      Gkk(i, j) = G(kept[i], kept[j]);
      Gkn(i, j) = G(kept[i], nu[j]);
      Gnn(i, j) = G(nu[i], nu[j]);
    }
  const Mat schur = Gkk - Gkn * Gnn.inverse() * Gkn.transpose();
  EXPECT_LT((r.information - schur).norm(), 1e-10 * schur.norm());
  EXPECT_EQ(r.rank, 2);
  EXPECT_EQ(r.nuisance_rank, 2);
  EXPECT_LT((r.covariance - schur.inverse()).norm(), 1e-9 * schur.inverse().norm());
  EXPECT_NEAR(r.correlation(0, 1), r.covariance(0, 1) / std::sqrt(r.covariance(0, 0) * r.covariance(1, 1)), 1e-12);
  // A kept column inside the nuisance span carries no information of its own.
  Mat M2 = M;
  M2.col(1) = 2.0 * M.col(0) - M.col(2);
  const RestrictedObservability r2 = restrictObservability(M2, {1}, {});
  EXPECT_EQ(r2.rank, 0);
  EXPECT_TRUE(r2.covariance.size() == 0);
}

TEST(ObservabilityGeneric, BadInputsThrow) {
  LinearizedSystem s;
  EXPECT_THROW(s.validate(), std::invalid_argument);  // no step
  s = doubleIntegrator(Mat::Identity(2, 2), 3);
  EXPECT_NO_THROW(s.validate());
  LinearizedSystem b = s;
  b.F.pop_back();
  EXPECT_THROW(analyseObservability(b), std::invalid_argument);  // too few F
  b = s;
  b.H[1] = Mat::Zero(1, 3);
  EXPECT_THROW(observabilityMatrix(b), std::invalid_argument);  // wrong columns
  b = s;
  b.W = {Mat::Identity(2, 2), Mat::Identity(2, 2)};
  EXPECT_THROW(observabilityGramian(b), std::invalid_argument);  // one W per step or none
  b.W.push_back(-Mat::Identity(2, 2));
  EXPECT_THROW(observabilityFactor(b), std::invalid_argument);  // not positive definite
  b = s;
  b.H[0](0, 0) = std::nan("");
  EXPECT_THROW(b.validate(), std::invalid_argument);
  EXPECT_THROW(observabilityMatrix(s, false, 4), std::invalid_argument);  // more steps than the system
  ObservabilityOptions o;
  o.relative_tolerance = 0.0;
  EXPECT_THROW(analyseMatrix(Mat::Identity(2, 2), o), std::invalid_argument);
  EXPECT_THROW(restrictObservability(Mat::Identity(3, 3), {0}, {0}), std::invalid_argument);  // overlap
  EXPECT_THROW(restrictObservability(Mat::Identity(3, 3), {3}), std::invalid_argument);       // out of range
  OrbitScenario sc;
  sc.distance = 0.1;  // inside the sphere
  EXPECT_THROW(makeOrbitTrajectory(sc), std::invalid_argument);
  sc = OrbitScenario();
  sc.landmarks = 0;
  EXPECT_THROW(sc.validate(), std::invalid_argument);
}

// ========================================================================= the trajectory and layout

TEST(ObservabilityScenario, TrajectoryIsTheGlobeOrbitAndAModelTrajectory) {
  const OrbitScenario sc = scenario();
  const OrbitTrajectory t = makeOrbitTrajectory(sc);
  ASSERT_EQ(static_cast<int>(t.states.size()), sc.steps);
  ASSERT_EQ(static_cast<int>(t.landmarks.size()), sc.landmarks);
  EXPECT_NEAR(t.dt, 0.1, 1e-15);
  // Rig at the world origin first; constant |w| = rate; v = w x (rig - centre), |v| = rate d cos(...) <= rate d.
  EXPECT_LT(t.states[0].p.norm(), 1e-15);
  EXPECT_NEAR(t.states[0].w.norm(), sc.rate, 1e-12);
  EXPECT_NEAR(t.centre.norm(), sc.distance, 1e-12);
  const Eigen::Vector3d v_expected = -t.states[0].w.cross(Eigen::Vector3d(0, 0, sc.distance));
  EXPECT_LT((t.states[0].v - v_expected).norm(), 1e-12);
  EXPECT_NEAR(t.states[0].w.z(), sc.rate * std::sin(sc.latitude), 1e-12);  // -rate z_G . z_L = rate sin(lat)
  // The orbit of the brief: v ~ (-0.074, -0.035, 0), w ~ (-0.058, 0.123, -0.063).
  EXPECT_NEAR(t.states[0].v.x(), -0.074, 2e-3);
  EXPECT_NEAR(t.states[0].v.y(), -0.035, 2e-3);
  EXPECT_NEAR(t.states[0].w.y(), 0.123, 2e-3);
  for (int k = 1; k < sc.steps; ++k) {
    const RigState x = propagateNominal(t.states[k - 1], t.dt, 1.0, 1.0);
    EXPECT_LT((x.p - t.states[k].p).norm(), 1e-15);
    EXPECT_LT(x.q.angularDistance(t.states[k].q), 1e-15);
    // Rig near its orbit (Euler steps stay within a few mm of the circle), looking at the centre.
    EXPECT_NEAR((t.states[k].p - t.centre).norm(), sc.distance, 5e-3);
  }
  for (const Eigen::Vector3d& m : t.landmarks) EXPECT_NEAR((m - t.centre).norm(), sc.sphere_radius, 1e-12);
  // Default scenario: every landmark is measured in every frame.
  for (int k = 0; k < sc.steps; ++k) EXPECT_EQ(static_cast<int>(t.visible[k].size()), sc.landmarks) << k;
  EXPECT_EQ(t.neverSeen(), 0);
}

TEST(ObservabilityScenario, LayoutAndGaugeBasis) {
  const std::vector<StateBlock> b = errorStateBlocks(15, 2);
  ASSERT_EQ(b.size(), 7u);
  EXPECT_EQ(b[4].name, "b_g");
  EXPECT_EQ(b[6].name, "m1");
  EXPECT_EQ(b[6].start, 18);
  const std::vector<std::string> labels = componentLabels(b);
  ASSERT_EQ(labels.size(), 21u);
  EXPECT_EQ(labels[4], "theta_y");
  EXPECT_EQ(labels[20], "m1_z");
  RigState x;
  x.p = Eigen::Vector3d(0.1, -0.2, 0.3);
  const std::vector<Eigen::Vector3d> m = {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 2, 1)};
  const Mat G = slamGaugeBasis(x, m, 12);
  ASSERT_EQ(G.rows(), 18);
  ASSERT_EQ(G.cols(), 6);
  // Translation x: p and both landmarks move by the same vector; nothing else.
  Vec t = Vec::Zero(18);
  t.segment<3>(0) = t.segment<3>(12) = t.segment<3>(15) = Eigen::Vector3d::UnitX();
  EXPECT_LT((G.col(0) - t.normalized()).norm(), 1e-15);
  // Rotation about z: dtheta = e_z, dp = e_z x p, dm = e_z x m; v, w untouched.
  Vec r = Vec::Zero(18);
  r.segment<3>(0) = Eigen::Vector3d::UnitZ().cross(x.p);
  r.segment<3>(3) = Eigen::Vector3d::UnitZ();
  r.segment<3>(12) = Eigen::Vector3d::UnitZ().cross(m[0]);
  r.segment<3>(15) = Eigen::Vector3d::UnitZ().cross(m[1]);
  EXPECT_LT((G.col(5) - r.normalized()).norm(), 1e-15);
  EXPECT_LT(G.middleRows(6, 6).norm(), 1e-15);
  EXPECT_NE(describeDirection(G.col(0), errorStateBlocks(12, 2)).find("m*"), std::string::npos);
}

// ============================================================================ experiments 1-3

class ObservabilityExperiments : public ::testing::TestWithParam<bool> {};  // information weighting on / off

TEST_P(ObservabilityExperiments, RanksAndGauge) {
  OrbitScenario sc = scenario(10, 20);
  sc.information_weighting = GetParam();
  const int K = sc.landmarks;
  const OrbitTrajectory t = makeOrbitTrajectory(sc);

  // Experiment 1: known landmarks: the rig state (12) is fully observable.
  const LinearizedSystem s1 = buildExperiment(t, sc, Experiment::KnownLandmarks);
  EXPECT_EQ(s1.dim(), 12);
  const ObservabilityReport r1 = analyseObservability(s1);
  EXPECT_EQ(r1.rank, 12);
  EXPECT_TRUE(r1.fullRank());

  struct Case {
    Experiment e;
    int rig;
  };
  for (const Case c : {Case{Experiment::Slam, 12}, Case{Experiment::SlamGyro, 12}, Case{Experiment::SlamGyroBias, 15}}) {
    SCOPED_TRACE(experimentName(c.e));
    const LinearizedSystem s = buildExperiment(t, sc, c.e);
    const int n = c.rig + 3 * K;
    ASSERT_EQ(s.dim(), n);
    EXPECT_EQ(experimentDim(c.e, K), n);
    const ObservabilityReport r = analyseObservability(s);
    // Theory: all measurements are relative, so the world frame's 6 dof (translation, rotation) are
    // unobservable, and nothing else (>= 3 non-collinear landmarks, all seen, >= 2 frames).
    EXPECT_EQ(r.rank, n - 6);
    ASSERT_EQ(r.deficiency(), 6);
    // The numerical null space is the analytic gauge, both ways.
    const Mat gauge = slamGaugeBasis(t.states[0], t.landmarks, c.rig);
    EXPECT_LT(subspaceResidual(gauge, r.nullSpace()), 1e-6);
    Mat Q = gauge;  // orthonormalise (Gram-Schmidt twice)
    for (int j = 0; j < 6; ++j) {
      for (int pass = 0; pass < 2; ++pass)
        for (int i = 0; i < j; ++i) Q.col(j) -= Q.col(i).dot(Q.col(j)) * Q.col(i);
      Q.col(j).normalize();
    }
    EXPECT_LT(subspaceResidual(r.nullSpace(), Q), 1e-6);
    // Directly: the gauge annihilates every row H_k Phi_k of the observability matrix.
    const Mat O = observabilityMatrix(s, true);
    EXPECT_LT((O * gauge).norm(), 1e-9 * O.norm());
    // Fixing the first pose (skin3d: zero initial covariance of p, theta) removes the gauge: full rank.
    const ObservabilityReport anchored = analyseMatrix(dropColumns(observabilityFactor(s), 0, 6));
    EXPECT_TRUE(anchored.fullRank());
    EXPECT_EQ(anchored.dim, n - 6);
  }
}

INSTANTIATE_TEST_SUITE_P(Weighting, ObservabilityExperiments, ::testing::Values(true, false));

TEST(ObservabilityExperiment, FewStepsAndFewLandmarks) {
  // One frame: v and w (6) never act on a measurement; exp 1 has rank 6, SLAM misses 6 + 6.
  OrbitScenario sc = scenario(10, 1);
  const OrbitTrajectory t = makeOrbitTrajectory(sc);
  EXPECT_EQ(analyseObservability(buildExperiment(t, sc, Experiment::KnownLandmarks)).rank, 6);
  EXPECT_EQ(analyseObservability(buildExperiment(t, sc, Experiment::Slam)).deficiency(), 12);
  // ... with the gyroscope w is measured directly: only v (3) joins the gauge.
  EXPECT_EQ(analyseObservability(buildExperiment(t, sc, Experiment::SlamGyro)).deficiency(), 9);
  // Two frames are enough for the relative motion from 3D-3D correspondences (>= 3 points).
  sc = scenario(3, 2);
  const OrbitTrajectory t2 = makeOrbitTrajectory(sc);
  EXPECT_EQ(analyseObservability(buildExperiment(t2, sc, Experiment::KnownLandmarks)).rank, 12);
  EXPECT_EQ(analyseObservability(buildExperiment(t2, sc, Experiment::Slam)).deficiency(), 6);
}

TEST(ObservabilityExperiment, LinearisingOffTheModelTrajectoryBreaksTheRotationGauge) {
  // On the exact circle the Euler model's F no longer carries the rotation gauge of step k to step
  // k + 1 (p_{k+1} != p_k + R_k v dt), so part of it looks observable; the translation gauge survives
  // (it is invariant at any linearisation point).
  OrbitScenario sc = scenario(10, 20);
  sc.model_consistent_trajectory = false;
  const OrbitTrajectory t = makeOrbitTrajectory(sc);
  const LinearizedSystem s = buildExperiment(t, sc, Experiment::Slam);
  const ObservabilityReport r = analyseObservability(s);
  EXPECT_GT(r.rank, 12 + 3 * sc.landmarks - 6);
  EXPECT_GE(r.deficiency(), 3);
  const Mat gauge = slamGaugeBasis(t.states[0], t.landmarks, 12);
  EXPECT_LT(subspaceResidual(gauge.leftCols(3), r.nullSpace()), 1e-6);
}

// ====================================================================== v_x - w_y and the filter

TEST(ObservabilityAmbiguity, VelocityRestrictionGaugeInvariantAndGyroAddsInformation) {
  const OrbitScenario sc = scenario(10, 20);
  const OrbitTrajectory t = makeOrbitTrajectory(sc);
  const LinearizedSystem s2 = buildExperiment(t, sc, Experiment::Slam);
  const Mat R2 = observabilityFactor(s2, 3);
  const Mat R3 = observabilityFactor(buildExperiment(t, sc, Experiment::SlamGyro), 3);
  const std::vector<int> vw = {6, 7, 8, 9, 10, 11}, pose = {0, 1, 2, 3, 4, 5};
  // v, w are gauge invariant: anchoring the first pose or not gives the same marginal information.
  const RestrictedObservability a = restrictObservability(R2, vw, pose), f = restrictObservability(R2, vw);
  EXPECT_EQ(f.nuisance_rank, 12 + 3 * sc.landmarks - 6 - 6);  // nuisance p, theta, m minus the 6 gauge dofs
  ASSERT_EQ(a.rank, 6);
  EXPECT_LT((a.information - f.information).norm(), 1e-8 * a.information.norm());
  // The compact factor and the full stacked (whitened) observability matrix give the same restriction.
  const RestrictedObservability full = restrictObservability(observabilityMatrix(s2, true, 3), vw, pose);
  EXPECT_LT((a.information - full.information).norm(), 1e-8 * a.information.norm());
  // Adding a sensor only adds information: J3 - J2 is positive semi-definite.
  const RestrictedObservability g = restrictObservability(R3, vw, pose);
  const Mat D = g.information - a.information + 1e-8 * a.information.norm() * Mat::Identity(6, 6);
  const Eigen::LDLT<Mat> ldlt(D);
  EXPECT_EQ(ldlt.info(), Eigen::Success);
  EXPECT_GE(ldlt.vectorD().minCoeff(), 0.0);
  EXPECT_GT(g.singular_values(5), a.singular_values(5));
  // The weak combination without the gyroscope: translation along x against rotation about y, i.e.
  // orbiting the observed surface: d v_x ~ -depth d w_y (for a point at depth d straight ahead,
  // x-translation t and y-rotation t/d shift it alike). Slope between -max depth and -min depth of
  // the landmarks (with a margin), and a strong negative correlation.
  double dmin = 1e9, dmax = 0.0;
  for (const Eigen::Vector3d& m : t.landmarks) {
    const double d = observeLandmark(t.states[0], m).z();
    dmin = std::min(dmin, d);
    dmax = std::max(dmax, d);
  }
  const double beta = a.covariance(0, 4) / a.covariance(4, 4);
  EXPECT_LT(beta, -0.8 * dmin);
  EXPECT_GT(beta, -1.2 * dmax);
  EXPECT_LT(a.correlation(0, 4), -0.9);
  // With the gyroscope w_y is pinned directly, so the correlation is weaker.
  EXPECT_GT(g.correlation(0, 4), a.correlation(0, 4));
}

TEST(ObservabilityAmbiguity, GramianInverseIsTheFiltersCovariance) {
  // Linear-Gaussian check tying the analysis to the filter: with no process noise and constant
  // velocities, the Eskf (first pose exactly known, prior on v and w, landmarks initialised from their
  // first measurement, all linearised at the truth) must end with the (v, w) covariance
  // (J + prior information)^-1, J the marginal information of the anchored Gramian.
  for (Experiment e : {Experiment::Slam, Experiment::SlamGyro, Experiment::KnownLandmarks}) {
    SCOPED_TRACE(experimentName(e));
    const OrbitScenario sc = scenario(6, 8);
    const OrbitTrajectory t = makeOrbitTrajectory(sc);
    EskfOptions opt;
    opt.velocity_noise = 0.0;
    opt.angular_rate_noise = 0.0;
    opt.initial_velocity_std = 0.1;
    opt.initial_angular_rate_std = 0.2;
    const FilterCorrelation fc = runFilterCorrelation(t, sc, e, opt);
    const Mat R = observabilityFactor(buildExperiment(t, sc, e));
    const std::vector<int> vw = {6, 7, 8, 9, 10, 11}, pose = {0, 1, 2, 3, 4, 5};
    const RestrictedObservability r = restrictObservability(R, vw, pose);
    Mat J = r.information;
    for (int i = 0; i < 3; ++i) {
      J(i, i) += 1.0 / (0.1 * 0.1);
      J(3 + i, 3 + i) += 1.0 / (0.2 * 0.2);
    }
    const Mat C = J.inverse();
    const int last = sc.steps - 1;
    EXPECT_NEAR(fc.std_vx[last], std::sqrt(C(0, 0)), 1e-6 * std::sqrt(C(0, 0)));
    EXPECT_NEAR(fc.std_wy[last], std::sqrt(C(4, 4)), 1e-6 * std::sqrt(C(4, 4)));
    EXPECT_NEAR(fc.corr_vx_wy[last], C(0, 4) / std::sqrt(C(0, 0) * C(4, 4)), 1e-6);
  }
}

TEST(ObservabilityAmbiguity, FilterCorrelationDropsWithTheGyroscope) {
  // The thesis' Fig. 7.4 claim at time instant 8: high v_x - w_y correlation without the gyroscope,
  // near zero with it (default filter tuning).
  const OrbitScenario sc = scenario(10, 20);
  const OrbitTrajectory t = makeOrbitTrajectory(sc);
  const FilterCorrelation c2 = runFilterCorrelation(t, sc, Experiment::Slam);
  const FilterCorrelation c3 = runFilterCorrelation(t, sc, Experiment::SlamGyro);
  ASSERT_EQ(c2.corr_vx_wy.size(), 20u);
  EXPECT_LT(c2.corr_vx_wy[8], 0.0);
  EXPECT_LT(std::abs(c3.corr_vx_wy[8]), std::abs(c2.corr_vx_wy[8]));
  EXPECT_LT(c3.std_wy[8], c2.std_wy[8]);
}
