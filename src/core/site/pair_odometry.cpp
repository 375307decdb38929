// SPDX-License-Identifier: BSD-3-Clause
// The rig's motion between two stereo pairs from their triangulated features (site/pair_odometry.h).
#include "skin3d/site/pair_odometry.h"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>

#include "skin3d/geometry/quaternion.h"

namespace skin3d {
namespace site {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

cv::Mat descriptors(const std::vector<stereo::StereoLandmark>& l) {
  const int n = static_cast<int>(l.size()), d = n ? static_cast<int>(l[0].descriptor.size()) : 0;
  cv::Mat m(n, d, CV_32F);
  for (int i = 0; i < n; ++i) {
    if (static_cast<int>(l[i].descriptor.size()) != d) throw std::invalid_argument("pair odometry: descriptors of different lengths");
    std::copy(l[i].descriptor.begin(), l[i].descriptor.end(), m.ptr<float>(i));
  }
  return m;
}

struct Match {
  int a, b;
};

/** Mutual nearest neighbours that pass Lowe's ratio. */
std::vector<Match> matchDescriptors(const cv::Mat& da, const cv::Mat& db, double ratio) {
  cv::BFMatcher bf(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> ab, ba;
  bf.knnMatch(da, db, ab, 2);
  bf.knnMatch(db, da, ba, 1);
  std::vector<Match> out;
  for (const auto& m : ab) {
    if (m.size() < 2 || !(m[0].distance < ratio * m[1].distance)) continue;
    const int a = m[0].queryIdx, b = m[0].trainIdx;
    if (ba[b].empty() || ba[b][0].trainIdx != a) continue;
    out.push_back({a, b});
  }
  return out;
}

/** The rigid motion (no scale) that takes the b points onto the a points, least squares (Umeyama). */
Eigen::Isometry3d umeyama(const std::vector<Eigen::Vector3d>& A, const std::vector<Eigen::Vector3d>& B) {
  Eigen::Matrix3Xd a(3, A.size()), b(3, B.size());
  for (std::size_t i = 0; i < A.size(); ++i) {
    a.col(i) = A[i];
    b.col(i) = B[i];
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.matrix() = Eigen::umeyama(b, a, false);
  return T;
}

}  // namespace

stereo::FrontEndOptions odometryFrontEndOptions() {
  stereo::FrontEndOptions o;
  o.features.type = stereo::FeatureType::AKAZE;
  o.features.threshold = 1e-5;
  o.features.max_features = 2000;
  return o;
}

geometry::CameraInfo scaledCameraInfo(const geometry::CameraInfo& c, double s) {
  geometry::CameraInfo o = c;
  o.width = static_cast<int>(std::lround(c.width * s));
  o.height = static_cast<int>(std::lround(c.height * s));
  o.K.topRows<2>() *= s;
  o.K(0, 2) += 0.5 * (s - 1);
  o.K(1, 2) += 0.5 * (s - 1);
  o.P.topRows<2>() *= s;
  o.P(0, 2) += 0.5 * (s - 1) * o.P(2, 2);
  o.P(1, 2) += 0.5 * (s - 1) * o.P(2, 2);
  return o;
}

std::vector<stereo::StereoLandmark> odometryFeatures(stereo::FrontEnd* fe, const cv::Mat& left_raw, const cv::Mat& right_raw,
                                                     const geometry::CameraInfo& left, const geometry::CameraInfo& right) {
  const int factor = std::max(1, static_cast<int>(std::ceil(left.width / 1400.0)));
  if (factor == 1) return fe->process(left_raw, right_raw, left, right).landmarks;
  const double s = 1.0 / factor;
  const geometry::CameraInfo l = scaledCameraInfo(left, s), r = scaledCameraInfo(right, s);
  cv::Mat ls, rs;
  cv::resize(left_raw, ls, cv::Size(l.width, l.height), 0, 0, cv::INTER_AREA);
  cv::resize(right_raw, rs, cv::Size(r.width, r.height), 0, 0, cv::INTER_AREA);
  return fe->process(ls, rs, l, r).landmarks;
}

void OdometryOptions::validate() const {
  if (!(ratio > 0 && ratio <= 1)) throw std::invalid_argument("odometry ratio = " + std::to_string(ratio) + " must be in (0, 1]");
  if (ransac_iterations < 1) throw std::invalid_argument("odometry ransac_iterations must be >= 1");
  if (!(gate_chi2 > 0)) throw std::invalid_argument("odometry gate_chi2 must be > 0");
  if (min_inliers < 3) throw std::invalid_argument("odometry min_inliers must be >= 3");
}

Eigen::Vector3d motionResidual(const Eigen::Isometry3d& T, const Eigen::Vector3d& Xa, const Eigen::Vector3d& Xb,
                               Eigen::Matrix<double, 3, 6>* J) {
  const Eigen::Vector3d RX = T.linear() * Xb;
  if (J) {
    J->leftCols<3>() = skew(RX);  // d(-Exp(dphi) R X)/d dphi = [R X]x
    J->rightCols<3>() = -Eigen::Matrix3d::Identity();
  }
  return Xa - (RX + T.translation());
}

RelativeMotion relativeMotion(const std::vector<stereo::StereoLandmark>& a, const std::vector<stereo::StereoLandmark>& b,
                              const OdometryOptions& o, std::uint64_t seed) {
  o.validate();
  RelativeMotion r;
  r.features_a = static_cast<int>(a.size());
  r.features_b = static_cast<int>(b.size());
  if (r.features_a < o.min_inliers || r.features_b < o.min_inliers) {
    r.why = "too few features (" + std::to_string(r.features_a) + " and " + std::to_string(r.features_b) + ")";
    return r;
  }
  const std::vector<Match> m = matchDescriptors(descriptors(a), descriptors(b), o.ratio);
  r.matches = static_cast<int>(m.size());
  if (r.matches < o.min_inliers) {
    r.why = "too few features match (" + std::to_string(r.matches) + " of " + std::to_string(r.features_b) + ")";
    return r;
  }
  auto inliersOf = [&](const Eigen::Isometry3d& T, std::vector<int>* in) {
    in->clear();
    double sum = 0;
    for (int k = 0; k < r.matches; ++k) {
      const auto& la = a[m[k].a];
      const auto& lb = b[m[k].b];
      const Eigen::Vector3d res = motionResidual(T, la.position, lb.position, nullptr);
      const Eigen::Matrix3d S = la.covariance + T.linear() * lb.covariance * T.linear().transpose();
      const double d2 = res.dot(S.ldlt().solve(res));
      if (d2 < o.gate_chi2) {
        in->push_back(k);
        sum += d2;
      }
    }
    return sum;
  };
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, r.matches - 1);
  std::vector<int> best, in;
  for (int it = 0; it < o.ransac_iterations; ++it) {
    int i = pick(rng), j = pick(rng), k = pick(rng);
    if (i == j || j == k || i == k) continue;
    const Eigen::Isometry3d T = umeyama({a[m[i].a].position, a[m[j].a].position, a[m[k].a].position},
                                        {b[m[i].b].position, b[m[j].b].position, b[m[k].b].position});
    inliersOf(T, &in);
    if (in.size() > best.size()) best = in;
  }
  if (static_cast<int>(best.size()) < o.min_inliers) {
    r.why = "too few matches agree on one motion (" + std::to_string(best.size()) + " of " + std::to_string(r.matches) + ")";
    return r;
  }
  // refine: Gauss-Newton in the Mahalanobis metric on the inliers, re-selecting them twice
  std::vector<Eigen::Vector3d> A, B;
  for (int k : best) {
    A.push_back(a[m[k].a].position);
    B.push_back(b[m[k].b].position);
  }
  Eigen::Isometry3d T = umeyama(A, B);
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  for (int round = 0; round < 3; ++round) {
    inliersOf(T, &best);
    if (static_cast<int>(best.size()) < o.min_inliers) break;
    for (int it = 0; it < 5; ++it) {
      H.setZero();
      Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
      for (int k : best) {
        const auto& la = a[m[k].a];
        const auto& lb = b[m[k].b];
        Eigen::Matrix<double, 3, 6> J;
        const Eigen::Vector3d res = motionResidual(T, la.position, lb.position, &J);
        const Eigen::Matrix3d W = (la.covariance + T.linear() * lb.covariance * T.linear().transpose()).inverse();
        H += J.transpose() * W * J;
        g += J.transpose() * W * res;
      }
      const Eigen::Matrix<double, 6, 1> dx = -H.ldlt().solve(g);
      T.linear() = geometry::so3Exp(dx.head<3>()) * T.linear();
      T.translation() += dx.tail<3>();
      if (dx.norm() < 1e-12) break;
    }
  }
  const double chi2 = inliersOf(T, &best);
  r.inliers = static_cast<int>(best.size());
  if (r.inliers < o.min_inliers) {
    r.why = "too few matches agree on one motion after refinement (" + std::to_string(r.inliers) + ")";
    return r;
  }
  r.ok = true;
  r.T_a_b = T;
  r.covariance = H.inverse();
  r.covariance = 0.5 * (r.covariance + r.covariance.transpose());
  r.rms_mahalanobis = std::sqrt(chi2 / (3.0 * r.inliers));
  return r;
}

}  // namespace site
}  // namespace skin3d
