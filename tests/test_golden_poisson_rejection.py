"""The vectorised PTRS Poisson sampler (golden.poisson_rejection) against numpy's scalar algorithm and the exact law."""

import math
import warnings

import numpy as np
import pytest

from tespike.golden import poisson_rejection
from tespike.golden.poisson_rejection import FACTORIAL_TABLE, PTRS_MAX, PTRS_MIN, log_factorial, poisson_draws


def _pmf(mean, k):
    return np.exp(-mean + k * math.log(mean) - np.array([math.lgamma(x + 1.0) for x in k]))


def _chi2_z(draws, mean):
    """Pearson's statistic against Poisson(mean) on bins of about a twentieth of a standard
    deviation (one value where that is less) expected at least 20 times, the rest pooled
    into one bin, as a z-score of its df (normal approximation)."""
    sd = math.sqrt(mean)
    width = max(1, int(sd / 20))
    k = np.arange(max(0, int(mean - 8 * sd)), int(mean + 8 * sd) + 20)
    k = k[:k.size - k.size % width]
    expected = _pmf(mean, k).reshape(-1, width).sum(axis=1) * draws.size
    starts = k[::width]
    keep = expected >= 20
    starts, expected = starts[keep], expected[keep]
    at = np.searchsorted(starts, draws, side="right") - 1
    inside = (at >= 0) & (draws < starts[np.maximum(at, 0)] + width)
    counts = np.bincount(at[inside], minlength=starts.size)
    rest_seen, rest_expected = draws.size - counts.sum(), draws.size - expected.sum()
    stat = ((counts - expected) ** 2 / expected).sum()
    df = starts.size - 1
    if rest_expected >= 20:
        stat += (rest_seen - rest_expected) ** 2 / rest_expected
        df += 1
    return (stat - df) / math.sqrt(2 * df)


@pytest.mark.parametrize("mean", [10.0, 10.5, 37.3, 350.7, 1234.5, 98765.4, 3.3e7])
def test_draws_have_the_poisson_law(mean):
    rng = np.random.Generator(np.random.SFC64(3))
    draws = poisson_draws(rng, np.full(400_000, mean))
    assert draws.dtype == np.int64
    sd = math.sqrt(mean)
    assert abs(draws.mean() - mean) < 5 * sd / math.sqrt(draws.size)
    assert abs(draws.var() / mean - 1) < 5 * math.sqrt(2 / draws.size)
    assert _chi2_z(draws, mean) < 5


def test_mixed_means_keep_their_places_and_laws():
    """Zeros draw nothing, means below PTRS_MIN and above PTRS_MAX go to numpy, the
    others to PTRS, each in its own place of an array of any shape."""
    rng = np.random.Generator(np.random.SFC64(4))
    means = np.array([0.0, 3.5, 25.0, 700.0, 2 * PTRS_MAX])
    lam = np.tile(means, (40_000, 1)).reshape(200, 200, 5)
    draws = poisson_draws(rng, lam)
    assert draws.shape == lam.shape
    per = draws.reshape(-1, 5)
    assert np.all(per[:, 0] == 0)
    for j, mean in enumerate(means[1:], 1):
        assert abs(per[:, j].mean() - mean) < 5 * math.sqrt(mean / per.shape[0]), j
        assert abs(per[:, j].var() / mean - 1) < 0.05, j


@pytest.mark.parametrize("size", [30_000, 5_000])        # PTRS draws, and numpy's (below PTRS_DRAWS)
def test_a_seed_gives_one_result_and_zeros_draw_nothing(size):
    """Same generator state, same draws; means of 0 among the others change none of theirs,
    nor which sampler draws them, however many zeros there are (the event path's mask relies
    on it: its masked frame holds zeros where the gathered pixels hold nothing)."""
    lam = np.linspace(PTRS_MIN, 5000.0, size)
    a = poisson_draws(np.random.default_rng(9), lam)
    b = poisson_draws(np.random.default_rng(9), lam)
    spread = np.zeros(4 * lam.size)
    spread[::4] = lam
    c = poisson_draws(np.random.default_rng(9), spread)
    assert np.array_equal(a, b) and np.array_equal(c[::4], a) and not c.reshape(-1, 4)[:, 1:].any()


def test_log_factorial_matches_lgamma_in_and_beyond_the_table():
    """Every entry of the table (lgamma below STIRLING_FROM, the series from it) and beyond it."""
    k = np.concatenate([np.arange(0, FACTORIAL_TABLE + 2), [1e5, 1e7, 3e9, 1e15]]).astype(np.float64)
    want = np.array([math.lgamma(x + 1.0) for x in k])
    got = log_factorial(k)
    assert np.all(np.abs(got - want) <= 4e-15 * np.maximum(np.abs(want), 1.0))


class _EdgeGenerator:
    """A generator whose first uniforms U (then V) of each round are chosen, then a real
    generator's: U = 0 (us = 0, the candidate -inf), U just below 1 (us = 2^-53, a candidate
    as large as the mean allows), V = 0 (log V = -inf: any candidate tested is accepted)."""

    def __init__(self, u, v):
        self.inner = np.random.default_rng(1)
        self.chosen = (u, v)
        self.calls = 0

    def random(self, out):
        self.inner.random(out=out)
        if self.calls < 2:
            values = self.chosen[self.calls]
            out[:len(values)] = values
        self.calls += 1
        return out

    def poisson(self, lam):
        return self.inner.poisson(lam)


def test_edge_uniforms_are_rejected_or_accepted_without_warnings():
    top = 1.0 - 2.0 ** -53
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        draws = poisson_draws(_EdgeGenerator((0.0, top, 0.5), (0.0, top, 0.5)), np.full(20000, 500.0))
        assert draws.min() >= 0 and abs(draws.mean() - 500) < 5 * math.sqrt(500 / 20000)
        # a candidate past int64 (us = 2^-53 at the largest mean) with V = 0: rejected, as numpy's
        # int64 conversion leaves it negative; at mean 500 it is within int64 and accepted, as by numpy
        huge = poisson_draws(_EdgeGenerator((top, top), (0.0, 0.0)), np.full(20000, PTRS_MAX))
        assert huge.min() >= 0 and huge.max() < 2 * PTRS_MAX
        within = poisson_draws(_EdgeGenerator((top,), (0.0,)), np.full(20000, 500.0))
    assert within[0] == _ptrs_attempt(500.0, top, 0.0) > 10 ** 15


def test_rejected_draws_start_again_until_none_is_open(monkeypatch):
    """With rounds kept to the end (no numpy finish) the law is unchanged."""
    monkeypatch.setattr(poisson_rejection, "ROUND_DRAWS", 1)
    rng = np.random.Generator(np.random.SFC64(5))
    draws = poisson_draws(rng, np.full(200_000, 61.7))
    assert _chi2_z(draws, 61.7) < 5


def _ptrs_attempt(lam, u, v):
    """One attempt of numpy's ``random_poisson_ptrs`` (Hoermann 1993) on uniforms (u, v),
    one draw at a time as its C code does: the candidate, or None where it is rejected."""
    slam, loglam = math.sqrt(lam), math.log(lam)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    vr = 0.9277 - 3.6224 / (b - 2)
    U = u - 0.5
    us = 0.5 - abs(U)
    if us == 0.0:
        return None
    k = math.floor((2 * a / us + b) * U + lam + 0.43)
    if k >= 2 ** 63:                       # (numpy's int64 conversion leaves it negative: rejected)
        return None
    if us >= 0.07 and v <= vr:
        return k
    if k < 0 or (us < 0.013 and v > us):
        return None
    if v == 0.0 or math.log(v) + math.log(invalpha) - math.log(a / (us * us) + b) <= -lam + k * loglam - math.lgamma(k + 1):
        return k
    return None


class _Recorder:
    """A generator that keeps every block of uniforms it gives."""

    def __init__(self, seed):
        self.inner, self.blocks = np.random.default_rng(seed), []

    def random(self, out):
        self.inner.random(out=out)
        self.blocks.append(out.copy())
        return out


def test_each_draw_is_numpys_ptrs_on_its_own_uniforms(monkeypatch):
    """Step for step: replaying the uniforms each round gave each open draw through the
    scalar algorithm (numpy's C code, one draw at a time) gives every draw, rejections
    and second rounds included."""
    monkeypatch.setattr(poisson_rejection, "ROUND_DRAWS", 1)
    lam = np.concatenate([np.linspace(PTRS_MIN, 60.0, 6000), np.linspace(300.0, 3e5, 6000)])
    rng = _Recorder(8)
    draws = poisson_draws(rng, lam)
    blocks, open_, rounds = iter(rng.blocks), np.arange(lam.size), 0
    while open_.size:
        u, v = next(blocks), next(blocks)
        got = [_ptrs_attempt(lam[i], u[j], v[j]) for j, i in enumerate(open_)]
        for j, i in enumerate(open_):
            if got[j] is not None:
                assert draws[i] == got[j], (i, lam[i])
        open_ = open_[[g is None for g in got]]
        rounds += 1
    assert next(blocks, None) is None and rounds >= 3


def test_a_small_call_is_numpys_own_draw():
    """Below PTRS_DRAWS means in PTRS's range a call's fixed cost exceeds what PTRS saves: its
    draws are numpy's, an int64 array whatever lam's shape; bad means are refused alike."""
    lam = np.linspace(0.0, 900.0, poisson_rejection.PTRS_DRAWS - 1)
    assert np.array_equal(poisson_draws(np.random.default_rng(3), lam), np.random.default_rng(3).poisson(lam))
    zero_d = poisson_draws(np.random.default_rng(3), np.float64(700.0))
    assert isinstance(zero_d, np.ndarray) and zero_d.shape == () and zero_d.dtype == np.int64
    for bad in (-1.0, np.nan):
        for size in (10, 3 * poisson_rejection.PTRS_DRAWS):
            lam = np.full(size, 500.0)
            lam[size // 2] = bad
            with pytest.raises(ValueError):
                poisson_draws(np.random.default_rng(3), lam)
