"""Dynamic range of a TE or ML configuration: the paper's formula and a measurement.

Formula (SPEC section 5, paper section 4.3), with N_s the longest accepted
spike interval in readouts: the darkest representable light is one spike in
N_s readouts, the brightest is the top code, 2^b1 * alpha spikes per readout
(TE, overflow in the first S_h cycle), 2^B - 1 (ML count) or 2^(B - 1) (ML
msb, eq. 10: its top word B decodes to 2^(B - 1), and a steady count above it
only fills the counter's remainder until it saturates). The paper writes
alpha = 2^b2 - 1 (its only setting); SPEC also allows a smaller alpha.

Measurement: constant light on a log grid is run through the cycle-exact
engine (:mod:`tespike.golden.sensor`) and decoded (:mod:`tespike.golden.decode`); a light
passes when the mean decoded light over a window of N_s readouts is within a
relative tolerance of the truth in at least a given fraction of the windows.
The measured range is the longest run of passing grid lights.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .config import DESIGN_ELECTRONS, SensorConfig
from .decode import decode_light
from .errors import InputError, check_counts, is_count, is_positive_number
from .light import check_seed, checked_light_levels, saturated_poisson
from .sensor import PixelArrayModel


def formula_db(config: SensorConfig, n_s: float = 1, *, paper_alpha: bool = False) -> float:
    """20 log10(top code * N_s) in dB: TE top = 2^b1 * alpha, ML count top = 2^B - 1,
    ML msb top = 2^(B - 1) (SPEC section 5).

    ``paper_alpha=True`` gives the paper's D_TE = 20 log10(2^b1 (2^b2 - 1) N_s)
    whatever alpha is configured; by default the configured alpha is used
    (the two agree for the default alpha = 2^b2 - 1).
    """
    config = SensorConfig.required(config, "formula_db")
    _check_positive(n_s, "N_s")
    if config.is_te:
        alpha = (1 << config.b2) - 1 if paper_alpha else config.alpha
        top = config.p_max * alpha
    elif config.is_msb:
        top = 1 << (config.ml_bits - 1)
    else:
        top = config.ml_max
    return 20 * math.log10(top * n_s)


def _check_positive(value, name: str) -> None:
    """Refuse ``value`` unless a finite number > 0 (never a bool), naming it."""
    if not is_positive_number(value):
        raise InputError(f"{name} = {value!r}: must be a finite number > 0")


def light_grid(low: float = 1e-6, high: float = 1e3, per_decade: int = 20) -> np.ndarray:
    """Log-spaced light levels (1.0 = design light, 42000 electrons per readout), ``per_decade`` a
    decade from ``low`` to ``high``; refused in one line where they are no such range (0 had been a
    ZeroDivisionError, a low above the high numpy's "negative samples", 2.5 a decade taken as 2)."""
    for name, value in (("low", low), ("high", high)):
        if not is_positive_number(value):
            raise InputError(f"light grid {name} {value!r}: must be a finite number > 0")
    if not low < high:
        raise InputError(f"light grid low {low!r} must be below its high {high!r}")
    if not is_count(per_decade, 1):
        raise InputError(f"light grid per_decade {per_decade!r}: must be an integer >= 1")
    decades = math.log10(high / low)
    return np.logspace(math.log10(low), math.log10(high), int(round(decades * per_decade)) + 1)


def constant_light_words(config: SensorConfig, light: np.ndarray, readouts: int, *,
                         seed: int | None = None, chunk_readouts: int = 16) -> np.ndarray:
    """Words (readouts, n) for n pixels under constant ``light`` (n,), from a zero start.

    ``seed=None``: noise-free electrons, spread as evenly as integers allow
    (clock t gets floor((t + 1) lam) - floor(t lam), lam = 42000 I / L per clock).
    Otherwise independent Poisson(lam) electrons per clock (SPEC section 6).
    Either way a clock carries at most 2^E - 1 electrons (the input saturates).
    """
    config = SensorConfig.required(config, "constant_light_words")
    light = checked_light_levels(light)
    check_counts(readouts=readouts, chunk_readouts=chunk_readouts)
    check_seed(seed)
    L = config.clocks_per_readout
    lam = DESIGN_ELECTRONS * light / L
    rng = None if seed is None else np.random.default_rng(seed)
    array = PixelArrayModel(config, (1, light.size))
    words = []
    for start in range(0, readouts, chunk_readouts):
        k = min(chunk_readouts, readouts - start)
        t = np.arange(start * L, (start + k) * L, dtype=np.float64)[:, None]
        if rng is None:
            electrons = np.floor((t + 1) * lam) - np.floor(t * lam)
        else:
            electrons = saturated_poisson(rng, lam, (k * L, light.size), config.input_max)
        electrons = np.minimum(electrons, config.input_max).astype(np.int64)
        words.append(array.feed(electrons[:, None, :])[:, 0, :])
    return np.concatenate(words)


@dataclasses.dataclass
class MeasuredRange:
    """Result of :func:`measure`: the passing light run and its width in dB."""

    low: float                 # darkest passing light (design-light units)
    high: float                # brightest passing light
    db: float                  # 20 log10(high / low)
    light: np.ndarray          # the grid
    passing: np.ndarray        # bool per grid light
    mean_decoded: np.ndarray   # mean decoded light over all scored readouts, per grid light


def measure(config: SensorConfig, n_s: int = 16, *, seed: int | None = None, estimator: str = "ratio",
            tolerance: float = 0.05, windows: int = 20, fraction: float = 0.9,
            light: np.ndarray | None = None, words: np.ndarray | None = None) -> MeasuredRange:
    """Measured dynamic range under constant light (rule in the module docstring).

    One warm-up window of N_s readouts is dropped (the accumulator starts
    empty), then ``windows`` windows are scored. ``words`` may be given (from
    :func:`constant_light_words` with ``n_s * (windows + 1)`` readouts) to
    score one simulation under several estimators or tolerances.
    """
    config = SensorConfig.required(config, "measure")
    check_counts(n_s=n_s, windows=windows)
    _check_positive(tolerance, "tolerance")
    if not (is_positive_number(fraction) and fraction <= 1):
        raise InputError(f"fraction = {fraction!r}: must be a number in (0, 1] (of the windows within tolerance)")
    light = light_grid() if light is None else checked_light_levels(light, positive=True)
    if words is None:
        words = constant_light_words(config, light, n_s * (windows + 1), seed=seed)
    words = np.asarray(words)
    if words.shape != (n_s * (windows + 1), light.size):
        raise InputError(f"words shape {words.shape} != ({n_s * (windows + 1)}, {light.size}): "
                         "(n_s x (windows + 1) readouts, one column a light)")
    decoded = decode_light(words[n_s:], config, estimator)
    window_means = decoded.reshape(windows, n_s, light.size).mean(axis=1)
    within = np.abs(window_means - light) <= tolerance * light
    passing = within.mean(axis=0) >= fraction
    best, run = (0, -1), None
    for i, ok in enumerate(np.append(passing, False)):
        if ok and run is None:
            run = i
        elif not ok and run is not None:
            if i - 1 - run > best[1] - best[0]:
                best = (run, i - 1)
            run = None
    if best[1] < 0:
        return MeasuredRange(math.nan, math.nan, 0.0, light, passing, decoded.mean(axis=0))
    low, high = light[best[0]], light[best[1]]
    return MeasuredRange(float(low), float(high), 20 * math.log10(high / low), light, passing,
                         decoded.mean(axis=0))


def estimator_error(config: SensorConfig, estimator: str, light: np.ndarray, readouts: int = 400,
                    replicas: int = 8, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Relative bias and spread of single-readout decoded light under constant Poisson light.

    Returns (bias, spread) per light: the mean and the standard deviation of
    (decoded - true) / true over ``readouts`` x ``replicas`` readouts, after a
    warm-up of 4 readouts.
    """
    config = SensorConfig.required(config, "estimator_error")
    light = checked_light_levels(light, positive=True)
    check_counts(readouts=readouts, replicas=replicas)
    grid = np.repeat(light, replicas)
    words = constant_light_words(config, grid, readouts + 4, seed=seed)[4:]
    error = (decode_light(words, config, estimator) - grid) / grid
    error = error.reshape(readouts, light.size, replicas).transpose(1, 0, 2).reshape(light.size, -1)
    return error.mean(axis=1), error.std(axis=1)
