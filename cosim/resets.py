"""Reset asserted in the middle of a run: the reset vector, its segments and what each top must show.

Every harness (Amaranth, Icarus, Verilator, cocotb; both tops) takes an optional
per-clock reset vector ``resets`` (T booleans) beside the stimulus. After the
harness's own initial reset (:data:`tespike.cosim.outside.RESET_CLOCKS` edges, charge
0), before rising edge t = 0, 1, ... it drives ``rst = resets[t]`` and
``charge`` = stimulus row t (the charge keeps flowing while ``rst`` is high, as
a photodiode's does) and samples the outputs.

SPEC section 6: ``rst`` is synchronous and pixel clock t = 0 is the first rising
edge with ``rst`` low. A run with resets is therefore a chain of fresh runs, the
*segments*: a segment starts at an edge s with ``rst`` low after an edge with
``rst`` high (or at 0) and ends at its *reset edge* r, the next edge with
``rst`` high (or at the run's end). What a correct design shows:

* at edges s .. r: exactly what a fresh design started at s shows at those
  edges, on stimulus rows s, s + 1, ...: a synchronous reset acts *at* its edge,
  so the outputs sampled just before edge r are still the segment's;
* at the edges after r while ``rst`` stays high: nothing (``frame_valid`` and
  ``out_valid`` low, the reset state); the next segment starts from scratch.

So a readout interval that has not reached its output when the reset edge comes
emits nothing: the parallel top shows interval k only if its ``frame_valid``
edge ``s + kL + L - 1 + latency`` is at most r; the streaming top sends the
beats due by edge r and none after (an interval under way is cut short). The
charge of the reset edges themselves and the pixels' state (residual, counts)
are lost. docs/cosim.md "Reset in the middle of a run" says it with the figures
of the generated tops (latency 1; beat j at 2 + j clocks after the interval).

:func:`frame_segments` and :func:`beat_segments` hold a run's captures to these
rules (:class:`tespike.cosim.outside.SimulatorRunError` naming the first broken one) and
return each segment's words; :func:`golden_segments` gives the golden model's
words of each segment from zero state; :func:`reset_sweep` makes a reset
vector that asserts ``rst`` at every phase of an interval and of its beats.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count
from tespike.golden.beats import beat_count

from .outside import SimulatorRunError, unpack_rows


@dataclasses.dataclass(frozen=True)
class Segment:
    """A fresh run inside a run with resets: harness clock of its t = 0 and of its reset edge."""

    start: int
    reset: int | None      # the edge with rst high that ends it; None: it runs to the end

    def holds(self, clocks: np.ndarray) -> np.ndarray:
        """Which harness clocks belong to the segment (s .. r inclusive)."""
        inside = clocks >= self.start
        return inside & (clocks <= self.reset) if self.reset is not None else inside

    def readouts(self, clocks: int, L: int) -> int:
        """Complete readout intervals of stimulus rows in the segment (rows s .. r, or s .. T - 1)."""
        stop = clocks if self.reset is None else min(clocks, self.reset + 1)
        return max(0, stop - self.start) // L


def check_resets(resets, clocks: int, path: str | None = None) -> np.ndarray | None:
    """``resets`` as a (T,) bool array (0/1 integers or booleans), or None; one line if it is not one,
    naming its file ``path`` where it was read from one."""
    if resets is None:
        return None
    arr = np.asarray(resets)
    what = "reset vector" if path is None else f"reset vector file {str(path)!r}"
    if arr.shape != (clocks,):
        raise InputError(f"{what} has shape {arr.shape}: want one value per stimulus clock, ({clocks},)")
    if arr.dtype.kind not in "biu":
        raise InputError(f"{what} holds {arr.dtype} values: want integers or booleans, 0 or 1 "
                         "(rst low or high at that clock)")
    if ((arr != 0) & (arr != 1)).any():
        raise InputError(f"{what}: every value must be 0 or 1 (rst low or high at that clock)")
    return arr.astype(bool)


def segments(resets: np.ndarray | None) -> list[Segment]:
    """The segments of a run whose reset vector is ``resets`` (one per stimulus clock; None or all low: one
    segment, from 0 to the end)."""
    if resets is None or not resets.any():
        return [Segment(0, None)]
    step = np.diff(np.concatenate([[0], resets.astype(np.int8), [0]]))
    rises = [int(r) for r in np.flatnonzero(step == 1)]          # reset edges
    falls = [int(f) for f in np.flatnonzero(step == -1)]         # first edge with rst low after each
    return [Segment(s, r) for s, r in zip([0, *falls], [*rises, None])]


def _refuse_during_reset(clocks: np.ndarray, parts: list[Segment], what: str, port: str) -> None:
    """A capture at an edge after a reset edge while rst is still high breaks the reset state."""
    inside = np.zeros(len(clocks), bool)
    for seg in parts:
        inside |= seg.holds(clocks)
    if not inside.all():
        c = int(clocks[np.flatnonzero(~inside)[0]])
        r = max(seg.reset for seg in parts if seg.reset is not None and seg.reset < c)
        raise SimulatorRunError(f"{what}: {port} high at clock {c}, while rst is held (reset edge {r}): "
                                f"SPEC section 6's reset state shows nothing until the first readout")


def frame_segments(clocks, frames, config: SensorConfig, height: int, width: int, resets: np.ndarray,
                   stimulus_clocks: int, what: str) -> list[np.ndarray]:
    """Captures of the parallel top -> each segment's words ``(n, H, W)`` (module docstring's rules).

    ``clocks`` are the harness clocks at which ``frame_valid`` was sampled high
    and ``frames`` the ``(captures, words)`` uint32 rows of ``frame``. Interval k
    of a segment must show at its clock ``kL + L - 1 + latency``, one latency in
    0..L for the whole run, every one due by the reset edge and none after it.
    """
    L = config.clocks_per_readout
    clocks = np.asarray(clocks, np.int64)
    parts = segments(resets)
    _refuse_during_reset(clocks, parts, what, "frame_valid")
    picks = [np.flatnonzero(seg.holds(clocks)) for seg in parts]
    first = next(((seg, p) for seg, p in zip(parts, picks) if len(p)), None)
    latency = L if first is None else int(clocks[first[1][0]]) - first[0].start - (L - 1)
    if not 0 <= latency <= L:
        raise SimulatorRunError(f"{what}: the first frame_valid after the reset at clock {first[0].start} "
                                f"came at clock {int(clocks[first[1][0]])}: latency {latency} is outside "
                                f"0..L = {L} (SPEC section 6)")
    words = []
    for i, (seg, pick) in enumerate(zip(parts, picks)):
        due = np.arange(seg.readouts(stimulus_clocks, L), dtype=np.int64) * L + (L - 1 + latency)
        if seg.reset is not None:
            due = due[due <= seg.reset - seg.start]
        got = clocks[pick] - seg.start
        if len(got) != len(due) or (got != due).any():
            end = "the run's end" if seg.reset is None else f"the reset edge {seg.reset}"
            raise SimulatorRunError(
                f"{what}: segment {i} (t = 0 at clock {seg.start}, up to {end}): frame_valid at its clocks "
                f"{got[:6].tolist()}, expected {due[:6].tolist()} (interval k at kL + L - 1 + latency "
                f"{latency}, L = {L}, every one due by the reset edge and none after it)")
        words.append(_unpack(frames, pick, height * width, config.word_bits).reshape(len(pick), height, width))
    return words


def _unpack(rows, pick: np.ndarray, values: int, bits: int) -> np.ndarray:
    """The picked capture rows (uint32 words of a port) -> ``(len(pick), values)`` int64."""
    if len(pick) == 0:
        return np.zeros((0, values), np.int64)
    picked = np.asarray(rows, np.uint32)[pick]
    return unpack_rows(picked.reshape(len(pick), -1), values, bits)


def beat_segments(clocks, firsts, lane_rows, config: SensorConfig, height: int, width: int, lanes: int,
                  resets: np.ndarray, stimulus_clocks: int, what: str) -> list[np.ndarray]:
    """Captures of the streaming top -> each segment's beats ``(n, N)`` in the order they came.

    Each segment's beats must be a prefix of its complete intervals' beats:
    ``out_first`` with beat 0 of each interval only, beat 0 not before the
    interval's last clock, every beat within 2L clocks of it; the last segment
    (no reset after it) sends every beat. Where every complete interval of the
    run sent its beat j at the same offset after the interval's last clock (the
    generated top: 2 + j), a cut segment must show exactly the beats due by its
    reset edge: none lost before it, none after.
    """
    L, B = config.clocks_per_readout, beat_count(height * width, lanes)
    clocks = np.asarray(clocks, np.int64)
    firsts = np.asarray(firsts, bool)
    parts = segments(resets)
    _refuse_during_reset(clocks, parts, what, "out_valid")
    picks = [np.flatnonzero(seg.holds(clocks)) for seg in parts]
    offsets = set()
    for i, (seg, pick) in enumerate(zip(parts, picks)):
        got, n = clocks[pick] - seg.start, len(pick)
        K = seg.readouts(stimulus_clocks, L)
        where = f"{what}: segment {i} (t = 0 at clock {seg.start})"
        want = K * B if seg.reset is None else None
        if n > K * B or (want is not None and n != want):
            raise SimulatorRunError(f"{where}: out_valid was high {n} times, expected "
                                    f"{'' if want is not None else 'at most '}{K * B} ({K} complete "
                                    f"readout intervals of B = {B} beats)")
        beat = np.arange(n)
        if (firsts[pick] != (beat % B == 0)).any():
            j = int(np.flatnonzero(firsts[pick] != (beat % B == 0))[0])
            raise SimulatorRunError(f"{where}: out_first is {int(firsts[pick][j])} on beat {j % B} of interval "
                                    f"{j // B} (its clock {int(got[j])}); SPEC section 6 wants it with beat 0 only")
        after = got - ((beat // B + 1) * L - 1)
        if (after < 0).any() or (after > 2 * L).any():
            j = int(np.flatnonzero((after < 0) | (after > 2 * L))[0])
            raise SimulatorRunError(f"{where}: beat {j % B} of interval {j // B} at its clock {int(got[j])}, "
                                    f"{int(after[j])} clocks after the interval's last clock (SPEC section 6: "
                                    f"0 .. 2L = {2 * L})")
        offsets.update(tuple(row) for row in after[:n // B * B].reshape(-1, B))
    if len(offsets) == 1:                     # one schedule: cut segments must follow it to the edge
        schedule = np.asarray(offsets.pop(), np.int64)
        for i, (seg, pick) in enumerate(zip(parts, picks)):
            if seg.reset is None:
                continue
            K = seg.readouts(stimulus_clocks, L)
            due = ((np.arange(K, dtype=np.int64)[:, None] + 1) * L - 1 + schedule[None, :]).reshape(-1)
            due = due[due <= seg.reset - seg.start]
            got = clocks[pick] - seg.start
            if len(got) != len(due) or (got != due).any():
                raise SimulatorRunError(
                    f"{what}: segment {i} (t = 0 at clock {seg.start}, reset edge {seg.reset}): beats at its "
                    f"clocks {got[:6].tolist()}, expected {due[:6].tolist()}: the beats due by the reset edge "
                    f"(beat j at {schedule[:4].tolist()}... clocks after its interval, as everywhere else "
                    f"in the run) and none after it")
    return [_unpack(lane_rows, pick, lanes, config.word_bits) for pick in picks]


def golden_segments(config: SensorConfig, stimulus: np.ndarray, resets: np.ndarray | None,
                    lanes: int | None = None) -> list[np.ndarray]:
    """The golden model's words of each segment from zero state (the literal SPEC rule).

    ``(K_s, H, W)`` per segment, its complete intervals; with ``lanes``, their beats
    flattened to ``(K_s B, N)``: what a segment cut by no reset sends, of which a cut
    one sends a prefix.
    """
    from tespike.golden.reference import step_reference
    from tespike.golden.beats import beats

    config = SensorConfig.required(config, "golden_segments")
    T, H, W = stimulus.shape
    L = config.clocks_per_readout
    out = []
    for seg in segments(check_resets(resets, T)):
        K = seg.readouts(T, L)
        words = step_reference(config, stimulus[seg.start:seg.start + K * L])[0]
        out.append(words if lanes is None else beats(words, lanes).reshape(-1, lanes))
    return out


def first_segment_difference(got: list[np.ndarray], expected: list[np.ndarray]) -> str | None:
    """None if every segment's output equals the start of the golden one, else where it first differs."""
    if len(got) != len(expected):
        return f"{len(got)} segments, golden {len(expected)}"
    for i, (g, e) in enumerate(zip(got, expected)):
        if len(g) > len(e):
            return f"segment {i}: {len(g)} outputs, the golden model has {len(e)}"
        differ = np.asarray(g) != np.asarray(e)[:len(g)]
        if differ.any():
            at = tuple(int(v) for v in np.argwhere(differ)[0])
            return (f"segment {i}: {int(differ.sum())} words differ; first at {at}: "
                    f"RTL {int(np.asarray(g)[at])}, golden {int(np.asarray(e)[at])}")
    return None


def reset_sweep(config: SensorConfig, rng: np.random.Generator, *, beats: int = 1,
                tail_readouts: int = 2) -> np.ndarray:
    """A reset vector that cuts a segment at every phase: mid-interval, its last clock, every beat.

    One segment for each reset edge offset 0 .. 2L + 1 clocks after its t = 0 (in
    random order; ``beats`` = B of the streaming top, so offsets up to L + B + 2 hit
    beat 0, the beats in between and the last beat of interval 0 too), each reset
    held 1 to 3 clocks (random); then ``tail_readouts`` intervals without reset, and
    up to L - 1 clocks more so that the vector's length is a multiple of L (as a
    stimulus's must be).
    """
    config = SensorConfig.required(config, "reset_sweep")
    if not isinstance(rng, np.random.Generator):          # (a seed had been an AttributeError)
        raise InputError(f"reset_sweep rng: must be a numpy Generator (numpy.random.default_rng(seed)), "
                         f"not {type(rng).__name__}")
    for name, value, least in (("beats", beats, 1), ("tail_readouts", tail_readouts, 0)):
        if not is_count(value, least):                   # (-1 tail readouts: a vector of no whole interval)
            raise InputError(f"reset_sweep {name} = {value!r}: must be an integer >= {least}")
    L = config.clocks_per_readout
    vector = []
    for offset in rng.permutation(max(2 * L + 2, L + beats + 3)):
        vector += [0] * int(offset) + [1] * int(rng.integers(1, 4))
    vector += [0] * (tail_readouts * L + (-len(vector) % L))
    return np.asarray(vector, bool)
