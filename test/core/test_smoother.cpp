// SPDX-License-Identifier: BSD-3-Clause
// The batch smoother (smoother.h): the gyro preintegration's bias Jacobian against finite differences and its
// covariance against Monte Carlo; a simulated orbit around a landmark sphere, started from a drifting
// trajectory, smoothed back to the truth with its gyro bias found within its stated std; the association ids
// SlamSystem hands it; bad input.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <iterator>
#include <map>
#include <random>
#include <vector>

#include "skin3d/slam/slam_config.h"
#include "skin3d/slam/slam_system.h"
#include "skin3d/slam/smoother.h"

namespace {

using skin3d::slam::GyroDelta;
using skin3d::slam::GyroSample;
using skin3d::slam::SmootherFrame;
using skin3d::slam::SmootherOptions;
using skin3d::slam::SmootherResult;

Eigen::Vector3d logSO3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

std::vector<GyroSample> randomSamples(std::mt19937& rng, double t0, double t1, double rate_hz) {
  std::normal_distribution<double> w(0.0, 0.4);
  std::vector<GyroSample> s;
  for (double t = t0; t < t1; t += 1.0 / rate_hz) s.push_back({t, Eigen::Vector3d(w(rng), w(rng), w(rng)), Eigen::Matrix3d::Zero()});
  return s;
}

TEST(Preintegration, BiasJacobianMatchesFiniteDifferences) {
  std::mt19937 rng(3);
  const std::vector<GyroSample> s = randomSamples(rng, 0.0, 0.2, 100.0);
  const Eigen::Vector3d b0(0.01, -0.02, 0.005);
  // the interval starts and ends between samples
  const GyroDelta g = skin3d::slam::preintegrate(s, 0.013, 0.187, b0, 0.002);
  ASSERT_NEAR(g.dt, 0.174, 1e-12);
  const double eps = 1e-6;
  for (int i = 0; i < 3; ++i) {
    const GyroDelta h = skin3d::slam::preintegrate(s, 0.013, 0.187, b0 + eps * Eigen::Vector3d::Unit(i), 0.002);
    const Eigen::Vector3d numeric = logSO3(g.dR.transpose() * h.dR) / eps;
    EXPECT_LT((numeric - g.J_bias.col(i)).norm(), 1e-5 * std::max(1.0, numeric.norm()))
        << "column " << i << ": numeric " << numeric.transpose() << ", analytic " << g.J_bias.col(i).transpose();
  }
}

TEST(Preintegration, CovarianceMatchesTheSpreadOfNoisySamples) {
  std::mt19937 rng(5);
  const std::vector<GyroSample> truth = randomSamples(rng, 0.0, 0.1, 200.0);
  const double sigma = 0.01;
  const GyroDelta g = skin3d::slam::preintegrate(truth, 0.0, 0.1, Eigen::Vector3d::Zero(), sigma);
  std::normal_distribution<double> n(0.0, sigma);
  Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
  const int runs = 4000;
  for (int r = 0; r < runs; ++r) {
    std::vector<GyroSample> noisy = truth;
    for (auto& x : noisy) x.omega += Eigen::Vector3d(n(rng), n(rng), n(rng));
    const GyroDelta h = skin3d::slam::preintegrate(noisy, 0.0, 0.1, Eigen::Vector3d::Zero(), sigma);
    const Eigen::Vector3d e = logSO3(g.dR.transpose() * h.dR);
    spread += e * e.transpose();
  }
  spread /= runs;
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(spread(i, i) / g.covariance(i, i), 1.0, 0.1) << "axis " << i;  // 4000 runs: ~2.2 % std
}

// A rig orbiting a sphere of landmarks (the globe's geometry, smaller), seen in stereo with a depth error
// several times the lateral one, and a gyroscope with a constant bias.
struct Orbit {
  std::vector<SmootherFrame> truth, start;
  std::vector<GyroSample> gyro;
  Eigen::Vector3d bias{0.0012, -0.0020, 0.0007};
};

Orbit makeOrbit(std::uint32_t seed, double rate = 0.2, int frames = 120) {
  Orbit o;
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  const double radius = 0.15, distance = 0.45, fps = 10.0;
  std::vector<Eigen::Vector3d> landmarks;
  std::vector<std::vector<float>> descriptors;
  for (int i = 0; i < 1500; ++i) {
    landmarks.push_back(radius * Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized());
    Eigen::VectorXf d(16);
    for (int j = 0; j < 16; ++j) d[j] = static_cast<float>(n(rng));
    d.normalize();
    descriptors.emplace_back(d.data(), d.data() + 16);
  }
  // the rig at angle a around the sphere's y axis, looking at its centre; world = the first frame's camera
  auto pose = [&](double t, Eigen::Matrix3d* R, Eigen::Vector3d* p) {
    const double a = rate * t;
    const Eigen::Vector3d c(distance * std::sin(a), 0.02 * std::sin(0.7 * t), -distance * std::cos(a));
    const Eigen::Vector3d zc = (-c).normalized(), yc(0, 1, 0);
    const Eigen::Vector3d xc = yc.cross(zc).normalized();
    R->col(0) = xc;
    R->col(1) = zc.cross(xc);
    R->col(2) = zc;
    *p = c;
  };
  Eigen::Matrix3d R0;
  Eigen::Vector3d p0;
  pose(0.0, &R0, &p0);
  auto world = [&](double t, Eigen::Matrix3d* R, Eigen::Vector3d* p) {  // relative to the first camera
    Eigen::Matrix3d Rs;
    Eigen::Vector3d ps;
    pose(t, &Rs, &ps);
    *R = R0.transpose() * Rs;
    *p = R0.transpose() * (ps - p0);
  };
  for (auto& m : landmarks) m = R0.transpose() * (m - p0);
  const double sx = 1e-4, sz = 6e-4;  // m: lateral and depth error of a stereo point
  for (int k = 0; k < frames; ++k) {
    const double t = k / fps;
    Eigen::Matrix3d R;
    Eigen::Vector3d p;
    world(t, &R, &p);
    SmootherFrame f;
    f.t = t;
    f.p = p;
    f.q = Eigen::Quaterniond(R);
    for (std::size_t i = 0; i < landmarks.size(); ++i) {
      const Eigen::Vector3d z = R.transpose() * (landmarks[i] - p);
      const Eigen::Vector3d normal_c = R.transpose() * (landmarks[i] - R0.transpose() * (-p0)).normalized();
      if (normal_c.dot(-z.normalized()) < 0.5) continue;  // faces the rig within 60 deg
      SmootherFrame::Observation ob;
      ob.landmark = static_cast<std::int64_t>(i);
      // depth error along the line of sight
      const Eigen::Vector3d los = z.normalized();
      Eigen::Matrix3d C = sx * sx * Eigen::Matrix3d::Identity() + (sz * sz - sx * sx) * los * los.transpose();
      const Eigen::LLT<Eigen::Matrix3d> llt(C);
      ob.z = z + Eigen::Matrix3d(llt.matrixL()) * Eigen::Vector3d(n(rng), n(rng), n(rng));
      ob.C = C;
      ob.descriptor = descriptors[i];
      for (float& x : ob.descriptor) x += 0.01f * static_cast<float>(n(rng));
      f.observations.push_back(ob);
    }
    o.truth.push_back(f);
  }
  // gyro at 100 Hz: the body rate (finite difference of the true attitude) + bias + noise
  const double gyro_sigma = 0.002;
  for (double t = 0.0; t < (frames - 1) / fps + 1e-9; t += 0.01) {
    Eigen::Matrix3d Ra, Rb;
    Eigen::Vector3d pa, pb;
    world(t, &Ra, &pa);
    world(t + 0.01, &Rb, &pb);
    const Eigen::Vector3d w = logSO3(Ra.transpose() * Rb) / 0.01;
    o.gyro.push_back({t, w + o.bias + gyro_sigma * Eigen::Vector3d(n(rng), n(rng), n(rng)), gyro_sigma * gyro_sigma * Eigen::Matrix3d::Identity()});
  }
  // the start: a trajectory that drifts (a turn-rate error of 3 mrad/s and 1 mm/s) plus noise
  o.start = o.truth;
  for (std::size_t k = 1; k < o.start.size(); ++k) {
    const double t = o.start[k].t;
    o.start[k].q = o.start[k].q * Eigen::Quaterniond(Eigen::AngleAxisd(0.003 * t, Eigen::Vector3d(0.3, 1, 0.2).normalized()));
    o.start[k].p += Eigen::Vector3d(0.001, -0.0005, 0.0008) * t + 2e-4 * Eigen::Vector3d(n(rng), n(rng), n(rng));
  }
  return o;
}

double positionRms(const std::vector<Eigen::Vector3d>& p, const std::vector<SmootherFrame>& truth) {
  double s = 0;
  for (std::size_t k = 0; k < p.size(); ++k) s += (p[k] - truth[k].p).squaredNorm();
  return std::sqrt(s / p.size());
}

TEST(Smoother, AnOrbitIsSmoothedBackToTheTruthAndItsGyroBiasFound) {
  const Orbit o = makeOrbit(11);
  SmootherOptions opt;
  opt.gyro_bias_walk = 2e-5;
  const SmootherResult r = skin3d::slam::smooth(o.start, o.gyro, opt);
  ASSERT_TRUE(r.ok) << r.message;
  std::vector<Eigen::Vector3d> start_p;
  for (const auto& f : o.start) start_p.push_back(f.p);
  const double before = positionRms(start_p, o.truth), after = positionRms(r.p, o.truth);
  std::printf("%s\nposition RMS %.3f mm -> %.3f mm\n", r.message.c_str(), 1e3 * before, 1e3 * after);
  // the start drifts by 3 mrad/s and 1.4 mm/s: 36 mrad and 16 mm at the end; the smoothed trajectory is held by the
  // points (0.1 mm lateral, 0.6 mm in depth, some hundred a frame) and the gyro: at least 20 times closer
  EXPECT_GT(before, 3e-3);
  EXPECT_LT(after, before / 20);
  double rot = 0, rot_before = 0;
  for (std::size_t k = 0; k < r.q.size(); ++k) {
    rot = std::max(rot, r.q[k].angularDistance(o.truth[k].q));
    rot_before = std::max(rot_before, o.start[k].q.angularDistance(o.truth[k].q));
  }
  std::printf("largest rotation error %.3f mrad -> %.3f mrad\n", 1e3 * rot_before, 1e3 * rot);
  EXPECT_LT(rot, rot_before / 20);
  // the bias: within 3 stated std on each axis, the std a real one (not the prior's 10 mrad/s)
  const Eigen::Vector3d b = r.gyro_bias.back();
  for (int i = 0; i < 3; ++i) {
    const double sd = std::sqrt(r.final_bias_covariance(i, i));
    std::printf("bias %d: %.4f mrad/s (truth %.4f), std %.4f mrad/s\n", i, 1e3 * b[i], 1e3 * o.bias[i], 1e3 * sd);
    EXPECT_GT(sd, 0.0);
    EXPECT_LT(sd, 1e-3);
    EXPECT_LT(std::fabs(b[i] - o.bias[i]), 3.0 * sd) << "axis " << i;
  }
  // the mean over the recording: within 3 of its std, which is smaller than the last frame's
  const Eigen::Vector3d mean = r.mean_bias();
  for (int i = 0; i < 3; ++i) {
    const double sd = std::sqrt(r.mean_bias_covariance(i, i));
    std::printf("mean bias %d: %.4f mrad/s, std %.4f mrad/s\n", i, 1e3 * mean[i], 1e3 * sd);
    EXPECT_GT(sd, 0.0);
    EXPECT_LT(sd, std::sqrt(r.final_bias_covariance(i, i)));
    EXPECT_LT(std::fabs(mean[i] - o.bias[i]), 3.0 * sd) << "axis " << i;
  }
  // the covariances given were the true ones: the variance factor is about 1, and about 5 % of the residuals
  // lie beyond the Huber radius (chi^2, 3 dof, 95 %)
  EXPECT_NEAR(r.sigma0, 1.0, 0.05);
  EXPECT_LT(r.outliers, 0.08 * r.observations) << r.outliers << " of " << r.observations;
  EXPECT_GT(r.outliers, 0.02 * r.observations) << r.outliers << " of " << r.observations;
}

// A whole turn and more (0.6 rad/s for 12 s): each landmark the rig sees again after 5 frames or more out of view
// comes back under a new id, as from a filter that had dropped it. The smoother finds them again: each such
// id joined to its own first id (the same position in the result), no two landmarks joined, and the drift that the
// loop closes goes.
TEST(Smoother, LandmarksFoundAgainCloseTheLoop) {
  Orbit o = makeOrbit(14, 0.6, 120);
  const std::int64_t kNew = 100000;
  std::map<std::int64_t, int> last_seen;
  std::map<std::int64_t, int> segment;
  int split = 0;
  for (int k = 0; k < static_cast<int>(o.start.size()); ++k) {
    for (std::size_t j = 0; j < o.start[k].observations.size(); ++j) {
      const std::int64_t i = o.start[k].observations[j].landmark;
      auto it = last_seen.find(i);
      if (it != last_seen.end() && k - it->second > 5) {
        ++segment[i];
        ++split;
      }
      last_seen[i] = k;
      o.start[k].observations[j].landmark = i + kNew * segment[i];
    }
  }
  ASSERT_GT(split, 100) << "the orbit must come back to landmarks it saw";
  SmootherOptions off;
  off.loop_radius = 0;
  const SmootherResult r0 = skin3d::slam::smooth(o.start, o.gyro, off);
  const SmootherResult r = skin3d::slam::smooth(o.start, o.gyro, SmootherOptions());
  ASSERT_TRUE(r0.ok && r.ok) << r0.message << " / " << r.message;
  std::printf("without: %s\nwith: %s\n%d ids split; position RMS %.3f mm without, %.3f mm with loop closure\n",
              r0.message.c_str(), r.message.c_str(), split, 1e3 * positionRms(r0.p, o.truth), 1e3 * positionRms(r.p, o.truth));
  EXPECT_EQ(r0.loops, 0);
  EXPECT_GT(r.loops, split / 2);
  // every id joined is joined to its own landmark: same position as that landmark's first id; distinct landmarks
  // keep distinct positions
  std::map<std::int64_t, Eigen::Vector3d> pos(r.landmark_positions.begin(), r.landmark_positions.end());
  int joined_right = 0;
  for (const auto& kv : pos) {
    if (kv.first < kNew) continue;
    auto first = pos.find(kv.first % kNew);
    if (first != pos.end() && (first->second - kv.second).norm() == 0.0) ++joined_right;
  }
  EXPECT_GE(joined_right, r.loops * 9 / 10);
  int wrong = 0;
  for (auto a = pos.begin(); a != pos.end(); ++a)
    for (auto b = std::next(a); b != pos.end(); ++b)
      if (a->first % kNew != b->first % kNew && a->second == b->second) ++wrong;
  EXPECT_EQ(wrong, 0) << "landmarks joined that are not the same";
  EXPECT_LE(positionRms(r.p, o.truth), positionRms(r0.p, o.truth));
}

TEST(Smoother, WithoutTheGyroThePosesAreSmoothedAndNoBiasIsMade) {
  const Orbit o = makeOrbit(12);
  const SmootherResult r = skin3d::slam::smooth(o.start, {}, SmootherOptions());
  ASSERT_TRUE(r.ok) << r.message;
  std::vector<Eigen::Vector3d> start_p;
  for (const auto& f : o.start) start_p.push_back(f.p);
  EXPECT_LT(positionRms(r.p, o.truth), positionRms(start_p, o.truth) / 20);
  EXPECT_TRUE(r.final_bias_covariance.isZero());
}

// The poses' stated covariances against their errors over Monte Carlo runs (each its own scene, noise and drifting
// start; the measurements' covariances the true ones): the average NEES of a frame over N runs, times N, is
// chi^2 with 6 N dof when the covariances are right. The two-sided 95 % band (Wilson-Hilferty) holds most frames.
TEST(Smoother, ThePoseCovariancesAreConsistentOverMonteCarloRuns) {
  const int runs = 24, frames = 40;
  std::vector<double> nees(frames, 0.0);
  SmootherOptions opt;
  for (int i = 0; i < runs; ++i) {
    const Orbit o = makeOrbit(1000 + i, 0.2, frames);
    const SmootherResult r = skin3d::slam::smooth(o.start, o.gyro, opt);
    ASSERT_TRUE(r.ok) << r.message;
    ASSERT_EQ(r.pose_covariance.size(), static_cast<std::size_t>(frames));
    EXPECT_TRUE(r.pose_covariance[0].isZero()) << "the first pose defines the world";
    for (int k = 1; k < frames; ++k) {
      const skin3d::slam::Matrix6d& P = r.pose_covariance[k];
      ASSERT_LT((P - P.transpose()).norm(), 1e-12 * P.norm()) << "frame " << k;
      const Eigen::LLT<skin3d::slam::Matrix6d> llt(P);
      ASSERT_EQ(llt.info(), Eigen::Success) << "frame " << k << " run " << i << ": not positive definite";
      Eigen::Matrix<double, 6, 1> e;  // the true state minus the estimate: R_true = Exp(theta) R_est
      e.head<3>() = o.truth[k].p - r.p[k];
      e.tail<3>() = logSO3(o.truth[k].q.toRotationMatrix() * r.q[k].toRotationMatrix().transpose());
      nees[k] += e.dot(llt.solve(e)) / runs;
    }
  }
  const double dof = 6.0 * runs, z = 1.959964;
  auto quantile = [&](double zz) { const double h = 2.0 / (9.0 * dof); return std::pow(1.0 - h + zz * std::sqrt(h), 3) * dof / runs; };
  const double lo = quantile(-z), hi = quantile(z);
  int inside = 0;
  double mean = 0;
  for (int k = 1; k < frames; ++k) {
    inside += nees[k] >= lo && nees[k] <= hi;
    mean += nees[k] / (frames - 1);
  }
  std::printf("average pose NEES %.2f (6 expected); %d of %d frames inside the 95 %% band [%.2f, %.2f]\n", mean, inside,
              frames - 1, lo, hi);
  EXPECT_GE(inside, 0.85 * (frames - 1));
  EXPECT_NEAR(mean, 6.0, 1.0);
}

TEST(Smoother, BadInputIsNamed) {
  const Orbit o = makeOrbit(13);
  std::vector<SmootherFrame> two(o.start.begin(), o.start.begin() + 2);
  SmootherResult r = skin3d::slam::smooth(two, o.gyro, SmootherOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("fewer than 3 frames"), std::string::npos) << r.message;
  std::vector<SmootherFrame> back = o.start;
  std::swap(back[4], back[5]);
  r = skin3d::slam::smooth(back, o.gyro, SmootherOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("time order"), std::string::npos) << r.message;
  SmootherOptions bad;
  bad.gyro_bias_walk = 0;
  EXPECT_THROW(skin3d::slam::smooth(o.start, o.gyro, bad), std::invalid_argument);
}

// The option: off, batch, and rosparam's reading of an unquoted off (the boolean false); anything else is named.
TEST(Smoother, TheOptionTakesOffOrBatch) {
  skin3d::slam::SlamOptions o;
  EXPECT_EQ(o.smoother, "batch");  // the default
  skin3d::slam::setSlamOption(&o, "smoother", "off");
  EXPECT_EQ(o.smoother, "off");
  skin3d::slam::setSlamOption(&o, "smoother", "batch");
  EXPECT_EQ(o.smoother, "batch");
  skin3d::slam::setSlamOption(&o, "smoother", "false");  // rosparam reads an unquoted off as false
  EXPECT_EQ(o.smoother, "off");
  try {
    skin3d::slam::setSlamOption(&o, "smoother", "sliding");
    ADD_FAILURE() << "'sliding' was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("smoother"), std::string::npos) << e.what();
  }
  o.smoother = "other";
  EXPECT_THROW(o.validate(), std::invalid_argument);
}

// The ids SlamSystem reports per measurement tie a landmark's observations together across frames.
TEST(Smoother, TheSlamSystemNamesTheLandmarkOfEachMeasurement) {
  skin3d::slam::SlamSystem slam;
  std::vector<skin3d::slam::Measurement> m(6);
  for (int i = 0; i < 6; ++i) {
    m[i].z = Eigen::Vector3d(0.05 * i - 0.1, 0.03 * (i % 3), 0.4 + 0.02 * i);
    m[i].C = 1e-8 * Eigen::Matrix3d::Identity();
    m[i].descriptor.assign(8, 0.0f);
    m[i].descriptor[i] = 1.0f;
    m[i].strength = 1.0f;
  }
  slam.processFrame(0.0, m);
  const std::vector<std::int64_t> first = slam.lastAssociations();
  ASSERT_EQ(first.size(), m.size());
  for (auto id : first) EXPECT_GE(id, 0);
  std::swap(m[0], m[3]);  // the same points in another order
  slam.processFrame(0.1, m);
  const std::vector<std::int64_t>& second = slam.lastAssociations();
  ASSERT_EQ(second.size(), m.size());
  EXPECT_EQ(second[0], first[3]);
  EXPECT_EQ(second[3], first[0]);
  EXPECT_EQ(second[1], first[1]);
}

}  // namespace
