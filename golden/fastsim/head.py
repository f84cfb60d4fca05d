"""The head path: a few clocks per clock, then a cheap path from the state reached.

Taken by a carried backlog under dim light, or by light above one threshold
per clock on an accumulator too low for the full path's bound: the first h
clocks per clock (cycle-exact), then the rest of the interval by the event,
queue or full path (:mod:`.interval`, :mod:`.window`) chosen from the state
reached, else per clock from it (:mod:`.clock`).
"""

from __future__ import annotations

import numpy as np

from ..reference import PixelState, overflow_word
from ..sensor import PixelArrayModel
from .clock import clock_draws, fallback, run_clocks, state_columns, walk
from .window import full_plan, full_walk, groups, queue_plan, queue_walk, round_window
from .codes import HEAD
from .words import ml_words, overflow_clock_word

#: Per-clock draws (head pixels x clocks per readout) at or below which a readout's heads
#: go per clock instead (:mod:`.clock`, with the pixels already there): a head call costs
#: about 0.3 ms whatever its pixels (a walk of its clocks, then each rest path's own calls),
#: the per-clock path 4-11 us more a pixel at 240 clocks in a call it mostly makes anyway.
#: 8192 is 34 pixels at 240 clocks (a dim interior pan, TE: 5 % less CPU a stripe, about 10
#: heads a readout) and none at 61440; docs/simulator.md, sixteenth round.
HEAD_CLOCK_DRAWS = 8192


def classify_head(levels, at, idx, lam, mean, dark, acc, path, length):
    """Head path for pixels ``idx`` (flat indices; their codes at ``at`` in ``path``) a
    few clocks away from a cheap path: a carried
    backlog (``acc >= theta``) under light that surely drains it, then the
    event path; or light above one threshold per clock with too little
    charge yet for the full path's bound, which a few clocks supply.
    ``length`` gets the head's length (a multiple of MIN_WINDOW). So few heads
    that their per-clock draws are at most HEAD_CLOCK_DRAWS stay per clock (a count
    of the light and the charges, as every path choice is; both paths are exact)."""
    c = levels.config
    theta, L = c.threshold, c.clocks_per_readout
    ok = dark == 0
    # drain: while acc >= theta every clock fires and acc falls by theta - e
    drain = ok & (acc >= theta) & ((mean <= levels.mean_event)
                                   | ((mean <= levels.mean_unclipped) & (lam < levels.rho_queue * theta)))
    clocks = np.zeros(idx.size)
    clocks[drain] = 2.0 * (acc[drain] - theta + 1) / (theta - lam[drain]) + 4.0
    # charge: the full path's bound needs acc >= a_full (each of its two
    # terms below budget - log 2), reached at about lam - theta per clock
    charge = ok & (lam > theta) & (mean <= levels.mean_unclipped)
    if charge.any():
        lc = lam[charge]
        s_full = 2.0 * (lc - theta) / lc
        a_full = np.ceil((np.log(2.0) - levels.budget) / s_full)
        top_ok = np.log(2.0 * L) - s_full * (c.acc_max + 1.0) < levels.budget
        clocks[charge] = 1.5 * np.maximum(a_full - acc[charge], 0.0) / (lc - theta) + 8.0
        charge[charge] = top_ok & (a_full <= c.acc_max)
    size = round_window(clocks)
    head = (drain | charge) & (size <= L // 2)
    if np.count_nonzero(head) * L <= HEAD_CLOCK_DRAWS:
        return
    path[at[head]] = HEAD
    length[idx[head]] = size[head]


def head_paths(sim, sel, length, expected, lam, words):
    """The head path of pixels ``sel`` (flat indices), in groups of one head length each
    (``length``: every pixel's, from the plan)."""
    for h, group in groups(sel, length[sel]):
        head_path(sim, group, h, expected, lam, words)


def head_path(sim, sel, h, expected, lam, words):
    """The first ``h`` clocks per clock through the cycle-exact model, then
    the rest of the interval by the cheapest path the state reached allows:
    event (``acc < theta`` and light below the event level), queue or full (their
    bounds hold from the charge reached), else per clock from that state. The
    choice depends on the head only, never on the rest's electrons, which
    are independent of it, so each outcome keeps its exact law; spikes and
    the TE overflow clock of the rest are shifted by the head's."""
    c = sim.config
    theta, L = c.threshold, c.clocks_per_readout
    n, rest = sel.size, L - h
    e = np.minimum(clock_draws(sim, lam[sel], h), c.input_max)
    st = run_head(c, sim.carried[sel], sim.sfc[sel], e)
    acc_h, sfc_h, ovf, m = st.acc[0], st.sfc[0], st.ovf[0], st.m[0]
    lam_s = lam[sel]
    # the rest's path, from the state after the head and the light only
    levels = sim.levels
    event = (acc_h < theta) & (lam_s <= levels.mean_event)
    queue = ~event & (acc_h < theta) & (lam_s < levels.rho_queue * theta)
    size, b_max = np.zeros(n), np.zeros(n)              # the rest's window lengths, backlog bounds
    if queue.any():
        i = np.flatnonzero(queue)
        queue[i], b_max[i], size[i] = queue_plan(levels, lam_s[i] / theta)
    full = ~event & (lam_s > theta)
    if full.any():
        i = np.flatnonzero(full)
        full[i], size[i] = full_plan(levels, lam_s[i], acc_h[i])
    size = round_window(size)
    queue &= size <= rest // 2
    full &= size <= rest // 2
    spikes = np.zeros(n, np.int64)                      # spikes of the rest
    at = np.full(n, -1, np.int64)                       # TE: clock of the overflow in the rest
    # TE: spikes still needed to overflow (none once it has: a count never reached)
    need = np.where(ovf, L + 1, c.p_max - sfc_h) if c.is_te else np.full(n, L + 1, np.int64)
    settled = np.ones(n, bool)                          # False: words written per clock
    if event.any():
        i = np.flatnonzero(event)
        total = sim.rng.poisson(expected[sel[i]] * (rest / L))
        level = acc_h[i] + total
        spikes[i] = level // theta
        sim.carried[sel[i]] = level - spikes[i] * theta
        over = spikes[i] >= need[i]
        if over.any():
            k = need[i[over]] * theta - acc_h[i[over]]  # electron that makes the overflow spike
            position = sim.rng.beta(k, total[over] - k + 1)
            at[i[over]] = h + np.minimum((position * rest).astype(np.int64), rest - 1)
    for tail in (queue, full):
        i = np.flatnonzero(tail)
        for w, j in groups(i, size[i]):
            own = size[j].astype(np.int64)
            if tail is queue:
                ok, got, end, at_clock, drawn, drawn_rest = queue_walk(sim, sel[j], w, lam, acc_h[j],
                                                                              rest, need[j], b_max[j], h, own)
                at[j[ok & (at_clock >= 0)]] = h + at_clock[ok & (at_clock >= 0)]
            else:
                ok, end, drawn, drawn_rest = full_walk(sim, sel[j], w, lam, acc_h[j], rest, own)
                got = np.full(j.size, rest, np.int64)   # a spike in every clock of the rest
                hit = ok & (rest >= need[j])
                at[j[hit]] = h + need[j[hit]] - 1
            sim.carried[sel[j[ok]]] = end[ok]
            spikes[j[ok]] = got[ok]
            bad = j[~ok]
            if bad.size:
                fallback(sim, sel[bad], drawn[:, ~ok], drawn_rest[~ok], words, state_columns(st, bad), own[~ok])
                settled[bad] = False
    slow = np.flatnonzero(~event & ~queue & ~full)
    if slow.size:
        e = np.minimum(clock_draws(sim, lam_s[slow], rest), c.input_max)
        sim.path_counts["fallback"] += slow.size
        run_clocks(sim, sel[slow], e, words, state_columns(st, slow))
        settled[slow] = False
    done = np.flatnonzero(settled)
    if c.is_te:
        word = np.minimum(sfc_h[done] + spikes[done], c.p_max)
        late = at[done] >= 0
        word[late] = overflow_clock_word(c, at[done][late])
        early = ovf[done]
        word[early] = overflow_word(c, m[done][early])
        words[sel[done]] = word
    elif c.is_msb:
        sim.sfc[sel[done]] = sfc_h[done]
        ml_words(sim, sel[done], spikes[done], words)
    else:
        ml_words(sim, sel[done], sfc_h[done] + spikes[done], words)


def run_head(c, acc0, sfc0, e):
    """The state (a (1, n) :class:`tespike.golden.reference.PixelState`) of pixels from charge
    ``acc0`` and counter ``sfc0`` after the head's electrons ``e`` (h, n) from the start
    of the interval: by :func:`tespike.golden.fastsim.clock.walk` (the cycle-exact trajectory in
    a few array passes), the cycle-exact model where the walk leaves a pixel."""
    h, n = e.shape
    settled, spikes, charge, at = walk(c, acc0, e)
    state = PixelState(h, charge[None].copy(), np.zeros((1, n), np.int64), np.zeros((1, n), bool),
                       np.zeros((1, n), np.int64))
    count = sfc0 + spikes
    if c.is_te:
        state.ovf[0] = count >= c.p_max
        state.sfc[0] = np.minimum(count, c.p_max)
        state.m[0] = np.where(state.ovf[0], at // c.clocks_per_tick + 1, 0)
    else:
        state.sfc[0] = np.minimum(count, c.ml_max)
    rest = np.flatnonzero(~settled)
    if rest.size:
        array = PixelArrayModel(c, (1, rest.size))
        array.state.acc[0] = acc0[rest]
        array.state.sfc[0] = sfc0[rest]
        array.feed(np.ascontiguousarray(e[:, rest]).reshape(h, 1, rest.size))
        for name in ("acc", "sfc", "ovf", "m"):
            getattr(state, name)[0, rest] = getattr(array.state, name)[0]
    return state

