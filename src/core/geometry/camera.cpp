// SPDX-License-Identifier: BSD-3-Clause
#include "skin3d/geometry/camera.h"

#include <Eigen/LU>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace geometry {

namespace {
std::string fieldError(const std::string& field, double value, const std::string& why) {
  std::ostringstream os;
  os << "camera: " << field << " = " << value << ": " << why;
  return os.str();
}
}  // namespace

PinholeCamera::PinholeCamera(const Eigen::Matrix3d& K, int width, int height, std::vector<double> D)
    : K_(K), width_(width), height_(height) {
  if (!(K(0, 0) > 0.0) || !std::isfinite(K(0, 0)))
    throw std::invalid_argument(fieldError("K[0] (fx)", K(0, 0), "must be finite and > 0 (uncalibrated camera?)"));
  if (!(K(1, 1) > 0.0) || !std::isfinite(K(1, 1)))
    throw std::invalid_argument(fieldError("K[4] (fy)", K(1, 1), "must be finite and > 0"));
  if (!K.allFinite()) throw std::invalid_argument("camera: K has a NaN or Inf entry");
  if (K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0)
    throw std::invalid_argument("camera: the last row of K must be (0, 0, 1)");
  if (width <= 0) throw std::invalid_argument(fieldError("width", width, "must be > 0"));
  if (height <= 0) throw std::invalid_argument(fieldError("height", height, "must be > 0"));
  if (!D.empty() && D.size() != 4 && D.size() != 5 && D.size() != 8) {
    std::ostringstream os;
    os << "camera: D has " << D.size() << " coefficients; plumb_bob takes 4 or 5 (k1 k2 p1 p2 [k3])";
    throw std::invalid_argument(os.str());
  }
  if (D.size() == 8) {
    for (size_t i = 5; i < 8; ++i)
      if (D[i] != 0.0)
        throw std::invalid_argument("camera: rational_polynomial distortion (D[5..7] != 0) is not supported");
  }
  D_.assign(5, 0.0);
  for (size_t i = 0; i < std::min<size_t>(D.size(), 5); ++i) {
    if (!std::isfinite(D[i])) throw std::invalid_argument(fieldError("D[" + std::to_string(i) + "]", D[i], "not finite"));
    D_[i] = D[i];
  }
  Kinv_ = K_.inverse();
}

PinholeCamera PinholeCamera::fromCameraInfo(const CameraInfo& info) {
  if (!info.distortion_model.empty() && info.distortion_model != "plumb_bob" &&
      info.distortion_model != "rational_polynomial")
    throw std::invalid_argument("camera: distortion_model '" + info.distortion_model +
                                "' is not supported (plumb_bob only)");
  return PinholeCamera(info.K, info.width, info.height, info.D);
}

PinholeCamera PinholeCamera::rectifiedFromCameraInfo(const CameraInfo& info) {
  return PinholeCamera(info.P.leftCols<3>(), info.width, info.height, {});
}

bool PinholeCamera::hasDistortion() const {
  for (double d : D_)
    if (d != 0.0) return true;
  return false;
}

Eigen::Vector2d PinholeCamera::distortNormalized(const Eigen::Vector2d& xn, Eigen::Matrix2d* J) const {
  const double k1 = D_[0], k2 = D_[1], p1 = D_[2], p2 = D_[3], k3 = D_[4];
  const double x = xn.x(), y = xn.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
  if (J) {
    const double dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
    const double drad_dx = dradial_dr2 * 2.0 * x;
    const double drad_dy = dradial_dr2 * 2.0 * y;
    (*J)(0, 0) = radial + x * drad_dx + 2.0 * p1 * y + p2 * 6.0 * x;
    (*J)(0, 1) = x * drad_dy + 2.0 * p1 * x + p2 * 2.0 * y;
    (*J)(1, 0) = y * drad_dx + p1 * 2.0 * x + 2.0 * p2 * y;
    (*J)(1, 1) = radial + y * drad_dy + p1 * 6.0 * y + 2.0 * p2 * x;
  }
  return Eigen::Vector2d(xd, yd);
}

Eigen::Vector2d PinholeCamera::project(const Eigen::Vector3d& X, Eigen::Matrix<double, 2, 3>* J) const {
  const double iz = 1.0 / X.z();
  const Eigen::Vector2d xn(X.x() * iz, X.y() * iz);
  Eigen::Matrix2d Jd;
  const Eigen::Vector2d xd = distortNormalized(xn, J ? &Jd : nullptr);
  const Eigen::Vector2d uv = K_.topLeftCorner<2, 2>() * xd + K_.topRightCorner<2, 1>();
  if (J) {
    Eigen::Matrix<double, 2, 3> Jn;
    Jn << iz, 0.0, -X.x() * iz * iz,  //
        0.0, iz, -X.y() * iz * iz;
    *J = K_.topLeftCorner<2, 2>() * Jd * Jn;
  }
  return uv;
}

Eigen::Vector2d PinholeCamera::undistortToNormalized(const Eigen::Vector2d& uv, Eigen::Matrix2d* J) const {
  const Eigen::Vector3d h = Kinv_ * Eigen::Vector3d(uv.x(), uv.y(), 1.0);
  const Eigen::Vector2d xd(h.x(), h.y());
  Eigen::Vector2d xn = xd;
  Eigen::Matrix2d Jd = Eigen::Matrix2d::Identity();
  if (hasDistortion()) {
    for (int it = 0; it < 30; ++it) {
      const Eigen::Vector2d r = distortNormalized(xn, &Jd) - xd;
      const Eigen::Vector2d step = Jd.partialPivLu().solve(r);
      xn -= step;
      if (step.norm() < 1e-15) break;
    }
    distortNormalized(xn, &Jd);
  }
  if (J) *J = Jd.inverse() * Kinv_.topLeftCorner<2, 2>();
  return xn;
}

Eigen::Vector2d PinholeCamera::undistortPixel(const Eigen::Vector2d& uv, Eigen::Matrix2d* J) const {
  Eigen::Matrix2d Jn;
  const Eigen::Vector2d xn = undistortToNormalized(uv, J ? &Jn : nullptr);
  if (J) *J = K_.topLeftCorner<2, 2>() * Jn;
  return K_.topLeftCorner<2, 2>() * xn + K_.topRightCorner<2, 1>();
}

Eigen::Vector3d PinholeCamera::unproject(const Eigen::Vector2d& uv, Eigen::Matrix<double, 3, 2>* J) const {
  Eigen::Matrix2d Jn;
  const Eigen::Vector2d xn = undistortToNormalized(uv, J ? &Jn : nullptr);
  if (J) {
    J->topRows<2>() = Jn;
    J->row(2).setZero();
  }
  return Eigen::Vector3d(xn.x(), xn.y(), 1.0);
}

bool PinholeCamera::inImage(const Eigen::Vector2d& uv) const {
  return uv.x() >= -0.5 && uv.y() >= -0.5 && uv.x() <= width_ - 0.5 && uv.y() <= height_ - 0.5;
}

}  // namespace geometry
}  // namespace skin3d
