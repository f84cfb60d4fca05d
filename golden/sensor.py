"""Cycle-exact model of a TE or ML pixel array (SPEC sections 3 and 4), fast and run in chunks.

:class:`PixelArray` gives the same words, clock for clock, as the literal
per-clock rule :func:`golden.reference.step_reference`, but advances whole
blocks of pixel clocks with closed forms instead of a Python step per clock.
State (acc, sfc, ovf, m and the clock phase; with the ML msb readout, sfc
keeps its remainder across readouts) is carried between calls, so a
run split anywhere gives the identical stream, and memory stays bounded by the
chunk size however many readouts a run has.

How it works (derivation in docs/golden-model.md). Per pixel, inside a block
of clocks starting with charge ``acc0`` and with ``Y_t = acc0 + sum_{u<=t}
(e_u - theta)``:

* without accumulator saturation the cumulative spike count is
  ``N_t = min(N_{t-1} + 1, floor(R_t / theta))`` (at most one spike per clock),
  which unrolls to ``N_t = t + 1 + floor(Z_t / theta)`` with
  ``Z_t = min(0, min_{u<=t} Y_u)``, a running minimum; ``acc_t = Y_t -
  theta * floor(Z_t / theta)``;
* a pixel busy on every clock of the block (N_t = t + 1) throws away
  ``D_t = max(0, max_{u<=t} Y_u - M)`` and holds ``acc_t = Y_t - D_t``
  (the top-reflected walk);
* per pixel, exact shortcuts come first (no input and acc0 < theta: no spike;
  every input >= theta: a spike every clock, acc a capped walk, pinned at M
  when every input >= theta + M), and the pixels that both saturate and idle
  in a block, for which no closed form is cheap, are stepped by the literal
  rule restricted to them (five row operations per clock on the subset).

All intermediates are bounded (see :func:`_magnitude_bound`), so the engine
uses int16 or int32 where a block provably fits and int64 otherwise; configurations
whose accumulator is too wide for any block in int64 (acc_bits >= 61) run the
literal per-clock rule, which is exact there by construction.
"""

from __future__ import annotations

from typing import Iterable, Iterator

import numpy as np

from .config import SensorConfig
from .io import check_stimulus
from .reference import PixelState, msb_index, step_reference

#: Pixel clocks x pixels processed at once by :func:`simulate` (bounds memory).
DEFAULT_CHUNK_ELEMENTS = 1 << 22

#: Pixel clocks advanced per closed-form block (rows of the working arrays).
BLOCK_CLOCKS = 16

#: Pixels per block (columns of the working arrays); keeps a block near the L2 cache.
BLOCK_PIXELS = 16384

#: Below this many pixels a time scan uses numpy's accumulate instead of a row loop.
ROW_LOOP_MIN_PIXELS = 512

#: Column subsets larger than this fraction are processed at full width instead of gathered.
GATHER_FRACTION = 0.125

#: The same for the pixels stepped by the literal rule (a gather costs less than
#: stepping the extra columns).
LITERAL_GATHER_FRACTION = 0.5

#: Quiet or pinned pixels (see _Engine.dynamics) above this fraction of a block are
#: split off, and only the others are gathered for the general closed form.
SHORTCUT_FRACTION = 0.5

#: Stands for "no pixel fires in this block" in place of the Z array.
NO_SPIKES = "no spikes"

_INT16_LIMIT = (1 << 15) - 1
_INT32_LIMIT = (1 << 31) - 1
_INT64_LIMIT = (1 << 63) - 1


def _magnitude_bound(config: SensorConfig, clocks: int, top: int | None = None) -> int:
    """Largest |value| any intermediate of a block of ``clocks`` clocks can take.

    With c = clocks * (e_max + theta), e_max = ``top`` or 2^E - 1: |Y| <= M + c,
    0 <= D <= M + c, |Z| <= 2M + 2c, |theta * f| <= 2M + 2c + theta,
    |Y - theta f| <= 3M + 3c + theta.
    """
    c = clocks * ((config.input_max if top is None else top) + config.threshold)
    return 4 * config.acc_max + 3 * c + config.threshold


def _plan(config: SensorConfig) -> tuple[int, np.dtype | None]:
    """Block length and working dtype; ``(0, None)`` means per-clock literal stepping."""
    if _magnitude_bound(config, BLOCK_CLOCKS) <= _INT32_LIMIT:
        return BLOCK_CLOCKS, np.dtype(np.int32)
    clocks = BLOCK_CLOCKS
    while clocks >= 1:
        if _magnitude_bound(config, clocks) <= _INT64_LIMIT:
            return clocks, np.dtype(np.int64)
        clocks //= 2
    return 0, None


def _scan(x: np.ndarray, op: np.ufunc, seed: int | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """Running ``op`` (add, minimum, maximum) of ``x`` along axis 0 into ``out`` (default: in place).

    ``seed`` joins row 0. Wide arrays are scanned by a loop over rows (one
    vector op per clock over all pixels), several times faster in numpy than
    ``accumulate`` along axis 0; narrow arrays use ``accumulate``, whose cost
    does not grow with the Python loop.
    """
    out = x if out is None else out
    if seed is not None:
        op(x[0], seed, out=out[0])
    elif out is not x:
        out[0] = x[0]
    if x.shape[1] >= ROW_LOOP_MIN_PIXELS:
        rows_in = list(x)                               # row views made in one C loop
        rows_out = rows_in if out is x else list(out)
        for i in range(1, len(rows_in)):
            op(rows_out[i - 1], rows_in[i], out=rows_out[i])
    elif x.shape[0] > 1:
        if out is not x:
            out[1:] = x[1:]
        op.accumulate(out, axis=0, out=out)
    return out


class _Engine:
    """The closed forms for one configuration (no state; :class:`PixelArray` holds it).

    :meth:`dynamics` returns, per block, an array ``Z`` with the cumulative
    spike count ``N_t = t + 1 + floor(Z_t / theta)`` (t from 0 at the block
    start), and the charge after the block.
    """

    def __init__(self, config: SensorConfig):
        self.config = config
        self.theta = config.threshold
        self.acc_max = config.acc_max
        self.block_clocks, self.dtype = _plan(config)
        # Saturation needs a spike with acc + e - theta > M >= acc, so e > theta.
        self.may_saturate = config.input_max > config.threshold
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
        """A read-only vector of n copies of ``value`` (a view of one kept per value and dtype)."""
        key = ("row", value, np.dtype(dtype))
        row = self._buffers.get(key)
        if row is None or row.size < n:
            row = np.full(max(n, BLOCK_PIXELS), value, dtype)
            row.flags.writeable = False
            self._buffers[key] = row
        return row[:n]

    def dynamics(self, e: np.ndarray, acc0: np.ndarray, reuse: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Advance pixels over a block: e (T, n) electrons, acc0 (n,) int64 charge -> (Z, acc_end).

        ``Z`` is None when every pixel fired on every clock (N_t = t + 1) and
        NO_SPIKES when none fired. With ``reuse`` the returned Z lives in a
        buffer that the next call with ``reuse`` overwrites (the caller
        consumes it first).

        Quiet, firing and pinned pixels take their shortcuts; the others get the
        no-saturation closed form, and only pixels that could saturate in this
        block are looked at again (:meth:`_general`): those provably calm keep
        it, those busy on every clock get the reflected-walk form, and the rest
        (a pixel that both saturates and idles) are stepped by :meth:`literal`.
        """
        theta, M = self.theta, self.acc_max
        T, n = e.shape
        emax = e.max(axis=0)
        top = int(emax.max())
        # int16 halves the memory traffic again when this block's own largest input allows it.
        dt = self.dtype
        if _magnitude_bound(self.config, T, top) <= _INT16_LIMIT:
            dt = np.dtype(np.int16)
        # Exact shortcuts, per pixel. Quiet: no input and acc0 < theta, so no spike and acc
        # stays. Firing: every input >= theta; acc >= 0 gives q >= theta, so the pixel fires
        # on every clock (N_t = t + 1) and acc is the capped walk min(acc + e - theta, M);
        # pinned: every input >= theta + M, so acc = M after the block.
        quiet = (emax == 0) & (acc0 < theta)
        if quiet.all():
            return NO_SPIKES, acc0.copy()
        pinned = None
        # (Row 0 rules out "every pixel fires" cheaply; pinned needs top >= theta + M.)
        if top >= theta + M or (top >= theta and int(e[0].min()) >= theta):
            emin = e.min(axis=0)
            if int(emin.min()) >= theta:
                if int(emin.min()) - theta >= M:
                    return None, np.full(n, M, np.int64)
                acc = acc0.astype(dt)
                theta_row, M_row = self._row(theta, n, dt), self._row(M, n, dt)
                for row in e:
                    np.add(acc, row, out=acc, dtype=dt, casting="unsafe")
                    np.subtract(acc, theta_row, out=acc)
                    np.minimum(acc, M_row, out=acc)
                return None, acc.astype(np.int64)
            pinned = emin >= theta + M if top >= theta + M else None
        # Pixels that surely saturate (an input > theta + M) and may idle (an input < theta)
        # would fail the closed form and be stepped anyway: step them at once.
        direct = None
        if pinned is not None:
            direct = (emax > theta + M) & (emin < theta)
        special = quiet if pinned is None else quiet | pinned | direct
        n_special = int(np.count_nonzero(special))
        if n_special <= SHORTCUT_FRACTION * n:
            return self._general(e, acc0, emax, dt, reuse, pinned)
        # Enough quiet, pinned or stepped pixels to pay for gathering the others (a column
        # gather costs about two passes): only those get the general closed form.
        Z = self._array("Zout", (T, n), dt, reuse)
        Z[:] = self._quiet_column(T, dt)                     # quiet: N_t = 0
        acc_end = acc0.copy()
        if pinned is not None and pinned.any():
            pin = np.flatnonzero(pinned)
            Z[:, pin] = 0                                    # pinned: N_t = t + 1
            acc_end[pin] = M
        if direct is not None and direct.any():
            step = np.flatnonzero(direct)
            Z[:, step], acc_end[step] = self.literal(e[:, step], acc0[step], dt)
        rest = np.flatnonzero(~special)
        if rest.size:
            Zr, acc_r = self._general(e[:, rest], acc0[rest], emax[rest], dt, False)
            # (Never NO_SPIKES: a pixel that is not quiet has input or acc0 >= theta.)
            Z[:, rest] = 0 if Zr is None else Zr
            acc_end[rest] = acc_r
        return Z, acc_end

    def _quiet_column(self, T: int, dt: np.dtype) -> np.ndarray:
        """Z of a pixel that does not fire in a block of T clocks: theta * (0 - t - 1), as (T, 1)."""
        return (-self.theta * np.arange(1, T + 1, dtype=np.int64)).astype(dt)[:, None]

    def _general(self, e, acc0, emax, dt, reuse, pinned=None):
        """:meth:`dynamics` for any pixels: the closed form, corrected where it may saturate.

        ``pinned`` (optional) marks pixels known to fire on every clock and end at M;
        they skip the busy-walk test.
        """
        theta, M = self.theta, self.acc_max
        T, n = e.shape
        Y = self._array("Y", (T, n), dt, reuse)
        np.subtract(e, theta, out=Y, dtype=dt, casting="unsafe")
        Y[0] += acc0.astype(dt)
        _scan(Y, np.add)                                   # Y_t = acc0 + sum (e - theta)
        # A pixel whose Y never drops below 0 fires on every clock under the closed
        # form: its running minimum is 0, no scan needed (the common case when bright).
        # Z = None stands for all zeros (every pixel fires on every clock: N_t = t + 1).
        never_idle = Y.min(axis=0) >= 0
        if never_idle.all():
            Z = None
            acc_end = Y[-1].astype(np.int64)
        else:
            Z = _scan(Y, np.minimum, seed=self._row(0, n, dt), out=self._array("Z", (T, n), dt, reuse))
            acc_end = (Y[-1] - theta * (Z[-1] // theta)).astype(np.int64)
        # Saturation needs e > theta on some clock. A pixel that never idles under the
        # closed form (Z = 0: Y_t >= 0) and never holds more than M (Y <= M) is exact;
        # one that never idles but exceeds M saturates under it for sure.
        unsure = emax > theta
        if not unsure.any():
            return Z, acc_end
        unsure &= ~never_idle | (Y.max(axis=0) > M)
        if pinned is not None:
            # Y >= 0 there (Z = 0: N_t = t + 1 is right already); only acc needs its cap.
            unsure &= ~pinned
            np.copyto(acc_end, M, where=pinned)
        if not unsure.any():
            return Z, acc_end
        if Z is None:
            Z = self._array("Z", (T, n), dt, reuse)
            Z.fill(0)
        # Two kinds of unsure pixels. Busy on every clock implies Y >= 0 (never idle),
        # so only never-idle pixels (which exceed M under the closed form) can be busy;
        # idle ones get the calm bound and, failing it, the exact check.
        walkers = unsure & never_idle
        if walkers.any():
            self._walkers(_Columns(walkers), e, Y, Z, acc0, acc_end, reuse)
        idlers = unsure & ~never_idle
        if idlers.any():
            self._idlers(_Columns(idlers), e, Y, Z, acc0, acc_end, reuse)
        return Z, acc_end

    def _walkers(self, cols, e, Y, Z, acc0, acc_end, reuse):
        """Pixels with Y >= 0 throughout and Y > M somewhere: busy walk, else the literal rule.

        The charge a pixel busy on every clock throws away is D_t = Dm_t - M with
        Dm_t = max(M, max_{u<=t} Y_u); it is busy on every clock iff Y_t >= D_{t-1}
        for all t, and then N_t = t + 1 (Z = 0 already) and acc = Y - D exactly.
        """
        theta, M, dt = self.theta, self.acc_max, Y.dtype
        T = Y.shape[0]
        Yu = cols.take(Y)
        Dm = _scan(Yu, np.maximum, seed=self._row(M, Yu.shape[1], dt), out=self._array("Dm", Yu.shape, dt, reuse and cols.full))
        busy = Yu[0] >= 0
        if T > 1:
            gap = np.subtract(Yu[1:], Dm[:-1], out=self._array("tmp", Yu.shape, dt, reuse and cols.full)[1:])
            busy &= gap.min(axis=0) >= -M
        busy = cols.local(busy)
        acc_u = cols.take_vector(acc_end)
        walk_end = np.subtract(Yu[-1], Dm[-1])                  # in dt: |Y - Dm| <= the bound
        walk_end += M
        np.copyto(acc_u, walk_end, where=busy)
        rest = cols.local(~busy)
        if rest.any():
            # Not busy: the closed form exceeds M (Y > M with Z = 0), so these saturate
            # and idle in the block; they are stepped by the literal rule.
            self._step_subset(_Columns(rest, gather_fraction=LITERAL_GATHER_FRACTION), cols.take(e),
                              cols.take_vector(acc0), cols, Z, acc_u)
        cols.put_vector(acc_end, acc_u)

    def _idlers(self, cols, e, Y, Z, acc0, acc_end, reuse):
        """Pixels that idle under the closed form and may saturate: a bound, else the literal rule.

        acc_t = Y_t - theta floor(Z_t / theta) <= Y_t - Z_t + theta - 1, so
        max(Y - Z) <= M - theta + 1 proves the block calm. The others are
        stepped clock by clock: that costs about five row operations per clock
        on the subset, less than checking the closed form (four passes) and then
        iterating the saturation fixed point on the pixels that fail it.
        """
        theta, M, dt = self.theta, self.acc_max, Y.dtype
        Yu, Zu = cols.take(Y), cols.take(Z)
        work = self._array("tmp", Yu.shape, dt, reuse and cols.full)
        np.subtract(Yu, Zu, out=work)
        suspect = cols.local(work.max(axis=0) > M - theta + 1)
        if not suspect.any():
            return
        acc_u = cols.take_vector(acc_end)
        self._step_subset(_Columns(suspect, gather_fraction=LITERAL_GATHER_FRACTION), cols.take(e),
                          cols.take_vector(acc0), cols, Z, acc_u)
        cols.put_vector(acc_end, acc_u)

    def _step_subset(self, sub, e, acc0, cols, Z, acc_out):
        """Overwrite Z and the end charge of the pixels in ``sub`` (within ``cols``) by literal steps."""
        Zs, acc_s = self.literal(sub.take(e), sub.take_vector(acc0), Z.dtype)
        Zu = cols.take(Z)
        sub.put(Zu, Zs)
        cols.put(Z, Zu)
        sub.put_vector(acc_out, acc_s)

    def literal(self, e, acc0, dt):
        """SPEC section 3 clock by clock on (T, k) pixels in ``dt``: -> (Z = theta (N_t - t - 1), acc_end).

        Exact for any pixel (the magnitude bound of the block covers acc + e and
        theta T); used where the closed form would need correcting.
        """
        theta, M = self.theta, self.acc_max
        T, k = e.shape
        acc = acc0.astype(dt)
        q, cut = np.empty(k, dt), np.empty(k, dt)
        spike = np.empty(k, bool)
        counts = np.empty((T + 1, k), dt)            # N_{t-1}, block-relative
        counts[0] = 0
        rows = list(counts)
        # Constant rows instead of scalars: numpy's minimum with a scalar is several
        # times slower than with an array, and a masked subtract slower than two ops.
        theta_row, M_row = self._row(theta, k, dt), self._row(M, k, dt)
        for t in range(T):
            np.add(acc, e[t], out=q, dtype=dt, casting="unsafe")     # q = acc + e
            np.greater_equal(q, theta_row, out=spike)
            np.multiply(spike, theta_row, out=cut)
            np.subtract(q, cut, out=q)                              # q - theta * spike
            np.minimum(q, M_row, out=acc)
            np.add(rows[t], spike, out=rows[t + 1], dtype=dt)
        Z = counts[1:]
        Z -= np.arange(1, T + 1, dtype=dt)[:, None]
        Z *= theta
        return Z, acc.astype(np.int64)


class _Columns:
    """A subset of pixel columns; gathers only when it is small.

    Fancy-indexing columns of a (T, n) array costs several times a plain pass,
    so a subset of more than GATHER_FRACTION of the columns is worked on in
    place at full width (the extra columns are computed and then ignored).
    """

    def __init__(self, mask: np.ndarray, gather_fraction: float | None = None):
        self.mask = mask
        fraction = GATHER_FRACTION if gather_fraction is None else gather_fraction
        self.full = mask.all() or fraction * mask.size < int(np.count_nonzero(mask))
        self.index = None if self.full else np.flatnonzero(mask)

    def local(self, mask: np.ndarray) -> np.ndarray:
        """A mask computed over the taken columns, restricted to this subset's members."""
        return mask & self.mask if self.full else mask

    def take(self, a: np.ndarray) -> np.ndarray:
        return a if self.full else a[:, self.index]

    def take_vector(self, v: np.ndarray) -> np.ndarray:
        return v if self.full else v[self.index]

    def put(self, a: np.ndarray, values: np.ndarray) -> None:
        if self.full:
            if values is not a:
                np.copyto(a, values, where=self.mask)
        else:
            a[:, self.index] = values

    def put_vector(self, v: np.ndarray, values: np.ndarray) -> None:
        if self.full:
            if values is not v:
                np.copyto(v, values, where=self.mask)
        else:
            v[self.index] = values


class PixelArray:
    """An H x W array of TE or ML pixels that consumes per-clock electrons in chunks."""

    def __init__(self, config: SensorConfig, shape: tuple[int, int]):
        self.config = config
        self.shape = tuple(shape)
        self.state = PixelState.zeros(self.shape)
        self._engine = _Engine(config)

    def feed(self, electrons: np.ndarray) -> np.ndarray:
        """Consume (T, H, W) electrons of any T; return the words (k, H, W) of the readouts completed."""
        check_stimulus(electrons, self.config, whole_readouts=False)
        if electrons.shape[1:] != self.shape:
            raise ValueError(f"chunk shape {electrons.shape[1:]} != array shape {self.shape}")
        if self._engine.dtype is None:
            words, self.state = step_reference(self.config, electrons, self.state)
            return words
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
                Z, acc[:] = self._engine.dynamics(e[t0:t1, p0:p1], acc, reuse=t1 - t0 == block)
                self._count(Z, segments, sfc, ovf, m, words[word_index:, p0:p1])
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

    def _count(self, Z, segments, sfc, ovf, m, words) -> None:
        """Update sfc/ovf/m from the spike counts of a block and emit finished words."""
        config, theta = self.config, self._engine.theta
        p_max, F = config.p_max, config.clocks_per_tick
        before = np.zeros(sfc.shape[0], np.int64)     # N_{a-1}, block-relative
        k = 0
        for a, b, phase, ends in segments:
            if Z is NO_SPIKES:
                after = before                    # no pixel fired: sfc, ovf, m unchanged
            elif Z is None:                       # every pixel fired on every clock
                after = np.full(sfc.shape[0], b, np.int64)
            else:                                 # N_{b-1} = (b - 1) + 1 + floor(Z / theta)
                after = b + Z[b - 1] // theta
            if Z is NO_SPIKES:
                pass
            elif config.is_te:
                new = sfc + (after - before)
                over = np.flatnonzero(~ovf & (new >= p_max))
                if over.size:
                    # The counter overflows at the first clock t with N_t >= target;
                    # N is nondecreasing, so bisect per pixel between the earliest
                    # possible clock (one spike per clock) and b - 1.
                    target = before[over] + (p_max - sfc[over])
                    lo = a + (target - before[over]) - 1
                    hi = np.full(over.size, b - 1, np.int64)
                    if Z is None:
                        hi = lo
                    else:
                        flat, width = Z.reshape(-1), Z.shape[1]
                        # Most overflowing pixels fire on every clock up to it: settle them first.
                        hi = np.where(lo + 1 + np.take(flat, lo * width + over) // theta >= target, lo, hi)
                    while True:
                        open_ = lo < hi
                        if not open_.any():
                            break
                        mid = (lo + hi) // 2
                        reached = mid + 1 + np.take(flat, mid * width + over) // theta >= target
                        hi = np.where(open_ & reached, mid, hi)
                        lo = np.where(open_ & ~reached, mid + 1, lo)
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
                if config.is_te:
                    words[k - 1] = np.where(ovf, (1 << config.d) | m, sfc)
                else:
                    words[k - 1] = sfc
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
    check_stimulus(stimulus, config, scan_values=False)
    array = PixelArray(config, stimulus.shape[1:])
    words = np.empty((stimulus.shape[0] // config.clocks_per_readout,) + stimulus.shape[1:], np.int64)
    done = 0
    for chunk in (chunks if chunks is not None else iter_chunks(stimulus, config)):
        part = array.feed(np.asarray(chunk))
        words[done:done + len(part)] = part
        done += len(part)
    if done != len(words) or array.state.clock != stimulus.shape[0]:
        raise ValueError(f"chunks covered {array.state.clock} of {stimulus.shape[0]} pixel clocks")
    return words
