/**
 * @file quaternion.h
 * @brief Hamilton quaternions and SO(3) helpers (thesis eq. 2.5-2.7, Sola 2017).
 *
 * Convention: Hamilton (ijk = -1), stored as Eigen::Quaterniond whose
 * constructor takes (w, x, y, z). A quaternion q "rotates frame-B vectors into
 * frame A": v_A = R(q) v_B, and q_AC = q_AB (x) q_BC.
 * Rotation vectors (Exp/Log arguments) are in radians.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace skin3d {
namespace geometry {

using Quat = Eigen::Quaterniond;

/** @brief Skew-symmetric matrix [v]x with [v]x w = v x w. */
Eigen::Matrix3d skew(const Eigen::Vector3d& v);

/** @brief Quaternion product p (x) q written out as thesis eq. 2.6 (w, x, y, z). */
Eigen::Vector4d quatProduct(const Eigen::Vector4d& p, const Eigen::Vector4d& q);

/** @brief Left-multiplication matrix [p]_L with p (x) q = [p]_L q (thesis eq. 2.7). */
Eigen::Matrix4d quatLeftMatrix(const Eigen::Vector4d& p);

/** @brief Right-multiplication matrix [q]_R with p (x) q = [q]_R p. */
Eigen::Matrix4d quatRightMatrix(const Eigen::Vector4d& q);

/** @brief (w, x, y, z) coefficients of an Eigen quaternion. */
Eigen::Vector4d toWxyz(const Quat& q);
/** @brief Eigen quaternion from (w, x, y, z) coefficients (not normalised). */
Quat fromWxyz(const Eigen::Vector4d& wxyz);

/** @brief Exp map: rotation vector phi (rad) -> unit quaternion. Exact near zero. */
Quat quatExp(const Eigen::Vector3d& phi);

/**
 * @brief Log map: unit quaternion -> rotation vector in the ball |phi| <= pi.
 * q and -q give the same rotation vector.
 */
Eigen::Vector3d quatLog(const Quat& q);

/** @brief Rodrigues: rotation vector -> rotation matrix. */
Eigen::Matrix3d so3Exp(const Eigen::Vector3d& phi);
/** @brief Rotation matrix -> rotation vector (|phi| <= pi). */
Eigen::Vector3d so3Log(const Eigen::Matrix3d& R);

/** @brief Rotation matrix of a unit quaternion (normalises first). */
Eigen::Matrix3d toRotationMatrix(const Quat& q);
/**
 * @brief Unit quaternion of a rotation matrix, with w >= 0.
 * @throws std::invalid_argument when R is not a rotation (|R^T R - I| or det off by > 1e-6).
 */
Quat fromRotationMatrix(const Eigen::Matrix3d& R);

/** @brief Left Jacobian of SO(3): Exp(phi + d) ~= Exp(Jl(phi) d) Exp(phi). */
Eigen::Matrix3d so3LeftJacobian(const Eigen::Vector3d& phi);
/** @brief Right Jacobian of SO(3): Exp(phi + d) ~= Exp(phi) Exp(Jr(phi) d). */
Eigen::Matrix3d so3RightJacobian(const Eigen::Vector3d& phi);
/** @brief Inverse of the left Jacobian. */
Eigen::Matrix3d so3LeftJacobianInverse(const Eigen::Vector3d& phi);

}  // namespace geometry
}  // namespace skin3d
