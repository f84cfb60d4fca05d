"""The streaming top's ports (SPEC section 6, ``--lanes N``): what every simulator's check shares.

Every harness (Amaranth, Icarus, Verilator, cocotb) samples ``out_valid``,
``out_first`` and ``out_words`` before each rising edge t (pixel clock t after
reset, the convention of :mod:`tespike.cosim.outside`) and records a capture for each
clock with ``out_valid`` high. :func:`check_beats` holds the captures to SPEC
section 6 and returns them as beats ``(K, B, N)``, to be compared with
:func:`tespike.golden.beats.beats` of the golden words:

* exactly K * B beats, ``out_first`` high on beat 0 of each interval only;
* interval k's beats not before its last clock t = (k+1)L - 1, and its last
  beat sampled at most 2L clocks after it;
* every beat of interval k before any beat of interval k + 1 (by construction:
  beats are numbered in the order they came).
"""

from __future__ import annotations

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.beats import beat_count

from .outside import SimulatorRunError, unpack_rows


def check_beats(clocks, firsts, lane_rows, config: SensorConfig, height: int, width: int, lanes: int,
                readouts: int, what: str) -> tuple[np.ndarray, int]:
    """Captured beats -> ``(K, B, N)`` int64 words and the largest latency of a last beat.

    ``clocks`` (sample index of each capture), ``firsts`` (its ``out_first``) and
    ``lane_rows`` (``(captures, ceil(N*Wd/32))`` uint32 rows of ``out_words``) come
    from a run that went on until K * B beats were seen or 2L + 1 clocks past the
    stimulus. Raises :class:`SimulatorRunError` naming the first broken rule.
    """
    L, B = config.clocks_per_readout, beat_count(height * width, lanes)
    clocks = np.asarray(clocks, np.int64)
    firsts = np.asarray(firsts, bool)
    want = readouts * B
    if len(clocks) != want:
        raise SimulatorRunError(f"{what}: out_valid was high {len(clocks)} times, expected {want} "
                                f"({readouts} readout intervals of B = {B} beats, each within 2L = "
                                f"{2 * L} clocks of the interval's end)")
    expected_first = np.zeros(want, bool)
    expected_first[::B] = True
    if (firsts != expected_first).any():
        j = int(np.flatnonzero(firsts != expected_first)[0])
        raise SimulatorRunError(f"{what}: out_first is {int(firsts[j])} on beat {j % B} of interval "
                                f"{j // B} (clock {int(clocks[j])}); SPEC section 6 wants it high with "
                                f"beat 0 only")
    ends = (np.arange(readouts, dtype=np.int64) + 1) * L - 1
    per = clocks.reshape(readouts, B)
    early = per[:, 0] < ends
    if early.any():
        k = int(np.flatnonzero(early)[0])
        raise SimulatorRunError(f"{what}: beat 0 of interval {k} at clock {int(per[k, 0])}, before the "
                                f"interval's last clock {int(ends[k])}")
    latency = per[:, -1] - ends
    if (latency > 2 * L).any():
        k = int(np.flatnonzero(latency > 2 * L)[0])
        raise SimulatorRunError(f"{what}: the last beat of interval {k} at clock {int(per[k, -1])}, "
                                f"{int(latency[k])} clocks after its last clock {int(ends[k])}; "
                                f"SPEC section 6 allows at most 2L = {2 * L}")
    words = unpack_rows(np.asarray(lane_rows, np.uint32).reshape(want, -1), lanes, config.word_bits)
    return words.reshape(readouts, B, lanes), int(latency.max()) if readouts else 0


def last_beat_latency(clocks, config: SensorConfig, beats_per_interval: int) -> int:
    """Clocks from each interval's last clock to its last beat, the largest of the run (0 without beats).

    ``clocks`` are the sample clocks of the run's K * B beats, in order.
    """
    config = SensorConfig.required(config, "last_beat_latency")
    clocks = np.asarray(clocks, np.int64)
    if len(clocks) == 0:
        return 0
    per = clocks.reshape(-1, beats_per_interval)
    ends = (np.arange(len(per), dtype=np.int64) + 1) * config.clocks_per_readout - 1
    return int((per[:, -1] - ends).max())


def flush_clocks(config: SensorConfig) -> int:
    """Clocks of zero charge a harness runs after the stimulus: 2L + 1 (the latency bound, and one)."""
    return 2 * SensorConfig.required(config, "flush_clocks").clocks_per_readout + 1
