"""Light front end: scene light -> electrons per pixel clock (SPEC section 6).

Light ``I`` is given per readout interval, normalised so that ``I = 1`` means
``DESIGN_ELECTRONS = 42000`` electrons per readout interval (0.7 x 60000),
whatever the configuration. By default the electrons of pixel clock ``t`` of
interval ``k`` are independent ``Poisson(42000 * I[k] / L)`` (photon shot
noise thinned by the quantum efficiency, which is again Poisson). Electrons
beyond ``2^input_bits - 1`` in one clock saturate at that value.

Options, off by default:

* dark current after the paper's eq. 12 (``"eq12"``: ``N(400, 50)`` extra
  electrons per readout interval) or eq. 13 (``"eq13"``: ``60000 / N(140, 50)``
  clipped to ``[0, 15000]``), one independent draw per pixel and readout
  interval, rounded to the nearest integer (:func:`dark_electrons` states the
  rules for negatives); the dark electrons of an interval fall in uniformly
  random clocks of it, like photons;
* ``noise=False``: no randomness at all; the interval's expected electrons are
  delivered as the increments of the running integer part of the expected
  charge (a fraction carried from clock to clock and across intervals), so the
  long-run mean is exact.

Where the outcome is certain except on an event of probability below
``2^-64`` over the whole scene (light so far above an input word's range that
every clock saturates), no random number is drawn; :func:`log_budget` gives
that per-clock bound and :func:`log_poisson_tail_below` the rigorous tail
bound it is compared with.
"""

from __future__ import annotations

import math

import numpy as np

from .config import DESIGN_ELECTRONS, SensorConfig
from .errors import InputError, is_count
from .io import unsigned_dtype

#: Dark-current models of the paper's appendix A.2.5.
DARK_CURRENT_MODELS = ("eq12", "eq13")

#: Mean and standard deviation of the normal draw of each dark model: eq. 12
#: draws the dark electrons per readout interval, eq. 13 the interval between
#: dark spikes (paper ref. [62]), which :func:`eq13_dark_per_readout` turns into electrons.
DARK_NORMAL = {"eq12": (400.0, 50.0), "eq13": (140.0, 50.0)}

#: Eq. 13: dark electrons per readout are ``EQ13_CHARGE / x`` clipped to ``[0, EQ13_CAP]``.
EQ13_CHARGE, EQ13_CAP = 60000.0, 15000.0

#: Natural log of the failure probability allowed for a whole scene: 2^-64.
LOG_SCENE_FAILURE = -64.0 * math.log(2.0)

#: Light above this (in units of the design light) behaves exactly like this:
#: 1e200 x 42000 electrons per readout saturates every input word (at most
#: 2^32 - 1 per clock, L <= 2^24 clocks) with probability 1 - exp(-1e204), and
#: capping keeps 42000 * I finite for every finite float64 I.
LIGHT_CAP = 1e200


def check_dark_current(dark_current: str | None) -> str | None:
    """``None`` / ``"none"`` (no dark current), ``"eq12"`` or ``"eq13"``."""
    if dark_current is None or dark_current == "none":
        return None
    if dark_current not in DARK_CURRENT_MODELS:
        raise InputError(f"dark current model {dark_current!r} unknown "
                         f"(known: none, {', '.join(DARK_CURRENT_MODELS)})")
    return dark_current


def check_seed(seed, what: str = "seed"):
    """``seed`` itself where it is one the library takes: ``None`` (fresh entropy), an integer >= 0
    (never a bool) or a list or tuple of them (numpy's entropy), a numpy SeedSequence, BitGenerator
    or Generator; refused in one line naming ``what`` otherwise (numpy's TypeError or ValueError
    named no argument, and took True as 1)."""
    if seed is None or is_count(seed) or isinstance(
            seed, (np.random.SeedSequence, np.random.BitGenerator, np.random.Generator)):
        return seed
    if isinstance(seed, (list, tuple)) and seed and all(is_count(part) for part in seed):
        return seed
    raise InputError(f"{what} {seed!r}: must be an integer >= 0 (or a list of them), a numpy Generator, "
                     f"SeedSequence or BitGenerator, or None (fresh entropy)")


def checked_light_levels(light, what: str = "light", positive: bool = False) -> np.ndarray:
    """``light`` (one level a pixel, 1 = design light) as a 1-D float64 array of finite values >= 0
    (> 0 with ``positive``: a relative error divides by it), refused in one line otherwise (a negative
    or NaN light had been refused as the stimulus value it became, or taken)."""
    light = np.asarray(light, np.float64)
    if light.ndim != 1 or not light.size:
        raise InputError(f"{what} shape {light.shape}: must be one light per pixel, (n,) with n >= 1")
    if not (np.isfinite(light).all() and (light > 0 if positive else light >= 0).all()):
        bound = "> 0" if positive else ">= 0"
        raise InputError(f"{what}: every value must be finite and {bound} (1 = design light)")
    return light


def as_generator(rng) -> np.random.Generator:
    """A numpy Generator from a Generator, a seed (:func:`check_seed`) or ``None`` (fresh entropy)."""
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(check_seed(rng))


def electrons_per_readout(light: np.ndarray) -> np.ndarray:
    """Light (1.0 = design light, any float dtype and strides) -> expected photo-electrons per
    readout interval, a new C-contiguous float64 array of its shape (two passes, each value
    converted once: a stripe's rows are a strided view of the frame)."""
    light = np.asarray(light)
    out = np.empty(light.shape)
    np.minimum(light, LIGHT_CAP, out=out, dtype=np.float64)
    out *= DESIGN_ELECTRONS
    return out


#: Largest mean ``Generator.poisson`` accepts (numpy's POISSON_LAM_MAX).
POISSON_LAM_MAX = float(np.iinfo(np.int64).max - np.sqrt(np.iinfo(np.int64).max) * 10)


def saturated_poisson(rng: np.random.Generator, lam: np.ndarray, shape, top: int) -> np.ndarray:
    """``min(Poisson(lam), top)`` draws of ``shape`` (int64; ``lam`` broadcast to it) for any finite
    mean >= 0: one past numpy's limit (``lam value too large``) is ``top`` without a draw (it is
    surely saturated), and its place draws ``Poisson(0)``, which takes no random number, so every other
    value is the draw ``rng.poisson`` gives."""
    lam = np.asarray(lam, np.float64)
    past = lam > POISSON_LAM_MAX
    if not past.any():
        return np.minimum(rng.poisson(np.broadcast_to(lam, shape)), top)
    out = np.minimum(rng.poisson(np.broadcast_to(np.where(past, 0.0, lam), shape)), top)
    out[np.broadcast_to(past, shape)] = top
    return out


def dark_electrons(model: str | None, shape, rng: np.random.Generator, *,
                   scale: np.ndarray | None = None) -> np.ndarray:
    """Dark electrons per pixel and readout interval (int64), one draw each.

    ``scale``: a per-pixel factor (float64, broadcast to ``shape``) applied to the
    model's electrons before rounding (:mod:`tespike.golden.noise`: dark level, DSNU, hot
    pixels); ``None`` is 1 and gives exactly the unscaled draws.

    ``eq12``: ``x ~ N(400, 50)``, ``round(x)`` (half to even), and a negative
    result (probability about 1e-15 per draw) is counted as 0 electrons: a
    photodiode cannot lose charge to dark current.
    ``eq13``: ``x ~ N(140, 50)`` (the interval between dark spikes, paper
    ref. [62]), ``60000 / x`` clipped to ``[0, 15000]`` as the paper states, so a
    non-positive ``x`` (probability 0.3 %) gives 0 and a tiny positive one 15000;
    then rounded to the nearest integer.
    ``None``: zeros.
    """
    model = check_dark_current(model)
    if model is None:
        return np.zeros(shape, np.int64)
    if not isinstance(rng, np.random.Generator):         # (None or a seed had been an AttributeError)
        raise InputError(f"dark_electrons rng: must be a numpy Generator, not {type(rng).__name__}")
    x = rng.normal(*DARK_NORMAL[model], shape)
    per = np.maximum(x, 0.0) if model == "eq12" else eq13_dark_per_readout(x)
    if scale is not None:       # (a hot pixel's scale can take the count past int64: held at DARK_MAX)
        per = np.minimum(per * scale, DARK_MAX)
    return np.rint(per).astype(np.int64)


#: Most dark electrons one pixel-readout is given: 2^62, where every clock of any legal readout
#: (at most 2^24 clocks of at most 2^32 - 1 electrons) is saturated all the same, and the int64 sums
#: of a readout cannot wrap (legal noise settings reach 1e19: the count came out negative).
DARK_MAX = float(1 << 62)


def eq13_dark_per_readout(x: np.ndarray) -> np.ndarray:
    """Eq. 13's dark electrons per readout (before rounding) for spike intervals ``x``:
    ``EQ13_CHARGE / x`` clipped to ``[0, EQ13_CAP]``, and 0 where ``x <= 0``; shared by the
    draw and by :func:`tespike.golden.noise.model_mean`, which integrates its mean."""
    with np.errstate(divide="ignore"):
        return np.clip(np.where(x > 0, EQ13_CHARGE / np.where(x > 0, x, 1.0), 0.0), 0.0, EQ13_CAP)


# -- rigorous tail bounds (natural logs) ---------------------------------------

def log_budget(pixel_intervals: int, clocks: int) -> float:
    """Log of the per-clock failure probability that keeps a scene of
    ``pixel_intervals`` pixel-readouts of ``clocks`` clocks below 2^-64 in total
    (union bound)."""
    return LOG_SCENE_FAILURE - math.log(max(1, pixel_intervals)) - math.log(max(1, clocks))


def log_poisson_tail_above(mean: np.ndarray, k) -> np.ndarray:
    """Upper bound on ``log P(X >= k)`` for X a sum of independent Poisson and
    Bernoulli variables with total ``mean`` (Chernoff: ``-m + k - k log(k / m)``
    for ``k > m``, else 0); ``k`` an int or an array, elementwise with mean."""
    m, k = np.broadcast_arrays(np.asarray(mean, np.float64), np.asarray(k, np.float64))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        bound = -m + k - k * np.log(k / m)
    bound = np.where(m <= 0, -np.inf, bound)
    return np.where(k <= 0, 0.0, np.where(m >= k, 0.0, bound))


def log_poisson_tail_below(mean: np.ndarray, k) -> np.ndarray:
    """Upper bound on ``log P(X <= k)`` for ``X ~ Poisson(mean)``:
    ``log P(X = k) - log(1 - k / m)`` for ``k < m`` (the pmf ratio
    ``P(j - 1) / P(j) = j / m <= k / m`` bounds the rest by a geometric series);
    ``-inf`` for ``k < 0``; 0 (no information) for ``k >= m``. ``k`` an int or
    an array, elementwise with mean."""
    k = np.asarray(k, np.float64)
    if k.ndim == 0:                                     # one k (the usual call): one lgamma
        log_factorial = math.lgamma(max(float(k), 0.0) + 1.0)
    else:
        log_factorial = np.vectorize(math.lgamma, otypes=[np.float64])(np.maximum(k, 0.0) + 1.0)
    m, k = np.broadcast_arrays(np.asarray(mean, np.float64), k)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        log_pmf = -m + np.where(k > 0, k * np.log(m), 0.0) - log_factorial
        bound = log_pmf - np.log1p(-k / m)
    return np.where(k < 0, -np.inf, np.where(m > k, bound, 0.0))


# -- electrons per pixel clock ------------------------------------------------

def stimulus_dtype(config: SensorConfig) -> np.dtype:
    """Smallest unsigned dtype that holds ``2^input_bits - 1``."""
    return unsigned_dtype(config.input_bits)


def clock_electrons(config: SensorConfig, mean_per_readout: np.ndarray, dark: np.ndarray,
                    rng: np.random.Generator, budget: float) -> np.ndarray:
    """Random electrons of one readout interval for n pixels: ``(n, L)`` int64.

    Clock t gets ``Poisson(mean / L)`` photo-electrons plus the dark electrons
    (``dark[i]`` per pixel, multinomial over the L clocks), saturated at
    ``2^input_bits - 1``. A pixel whose light makes ``P(photo-electrons of a clock
    < 2^input_bits - 1)`` smaller than ``exp(budget)`` gets the saturated value in
    every clock without drawing (the shortcut that keeps 1e30 x design light
    finite and fast).
    """
    L, top = config.clocks_per_readout, config.input_max
    lam = np.asarray(mean_per_readout, np.float64) / L
    n = lam.shape[0]
    out = np.full((n, L), top, np.int64)
    sure = log_poisson_tail_below(lam, top - 1) < budget
    draw = ~sure
    if draw.any():
        e = rng.poisson(lam[draw, None], size=(int(draw.sum()), L))
        d = dark[draw]
        if d.any():
            e += rng.multinomial(d, np.full(L, 1.0 / L))
        out[draw] = np.minimum(e, top)
    return out


def deterministic_clock_electrons(config: SensorConfig, mean_per_readout: np.ndarray,
                                  fraction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free electrons of one readout interval for n pixels: ``(n, L)`` int64.

    Clock t gets ``floor(f + expected (t + 1) / L) - floor(f + expected t / L)`` electrons,
    f the fraction carried in (``fraction``, in [0, 1)), saturated at
    ``2^input_bits - 1``. Returns the electrons and the fraction carried out.
    """
    L, top = config.clocks_per_readout, config.input_max
    expected = np.asarray(mean_per_readout, np.float64)
    level = fraction[:, None] + expected[:, None] * (np.arange(L + 1, dtype=np.float64) / L)
    whole = np.floor(level)
    e = np.minimum(np.diff(whole, axis=1), top)
    fraction_out = level[:, -1] - whole[:, -1]
    fraction_out = np.where(np.isfinite(fraction_out), fraction_out, 0.0)
    return e.astype(np.int64), fraction_out

