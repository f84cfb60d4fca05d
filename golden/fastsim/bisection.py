"""The light level where a tail bound crosses the error budget, found once per configuration.

Every bound a path relies on is monotone in the light, so each path test is one
comparison with such a level (:class:`tespike.golden.fastsim.plan.PathLevels`).
The search evaluates the bound at many points of the bracket in one array call
per step (the bounds are vectorised): 13 calls where bisection made 64, which
took about 40 ms of every simulation's start.
"""

from __future__ import annotations

import numpy as np

#: Points per step of the search: the bracket shrinks SPLIT-fold per bound call.
SPLIT = 32

#: The bracket's final width, as a fraction of its first (that of 64 halvings).
RESOLUTION = 2.0 ** -64


def largest_below(bound, budget, hi):
    """Largest m in [0, hi] (to 2^-64 of the bracket) with bound(m) < budget, bound increasing."""
    ok = _below(bound, budget)
    return _boundary(ok, 0.0, hi) if ok(np.zeros(1))[0] else -1.0


def smallest_below(bound, budget, lo):
    """Smallest m >= lo with bound(m) < budget (to 2^-64 of the bracket), bound decreasing."""
    ok = _below(bound, budget)
    hi = max(2.0 * lo, 1.0)
    while not ok(np.array([hi]))[0]:
        hi *= 2.0
    return _boundary(ok, hi, lo)


def _below(bound, budget):
    return lambda m: bound(m) < budget


def _boundary(ok, good, bad):
    """The point next to the boundary, on ``good``'s side, between ``good`` (ok holds) and
    ``bad`` (it fails): each step evaluates ``ok`` at SPLIT - 1 evenly spaced points of the
    bracket at once and keeps the two around its first failure (the result always holds),
    until the bracket is RESOLUTION of the first or float64 splits it no further."""
    width = abs(bad - good) * RESOLUTION
    steps = np.arange(1, SPLIT) / SPLIT
    while abs(bad - good) > width:
        points = good + (bad - good) * steps
        holds = ok(points)
        first_fail = int(np.argmin(holds)) if not holds.all() else points.size
        new_good = points[first_fail - 1] if first_fail else good
        new_bad = points[first_fail] if first_fail < points.size else bad
        if new_good == good and new_bad == bad:
            break
        good, bad = float(new_good), float(new_bad)
    return good
