"""Exact switching activity of the pixel's flip-flops and readout word (an energy proxy).

Counts, clock by clock, how many register bits change in each pixel of the RTL
(:mod:`tespike.rtl.pixel`): the accumulator ``acc``, the TE counter ``sfc`` (b1 bits; its
carry *is* the flag, so after an overflow it holds 0), flag ``ovf`` and latch ``m``
(which the RTL does not clear at readout: it keeps the value it would latch), or
the ML counter; and the readout word register (``word_reg``, loaded once per
interval: the word bus, whose toggles are popcount(word[k] xor word[k-1])).
The per-clock charge input register of the array is left out: it toggles with
the light whatever the camera, and is the same for cameras with the same E.

It is the literal SPEC section 3 rule over all pixels at once (one numpy
operation per register per clock), not :class:`tespike.golden.sensor.PixelArrayModel`'s
engine: that engine's whole-block shortcuts never form the per-clock
accumulator values whose bit changes are counted here. The words it returns are
checked against that engine's in the tests, the toggles against a VCD of the
Amaranth pixels.

A toggle count is a proxy for dynamic energy (each bit change charges or
discharges a node), not energy: it ignores the logic between the registers,
glitches, the clock tree (which toggles every flip-flop's clock pin every
clock whatever the data) and leakage.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .config import SensorConfig
from .errors import InputError, check_counts
from .io import check_stimulus
from .light import check_seed, checked_light_levels, saturated_poisson
from .reference import msb_remainder, readout_word


@dataclasses.dataclass
class Toggles:
    """Bit changes per pixel over a run: ``registers`` {name: (n,) int64}, ``word`` (n,) the
    word register's, ``words`` (K, n) the words read out, ``intervals`` K."""

    registers: dict[str, np.ndarray]
    word: np.ndarray
    words: np.ndarray
    intervals: int

    @property
    def flops(self) -> np.ndarray:
        """Toggles of the pixel's state registers (not the word register), per pixel."""
        return sum(self.registers.values())

    @property
    def counters(self) -> np.ndarray:
        """Toggles of the counting registers alone (all but ``acc``: the part a pixel with an
        analog integrate-and-fire front end, as the paper's, keeps digital)."""
        return self.flops - self.registers["acc"]

    def per_interval(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(state flip-flop, counter, word bus) toggles per pixel per readout interval, float64."""
        k = max(self.intervals, 1)
        return self.flops / k, self.counters / k, self.word / k


def flips(old, new) -> np.ndarray:
    """Bits that differ between register values ``old`` and ``new`` (int64 popcount of the xor)."""
    return np.bitwise_count(np.asarray(old, np.int64) ^ np.asarray(new, np.int64)).astype(np.int64)


def pixel_register_names(config: SensorConfig) -> tuple[str, ...]:
    """The pixel's state registers (SPEC section 3) in the order of :func:`register_step`'s state."""
    return ("acc", "sfc", "ovf", "m") if config.is_te else ("acc", "count")


def pixel_register_bits(config: SensorConfig) -> dict[str, int]:
    """Width of each of the pixel's state registers."""
    c = config
    if c.is_te:
        return {"acc": c.acc_bits, "sfc": c.b1, "ovf": 1, "m": c.b2}
    return {"acc": c.acc_bits, "count": c.ml_bits}


def register_step(config: SensorConfig, state: dict, charge, ccc: int, last: bool):
    """One clock of every pixel's registers (SPEC section 3 as the RTL holds it: the TE counter
    is b1 bits, its carry the flag, so after an overflow it holds 0; ``m`` is not cleared at
    readout). ``state``: {name: (n,) int64} of :func:`pixel_register_names`; ``ccc``: the
    tick this clock is in (1..alpha); ``last``: the interval's last clock. -> (the next
    state, the word read out at this clock (SPEC section 4) if ``last``, else None)."""
    c = config
    q = state["acc"] + charge
    spike = (q >= c.threshold).astype(np.int64)
    acc = np.minimum(q - c.threshold * spike, c.acc_max)
    word = None
    if c.is_te:
        total = state["sfc"] + (spike & (1 - state["ovf"]))
        carry = total >> c.b1
        ovf = state["ovf"] | carry
        m = np.where(carry == 1, ccc, state["m"])
        count = total & (c.p_max - 1)
        if last:
            word = readout_word(c, count, ovf, m)
            count, ovf = 0 * count, 0 * ovf
        return {"acc": acc, "sfc": count, "ovf": ovf, "m": m}, word
    count = np.minimum(state["count"] + spike, c.ml_max)
    if last:
        word = readout_word(c, count, None, None)
        count = msb_remainder(count, word) if c.is_msb else 0 * count
    return {"acc": acc, "count": count}, word


def count_toggles(config: SensorConfig, electrons: np.ndarray) -> Toggles:
    """Toggles of n pixels fed ``electrons`` (T, n) integers from the zero start, T a
    multiple of L (whole readout intervals)."""
    config = SensorConfig.required(config, "count_toggles")
    e = np.asarray(electrons)
    if e.ndim != 2:
        raise InputError(f"electrons shape {e.shape}: must be (T, n), T clocks of n pixels")
    check_stimulus(e[:, None, :], config, whole_readouts=False, what="electrons")   # integers in 0..2^E - 1
    e = e.astype(np.int64, copy=False)
    T, n = e.shape
    L, F = config.clocks_per_readout, config.clocks_per_tick
    if T % L:
        raise InputError(f"{T} clocks is not a whole number of readout intervals (L = {L})")
    names = pixel_register_names(config)
    state = {name: np.zeros(n, np.int64) for name in names}
    counts = {name: np.zeros(n, np.int64) for name in names}
    word_reg, word_count = np.zeros(n, np.int64), np.zeros(n, np.int64)
    words = np.empty((T // L, n), np.int64)
    for t in range(T):
        nxt, word = register_step(config, state, e[t], (t % L) // F + 1, t % L == L - 1)
        for name in names:
            counts[name] += flips(state[name], nxt[name])
        state = nxt
        if word is not None:
            word_count += flips(word_reg, word)
            word_reg = word
            words[t // L] = word
    return Toggles(counts, word_count, words, T // L)


def constant_light_toggles(config: SensorConfig, light: np.ndarray, readouts: int, *,
                           seed: int = 0) -> Toggles:
    """Toggles of n pixels under constant ``light`` (n,) (1 = the brightest designed light,
    42000 electrons per readout), Poisson electrons per clock as SPEC section 6's
    stimulus, saturated at 2^E - 1, over ``readouts`` intervals from the zero start."""
    from .config import DESIGN_ELECTRONS

    config = SensorConfig.required(config, "constant_light_toggles")
    light = checked_light_levels(light)
    check_counts(readouts=readouts)
    lam = DESIGN_ELECTRONS * light / config.clocks_per_readout
    rng = np.random.default_rng(check_seed(seed))
    electrons = saturated_poisson(rng, lam, (readouts * config.clocks_per_readout, light.size), config.input_max)
    return count_toggles(config, electrons)
