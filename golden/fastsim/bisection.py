"""The light level where a tail bound crosses the error budget, found once by bisection.

Every bound a path relies on is monotone in the light, so each path test is one
comparison with such a level (:class:`tespike.golden.fastsim.plan.PathLevels`).
"""

from __future__ import annotations

import numpy as np


def largest_below(bound, budget, hi):
    """Largest m in [0, hi] (to 2^-64 of the bracket) with bound(m) < budget, bound increasing."""
    ok = _below(bound, budget)
    return _boundary(ok, 0.0, hi) if ok(0.0) else -1.0


def smallest_below(bound, budget, lo):
    """Smallest m >= lo with bound(m) < budget (to 2^-64 of the bracket), bound decreasing."""
    ok = _below(bound, budget)
    hi = max(2.0 * lo, 1.0)
    while not ok(hi):
        hi *= 2.0
    return _boundary(ok, hi, lo)


def _below(bound, budget):
    return lambda m: bound(np.array([m]))[0] < budget


def _boundary(ok, good, bad):
    """The point next to the boundary, on ``good``'s side, between ``good`` (ok holds) and
    ``bad`` (it fails): 64 halvings of the bracket."""
    for _ in range(64):
        mid = 0.5 * (good + bad)
        if ok(mid):
            good = mid
        else:
            bad = mid
    return good
