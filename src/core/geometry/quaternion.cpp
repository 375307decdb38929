// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/geometry/quaternion.h"

#include <Eigen/LU>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace geometry {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0.0, -v.z(), v.y(),  //
      v.z(), 0.0, -v.x(),   //
      -v.y(), v.x(), 0.0;
  return S;
}

Eigen::Vector4d quatProduct(const Eigen::Vector4d& p, const Eigen::Vector4d& q) {
  const double pw = p[0], px = p[1], py = p[2], pz = p[3];
  const double qw = q[0], qx = q[1], qy = q[2], qz = q[3];
  return Eigen::Vector4d(pw * qw - px * qx - py * qy - pz * qz,  //
                         pw * qx + px * qw + py * qz - pz * qy,  //
                         pw * qy - px * qz + py * qw + pz * qx,  //
                         pw * qz + px * qy - py * qx + pz * qw);
}

Eigen::Matrix4d quatLeftMatrix(const Eigen::Vector4d& p) {
  Eigen::Matrix4d L;
  L << p[0], -p[1], -p[2], -p[3],  //
      p[1], p[0], -p[3], p[2],     //
      p[2], p[3], p[0], -p[1],     //
      p[3], -p[2], p[1], p[0];
  return L;
}

Eigen::Matrix4d quatRightMatrix(const Eigen::Vector4d& q) {
  Eigen::Matrix4d R;
  R << q[0], -q[1], -q[2], -q[3],  //
      q[1], q[0], q[3], -q[2],     //
      q[2], -q[3], q[0], q[1],     //
      q[3], q[2], -q[1], q[0];
  return R;
}

Eigen::Vector4d toWxyz(const Quat& q) { return Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()); }

Quat fromWxyz(const Eigen::Vector4d& wxyz) { return Quat(wxyz[0], wxyz[1], wxyz[2], wxyz[3]); }

Quat quatExp(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  const double half = 0.5 * angle;
  double w, s;  // s = sin(half) / angle
  if (angle < 1e-8) {
    w = 1.0 - half * half / 2.0;
    s = 0.5 - angle * angle / 48.0;
  } else {
    w = std::cos(half);
    s = std::sin(half) / angle;
  }
  return Quat(w, s * phi.x(), s * phi.y(), s * phi.z());
}

Eigen::Vector3d quatLog(const Quat& q_in) {
  Quat q = q_in.normalized();
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // shortest rotation
  const Eigen::Vector3d v = q.vec();
  const double n = v.norm();
  if (n < 1e-8) {
    // angle = 2 atan2(n, w) ~= 2 n / w
    return (2.0 / q.w()) * v;
  }
  const double angle = 2.0 * std::atan2(n, q.w());
  return (angle / n) * v;
}

Eigen::Matrix3d so3Exp(const Eigen::Vector3d& phi) { return toRotationMatrix(quatExp(phi)); }

Eigen::Vector3d so3Log(const Eigen::Matrix3d& R) { return quatLog(fromRotationMatrix(R)); }

Eigen::Matrix3d toRotationMatrix(const Quat& q) { return q.normalized().toRotationMatrix(); }

Quat fromRotationMatrix(const Eigen::Matrix3d& R) {
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  const double det = R.determinant();
  if (!std::isfinite(orth) || orth > 1e-6 || std::abs(det - 1.0) > 1e-6) {
    std::ostringstream os;
    os << "fromRotationMatrix: not a rotation matrix (|R^T R - I| = " << orth
       << ", det = " << det << ")";
    throw std::invalid_argument(os.str());
  }
  Quat q(R);
  q.normalize();
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  return q;
}

Eigen::Matrix3d so3LeftJacobian(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  const Eigen::Matrix3d S = skew(phi);
  if (a < 1e-6) return Eigen::Matrix3d::Identity() + 0.5 * S + S * S / 6.0;
  const double a2 = a * a;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(a)) / a2 * S +
         (a - std::sin(a)) / (a2 * a) * S * S;
}

Eigen::Matrix3d so3RightJacobian(const Eigen::Vector3d& phi) { return so3LeftJacobian(-phi); }

Eigen::Matrix3d so3LeftJacobianInverse(const Eigen::Vector3d& phi) {
  const double a = phi.norm();
  const Eigen::Matrix3d S = skew(phi);
  if (a < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * S + S * S / 12.0;
  const double a2 = a * a;
  const double c = 1.0 / a2 - (1.0 + std::cos(a)) / (2.0 * a * std::sin(a));
  return Eigen::Matrix3d::Identity() - 0.5 * S + c * S * S;
}

}  // namespace geometry
}  // namespace skin3d
