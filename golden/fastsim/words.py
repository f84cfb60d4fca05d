"""Readout words from a pixel-readout's spike count, shared by every path.

TE: a path that knows the spike count and the overflow clock writes the word
itself; a pixel that fired on every clock has one known word. ML (SPEC
section 3): the counter is ``min(sfc + spikes, 2^ml_bits - 1)`` from the
carried remainder ``sfc`` (0 for the count readout); count reads it all, msb
reads its top bit's index and keeps the remainder below that bit. The
remainder is a function of past spike counts, so each path stays exact in
distribution.
"""

from __future__ import annotations

import functools

import numpy as np

from ..config import SensorConfig
from ..reference import msb_index, overflow_word


class WordTables:
    """Words every path shares for one configuration: ``bright_word`` (a spike in
    every clock of the interval) and, for the msb readout, the word and remainder
    of every counter value 0..2^ml_bits - 1 (at most 64 Ki entries). Read-only."""

    def __init__(self, config: SensorConfig):
        c = self.config = config
        if c.is_te:
            ovf_clock = c.p_max - 1                       # spike in every clock
            self.bright_word = (overflow_clock_word(c, ovf_clock)
                                if c.p_max <= c.clocks_per_readout else c.clocks_per_readout)
        else:
            self.bright_word = min(c.clocks_per_readout, c.ml_max)
        if c.is_msb:
            count = np.arange(c.ml_max + 1, dtype=np.int64)
            self.msb_word = msb_index(count)
            self.msb_rest = count - np.where(count > 0, np.left_shift(1, np.maximum(self.msb_word - 1, 0)), 0)
            self.msb_word.flags.writeable = self.msb_rest.flags.writeable = False


def overflow_clock_word(config: SensorConfig, clock):
    """TE word of an overflow (the 2^b1-th spike) in 0-based clock ``clock`` of the interval: its tick
    ``clock // clocks_per_tick + 1`` latched (:func:`tespike.golden.reference.overflow_word`)."""
    return overflow_word(config, clock // config.clocks_per_tick + 1)


@functools.lru_cache(maxsize=16)
def word_tables(config: SensorConfig) -> WordTables:
    """:class:`WordTables` of ``config``, made once per process."""
    return WordTables(config)


def firing_words(sim, sel, words):
    """Words of pixels ``sel`` that fired on every clock of the interval (L spikes)."""
    if sim.config.is_msb:
        ml_words(sim, sel, sim.config.clocks_per_readout, words)
    else:
        words[sel] = sim.tables.bright_word


#: No pixels: an empty flat index array (read-only), for a path's optional subsets.
NO_PIXELS = np.zeros(0, np.int64)
NO_PIXELS.flags.writeable = False


def is_mask(sel) -> bool:
    """Whether pixels ``sel`` are a boolean mask of the frame (the event path's whole-frame
    form) rather than flat indices or a slice."""
    return isinstance(sel, np.ndarray) and sel.dtype == bool


def gather(values, sel):
    """``values`` of pixels ``sel``: under a mask the whole frame (the path runs on every pixel
    and writes back under the mask), else ``values[sel]``."""
    return values if is_mask(sel) else values[sel]


def put(target, sel, values):
    """Write ``values`` of pixels ``sel`` into ``target``: under a mask from whole-frame values,
    else by index (or slice)."""
    if is_mask(sel):
        np.copyto(target, values, where=sel)
    else:
        target[sel] = values


def ml_words(sim, sel, spikes, words):
    """ML words of pixels ``sel`` (flat indices, a slice, or a boolean mask of the frame
    with ``spikes`` over the whole frame) from their spike counts in the interval: the
    counter ``min(sfc + spikes, 2^ml_bits - 1)`` (it saturates one spike at a time, so
    the clipped sum is exact); count reads it all, msb reads its top bit's index and
    keeps the remainder."""
    c = sim.config
    if not c.is_msb:
        put(words, sel, np.minimum(spikes, c.ml_max))
        return
    count = np.minimum(gather(sim.sfc, sel) + spikes, c.ml_max)
    put(words, sel, sim.tables.msb_word[count])
    put(sim.sfc, sel, sim.tables.msb_rest[count])
