"""Cycle-exact model of a TE or ML pixel array (SPEC sections 3 and 4), fast and run in chunks.

:class:`PixelArrayModel` gives the same words, clock for clock, as the literal
per-clock rule :func:`tespike.golden.reference.step_reference`. State (acc, sfc, ovf,
m and the clock phase; with the ML msb readout, sfc keeps its remainder across
readouts) is carried between calls, so a run split anywhere gives the
identical stream, and memory stays bounded by the chunk size however many
readouts a run has.

How it works (docs/golden-model.md). Pixels are advanced in blocks of
BLOCK_CLOCKS clocks x BLOCK_PIXELS pixels:

* two exact whole-block shortcuts: no input and every acc0 < theta (nothing
  fires, acc stays); every input >= theta (a spike on every clock, acc the
  capped walk, pinned at M when every input >= theta + M);
* otherwise the literal rule itself, made cheap: inputs clipped to theta + M
  (exact: any larger input fires and fills the accumulator), then five
  branch-free operations per clock in the narrowest integer dtype that holds
  every value (int16 for the paper's configurations), with the clock's
  "no spike" bit taken from the sign of acc + e - theta by an arithmetic
  shift; its running sum C gives the spike count N_t = t + 1 + C_t;
* words follow from N at readout boundaries, and the TE overflow clock from the
  first clock whose N reaches the target.
"""

from __future__ import annotations

from typing import Iterable, Iterator

import numpy as np

from .config import SensorConfig
from .errors import InputError
from .io import check_frame_shape, check_stimulus
from .reference import PixelState, msb_index, readout_word

#: Pixel clocks x pixels processed at once by :func:`simulate` (bounds memory).
DEFAULT_CHUNK_ELEMENTS = 1 << 22

#: Pixel clocks stepped per block (rows of the working arrays).
BLOCK_CLOCKS = 32

#: Pixels per block (columns of the working arrays); keeps a block's rows in the L2 cache.
BLOCK_PIXELS = 16384

#: Stands for "no pixel fires in this block" in place of the idle-count array.
NO_SPIKES = "no spikes"

#: Stands for "every pixel fires on every clock of this block" (C = 0 throughout).
EVERY_CLOCK = None


def _plan(config: SensorConfig) -> np.dtype:
    """The narrowest signed working dtype that holds every intermediate of :meth:`_Engine.step`.

    With inputs clipped to theta + M, ``r = acc + e - theta`` lies in [-theta, 2M],
    the clipped input in [0, theta + M] and the idle count in [-BLOCK_CLOCKS, 0];
    theta <= M (SPEC section 2) and M <= 2^62 - 1, so int64 always suffices.
    """
    need = max(2 * config.acc_max, config.threshold + config.acc_max, BLOCK_CLOCKS)
    for dt in (np.int16, np.int32, np.int64):
        if need <= np.iinfo(dt).max:
            return np.dtype(dt)
    raise ValueError(f"acc_bits = {config.acc_bits}: the accumulator does not fit int64")


class _Engine:
    """The per-clock rule in one narrow integer dtype, on whole rows of pixels.

    :meth:`dynamics` returns, per block, an array ``C`` of idle counts with the
    cumulative spike count ``N_t = t + 1 + C_t`` (t from 0 at the block start;
    C_t = minus the clocks up to t without a spike), and the charge after the block.
    """

    def __init__(self, config: SensorConfig):
        self.config = config
        self.theta = config.threshold
        self.acc_max = config.acc_max
        self.block_clocks = BLOCK_CLOCKS
        self.dtype = _plan(config)
        self._buffers: dict = {}

    def _array(self, name: str, shape: tuple[int, int], dtype: np.dtype, reuse: bool) -> np.ndarray:
        """A work array; with ``reuse`` the same memory serves every block of this shape
        (fresh pages cost a page fault each, about a pass over the array)."""
        if not reuse:
            return np.empty(shape, dtype)
        key = (name, shape, np.dtype(dtype))
        if key not in self._buffers:
            self._buffers[key] = np.empty(shape, dtype)
        return self._buffers[key]

    def _row(self, value: int, n: int, dtype: np.dtype) -> np.ndarray:
        """A read-only vector of n copies of ``value`` (a view of one kept per value and dtype).

        Constant rows instead of scalars: numpy's binary ufuncs against a scalar
        are several times (minimum: over ten times) slower than against an array.
        """
        key = ("row", value, np.dtype(dtype))
        row = self._buffers.get(key)
        if row is None or row.size < n:
            row = np.full(max(n, BLOCK_PIXELS), value, dtype)
            row.flags.writeable = False
            self._buffers[key] = row
        return row[:n]

    def dynamics(self, e: np.ndarray, acc0: np.ndarray, reuse: bool = False):
        """Advance pixels over a block: e (T, n) electrons, acc0 (n,) int64 charge -> (C, acc_end).

        ``C`` is EVERY_CLOCK when every pixel fired on every clock (C = 0) and
        NO_SPIKES when none fired. With ``reuse`` the returned C lives in a
        buffer that the next call with ``reuse`` overwrites (the caller
        consumes it first).

        Two exact whole-block shortcuts come first: no input anywhere and every
        acc0 < theta (no spike, acc unchanged); every input >= theta (acc >= 0
        gives q >= theta: a spike on every clock, acc the capped walk
        min(acc + e - theta, M), pinned at M when every input >= theta + M).
        Everything else is stepped by :meth:`step`.
        """
        theta, M, dt = self.theta, self.acc_max, self.dtype
        T, n = e.shape
        top = int(e.max())
        if top == 0 and int(acc0.max()) < theta:
            return NO_SPIKES, acc0.copy()
        ep = self._inputs(e, top, reuse)
        low = int(e.min())
        if low >= theta:
            if low - theta >= M:
                return EVERY_CLOCK, np.full(n, M, np.int64)
            acc = acc0.astype(dt)
            M_row = self._row(M, n, dt)
            for row in ep:
                np.add(acc, row, out=acc)               # e - theta >= 0: no spike is lost
                np.minimum(acc, M_row, out=acc)
            return EVERY_CLOCK, acc.astype(np.int64)
        return self.step(ep, acc0, reuse)

    def _inputs(self, e: np.ndarray, top: int, reuse: bool) -> np.ndarray:
        """min(e, theta + M) - theta in the working dtype, (T, n).

        Clipping is exact: any e >= theta + M fires (acc >= 0) and leaves
        min(acc + e - theta, M) = M, whatever acc was.
        """
        theta, M, dt = self.theta, self.acc_max, self.dtype
        T, n = e.shape
        ep = self._array("ep", (T, n), dt, reuse)
        if top > theta + M:                             # then theta + M fits e's dtype
            np.minimum(e, self._row(theta + M, n, e.dtype), out=ep, casting="unsafe")
            np.subtract(ep, self._row(theta, n, dt), out=ep)
        else:
            np.subtract(e, self._row(theta, n, dt), out=ep, dtype=dt, casting="unsafe")
        return ep

    def step(self, ep: np.ndarray, acc0: np.ndarray, reuse: bool = False):
        """SPEC section 3 clock by clock on ep = min(e, theta + M) - theta, (T, n): -> (C, acc_end).

        Per clock, five operations in the working dtype and no branch:
        r = acc + e - theta; s = r >> (bits - 1) (-1 where r < 0, i.e. no spike,
        else 0: it is the clock's idle count); acc = min(r + (s & theta), M),
        which is min(q - theta, M) after a spike and min(q, M) without one
        (q = acc + e). A running sum of s gives C. Values stay within the bound
        of :func:`_plan`.
        """
        theta, M, dt = self.theta, self.acc_max, self.dtype
        T, n = ep.shape
        acc = acc0.astype(dt)
        r = np.empty(n, dt)
        cut = np.empty(n, dt)
        C = self._array("C", (T, n), dt, reuse)
        rows = list(C)                                  # row views made in one C loop
        sign_row = self._row(8 * dt.itemsize - 1, n, dt)
        theta_row, M_row = self._row(theta, n, dt), self._row(M, n, dt)
        for t, row in enumerate(ep):
            np.add(acc, row, out=r)
            s = rows[t]
            np.right_shift(r, sign_row, out=s)
            np.bitwise_and(s, theta_row, out=cut)
            np.add(r, cut, out=r)
            np.minimum(r, M_row, out=acc)
        for t in range(1, T):
            np.add(rows[t - 1], rows[t], out=rows[t])
        return C, acc.astype(np.int64)


class PixelArrayModel:
    """The cycle-exact model of an H x W array of TE or ML pixels, consuming per-clock electrons in
    chunks (named apart from the hardware's :class:`tespike.rtl.array.PixelArray`, which it models)."""

    def __init__(self, config: SensorConfig, shape: tuple[int, int]):
        config = SensorConfig.required(config, "PixelArrayModel")
        self.config = config
        self.shape = check_frame_shape(shape, "pixel array shape")
        self.state = PixelState.zeros(self.shape)
        self._engine = _Engine(config)

    def feed(self, electrons: np.ndarray) -> np.ndarray:
        """Consume (T, H, W) electrons of any T; return the words (k, H, W) of the readouts completed."""
        check_stimulus(electrons, self.config, whole_readouts=False)
        if electrons.shape[1:] != self.shape:
            raise InputError(f"stimulus chunk shape {electrons.shape[1:]} != pixel array shape {self.shape}")
        config, state = self.config, self.state
        T = electrons.shape[0]
        H, W = self.shape
        P = H * W
        L = config.clocks_per_readout
        e = electrons.reshape(T, P)
        n_words = (state.clock + T) // L - state.clock // L
        words = np.empty((n_words, P), np.int64)
        flat = [a.reshape(P) for a in (state.acc, state.sfc, state.ovf, state.m)]
        block = self._engine.block_clocks
        word_index = 0
        for t0 in range(0, T, block):
            t1 = min(T, t0 + block)
            segments = self._segments(state.clock + t0, t1 - t0)
            for p0 in range(0, P, BLOCK_PIXELS):
                p1 = min(P, p0 + BLOCK_PIXELS)
                acc, sfc, ovf, m = (a[p0:p1] for a in flat)
                # Work buffers are kept for full-length blocks only, so odd chunk
                # lengths do not pile up buffers of every partial length.
                C, acc[:] = self._engine.dynamics(e[t0:t1, p0:p1], acc, reuse=t1 - t0 == block)
                self._count(C, segments, sfc, ovf, m, words[word_index:, p0:p1])
            word_index += sum(1 for seg in segments if seg[3])
        state.clock += T
        return words.reshape(n_words, H, W)

    def _segments(self, clock: int, length: int) -> list[tuple[int, int, int, bool]]:
        """Pieces of a block inside one readout interval: (row a, row b, phase at a, ends interval)."""
        L = self.config.clocks_per_readout
        pieces, a = [], 0
        while a < length:
            phase = (clock + a) % L
            b = min(length, a + L - phase)
            pieces.append((a, b, phase, phase + (b - a) == L))
            a = b
        return pieces

    def _count(self, C, segments, sfc, ovf, m, words) -> None:
        """Update sfc/ovf/m from the idle counts C of a block (N_t = t + 1 + C_t) and emit finished words."""
        config = self.config
        p_max, F = config.p_max, config.clocks_per_tick
        before = np.zeros(sfc.shape[0], np.int64)     # N_{a-1}, block-relative
        k = 0
        for a, b, phase, ends in segments:
            if C is NO_SPIKES:
                after = before                    # no pixel fired: sfc, ovf, m unchanged
            elif C is EVERY_CLOCK:                # every pixel fired on every clock
                after = np.full(sfc.shape[0], b, np.int64)
            else:                                 # N_{b-1} = (b - 1) + 1 + C_{b-1}
                after = C[b - 1] + np.int64(b)
            if C is NO_SPIKES:
                pass
            elif config.is_te:
                new = sfc + (after - before)
                over = np.flatnonzero(~ovf & (new >= p_max))
                if over.size:
                    # The counter overflows at the first clock t with N_t >= target;
                    # N is nondecreasing. Most overflowing pixels fire on every clock
                    # up to it: the earliest possible clock (one spike per clock)
                    # settles them; the others are bisected between it and b - 1.
                    target = before[over] + (p_max - sfc[over])
                    lo = a + (target - before[over]) - 1
                    if C is not EVERY_CLOCK:
                        flat, width = C.reshape(-1), C.shape[1]
                        late = np.flatnonzero(lo + 1 + np.take(flat, lo * width + over) < target)
                        if late.size:
                            cols, goal = over[late], target[late]
                            low = lo[late] + 1                  # N_{low - 1} < target <= N_{b-1}
                            high = np.full(late.size, b - 1, np.int64)
                            # A fixed number of halvings for all: a settled pixel (low = high)
                            # stays put, and no per-round compaction is paid.
                            for _ in range(int(high[0] - low.min()).bit_length()):
                                mid = (low + high) >> 1
                                reached = np.take(flat, mid * width + cols) + (mid + 1) >= goal
                                np.copyto(high, mid, where=reached)
                                np.copyto(low, mid + 1, where=~reached)
                            lo[late] = low
                    m[over] = (phase + lo - a) // F + 1
                # sfc stays at p_max once overflowed and is below it otherwise, so
                # min(new, p_max) freezes overflowed counters and latches new ones.
                np.minimum(new, self._engine._row(p_max, new.size, np.int64), out=sfc)
                if over.size:
                    ovf[over] = True
            else:
                np.minimum(sfc + (after - before), config.ml_max, out=sfc)
            if ends:
                k += 1
                if config.is_msb:                 # that power of two leaves; the rest counts on
                    words[k - 1] = msb_index(sfc)
                    sfc -= np.where(sfc > 0, np.left_shift(1, np.maximum(words[k - 1] - 1, 0)), 0)
                    before = after
                    continue
                words[k - 1] = readout_word(config, sfc, ovf, m)
                sfc[:] = 0
                ovf[:] = False
                m[:] = 0
            before = after


def iter_chunks(stimulus: np.ndarray, config: SensorConfig,
                chunk_elements: int = DEFAULT_CHUNK_ELEMENTS) -> Iterator[np.ndarray]:
    """Split (T, H, W) into whole-readout chunks of about ``chunk_elements`` values."""
    T, H, W = stimulus.shape
    L = config.clocks_per_readout
    step = max(1, chunk_elements // max(1, H * W * L)) * L
    for start in range(0, T, step):
        yield stimulus[start:start + step]


def simulate(config: SensorConfig, stimulus: np.ndarray,
             chunks: Iterable[np.ndarray] | None = None) -> np.ndarray:
    """Stimulus (T, H, W), T a multiple of L -> readout words (T / L, H, W), int64.

    The stimulus is fed in whole-readout chunks (``chunks`` overrides the
    split), so it may be a memory-mapped file larger than memory; each chunk's
    values are checked as it is fed.
    """
    config = SensorConfig.required(config, "simulate")
    check_stimulus(stimulus, config, scan_values=False)
    array = PixelArrayModel(config, stimulus.shape[1:])
    words = np.empty((stimulus.shape[0] // config.clocks_per_readout,) + stimulus.shape[1:], np.int64)
    done = 0
    if chunks is not None:
        try:
            chunks = iter(chunks)
        except TypeError:                                # (an int had been "not iterable")
            raise InputError(f"chunks {chunks!r}: must be an iterable of (t, H, W) stimulus arrays") from None
    for chunk in (chunks if chunks is not None else iter_chunks(stimulus, config)):
        part = array.feed(np.asarray(chunk))
        words[done:done + len(part)] = part
        done += len(part)
    if done != len(words) or array.state.clock != stimulus.shape[0]:
        raise InputError(f"chunks covered {array.state.clock} of {stimulus.shape[0]} pixel clocks")
    return words
