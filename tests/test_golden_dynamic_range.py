import math
import re

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.dynamic_range import constant_light_words, formula_db, light_grid, measure
from tespike.golden.errors import InputError
from tespike.golden.reference import step_reference


def test_formula_paper_settings():
    te, ml = SensorConfig(), SensorConfig(mode="ml")
    assert formula_db(te, 1) == pytest.approx(20 * math.log10(240))
    assert formula_db(ml, 1) == pytest.approx(20 * math.log10(255))
    assert formula_db(te, 100) - formula_db(te, 1) == pytest.approx(40)
    # alpha below 2^b2 - 1: the configured alpha bounds the code, the paper's formula does not see it
    small = SensorConfig(alpha=5)
    assert formula_db(small, 1) == pytest.approx(20 * math.log10(16 * 5))
    assert formula_db(small, 1, paper_alpha=True) == pytest.approx(20 * math.log10(16 * 15))
    with pytest.raises(InputError):
        formula_db(te, 0)


def test_formula_msb_readout():
    """Eq. 10: 20 log10(2^(B-1) N_s); one bit gives the classic 1-bit camera's 20 log10(N_s)."""
    msb = SensorConfig.preset("ml-msb")
    assert formula_db(msb, 1) == pytest.approx(20 * math.log10(128))
    assert formula_db(msb, 16) == pytest.approx(20 * math.log10(128 * 16))
    assert formula_db(SensorConfig(mode="ml", ml_readout="msb", ml_bits=16), 1) == pytest.approx(20 * math.log10(2 ** 15))
    assert formula_db(SensorConfig(mode="ml", ml_readout="msb", ml_bits=1), 100) == pytest.approx(40)
    assert formula_db(SensorConfig(mode="ml", ml_bits=1), 100) == pytest.approx(40)


def test_constant_light_words_are_the_engine_on_that_stimulus():
    c = SensorConfig(b1=2, b2=2, threshold=50)
    light = np.array([0.0, 0.01, 0.3, 5.0])
    words = constant_light_words(c, light, 7, chunk_readouts=3)
    L = c.clocks_per_readout
    t = np.arange(7 * L)[:, None]
    lam = 42000 * light / L
    stim = np.minimum(np.floor((t + 1) * lam) - np.floor(t * lam), c.input_max).astype(np.int64)
    assert np.array_equal(words, step_reference(c, stim[:, None, :])[0][:, 0, :])
    noisy = constant_light_words(c, light, 7, seed=5)
    assert np.array_equal(noisy, constant_light_words(c, light, 7, seed=5)) and noisy.shape == (7, 4)


def test_measured_range_ml_noise_free():
    """ML 8-bit: passes from the counting limit up to the one-spike-per-clock / 8-bit saturation."""
    c = SensorConfig(mode="ml")
    light = light_grid(1e-4, 1e2, 10)
    r = measure(c, 8, windows=4, light=light)
    # 5 % needs about 20 spikes per window of 8 readouts: r >= 2.5 spikes -> I >= 2.5 * 328 / 42000
    assert 0.5 * 2.5 * 328 / 42000 <= r.low <= 2 * 2.5 * 328 / 42000
    # the count saturates at L = 240 spikes = 240 * 328 / 42000 = 1.87
    assert 1.0 <= r.high <= 1.87
    assert r.passing.sum() >= (np.log10(r.high / r.low) * 10)
    looser = measure(c, 8, windows=4, light=light, tolerance=0.2)
    assert looser.db >= r.db


def test_measure_refuses_words_of_the_wrong_shape():
    with pytest.raises(InputError, match="shape"):
        measure(SensorConfig(), 4, windows=2, light=np.array([0.1, 1.0]), words=np.zeros((5, 2), np.int64))


@pytest.mark.parametrize("call, refusal", [
    (lambda: measure(SensorConfig(), 0), r"^n_s = 0: must be an integer >= 1$"),
    (lambda: measure(SensorConfig(), 2.5), r"^n_s = 2.5: must be an integer >= 1$"),
    (lambda: measure(SensorConfig(), 4, windows=-1), r"^windows = -1: must be an integer >= 1$"),
    (lambda: measure(SensorConfig(), 4, tolerance=float("nan")), r"^tolerance = nan: must be a finite number > 0$"),
    (lambda: measure(SensorConfig(), 4, fraction=1.5), r"^fraction = 1.5: must be a number in \(0, 1\]"),
    (lambda: measure(SensorConfig(), 4, light=np.array([0.0, 1.0])), r"^light: every value must be finite and > 0"),
    (lambda: formula_db(SensorConfig(), float("nan")), r"^N_s = nan: must be a finite number > 0$"),
    (lambda: formula_db(SensorConfig(), 0), r"^N_s = 0: must be a finite number > 0$"),
    (lambda: constant_light_words(SensorConfig(), np.array([np.nan]), 2), r"^light: every value must be finite and >= 0"),
    (lambda: constant_light_words(SensorConfig(), np.array([-1.0]), 2), r"^light: every value must be finite and >= 0"),
    (lambda: constant_light_words(SensorConfig(), np.ones((2, 2)), 2), r"^light shape \(2, 2\): must be one light per pixel"),
    (lambda: constant_light_words(SensorConfig(), np.ones(2), 0), r"^readouts = 0: must be an integer >= 1$"),
    (lambda: constant_light_words(SensorConfig(), np.ones(2), 2, seed="x"), r"^seed 'x': must be an integer >= 0 \(or a list of them\)"),
])
def test_bad_arguments_are_refused_naming_them(call, refusal):
    """(n_s = 0 had been numpy's 'need at least one array to concatenate', N_s = NaN a NaN range,
    a NaN light 'stimulus value -9223372036854775808 is negative'.)"""
    with pytest.raises(InputError, match=refusal):
        call()


def test_measured_range_msb_noise_free():
    """ML msb 8-bit: the dark end of the count readout (the remainder carries what
    a readout leaves, so nothing is lost over a run), the bright end at a count of
    2^(B-1) = 128 per readout, the design light I = 1 (6 dB below the count's
    one-spike-per-clock limit), and windows of N_s readouts less exact than the
    count's: a window's total is off by the remainder it leaves, up to half a
    readout's count."""
    msb, count = SensorConfig.preset("ml-msb"), SensorConfig(mode="ml")
    light = light_grid(1e-4, 1e2, 10)
    r = measure(msb, 8, windows=4, light=light, tolerance=0.2)
    c = measure(count, 8, windows=4, light=light, tolerance=0.2)
    assert r.low == c.low and r.high == 1.0 and c.high > 1.9
    assert r.db == pytest.approx(c.db - 6.0)
    # above the top, every word is 8: the decoded light is stuck at 128 spikes per readout
    bright = light > 1.3
    assert np.allclose(r.mean_decoded[bright], 128 * 328 / 42000)
    # over the 32 scored readouts the remainder left at the end is all that is missing
    mid = (light > 0.05) & (light <= 1.0)
    assert np.all(np.abs(r.mean_decoded[mid] / light[mid] - 1) < 0.04)
    # at 5 % the msb windows fail where the count's pass
    strict = measure(msb, 8, windows=4, light=light, words=constant_light_words(msb, light, 40))
    assert strict.db < measure(count, 8, windows=4, light=light).db


@pytest.mark.parametrize("args, words", [
    ((0, 1), "light grid low 0: must be a finite number > 0"),
    ((-1, 10), "light grid low -1: must be a finite number > 0"),
    ((1, float("inf")), "light grid high inf: must be a finite number > 0"),
    (("a", 100), "light grid low 'a': must be a finite number > 0"),
    ((10, 1), "light grid low 10 must be below its high 1"),
    ((1, 10, 2.5), "light grid per_decade 2.5: must be an integer >= 1"),
    ((1, 10, 0), "light grid per_decade 0: must be an integer >= 1"),
], ids=["zero-low", "negative-low", "infinite-high", "text-low", "reversed", "fractional-decade", "no-decade"])
def test_light_grid_refuses_what_is_no_range_in_one_line(args, words):
    """0 was a ZeroDivisionError, -1 math's domain error, a reversed range numpy's "negative samples",
    and 2.5 points a decade were taken as 2 silently."""
    from tespike.golden.dynamic_range import light_grid
    from tespike.golden.errors import InputError
    with pytest.raises(InputError, match="^" + re.escape(words) + "$"):
        light_grid(*args)


def test_light_past_numpys_poisson_limit_is_saturated_and_leaves_the_other_pixels_draws_alone():
    """1e30 x the design light was numpy's "lam value too large" in constant_light_words and
    constant_light_toggles; it is surely saturated, and draws no random number, so a pixel beside it
    gets the words it gets alone."""
    from tespike.golden.toggles import constant_light_toggles
    config = SensorConfig()
    for run in (lambda light: constant_light_words(config, light, 3, seed=1),
                lambda light: constant_light_toggles(config, light, 3, seed=1).words):
        both, alone, saturated = run(np.array([1e30, 0.5])), run(np.array([0.5])), run(np.array([1e3]))
        assert np.array_equal(both[:, 1], alone[:, 0])
        assert np.array_equal(both[:, 0], saturated[:, 0])
