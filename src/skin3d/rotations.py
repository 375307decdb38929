# SPDX-License-Identifier: BSD-3-Clause
"""Rotations for results files: Hamilton quaternions in TUM order (x, y, z, w), SO(3) exp / log, Euler angles."""
import math

import numpy as np


def quat_to_rot(q):
    """Rotation matrix of the quaternion q = (x, y, z, w) (normalised here)."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def so3_log(R):
    """Rotation vector (rad) of R; exact near 0 and near pi."""
    c = max(-1.0, min(1.0, (np.trace(R) - 1) / 2))
    a = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if a < 1e-9:
        return 0.5 * v
    if a > math.pi - 1e-6:  # near pi: axis from the diagonal
        ax = np.sqrt(np.maximum((np.diag(R) + 1) / 2, 0))
        ax *= np.sign(v + (v == 0))
        return a * ax / np.linalg.norm(ax)
    return a / (2 * math.sin(a)) * v


def so3_exp(w):
    """Rotation matrix of the rotation vector w (rad)."""
    a = float(np.linalg.norm(w))
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if a < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + math.sin(a) / a * K + (1 - math.cos(a)) / (a * a) * K @ K


def euler_zyx_deg(R):
    """Roll (x), pitch (y), yaw (z) of R = Rz Ry Rx, degrees."""
    yaw = math.atan2(R[1, 0], R[0, 0])
    pitch = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    roll = math.atan2(R[2, 1], R[2, 2])
    return np.degrees([roll, pitch, yaw])
