"""The light level where a tail bound crosses the error budget, found once by bisection.

Every bound a path relies on is monotone in the light, so each path test is one
comparison with such a level (:class:`tespike.golden.fastsim.plan.PathLevels`).
"""

from __future__ import annotations

import numpy as np


def largest_below(bound, budget, hi):
    """Largest m in [0, hi] (to 2^-64 of the bracket) with bound(m) < budget, bound increasing."""
    lo = 0.0
    if not bound(np.array([lo]))[0] < budget:
        return -1.0
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        if bound(np.array([mid]))[0] < budget:
            lo = mid
        else:
            hi = mid
    return lo


def smallest_below(bound, budget, lo):
    """Smallest m >= lo with bound(m) < budget (to 2^-64 of the bracket), bound decreasing."""
    hi = max(2.0 * lo, 1.0)
    while not bound(np.array([hi]))[0] < budget:
        hi *= 2.0
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        if bound(np.array([mid]))[0] < budget:
            hi = mid
        else:
            lo = mid
    return hi
