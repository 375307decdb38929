# SPDX-License-Identifier: BSD-3-Clause
"""TUM trajectory files (`t x y z qx qy qz qw` per line, '#' comments): trajectory.tum, ground_truth.tum."""
import os

import numpy as np


def read_tum(path):
    """All rows as an (N, 8) array; (0, 8) when the file does not exist."""
    if not os.path.exists(path):
        return np.zeros((0, 8))
    a = np.loadtxt(path, comments="#", ndmin=2)
    return a.reshape(-1, 8)


def read_tum_poses(path):
    """(t, p, q) arrays: stamps (s), positions (N, 3) in metres, quaternions (N, 4) as (x, y, z, w).

    Raises ValueError when the file holds no pose, OSError when it cannot be read."""
    with open(path) as f:
        rows = [line.split() for line in f if line.strip() and not line.startswith("#")]
    if not rows:
        raise ValueError("'%s' has no poses" % path)
    a = np.array([[float(v) for v in r[:8]] for r in rows])
    return a[:, 0], a[:, 1:4], a[:, 4:8]
