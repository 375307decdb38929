// SPDX-License-Identifier: BSD-3-Clause
// The front end's landmarks against the rendered globe's ground truth (the front end's quality target): a
// globe-images bag is made by the real tool, then rectified, matched and triangulated with the core
// exactly as the nodelets do; errors are measured against the true sphere.
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sys/wait.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>

#include "bag_reading.h"
#include "skin3d/ros/conversions.h"
#include "skin3d/stereo/features.h"
#include "skin3d/stereo/rectification.h"
#include "skin3d/stereo/stereo_landmarks.h"

using namespace skin3d;

namespace {

const std::string kBin = SKIN3D_MAKE_DATASET_BIN;

std::string tmp(const std::string& name) { return ::testing::TempDir() + "skin3d_frontend_acc_" + name; }

template <class M>
std::vector<M> read(const std::string& bag_path, const std::string& topic) {
  return skin3d::test::readTopic<M>(bag_path, topic);
}

using skin3d::ros_conv::fromMsg;

struct Stats {
  std::vector<int> per_frame;
  std::vector<double> abs_radial_mm;
  std::vector<double> z2_normal;  // squared radial error / predicted radial variance
  std::vector<double> nees;       // 3D: truth = the true sphere point on the left keypoint's ray
  std::vector<double> nees_size;  // the keypoint size of each nees entry (px)
  std::vector<double> nees_depth;  // the NEES's share along the covariance's major axis (~ the viewing ray)
  double rms_radial_mm = 0.0;
};

// Landmarks of every frame against the true sphere: along the surface normal, error / predicted sigma.
Stats evaluate(const std::string& bag, const std::string& truth_path, stereo::FeatureType type, double sigma_px) {
  const YAML::Node truth = YAML::LoadFile(truth_path);
  const auto& c = truth["sphere"]["centre_world_m"];
  const Eigen::Vector3d centre_w(c[0].as<double>(), c[1].as<double>(), c[2].as<double>());
  const double radius = truth["sphere"]["radius_m"].as<double>();
  const auto li = read<sensor_msgs::CameraInfo>(bag, "stereo/left/camera_info");
  const auto ri = read<sensor_msgs::CameraInfo>(bag, "stereo/right/camera_info");
  const auto limg = read<sensor_msgs::Image>(bag, "stereo/left/image_raw");
  const auto rimg = read<sensor_msgs::Image>(bag, "stereo/right/image_raw");
  const auto poses = read<geometry_msgs::PoseStamped>(bag, "ground_truth/pose");
  const geometry::CameraInfo L = fromMsg(li[0]), R = fromMsg(ri[0]);
  stereo::FeatureOptions fo;
  fo.type = type;
  fo.disparity_offset = L.P(0, 2) - R.P(0, 2);
  const stereo::StereoFeatureMatcher matcher(fo);
  const stereo::Rectifier rect_l(L), rect_r(R);  // the maps once, as the nodelets do
  stereo::TriangulateOptions to;
  to.sigma_px = sigma_px;
  Stats s;
  double sum_sq = 0.0;
  const char* dump_path = std::getenv("SKIN3D_ACCURACY_DUMP");
  std::ofstream dump;
  if (dump_path) {
    dump.open(std::string(dump_path) + "_" + stereo::featureTypeName(type) + ".csv");
    dump << "frame,ul,vl,ur,vr,size,strength,var_u,var_v,nees,nees_major,eu_r,ev_r,depth\n";
  }
  for (size_t k = 0; k < limg.size(); ++k) {
    const auto matches = matcher.process(rect_l(ros_conv::toMono8(limg[k])), rect_r(ros_conv::toMono8(rimg[k])));
    const auto lms = stereo::triangulateMatches(L, R, matches, to);
    s.per_frame.push_back(static_cast<int>(lms.size()));
    const auto& p = poses[k].pose;
    Eigen::Isometry3d T_W_L = Eigen::Isometry3d::Identity();
    T_W_L.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
    T_W_L.linear() = Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z).toRotationMatrix();
    const Eigen::Vector3d centre = T_W_L.inverse() * centre_w;
    for (const auto& l : lms) {
      const Eigen::Vector3d d = l.position - centre;
      const Eigen::Vector3d n = d.normalized();
      const double e = d.norm() - radius;
      s.z2_normal.push_back(e * e / n.dot(l.covariance * n));
      s.abs_radial_mm.push_back(1e3 * std::abs(e));
      sum_sq += e * e;
      // The 3D truth of a landmark: where the ray of its (rectified) left pixel meets the true sphere, as a
      // ground-truth depth map is used. Its lateral part differs from the MMSE estimate by half the left-right
      // localisation difference, which is what the predicted covariance says of the lateral error too.
      const Eigen::Vector3d ray =
          (L.R.transpose() * Eigen::Vector3d((l.uv_left.x() - L.P(0, 2)) / L.P(0, 0), (l.uv_left.y() - L.P(1, 2)) / L.P(1, 1), 1.0))
              .normalized();
      const double bq = ray.dot(-centre), disc = bq * bq - (centre.squaredNorm() - radius * radius);
      if (disc > 0.0) {
        const Eigen::Vector3d err = l.position - (-bq - std::sqrt(disc)) * ray;
        s.nees.push_back(err.dot(l.covariance.ldlt().solve(err)));
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(l.covariance);  // ascending eigenvalues
        const double w = eig.eigenvectors().col(2).dot(err);
        s.nees_depth.push_back(w * w / eig.eigenvalues()[2]);
        if (dump_path) {
          const Eigen::Vector3d Xt = L.R * ((-bq - std::sqrt(disc)) * ray);  // rectified-left frame
          const Eigen::Vector3d pr = R.P * Xt.homogeneous();
          dump << k << ',' << l.uv_left.x() << ',' << l.uv_left.y() << ',' << l.uv_right.x() << ',' << l.uv_right.y() << ','
               << l.size << ',' << l.strength << ',' << l.var_u << ',' << l.var_v << ',' << s.nees.back() << ','
               << s.nees_depth.back() << ',' << l.uv_right.x() - pr.x() / pr.z() << ',' << l.uv_right.y() - pr.y() / pr.z()
               << ',' << Xt.z() << '\n';
        }
        s.nees_size.push_back(l.size);
      }
    }
  }
  s.rms_radial_mm = 1e3 * std::sqrt(sum_sq / std::max<size_t>(1, s.z2_normal.size()));
  return s;
}

int run(const std::string& args) {
  const int rc = std::system((kBin + " " + args + " > /dev/null 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

void report(const char* name, const Stats& s) {
  std::vector<int> n = s.per_frame;
  std::sort(n.begin(), n.end());
  std::vector<double> z = s.z2_normal;
  std::sort(z.begin(), z.end());
  std::vector<double> a = s.abs_radial_mm;
  std::sort(a.begin(), a.end());
  const size_t inliers = std::lower_bound(z.begin(), z.end(), 10.83) - z.begin();  // chi2(1) 99.9 %
  const double inlier_mean = std::accumulate(z.begin(), z.begin() + inliers, 0.0) / std::max<size_t>(1, inliers);
  std::vector<double> q = s.nees;
  std::sort(q.begin(), q.end());
  const double nees_mean = std::accumulate(q.begin(), q.end(), 0.0) / std::max<size_t>(1, q.size());
  const double nees_tail = 100.0 * (q.end() - std::lower_bound(q.begin(), q.end(), 16.27)) / std::max<size_t>(1, q.size());
  const double depth_mean =
      std::accumulate(s.nees_depth.begin(), s.nees_depth.end(), 0.0) / std::max<size_t>(1, s.nees_depth.size());
  const auto share = [&q](double lo, double hi) {
    return 100.0 * (std::lower_bound(q.begin(), q.end(), hi) - std::lower_bound(q.begin(), q.end(), lo)) /
           std::max<size_t>(1, q.size());
  };
  std::printf("%s: 3D NEES mean %.3f (chi2(3): 3), median %.3f (2.366), %.1f %% below 0.352 (5 %%), %.1f %% beyond 7.81 "
              "(5 %%), %.1f %% beyond 16.27 (0.1 %%); along the major axis %.3f (1), across %.3f (2)\n",
              name, nees_mean, q.empty() ? 0.0 : q[q.size() / 2], share(-1.0, 0.3518), share(7.815, 1e300), nees_tail,
              depth_mean, nees_mean - depth_mean);
  std::printf("%s: landmarks/frame min %d median %d max %d; |radial error| median %.3f mm, 90%% %.3f mm, RMS %.1f mm; "
              "z2 = (radial error)^2 / predicted variance: median %.3f (chi2(1): 0.455), %.1f %% beyond 10.83 "
              "(chi2(1): 0.1 %%), mean of the rest %.3f (chi2(1) truncated: 0.99); %zu landmarks\n",
              name, n.front(), n[n.size() / 2], n.back(), a[a.size() / 2], a[a.size() * 9 / 10], s.rms_radial_mm,
              z[z.size() / 2], 100.0 * (z.size() - inliers) / z.size(), inlier_mean, z.size());
}

}  // namespace

// Prints the figures of merit (see the issue notes) and checks what the front end does guarantee today:
// enough landmarks for SLAM, sub-millimetre depth with an exact calibration, no gross mismatch, and covariances
// consistent on average within the bounds stated below (the strict chi2 bar is not met: heavy tail).
TEST(FrontEndAccuracy, RenderedGlobeLandmarks) {
  const std::string bag = tmp("globe.bag");
  ASSERT_EQ(run("globe-images --quiet --frames 6 --out " + bag), 0);
  const Stats s = evaluate(bag, tmp("globe.truth.yaml"), stereo::FeatureType::KAZE, 0.0);
  report("KAZE, realism on (perturbed calibration)", s);
  ASSERT_FALSE(s.z2_normal.empty());
  EXPECT_GE(*std::min_element(s.per_frame.begin(), s.per_frame.end()), 100) << "too few landmarks for SLAM";

  std::ofstream(tmp("exact.yaml")) << "images: {calibration_error: {enabled: false}}\n";
  // CI: 6 frames of seed 1. The 40-frame, 5-seed figures of docs/validation.md: SKIN3D_ACCURACY_FRAMES=40 SKIN3D_ACCURACY_SEED=N;
  // SKIN3D_ACCURACY_DUMP=PREFIX also writes PREFIX_kaze.csv and PREFIX_akaze.csv, a row per landmark (pixels, size,
  // strength, modelled variances, NEES, the right pixel's error against the truth projected, depth).
  const char* frames = std::getenv("SKIN3D_ACCURACY_FRAMES");
  const char* seed = std::getenv("SKIN3D_ACCURACY_SEED");
  ASSERT_EQ(run(std::string("globe-images --quiet --frames ") + (frames ? frames : "6") +
                (seed ? std::string(" --seed ") + seed : std::string()) + " --config " + tmp("exact.yaml") + " --out " +
                tmp("exact.bag")),
            0);
  for (auto type : {stereo::FeatureType::KAZE, stereo::FeatureType::AKAZE}) {
    const Stats e = evaluate(tmp("exact.bag"), tmp("exact.truth.yaml"), type, 0.0);
    report((stereo::featureTypeName(type) + ", realism on, exact calibration").c_str(), e);
    EXPECT_GE(*std::min_element(e.per_frame.begin(), e.per_frame.end()), 100);
    // At 400 mm one pixel of disparity is 1.88 mm of depth: a median error below 0.5 mm means the matches are
    // localised to about a quarter pixel through blur, noise and photometric differences.
    std::vector<double> a = e.abs_radial_mm;
    std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
    EXPECT_LT(a[a.size() / 2], 0.5) << stereo::featureTypeName(type);
    // No gross mismatch survives the gates: 10 mm off the sphere is > 5 px of disparity at 400 mm, more than
    // 20 predicted sigmas anywhere on the globe (40 frames of seeds 1-5 too; before FeatureOptions::border_margin,
    // seed 3 had one, 10.09 mm: a unique candidate near the right image's edge).
    EXPECT_LT(*std::max_element(e.abs_radial_mm.begin(), e.abs_radial_mm.end()), 10.0) << stereo::featureTypeName(type);
    // Covariance consistency (quality target NOT fully met: see docs/validation.md, "Stereo front end"). A consistent covariance gives a
    // 3D NEES averaging 3 with 0.1 % beyond the chi2(3) 99.9 % point 16.27. The front end's errors are
    // heavy-tailed (oblique surface, large keypoints), so we guard what holds today: the average within 3 / 1.5
    // .. 3 x 1.5 and at most 5 % beyond 16.27 (without the slant-dependent noise model: mean 6.3, 8.8 %).
    std::vector<double> q = e.nees;
    ASSERT_GT(q.size(), 1000u);
    const double mean = std::accumulate(q.begin(), q.end(), 0.0) / q.size();
    const double tail = static_cast<double>(std::count_if(q.begin(), q.end(), [](double v) { return v > 16.27; })) / q.size();
    EXPECT_GT(mean, 2.0) << stereo::featureTypeName(type);
    EXPECT_LT(mean, 4.5) << stereo::featureTypeName(type);
    EXPECT_LT(tail, 0.05) << stereo::featureTypeName(type);
    // The scale-dependent noise model (TriangulateOptions::size_noise): a keypoint found at a coarse scale is
    // localised worse, and its covariance says so. Without the model the largest-keypoint fifth averaged a NEES of
    // 7.6 and the smallest 1.7 (40 frames); with it every fifth stays within 3 / 1.5 .. 3 x 1.5.
    std::vector<size_t> order(q.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return e.nees_size[a] < e.nees_size[b]; });
    for (int fifth = 0; fifth < 5; ++fifth) {
      double sum = 0.0;
      const size_t lo = order.size() * fifth / 5, hi = order.size() * (fifth + 1) / 5;
      for (size_t i = lo; i < hi; ++i) sum += e.nees[order[i]];
      const double m = sum / (hi - lo);
      std::printf("%s: size fifth %d (%.1f .. %.1f px): mean NEES %.2f\n", stereo::featureTypeName(type).c_str(), fifth + 1,
                  e.nees_size[order[lo]], e.nees_size[order[hi - 1]], m);
      EXPECT_GT(m, 1.5) << stereo::featureTypeName(type) << " size fifth " << fifth + 1;
      EXPECT_LT(m, 4.5) << stereo::featureTypeName(type) << " size fifth " << fifth + 1;
    }
  }
}
