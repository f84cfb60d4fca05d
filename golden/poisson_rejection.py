"""Poisson draws of many different means at once: Hoermann's transformed rejection (PTRS), vectorised.

Why hand-written: numpy's ``Generator.poisson`` runs the same method one draw at
a time, about 30 ns a draw at means in the hundreds or thousands, most of it the
latency of the square root, logarithm and divisions each draw waits on (numpy
computes ``log(lam)`` even for the three quarters of draws the quick test
accepts). The fast simulator's event path draws one interval total per pixel,
each with its own mean, millions per scene; :mod:`tespike.golden.poisson`'s
tables need a mean shared by many draws. Here each step of the method is one
array pass over a block of draws (``BLOCK``), and the logarithms are taken only
for the draws the quick test leaves: about a fifth cheaper than numpy's on the event
path's means (``benchmarks/bench_poisson.py``).

The method: W. Hoermann, "The transformed rejection method for generating
Poisson random variables", Insurance: Mathematics and Economics 12 (1993), as
numpy's ``random_poisson_ptrs`` runs it, with its constants, hat, squeeze and
acceptance test (its three logarithms taken as one; ``log k!`` from
:func:`log_factorial`). Each candidate and its two uniforms are accepted or
rejected exactly as numpy's scalar code would (``tests/test_golden_poisson_rejection.py``
replays the uniforms through a transcription of it, and checks the draws
against the exact pmf). A rejected draw starts again with new uniforms, which
keeps its law whatever the order in which they are used, so a seed's draws
differ from numpy's, never their law; the last few open draws of a call go to
numpy's own sampler (a round of array passes would cost more than they do).
Means below ``PTRS_MIN`` (where the method does not hold) or above ``PTRS_MAX``
(where a candidate need not fit an int64), and the zeros of a masked path, go
to numpy's sampler.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

#: Smallest mean of the transformed rejection (Hoermann's method, and numpy's, holds from 10).
PTRS_MIN = 10.0

#: PTRS draws (means in [PTRS_MIN, PTRS_MAX]) of a call below which numpy's sampler takes the whole
#: call: a call's fixed cost (about 40 array operations, 30-55 us) is won back by the 6-8 ns it
#: saves a draw only past a few thousand draws (measured crossover 4096 to 16384 on means 300-3000,
#: ``benchmarks/bench_poisson.py`` case (c)). Counted on those means alone, so that zeros (a masked
#: path's other pixels) never change which sampler draws.
PTRS_DRAWS = 8192

#: Largest mean drawn here (float64 holds its candidates' integers exactly; a candidate past int64,
#: possible where ``us`` is within about ``a / 2^63`` of 0, is rejected as numpy's conversion
#: rejects it). Above it numpy's sampler, whose acceptance test rounds as this one does.
PTRS_MAX = float(1 << 40)

#: Candidates at or past this are rejected: numpy converts a candidate to int64 before its tests,
#: and one past int64 comes out negative there (x86), so rejected.
_CANDIDATE_LIMIT = 2.0 ** 63

#: Draws per block of array passes (five float64 arrays of 1 MiB: fewer, larger passes
#: measured faster here than blocks that stay in a core's cache).
BLOCK = 1 << 17

#: Open draws below which a round of array passes costs more than numpy's sampler on them.
ROUND_DRAWS = 4096

#: ``log k!`` is looked up below this k (and computed from Stirling's series above it).
FACTORIAL_TABLE = 1 << 14

#: Coefficients of Stirling's series for ``log Gamma(x)`` (numpy's ``random_loggam``).
_STIRLING = (8.333333333333333e-02, -2.777777777777778e-03, 7.936507936507937e-04,
             -5.952380952380952e-04, 8.417508417508418e-04, -1.917526917526918e-03,
             6.410256410256410e-03, -2.955065359477124e-02, 1.796443723688307e-01,
             -1.39243221690590e+00)


#: ``log k!`` is taken from ``math.lgamma`` below this k and from Stirling's series from it (within
#: 5e-16 relative of lgamma there: ``tests/test_golden_poisson_rejection.py``).
STIRLING_FROM = 16


@lru_cache(maxsize=1)
def _factorial_table() -> np.ndarray:
    """``log k!`` for k below FACTORIAL_TABLE: ``math.lgamma`` below STIRLING_FROM, the series above,
    as one array pass (0.3 ms where 16,384 lgamma calls took 3 ms of each process's first readout)."""
    table = np.empty(FACTORIAL_TABLE)
    table[:STIRLING_FROM] = [math.lgamma(k + 1.0) for k in range(STIRLING_FROM)]
    table[STIRLING_FROM:] = _stirling(np.arange(STIRLING_FROM, FACTORIAL_TABLE, dtype=np.float64))
    return table


def _stirling(k: np.ndarray) -> np.ndarray:
    """``log k!`` of float64 integers ``k >= STIRLING_FROM`` by Stirling's series with numpy's ten
    coefficients (``random_loggam``)."""
    x = k + 1.0
    inv2 = 1.0 / (x * x)
    series = np.full(x.shape, _STIRLING[-1])
    for c in _STIRLING[-2::-1]:
        series = series * inv2 + c
    return series / x + 0.5 * math.log(2 * math.pi) + (x - 0.5) * np.log(x) - x


def log_factorial(k: np.ndarray) -> np.ndarray:
    """``log k!`` of float64 integers ``k >= 0``: a table below FACTORIAL_TABLE, Stirling's
    series above (relative error near 1e-16 in both)."""
    table = _factorial_table()
    out = table[np.minimum(k, FACTORIAL_TABLE - 1).astype(np.int64)]
    far = np.flatnonzero(k >= FACTORIAL_TABLE)
    if far.size:
        out[far] = _stirling(k[far])
    return out


def poisson_draws(rng: np.random.Generator, lam: np.ndarray) -> np.ndarray:
    """Independent Poisson(``lam[j]``) draws (an int64 array of lam's shape) from ``rng``: PTRS
    for means in [PTRS_MIN, PTRS_MAX], ``rng.poisson`` for the others (a mean of 0 draws
    nothing, so the draws of the other means do not depend on zeros among them), and for a call
    with fewer than PTRS_DRAWS means in that range. A negative or NaN mean is refused as numpy
    refuses it (``ValueError``)."""
    lam = np.asarray(lam, np.float64)
    flat = lam.reshape(-1)
    big = (flat >= PTRS_MIN) & (flat <= PTRS_MAX)
    count = int(np.count_nonzero(big))
    if count < PTRS_DRAWS:
        return np.asarray(rng.poisson(lam), np.int64)
    if not flat.min() >= 0:                             # (NaN fails too)
        raise ValueError("lam < 0 or lam contains NaNs")
    out = np.zeros(flat.shape, np.int64)
    if count == flat.size:
        _ptrs(rng, flat, out)
        return out.reshape(lam.shape)
    at = np.flatnonzero(big)
    if at.size:
        out[at] = _ptrs(rng, flat[at], np.empty(at.size, np.int64))
    small = np.flatnonzero(~big & (flat > 0))
    if small.size:
        out[small] = rng.poisson(flat[small])
    return out.reshape(lam.shape)


def _ptrs(rng, lam, out):
    """PTRS draws of means ``lam`` (all in [PTRS_MIN, PTRS_MAX]) into ``out``: rounds of
    one candidate per draw still open (about 12 % are rejected in a round) while at least
    ROUND_DRAWS are; the last few by ``rng.poisson`` (a rejected draw starts afresh, so
    any exact sampler may finish it: a round's fixed cost would exceed their draws')."""
    open_ = _round(rng, lam, out)
    while open_.size >= ROUND_DRAWS:
        again = np.empty(open_.size, np.int64)
        still = _round(rng, lam[open_], again)
        done = np.ones(open_.size, bool)
        done[still] = False
        out[open_[done]] = again[done]
        open_ = open_[still]
    if open_.size:
        out[open_] = rng.poisson(lam[open_])
    return out


def _round(rng, lam, out):
    """One PTRS candidate per mean: writes the accepted ones into ``out``; returns the
    indices of the rejected (their ``out`` entries are to be drawn again)."""
    n = lam.size
    width = min(n, BLOCK)
    buffers = np.empty((5, width))
    quick = np.empty(width, bool)
    wide = np.empty(width, bool)
    left = []
    with np.errstate(divide="ignore", invalid="ignore"):   # us = 0 (U = -0.5): k = -inf, rejected
        for start in range(0, n, BLOCK):
            stop = min(n, start + BLOCK)
            m = stop - start
            mean = lam[start:stop]
            b, t, u, v, us = (row[:m] for row in buffers)
            ok, far = quick[:m], wide[:m]
            np.sqrt(mean, out=b)
            b *= 2.53
            b += 0.931                                     # b = 0.931 + 2.53 sqrt(lam)
            rng.random(out=u)
            u -= 0.5                                       # U
            rng.random(out=v)                              # V
            np.abs(u, out=us)
            np.subtract(0.5, us, out=us)                   # us = 0.5 - |U|
            np.subtract(b, 2.0, out=t)
            np.divide(3.6224, t, out=t)
            np.subtract(0.9277, t, out=t)                  # vr = 0.9277 - 3.6224 / (b - 2)
            np.less_equal(v, t, out=ok)
            np.greater_equal(us, 0.07, out=far)
            ok &= far                                      # the quick acceptance
            np.multiply(b, 0.02483, out=t)
            t -= 0.059                                     # a = -0.059 + 0.02483 b
            t *= 2.0
            t /= us
            t += b
            t *= u
            t += mean
            t += 0.43
            np.floor(t, out=t)                             # k = floor((2 a / us + b) U + lam + 0.43)
            out[start:stop] = t                            # (the rejected are written again)
            np.logical_not(ok, out=ok)
            slow = np.flatnonzero(ok)
            if slow.size:
                left.append((slow + start, t[slow], us[slow], v[slow], b[slow]))
        if not left:
            return np.zeros(0, np.int64)
        at, k, us, v, b = (np.concatenate(parts) for parts in zip(*left))
        tested = np.flatnonzero((k >= 0) & (k < _CANDIDATE_LIMIT) & ((us >= 0.013) | (v <= us)))
        k_t, us_t, b_t, mean = k[tested], us[tested], b[tested], lam[at[tested]]
        a = b_t * 0.02483
        a -= 0.059
        inv_alpha = 1.1328 / (b_t - 3.4)
        inv_alpha += 1.1239
        # log V + log(1 / alpha) - log(a / us^2 + b), its three logarithms taken as one
        us_t *= us_t
        np.divide(a, us_t, out=a)
        a += b_t
        hat = v[tested] * inv_alpha
        hat /= a
        accept = np.log(hat) <= k_t * np.log(mean) - mean - log_factorial(k_t)
    won = tested[accept]
    out[at[won]] = k[won]
    rejected = np.ones(at.size, bool)
    rejected[won] = False
    return at[rejected]

