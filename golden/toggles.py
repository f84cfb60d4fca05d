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
operation per register per clock), not :class:`tespike.golden.sensor.PixelArray`'s
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
from .reference import msb_index, readout_word


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


def _flips(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    return np.bitwise_count(old ^ new).astype(np.int64)


def count_toggles(config: SensorConfig, electrons: np.ndarray) -> Toggles:
    """Toggles of n pixels fed ``electrons`` (T, n) integers from the zero start, T a
    multiple of L (whole readout intervals)."""
    e = np.asarray(electrons, np.int64)
    T, n = e.shape
    L, F = config.clocks_per_readout, config.clocks_per_tick
    if T % L:
        raise ValueError(f"{T} clocks is not a whole number of readout intervals (L = {L})")
    theta, top = config.threshold, config.acc_max
    zeros = lambda: np.zeros(n, np.int64)                                   # noqa: E731
    acc, sfc, ovf, m, word_reg = zeros(), zeros(), zeros(), zeros(), zeros()
    names = ("acc", "sfc", "ovf", "m") if config.is_te else ("acc", "count")
    counts = {name: zeros() for name in names}
    word_count = zeros()
    words = np.empty((T // L, n), np.int64)
    p_max = config.p_max if config.is_te else 0
    for t in range(T):
        q = acc + e[t]
        s = (q >= theta).astype(np.int64)
        new_acc = np.minimum(q - theta * s, top)
        counts["acc"] += _flips(acc, new_acc)
        acc = new_acc
        last = t % L == L - 1
        if config.is_te:
            total = sfc + (s & (1 - ovf))
            carry = (total == p_max).astype(np.int64)
            ovf_next = ovf | carry
            m_next = np.where(carry == 1, (t % L) // F + 1, m)
            sfc_next = total & (p_max - 1)
            if last:
                word = readout_word(config, sfc_next, ovf_next, m_next)
                sfc_next, ovf_next = zeros(), zeros()
            counts["sfc"] += _flips(sfc, sfc_next)
            counts["ovf"] += _flips(ovf, ovf_next)
            counts["m"] += _flips(m, m_next)
            sfc, ovf, m = sfc_next, ovf_next, m_next
        else:
            count_next = np.minimum(sfc + s, config.ml_max)
            if last:
                if config.is_msb:
                    word = msb_index(count_next).astype(np.int64)
                    count_next = np.where(word > 0, count_next - (1 << np.maximum(word - 1, 0)), 0)
                else:
                    word = count_next
                    count_next = zeros()
            counts["count"] += _flips(sfc, count_next)
            sfc = count_next
        if last:
            word_count += _flips(word_reg, word)
            word_reg = word
            words[t // L] = word
    return Toggles(counts, word_count, words, T // L)


def constant_light_toggles(config: SensorConfig, light: np.ndarray, readouts: int, *,
                           seed: int = 0) -> Toggles:
    """Toggles of n pixels under constant ``light`` (n,) (1 = the brightest designed light,
    42000 electrons per readout), Poisson electrons per clock as SPEC section 6's
    stimulus, saturated at 2^E - 1, over ``readouts`` intervals from the zero start."""
    from .config import DESIGN_ELECTRONS

    light = np.asarray(light, np.float64)
    lam = DESIGN_ELECTRONS * light / config.clocks_per_readout
    rng = np.random.default_rng(seed)
    electrons = rng.poisson(np.broadcast_to(lam, (readouts * config.clocks_per_readout, light.size)))
    return count_toggles(config, np.minimum(electrons, config.input_max))
