"""The queue and full paths: light near one threshold per clock, settled by a window of its last clocks.

``queue``    light below one threshold per clock, no clipping (Lundberg bound):
             spikes follow the threshold crossings through a unit-rate queue;
             the last w clocks are drawn per clock to settle the backlog left
             at readout (:func:`queue_walk`); the TE overflow clock comes from
             the first crossings' light-times, drawn first where they surely
             come before the window (:func:`first_crossings`), else from
             Gamma-gap order statistics of the rest's electrons.
``full``     light above one threshold per clock and a spike in every clock
             sure (Lundberg bound on the walk from the carried charge): word
             known, accumulator from a window of the last clocks (:func:`full_walk`).

A window that does not settle its pixel's outcome sends it per clock with
what was drawn (:func:`tespike.golden.fastsim.clock.fallback`). The head path
(:mod:`.head`) runs the same walks on the rest of an interval.
"""

from __future__ import annotations

import numpy as np

from ..config import SensorConfig
from ..poisson_rejection import poisson_draws
from .clock import clock_draws, clock_path, fallback, tabled_call
from .codes import FULL, QUEUE
from .distinct import distinct, distinct_counts
from .words import NO_PIXELS, firing_words, ml_words, overflow_clock_word

#: Largest backlog bound the queue path accepts, and its shortest window.
MAX_BACKLOG = 64
MIN_WINDOW = 4

#: Pixels of one path processed as one group whatever their window lengths.
SMALL_GROUP = 256

#: Padding entries a block of neighbouring window lengths may add by running at its
#: longest (each pixel keeps its own window: :func:`window_rows`): about the cost of one
#: more call of a window path, half a millisecond, where the table sampler draws the
#: padding too (:func:`window_draws`; numpy's sampler skips it for about 7 ns an entry).
MERGE_DRAWS = 16384


def queue_level(config: SensorConfig, budget: float) -> float:
    """Largest light per clock, in thresholds, of the queue path: ``L exp(-s (acc_max
    + 2 - theta))`` below budget with ``s = 2 (1 - rho)`` (the accumulator never clips)."""
    h = config.acc_max + 2 - config.threshold
    return 1.0 - (np.log(config.clocks_per_readout) - budget) / (2.0 * h)


def classify_window(levels, at, idx, lam, mean, dark, acc, path, length, b_max):
    """Queue or full path for pixels ``idx`` (flat indices; their codes at ``at`` in
    ``path``) near one threshold per clock, where allowed; their window lengths
    (rounded) and queue backlog bounds are written into ``length`` and ``b_max``."""
    theta = levels.config.threshold
    ok = (dark == 0) & (mean <= levels.mean_unclipped)
    rho = lam / theta
    # queue: below the threshold per clock, the accumulator surely never clips
    queue = ok & (acc < theta) & (rho < levels.rho_queue)
    if queue.any():
        sel = idx[queue]
        keep, bound, window = queue_plan(levels, rho[queue])
        path[at[queue][keep]] = QUEUE
        length[sel[keep]] = round_window(window[keep])
        b_max[sel[keep]] = bound[keep]
    # full: above the threshold per clock, a spike in every clock surely
    full = ok & (lam > theta)
    if full.any():
        sel = idx[full]
        keep, window = full_plan(levels, lam[full], acc[full])
        path[at[full][keep]] = FULL
        length[sel[keep]] = round_window(window[keep])


def full_plan(levels, lam, acc):
    """Full path at ``lam`` > theta electrons per clock from charge ``acc`` ->
    (where the bound makes a spike in every clock sure, window length): the
    walk held at ``acc_max`` never goes below 0 (Lundberg, ``s = 2 (lam -
    theta) / lam``: ``exp(-s (acc + 1)) + L exp(-s (acc_max + 1))`` below budget)."""
    c = levels.config
    theta = c.threshold
    s_full = 2.0 * (lam - theta) / lam
    fire = np.logaddexp(-s_full * (acc + 1.0), np.log(c.clocks_per_readout) - s_full * (c.acc_max + 1.0))
    gap = lam - theta
    window = 1.3 * -levels.budget / s_full / gap + 16.0 * lam / gap ** 2
    return fire < levels.budget, window


def queue_plan(levels, rho):
    """Queue path at ``rho`` thresholds per clock -> (where the bound allows the
    path, b_max <= MAX_BACKLOG; backlog bound b_max; window length)."""
    L = levels.config.clocks_per_readout
    theta = levels.config.threshold
    s_queue = 2.0 * (1.0 - rho)                        # Lundberg exponent (see queue_walk)
    # P(backlog >= b at the window) <= L exp(-s ((b - 1) theta + 1)): b_max + 1 is unlikely
    bound = np.floor(((np.log(L) - levels.budget) / s_queue - 1.0) / theta) + 1.0
    bound = np.maximum(bound, 0.0)
    # the Lindley recursion drains b_max in about b_max / (1 - rho) clocks (a crossing's
    # count over them varies by a fraction of one: one more crossing's drain is ample;
    # a window that does not settle only sends its pixel per clock)
    return bound <= MAX_BACKLOG, bound, (bound + 1.0) / (1.0 - rho)


def round_window(clocks: np.ndarray) -> np.ndarray:
    """Window or head lengths rounded up to multiples of MIN_WINDOW, at least
    MIN_WINDOW: pixels of one length are one block, and few lengths mean few blocks."""
    return MIN_WINDOW * np.maximum(1.0, np.ceil(clocks / MIN_WINDOW))


def groups(sel, size):
    """Pixels ``sel`` (any index array) grouped by window (or head) length ``size``, in
    blocks of one length, their longest (a window path pads the shorter windows, each
    pixel keeping its own: :func:`window_rows`; a head runs at the block's length, as
    exact, only dearer): a few pixels go together, and neighbouring lengths share a block
    while the padding it adds stays below MERGE_DRAWS, about what one more call costs
    -> [(length, pixels)]."""
    if sel.size <= SMALL_GROUP:
        return [(int(size.max()), sel)] if sel.size else []
    lengths, counts = distinct_counts(size)
    out, first = [], 0
    for j in range(1, lengths.size + 1):
        if j < lengths.size and (counts[first:j + 1] * (lengths[j] - lengths[first:j + 1])).sum() <= MERGE_DRAWS:
            continue
        block = sel[(size >= lengths[first]) & (size <= lengths[j - 1])] if j - first > 1 else sel[size == lengths[first]]
        out.append((int(lengths[j - 1]), block))
        first = j
    return out


def window_path(sim, code, sel, plan, expected, dark, lam, words):
    """Pixels ``sel`` of path ``code`` (QUEUE or FULL), grouped by window length
    (multiples of MIN_WINDOW) so that each group is one block; a window longer
    than half the interval would cost more than the per-clock path, which takes it."""
    name = "queue" if code == QUEUE else "full"
    L = sim.config.clocks_per_readout
    size = plan.length[sel]
    too_long = size > L // 2
    if too_long.any():
        sim.path_counts[name] -= int(too_long.sum())
        sim.path_counts["clock"] += int(too_long.sum())
        clock_path(sim, sel[too_long], expected, dark, words)
    for w, group in groups(sel[~too_long], size[~too_long]):
        own = plan.length[group].astype(np.int64)
        if code == QUEUE:
            queue_path(sim, group, w, plan.b_max[group], lam, words, own)
        else:
            full_path(sim, group, w, lam, words, own)


def window_rows(w: int, own: np.ndarray) -> np.ndarray:
    """``(w, n)`` bool: the rows of a block of ``w`` clocks that are pixel j's own window,
    its last ``own[j]`` clocks (the rows before them are padding: no electrons, no clock)."""
    return np.arange(w)[:, None] >= (w - own)[None, :]


def window_draw(sim, sel, w, lam, clocks=None, own=None):
    """Electrons of each pixel's last ``own[j]`` of ``clocks`` clocks (default L; iid
    Poisson; ``own`` default ``w``), ``(w, n)`` clock-major with the padding rows of
    :func:`window_rows` at 0, and the total of the other ``clocks - own[j]``; the order
    in which independent clocks are drawn does not change their law."""
    clocks = sim.config.clocks_per_readout if clocks is None else clocks
    window = window_draws(sim, lam[sel], w, own)
    rest = sim.rng.poisson(lam[sel] * (clocks - (w if own is None else own)))
    return window, rest


def window_draws(sim, lam, w, own=None):
    """Per-clock electrons of windows of ``own[j]`` clocks (default all ``w``) in one
    ``(w, n)`` block: column j's last ``own[j]`` rows iid Poisson(lam[j]), its padding rows
    0. :func:`tespike.golden.poisson_rejection.poisson_draws` gets a mean of 0 there (a 0 without
    a draw);
    the table sampler, where :func:`tabled_call` takes the call, draws the block whole and
    the padding is zeroed (draws thrown away are independent of those kept)."""
    if own is None or own.min() >= w:
        return clock_draws(sim, lam, w)
    rows = window_rows(w, own)
    if tabled_call(lam, w, int(own.sum())):
        window = clock_draws(sim, lam, w)
        window *= rows
        return window
    return poisson_draws(sim.rng, np.where(rows, lam[None, :], 0.0))


def queue_path(sim, sel, w, b_max, lam, words, own=None):
    """Light below one threshold per clock and no clipping (bound): spikes
    and the accumulator from :func:`queue_walk` over the whole interval
    (windows of ``own`` clocks in a block of ``w``, backlog bounds ``b_max``)."""
    c = sim.config
    ok, spikes, end, at, window, rest = queue_walk(
        sim, sel, w, lam, sim.carried[sel], c.clocks_per_readout, np.full(sel.size, c.p_max, np.int64), b_max,
        own=own)
    fallback(sim, sel[~ok], window[:, ~ok], rest[~ok], words, own=None if own is None else own[~ok])
    done = sel[ok]
    sim.carried[done] = end[ok]
    if not c.is_te:
        ml_words(sim, done, spikes[ok], words)
        return
    words[done] = np.where(at[ok] >= 0, overflow_clock_word(c, at[ok]), spikes[ok])


def lindley_ends(walk: np.ndarray, *b0s: np.ndarray) -> list[np.ndarray]:
    """Backlogs after the unit-rate queue ``b <- max(b + x_j - 1, 0)`` over the
    rows of a window, from each start backlog in ``b0s`` (n,), given the walk
    ``W_k = sum_{j<=k} (x_j - 1)`` (w, n), in closed form (Lindley):
    ``b_w = max(b0 + W_w, W_w - min_{1<=k<=w} W_k) = W_w - min(-b0, min_k W_k)``;
    one reduction for all starts instead of a Python step per clock."""
    low = walk.min(axis=0)
    return [walk[-1] - np.minimum(-b0, low) for b0 in b0s]


def queue_walk(sim, sel, w, lam, acc0, clocks, need, b_max, offset=0, own=None):
    """``clocks`` clocks of light below one threshold per clock from charge
    ``acc0 < theta``, no clipping (bound): spikes follow the crossings of the
    threshold levels through a unit-rate queue.

    Without clipping, spike j fires at ``s_j = max(c_j, s_{j-1} + 1)``, c_j
    the clock where the charge reaches ``j theta``; the count at the end is
    the crossings minus the backlog left. The backlog entering the window
    of the last ``w`` clocks is at most ``b_max`` (per pixel, bound); the Lindley
    recursion over the window from 0 and from ``b_max`` agreeing settles the
    end backlog. TE: the clock of spike ``need`` (per pixel) when it fires,
    from the first ``need`` crossings, all before the window; where they surely
    are, a clock of its tick (:func:`first_crossings`; ``offset``: the clocks of
    the interval before these, a head's, for the tick). ``own``: each pixel's window
    length (default ``w``), its last ``own[j]`` rows of the block (:func:`window_rows`):
    a padding row has no electrons and serves no crossing, so the walk stays at 0 there,
    which leaves the Lindley minimum (``min(-b0, ...)``, ``b0 >= 0``) unchanged.
    -> (ok, spikes, end accumulator, that clock or -1, window, rest total);
    pixels not ``ok`` go per clock with the window and rest drawn."""
    c = sim.config
    theta = c.threshold
    lam_s = lam[sel]
    span = clocks - (w if own is None else own)       # clocks before each pixel's window
    window = window_draws(sim, lam_s, w, own)
    rest_mean = lam_s * span
    at = np.full(sel.size, -1, np.int64)
    first = NO_PIXELS
    if c.is_te:                                        # crossings surely before the window: drawn first
        first = np.flatnonzero((need <= c.p_max) & (rest_mean >= sim.levels.mean_overflow))
    if first.size:
        at[first], reached, light_time = first_crossings(sim, lam_s[first], acc0[first], need[first],
                                                         span if own is None else span[first],
                                                         b_max[first], offset)
        first, light_time = first[reached], light_time[reached]
        rest_mean[first] -= light_time                 # the electrons after the last of them
    rest = sim.rng.poisson(rest_mean)
    if first.size:
        rest[first] += need[first] * theta - acc0[first]
    level0 = acc0 + rest                               # charge before the window
    levels = np.cumsum(window, axis=0)
    levels += level0
    # the queue's walk W_k = crossings up to window clock k, minus k
    walk = levels // theta
    if own is None or own.min() >= w:
        walk -= (level0 // theta + 1) + np.arange(w)[:, None]
    else:                                              # clocks served: 0 on the padding rows
        walk -= level0 // theta
        walk -= np.maximum(np.arange(1, w + 1)[:, None] - (w - own)[None, :], 0)
    b_lo, b_hi = lindley_ends(walk, np.zeros(sel.size, np.int64), b_max.astype(np.int64))
    ok = b_lo == b_hi
    level_end = levels[-1]
    spikes = level_end // theta - b_lo
    if not c.is_te:
        return ok, spikes, level_end - theta * spikes, at, window, rest
    over = ok & (spikes >= need)
    ok &= ~over | ((need * theta - acc0) <= rest)       # the crossings' ranks lie in the rest
    over &= ok
    late = np.ones(sel.size, bool)
    late[first] = False                                 # (their crossings are drawn: at is set)
    np.copyto(at, -1, where=~over)
    over &= late
    for p in distinct(need[over]):
        i = np.flatnonzero(over & (need == p))
        a, t = acc0[i], rest[i]
        shapes = np.empty((i.size, p + 1))
        shapes[:, 0] = theta - a                       # electron of the first crossing
        shapes[:, 1:p] = theta
        shapes[:, p] = t - (p * theta - a) + 1
        gaps = sim.rng.standard_gamma(shapes)
        position = np.cumsum(gaps[:, :p], axis=1) / gaps.sum(axis=1, keepdims=True)
        span_i = span if own is None else span[i][:, None]
        cross = np.minimum((position * span_i).astype(np.int64), span_i - 1)
        at[i] = (cross - np.arange(1, p + 1)).max(axis=1) + p   # s_p = max_i (c_i + p - i)
    return ok, spikes, level_end - theta * spikes, at, window, rest


def first_crossings(sim, lam, acc0, need, span, b_max, offset=0):
    """TE pixels whose first ``need`` threshold crossings surely come in the first
    ``span`` clocks (``lam span`` at least ``mean_overflow``): their electrons are a
    unit-rate Poisson process in light-time (``lam`` per clock), so crossing ``p = need``
    comes at ``T ~ Gamma(p theta - acc0)``, in clock ``c_p = floor(T / lam)``, and the
    electrons after it are ``Poisson(lam span - T)``, independent of it (the caller draws
    them). Spike p fires at ``s_p = max_i (c_i + p - i)``, in ``[c_p, c_p + b_max]`` (its
    wait is at most the backlog at ``c_p``, which the queue path's bound caps at any clock
    at ``b_max``), and the word reads only its tick (``clocks_per_tick`` clocks, the
    interval starting ``offset`` clocks before these): where that range lies in one tick,
    ``c_p`` is the answer; elsewhere the earlier crossings are drawn given ``T``: the
    shares of ``T`` of the gaps (``Gamma(theta - acc0)``, then ``Gamma(theta)``, one scalar
    shape, drawn a third faster) are a Dirichlet vector independent of their sum. One
    Gamma draw per pixel, and ``p`` more for the few near a tick's end, where drawing
    every crossing took ``p``. ``span``: one number, or one per pixel. -> (a clock in the tick of spike ``p`` (the one ``max_i``
    gives where it was drawn), whether crossing p came within the span (surely; the
    others go the order-statistics way), its light-time)."""
    c = sim.config
    theta, per_tick = c.threshold, c.clocks_per_tick
    last = sim.rng.standard_gamma((need * theta - acc0).astype(np.float64))
    reached = last < lam * span
    at = np.minimum((last / lam).astype(np.int64), span - 1)
    unsure = reached & (need > 1) & ((offset + at) % per_tick + b_max >= per_tick)
    draw = np.flatnonzero(unsure)
    needs = distinct(need[draw]) if draw.size else NO_PIXELS
    for p in needs.tolist():
        i = draw[need[draw] == p] if needs.size > 1 else draw
        gaps = np.empty((p, i.size))
        gaps[0] = sim.rng.standard_gamma((theta - acc0[i]).astype(np.float64))
        sim.rng.standard_gamma(float(theta), (p - 1, i.size), out=gaps[1:])
        np.cumsum(gaps, axis=0, out=gaps)
        times = gaps * (last[i] / gaps[-1])             # crossing i's light-time, given T
        times[-1] = last[i]
        span_i = span if np.ndim(span) == 0 else span[i]     # (per pixel where windows differ)
        cross = np.minimum((times / lam[i]).astype(np.int64), span_i - 1)
        cross -= np.arange(1, p + 1)[:, None]
        at[i] = cross.max(axis=0) + p                   # s_p = max_i (c_i + p - i)
    return at, reached, last


def full_path(sim, sel, w, lam, words, own=None):
    """Light above one threshold per clock, a spike in every clock (bound):
    the word is known and the accumulator comes from :func:`full_walk`."""
    ok, end, window, rest = full_walk(sim, sel, w, lam, sim.carried[sel], sim.config.clocks_per_readout, own)
    fallback(sim, sel[~ok], window[:, ~ok], rest[~ok], words, own=None if own is None else own[~ok])
    done = sel[ok]
    sim.carried[done] = end[ok]
    firing_words(sim, done, words)


def full_walk(sim, sel, w, lam, acc0, clocks, own=None):
    """End accumulator of ``clocks`` clocks that surely all fire (bound): the
    walk ``acc0 + sum(e - theta)`` held at or below ``2^A - 1`` ends at
    ``min(acc0 - R, acc_max - M)``, R the sum of ``theta - e`` and M its
    largest suffix sum. M is read from a window of the last ``w`` clocks
    where the rest provably cannot exceed it (bound); ``own``: each pixel's window
    length (default ``w``), whose padding rows (:func:`window_rows`) add no deficit
    -> (ok, end, window, rest): pixels not ``ok`` go per clock with the window and
    rest drawn."""
    c = sim.config
    theta, acc_max = c.threshold, c.acc_max
    window, rest = window_draw(sim, sel, w, lam, clocks, own)
    if own is None or own.min() >= w:
        deficit = theta - window
    else:
        deficit = window_rows(w, own) * theta - window
    suffix = np.cumsum(deficit[::-1], axis=0)
    m_win = np.maximum(suffix.max(axis=0), 0)
    r_win = suffix[-1]
    lam_s = lam[sel]
    s = 2.0 * (lam_s - theta) / lam_s
    ok = -s * (m_win + 1 - r_win) < sim.budget
    total_deficit = r_win + (clocks - (w if own is None else own)) * theta - rest
    end = np.minimum(acc0 - total_deficit, acc_max - m_win)
    # under the sure event every clock fires, so end >= 0; clip only guards
    # the 2^-64 failure event against an illegal state
    return ok, np.clip(end, 0, acc_max), window, rest
