import math
import warnings

import numpy as np
import pytest

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.light import (LIGHT_CAP, dark_electrons, deterministic_clock_electrons, log_budget,
                                  log_poisson_tail_above, log_poisson_tail_below, stimulus_dtype)
from tespike.golden.stimulus import poisson_stimulus
from tespike.golden.io import check_stimulus
from tests.configs import EDGE_CONFIGS


def _log_poisson_cdf(m, k):
    """Exact log P(X <= k), X ~ Poisson(m), by summing the pmf in log space."""
    terms = [-m + j * math.log(m) - math.lgamma(j + 1) for j in range(k + 1)]
    top = max(terms)
    return top + math.log(sum(math.exp(t - top) for t in terms))


def _log_poisson_sf(m, k):
    """Exact log P(X >= k) by summing the pmf from k up to far in the tail."""
    terms = [-m + j * math.log(m) - math.lgamma(j + 1) for j in range(k, k + 4000)]
    top = max(terms)
    return top + math.log(sum(math.exp(t - top) for t in terms))


@pytest.mark.parametrize("m, k", [(1.0, 5), (60.0, 176), (150.0, 176), (174.0, 176), (0.01, 1)])
def test_upper_tail_bound_holds(m, k):
    bound = float(log_poisson_tail_above(np.array([m]), k)[0])
    assert bound >= _log_poisson_sf(m, k) - 1e-9
    assert bound < 0


@pytest.mark.parametrize("m, k", [(400.0, 174), (200.0, 174), (70000.0, 65534), (5.0, 0), (180.0, 174)])
def test_lower_tail_bound_holds_and_is_tight(m, k):
    bound = float(log_poisson_tail_below(np.array([m]), k)[0])
    exact = _log_poisson_cdf(m, k)
    assert exact - 1e-9 <= bound <= exact + math.log(1 / (1 - k / m)) + 1e-9


def test_tail_bounds_edge_values():
    assert log_poisson_tail_above(np.array([0.0]), 3)[0] == -np.inf      # no light: never
    assert log_poisson_tail_above(np.array([5.0]), 3)[0] == 0.0          # no information
    assert log_poisson_tail_below(np.array([5.0]), -1)[0] == -np.inf
    assert log_poisson_tail_below(np.array([3.0]), 3)[0] == 0.0
    assert log_budget(10 ** 6, 240) < -64 * math.log(2)


def test_stimulus_is_poisson_per_clock(rng):
    config = SensorConfig()                     # L = 240
    L = config.clocks_per_readout
    light = np.array([0.01, 0.3, 1.0])
    scene = np.broadcast_to(light[None, :, None], (2, 3, 4000)).copy()
    stim = poisson_stimulus(config, scene, rng)
    assert stim.shape == (2 * L, 3, 4000) and stim.dtype == np.uint16
    check_stimulus(stim, config)
    for i, level in enumerate(light):
        lam = DESIGN_ELECTRONS * level / L
        per_clock = stim[:, i].astype(np.float64)
        n = per_clock.size
        assert abs(per_clock.mean() - lam) < 5 * math.sqrt(lam / n)
        assert abs(per_clock.var() / lam - 1) < 0.02
        # clocks of one interval are independent: the interval total has variance mu
        totals = per_clock.reshape(2, L, -1).sum(axis=1)
        assert abs(totals.var() / (lam * L) - 1) < 0.06


def test_stimulus_saturates_at_input_max(rng):
    config = SensorConfig(b1=2, b2=2, input_bits=4)       # inputs up to 15 per clock
    lam = 12.0
    scene = np.full((3, 50, 50), lam * config.clocks_per_readout / DESIGN_ELECTRONS)
    stim = poisson_stimulus(config, scene, rng)
    assert stim.max() == 15 and stim.dtype == np.uint8
    # the saturated value carries the whole tail P(X >= 15)
    expected = sum(math.exp(-lam + j * math.log(lam) - math.lgamma(j + 1)) for j in range(15, 200))
    assert abs((stim == 15).mean() - expected) < 5 * math.sqrt(expected / stim.size)


@pytest.mark.parametrize("config", EDGE_CONFIGS, ids=str)
def test_extreme_light_gives_legal_stimulus_without_warnings(config, rng):
    scene = np.zeros((2, 2, 6))
    scene[:, 0] = [0, 1e-7, 1, 1e3, 1e30, 1e308]
    scene[:, 1] = np.logspace(-12, 0, 6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stim = poisson_stimulus(config, scene, rng)
    check_stimulus(stim, config)
    assert stim.dtype == stimulus_dtype(config)
    L = config.clocks_per_readout
    assert not stim[:, 0, 0].any()                                    # no light, no electron
    assert (stim[:, 0, 4] == config.input_max).all()                  # 1e30: saturated
    assert (stim[:, 0, 5] == config.input_max).all()
    assert stim.shape == (2 * L, 2, 6)


def test_noise_free_stimulus_delivers_the_expected_charge():
    config = SensorConfig(b1=2, b2=2)                     # L = 12
    L = config.clocks_per_readout
    light = np.array([1e-4, 0.013, 0.5, 2.0])
    scene = np.broadcast_to(light[None, None, :], (7, 1, 4)).copy()
    stim = poisson_stimulus(config, scene, noise=False)
    assert np.array_equal(stim, poisson_stimulus(config, scene, noise=False))
    total = stim.astype(np.int64).sum(axis=0)[0]
    expected = 7 * light * DESIGN_ELECTRONS
    assert np.all(np.abs(total - expected) < 1 + 1e-9)                # carried fraction
    # spread evenly: clock counts within one of each other inside an interval
    per_clock = stim[:L].astype(np.int64)[:, 0]
    assert np.all(per_clock.max(axis=0) - per_clock.min(axis=0) <= 1)


def test_noise_free_fraction_carry_across_intervals():
    config = SensorConfig()
    e, fraction = deterministic_clock_electrons(config, np.array([0.5, 2.25]), np.zeros(2))
    assert e.sum(axis=1).tolist() == [0, 2] and np.allclose(fraction, [0.5, 0.25])
    e, fraction = deterministic_clock_electrons(config, np.array([0.5, 2.25]), fraction)
    assert e.sum(axis=1).tolist() == [1, 2] and np.allclose(fraction, [0.0, 0.5])


def test_seeds_reproduce_and_differ():
    config = SensorConfig(b1=2, b2=2)
    scene = np.full((2, 4, 4), 0.3)
    a = poisson_stimulus(config, scene, 7)
    assert np.array_equal(a, poisson_stimulus(config, scene, np.random.default_rng(7)))
    assert not np.array_equal(a, poisson_stimulus(config, scene, 8))


@pytest.mark.parametrize("bad, words", [
    (np.full((1, 2, 2), -0.5), ["negative", "-0.5"]),
    (np.full((1, 2, 2), np.nan), ["non-finite", "nan"]),
    (np.full((1, 2, 2), np.inf), ["non-finite", "inf"]),
    (np.zeros((2, 2)), ["shape"]),
    (np.zeros((1, 2, 2), bool), ["dtype"]),
])
def test_refuses_bad_light(bad, words):
    with pytest.raises(InputError) as info:
        poisson_stimulus(SensorConfig(), bad, 0)
    for word in words:
        assert word in str(info.value)


def test_dark_current_models(rng):
    eq12 = dark_electrons("eq12", (200000,), rng)
    assert eq12.dtype == np.int64 and eq12.min() >= 0
    assert abs(eq12.mean() - 400) < 0.5 and abs(eq12.std() - 50) < 0.5
    eq13 = dark_electrons("eq13", (200000,), rng)
    assert eq13.min() == 0 and eq13.max() == 15000                    # both clip ends reached
    x = rng.normal(140.0, 50.0, 200000)
    expected = np.rint(np.clip(np.where(x > 0, 60000 / np.where(x > 0, x, 1), 0), 0, 15000))
    assert abs(np.median(eq13) - np.median(expected)) <= 3
    assert abs((eq13 == 0).mean() - (x <= 0).mean()) < 0.002
    assert not dark_electrons(None, (5,), rng).any()
    with pytest.raises(InputError, match="eq14"):
        dark_electrons("eq14", (5,), rng)


def test_dark_current_spreads_over_clocks(rng):
    config = SensorConfig(b1=2, b2=2)                     # L = 12, default threshold
    L = config.clocks_per_readout
    stim = poisson_stimulus(config, np.zeros((3, 100, 100)), rng, dark_current="eq12")
    per_interval = stim.astype(np.int64).reshape(3, L, 100, 100).sum(axis=1)
    assert abs(per_interval.mean() - 400) < 1.5
    # uniform over the clocks of an interval
    per_clock = stim.astype(np.float64).reshape(3, L, -1).mean(axis=(0, 2))
    assert np.all(np.abs(per_clock - 400 / L) < 0.5)
    with pytest.raises(InputError, match="noise"):
        poisson_stimulus(config, np.zeros((1, 1, 1)), rng, dark_current="eq12", noise=False)


def test_light_cap_is_far_above_any_saturation():
    # a clock's mean at the cap dwarfs the largest input word and the longest L
    assert LIGHT_CAP * DESIGN_ELECTRONS / (1 << 24) > 1e100 * (1 << 32)


def test_electrons_per_readout_of_a_strided_float32_view():
    """A stripe's rows (a strided float32 view) convert as the float64 values would, capped,
    into a new contiguous array of the view's shape; the input is left alone."""
    from tespike.golden.light import electrons_per_readout
    frame = np.random.default_rng(4).random((8, 6)).astype(np.float32) * 3
    frame[0, 0] = np.float32(3e38)
    rows = frame[1::2]
    kept = frame.copy()
    got = electrons_per_readout(rows)
    want = np.minimum(rows.astype(np.float64), LIGHT_CAP) * 42000.0
    assert got.dtype == np.float64 and got.flags.c_contiguous and np.array_equal(got, want)
    assert np.array_equal(electrons_per_readout(np.array([1e300, 0.5])), [LIGHT_CAP * 42000.0, 21000.0])
    assert np.array_equal(frame, kept)
