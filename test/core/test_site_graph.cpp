// SPDX-License-Identifier: BSD-3-Clause
// The site scan's pose graph (src/core/site/site_graph.cpp): its costs against numerical differences, the block
// summary against the samples it sums, and misplaced frames brought back onto the skin the others saw.
#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "../../src/core/site/site_detail.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/induration/induration.h"
#include "skin3d/sim/skin.h"
#include "skin3d/site/site_fusion.h"
#include "site_test_scene.h"

namespace skin3d {
namespace site {
namespace site_detail {
ceres::CostFunction* blockPairCost(const BlockSummary& a, const BlockSummary& b);
ceres::CostFunction* posePriorCost(const Eigen::Isometry3d& given, double sigma_r, double sigma_t);
}  // namespace site_detail
}  // namespace site

namespace {

constexpr double kDeg = M_PI / 180.0;

Eigen::Isometry3d randomPose(std::mt19937_64& rng, double rot, double trans) {
  std::normal_distribution<double> n01(0, 1);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = geometry::so3Exp(Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * rot);
  T.translation() = Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * trans;
  return T;
}

/** A block's summary made from samples X (camera frame) with tangent planes (P, n) and weights w, as the code sums. */
site::site_detail::BlockSummary summary(const std::vector<Eigen::Vector3d>& X, const std::vector<Eigen::Vector3d>& P,
                                        const std::vector<Eigen::Vector3d>& n, const std::vector<double>& w) {
  site::site_detail::BlockSummary s;
  double W = 0;
  for (std::size_t k = 0; k < X.size(); ++k) {
    s.M += w[k] * X[k] * n[k].transpose();
    s.n += w[k] * n[k];
    s.c += w[k] * n[k].dot(P[k]);
    W += w[k];
  }
  s.M /= W;
  s.n /= W;
  s.c /= W;
  s.var = 1e-9;
  return s;
}

/** Each parameter block's Jacobian (ambient coordinates) against central differences of the cost itself. */
void expectJacobiansMatch(ceres::CostFunction& cost, std::vector<std::vector<double>> params, const char* what) {
  const int m = cost.num_residuals();
  const auto& sizes = cost.parameter_block_sizes();
  std::vector<double*> p;
  for (auto& b : params) p.push_back(b.data());
  std::vector<std::vector<double>> J(sizes.size());
  std::vector<double*> Jp;
  for (std::size_t b = 0; b < sizes.size(); ++b) {
    J[b].assign(static_cast<std::size_t>(m * sizes[b]), 0.0);
    Jp.push_back(J[b].data());
  }
  std::vector<double> r(m), rp(m), rm(m);
  ASSERT_TRUE(cost.Evaluate(p.data(), r.data(), Jp.data()));
  for (std::size_t b = 0; b < sizes.size(); ++b)
    for (int k = 0; k < sizes[b]; ++k) {
      const double h = 1e-7, keep = params[b][k];
      params[b][k] = keep + h;
      ASSERT_TRUE(cost.Evaluate(p.data(), rp.data(), nullptr));
      params[b][k] = keep - h;
      ASSERT_TRUE(cost.Evaluate(p.data(), rm.data(), nullptr));
      params[b][k] = keep;
      for (int i = 0; i < m; ++i) {
        const double num = (rp[i] - rm[i]) / (2 * h), ana = J[b][i * sizes[b] + k];
        EXPECT_NEAR(ana, num, 1e-5 * std::max(1.0, std::fabs(num))) << what << ": block " << b << " parameter " << k << " residual " << i;
      }
    }
}

std::vector<double> quat(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  return {q.x(), q.y(), q.z(), q.w()};
}
std::vector<double> trans(const Eigen::Isometry3d& T) { return {T.translation().x(), T.translation().y(), T.translation().z()}; }

}  // namespace

// The block summary is exact for fixed tangent planes: its offset at any pose equals the weighted mean of the samples'
// point-to-plane distances at that pose.
TEST(SitePoseGraph, ABlockSummaryGivesItsSamplesMeanOffsetAtAnyPose) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n01(0, 1);
  std::uniform_real_distribution<double> u01(0.2, 1.0);
  std::vector<Eigen::Vector3d> X, P, n;
  std::vector<double> w;
  for (int k = 0; k < 40; ++k) {
    X.emplace_back(0.01 * n01(rng), 0.01 * n01(rng), 0.25 + 0.002 * n01(rng));
    P.emplace_back(X.back() + Eigen::Vector3d(n01(rng), n01(rng), n01(rng)) * 1e-4);
    n.push_back(Eigen::Vector3d(0.1 * n01(rng), 0.1 * n01(rng), -1).normalized());
    w.push_back(u01(rng));
  }
  const site::site_detail::BlockSummary s = summary(X, P, n, w);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::Isometry3d T = randomPose(rng, 0.05, 0.01);
    double direct = 0, W = 0;
    for (std::size_t k = 0; k < X.size(); ++k) {
      direct += w[k] * n[k].dot(T * X[k] - P[k]);
      W += w[k];
    }
    EXPECT_NEAR(site::site_detail::blockOffset(s, T), direct / W, 1e-12) << "trial " << trial;
  }
}

TEST(SitePoseGraph, CostJacobiansMatchNumericalDifferences) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n01(0, 1);
  for (int trial = 0; trial < 3; ++trial) {
    std::vector<Eigen::Vector3d> X, P, n;
    std::vector<double> w;
    for (int k = 0; k < 10; ++k) {
      X.emplace_back(0.01 * n01(rng), 0.01 * n01(rng), 0.25);
      P.emplace_back(X.back());
      n.push_back(Eigen::Vector3d(0.2 * n01(rng), 0.2 * n01(rng), -1).normalized());
      w.push_back(1.0);
    }
    site::site_detail::BlockSummary a = summary(X, P, n, w), b = a;
    b.var = 4e-9;
    const Eigen::Isometry3d Ta = randomPose(rng, 0.3, 0.05), Tb = randomPose(rng, 0.3, 0.05);
    std::unique_ptr<ceres::CostFunction> pair(site::site_detail::blockPairCost(a, b));
    expectJacobiansMatch(*pair, {quat(Ta), trans(Ta), quat(Tb), trans(Tb)}, "block pair");
    std::unique_ptr<ceres::CostFunction> prior(site::site_detail::posePriorCost(Tb, 5e-3, 1e-3));
    expectJacobiansMatch(*prior, {quat(Ta * randomPose(rng, 0.01, 0.0)), trans(Ta)}, "pose prior");
  }
}

// Frames fused from poses 1 mrad and 0.2 mm off (each axis), with the registration off: the pose graph brings each
// onto the skin the others saw. The block differences drop, and the skin each frame looks at moves towards its
// true place along the body's normal (what the fused heights feel) to within the samples' noise.
TEST(SitePoseGraph, MisplacedFramesAreBroughtOntoTheSkinTheOthersSaw) {
  sim::SkinGeometry g;
  g.semi_axis_y = 0.045;
  g.semi_axis_z = 0.040;
  for (int k = 0; k < 3; ++k) {
    sim::SkinPlaque p;
    p.centre = Eigen::Vector2d(0.004 * (k - 1), g.meanRadius() * (k - 1) * 35 * kDeg);
    p.radii = Eigen::Vector2d(0.007, 0.0055);
    p.height = 0.4e-3;
    p.ramp = 0.8e-3;
    p.shape_seed = 21 + k;
    g.plaques.push_back(p);
  }
  const sim::SkinScene scene(g, 9);
  const int width = 480, height = 360;
  const double f = 1400, noise = 10e-6, distance = 0.25;
  auto pose = [&](double a) {  // the left camera in the limb frame, looking at the limb from angle a around its axis
    const Eigen::Vector3d out(0, std::sin(a), std::cos(a)), z = -out, x = Eigen::Vector3d::UnitX();
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear().col(0) = x;
    T.linear().col(1) = z.cross(x);
    T.linear().col(2) = z;
    T.translation() = (g.meanRadius() + distance) * out;
    return T;
  };
  auto cloud = [&](const Eigen::Isometry3d& T, std::uint64_t seed) {
    return site_test::castCloud(scene, T, width, height, f, 0.1, noise, seed);
  };
  induration::IndurationOptions io;
  site::SiteOptions so;
  so.register_frames = false;  // the poses as given: only the graph moves them
  so.pose_graph = true;
  site::SiteFusion fusion(so, io);
  const double angles[] = {-30, -15, 0, 15, 30};
  const Eigen::Isometry3d T_limb_C0 = pose(angles[0] * kDeg), T_C0_limb = T_limb_C0.inverse();
  std::mt19937_64 rng(23);
  std::vector<Eigen::Isometry3d> truth;
  std::vector<geometry::DenseCloud> clouds;
  std::vector<induration::IndurationResult> own;
  site::SiteOptions exact_o = so;
  exact_o.pose_graph = false;
  site::SiteFusion exact(exact_o, io);  // the same frames from their true poses: the seams' floor
  for (int k = 0; k < 5; ++k) {
    truth.push_back(T_C0_limb * pose(angles[k] * kDeg));
    clouds.push_back(cloud(T_limb_C0 * truth.back(), 500 + k));
    own.push_back(induration::measureInduration(clouds.back(), io));
    const Eigen::Isometry3d given = k == 0 ? truth.back() : truth.back() * randomPose(rng, 1e-3, 0.2e-3);
    ASSERT_TRUE(fusion.add(clouds.back(), own.back(), given, 0.25 * k).fused) << "frame " << k;
    ASSERT_TRUE(exact.add(clouds.back(), own.back(), truth.back(), 0.25 * k).fused) << "frame " << k;
  }
  // along the body's normal: how far each frame's skin lies from where it is
  auto normalError = [&](int k, const Eigen::Isometry3d& T, double* whole = nullptr) {
    double h2 = 0, s2 = 0;
    long n = 0;
    for (int v = 0; v < height; v += 6)
      for (int u = 0; u < width; u += 6) {
        const cv::Vec3f p = clouds[k].xyz.at<cv::Vec3f>(v, u);
        if (!std::isfinite(p[0])) continue;
        const Eigen::Vector3d X(p[0], p[1], p[2]), L = T_limb_C0 * truth[k] * X;
        const Eigen::Vector3d nrm = T_C0_limb.linear() * Eigen::Vector3d(0, L.y() / (g.semi_axis_y * g.semi_axis_y),
                                                                            L.z() / (g.semi_axis_z * g.semi_axis_z)).normalized();
        h2 += std::pow((T * X - truth[k] * X).dot(nrm), 2);
        s2 += (T * X - truth[k] * X).squaredNorm();
        ++n;
      }
    if (whole) *whole = std::sqrt(s2 / n);
    return std::sqrt(h2 / n);
  };
  std::vector<double> before;
  for (int k = 1; k < 5; ++k) before.push_back(normalError(k, fusion.frames()[k].pose));
  const site::SitePoseGraph rep = fusion.refine();
  ASSERT_TRUE(rep.run);
  ASSERT_TRUE(rep.used) << rep.message;
  EXPECT_EQ(rep.frames, 5);
  EXPECT_EQ(rep.pairs, 10);
  EXPECT_LT(rep.rms_after, 0.5 * rep.rms_before);
  std::printf("pose graph: %d iterations, block differences %.1f -> %.1f um RMS\n", rep.iterations, rep.rms_before * 1e6, rep.rms_after * 1e6);
  for (int k = 1; k < 5; ++k) {
    double placed = 0;
    const double after = normalError(k, fusion.frames()[k].pose, &placed);
    std::printf("frame %d: along the normal %.1f um before, %.1f um after (placed %.1f um from the truth)\n", k, before[k - 1] * 1e6,
                after * 1e6, placed * 1e6);
    EXPECT_GT(before[k - 1], 3 * noise) << "frame " << k << ": the test's pose error must show";
    EXPECT_LT(after, 0.5 * noise) << "frame " << k;
    EXPECT_LT(placed, 0.1e-3) << "frame " << k << ": along the skin (held by its relief only), as the registration's bar";
  }
  // the site fused again from the refined poses: its seams within the registration's bar (5 um beyond the noise)
  for (int k = 1; k < 5; ++k) {
    std::printf("frame %d: seams beyond the noise %.1f um (true poses %.1f um)\n", k, fusion.frames()[k].seam_excess * 1e6,
                exact.frames()[k].seam_excess * 1e6);
    EXPECT_LT(fusion.frames()[k].seam_excess, 5e-6) << "frame " << k;
  }
}

}  // namespace skin3d
