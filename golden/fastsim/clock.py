"""The per-clock path: electrons drawn per pixel clock, then the queue of crossings or the cycle-exact model.

Taken by pixels no shortcut covers (light within about 10 % of one threshold
per clock, where charge backs up and the accumulator can clip), by every
pixel with ``method="per-clock"`` or ``noise=False``, and as the fallback of
the window paths (:mod:`.window`) and the head (:mod:`.head`) where a drawn
window did not settle the outcome. Where few pixels take it, the queue of
crossings over all clocks in a few array passes (:func:`walk_clocks`), kept where no
clock clipped; else the cycle-exact model :class:`tespike.golden.sensor.PixelArrayModel`.
Nothing here classifies: the path is what is left when the others decline.
"""

from __future__ import annotations

import numpy as np

from ..light import deterministic_clock_electrons
from ..poisson import PoissonSampler
from ..poisson_rejection import poisson_draws
from ..reference import PixelState, overflow_word
from ..sensor import PixelArrayModel
from .distinct import distinct
from .words import ml_words, overflow_clock_word

#: Per-clock draws of one call below which numpy's sampler is used (no table).
SMALL_DRAW = 4096

#: Per-clock draws per distinct integer mean below which a call keeps numpy's sampler
#: (:func:`tabled_call`; measured best of 256, 1024 and 4096 on the dim interiors and
#: the drifting log-uniform scene of docs/simulator.md).
TABLE_DRAWS = 1024

#: Pixel clocks x pixels of per-clock electrons held at once (bounds memory).
CLOCK_CHUNK_ELEMENTS = 1 << 21

#: Pixels up to which the per-clock path first tries the walk
#: (:func:`walk_clocks`): a few array passes over all clocks instead of the
#: cycle-exact model's five per clock, whose Python cost dominates for few pixels.
WALK_PIXELS = 512

#: Phases (queue, firing, queue, ...) :func:`walk_clocks` walks before it may leave a
#: pixel to the cycle-exact model (:func:`walk_on`).
MAX_PHASES = 16

#: The costs :func:`walk_on` weighs, measured here (one walk phase and the cycle-exact model on the
#: same electrons, 1 to 64 pixels, L = 240 and 61440): a phase's fixed cost, its cost per
#: (clock, pixel), and the model's per clock (its Python steps, few pixels).
WALK_PHASE_SECONDS = 70e-6
WALK_ELEMENT_SECONDS = 60e-9
MODEL_CLOCK_SECONDS = 4e-6


def walk_on(phase: int, pixels: int, clocks: int) -> bool:
    """Whether :func:`walk` takes another phase (the ``phase``-th, from 0) for its ``pixels`` still
    walking over ``clocks`` clocks: always within MAX_PHASES; past them while the phases so far and
    this one cost less than the cycle-exact model, which walks every clock again from the start
    (at 240 clocks never; at millions of clocks near one threshold a clock, where a pixel alternates
    queue and firing many more times, a few pixels walk on for tens of phases instead of minutes of
    the model's steps). Both are exact on the same electrons: only the time changes."""
    if phase < MAX_PHASES:
        return True
    return (phase + 1) * (WALK_PHASE_SECONDS + pixels * clocks * WALK_ELEMENT_SECONDS) < clocks * MODEL_CLOCK_SECONDS


def clock_path(sim, sel, expected, dark, words):
    """Exact per-clock simulation of the pixels ``sel`` (flat indices) of simulator ``sim``.

    Electrons are drawn straight into the clock-major layout the engine
    steps through (iid clocks: the layout does not change their law)."""
    for part, e in clock_chunks(sim, sel, expected, dark):
        run_clocks(sim, part, e, words)


def clock_chunks(sim, sel, expected, dark):
    """Per-clock electrons ``(L, n)`` of the pixels ``sel``, chunk by chunk: the
    one place the per-clock path draws them (``SceneSimulator.clock_stimulus`` reuses it)."""
    c = sim.config
    L = c.clocks_per_readout
    step = max(1, CLOCK_CHUNK_ELEMENTS // L)
    for start in range(0, sel.size, step):
        part = sel[start:start + step]
        if sim.noise:
            e = path_electrons(sim, expected[part], dark[part])
        else:
            e, sim.fraction[part] = deterministic_clock_electrons(c, expected[part], sim.fraction[part])
            e = np.ascontiguousarray(e.T)
        yield part, e


def path_electrons(sim, expected, dark):
    """Random electrons ``(L, n)`` of one interval, the law of
    :func:`tespike.golden.light.clock_electrons` (Poisson per clock, dark electrons
    multinomial over the clocks, saturated at ``2^E - 1``; no draw where
    every clock surely saturates)."""
    c = sim.config
    L, top = c.clocks_per_readout, c.input_max
    lam = expected / L
    sure = lam >= sim.levels.lam_top                     # (its tail bound below budget)
    if sure.all():
        return np.full((L, expected.size), top, np.int64)
    draw = np.flatnonzero(~sure)
    e = clock_draws(sim, lam[draw], L)
    d = dark[draw]
    if d.any():
        e += sim.rng.multinomial(d, np.full(L, 1.0 / L)).T
    np.minimum(e, top, out=e)
    if draw.size == expected.size:
        return e
    out = np.full((L, expected.size), top, np.int64)
    out[:, draw] = e
    return out


def clock_draws(sim, lam, clocks):
    """Per-clock photo-electrons ``(clocks, n)``, iid Poisson(lam[j]) in column j.

    The fast method draws them with :class:`tespike.golden.poisson.PoissonSampler`
    (tables of the integer part of the mean, 3-5x cheaper than numpy's
    sampler per draw; same law to float64 precision, tables cut where the
    tail is below the per-clock budget); ``method="per-clock"``, the
    reference the shortcuts are tested against, and ``clock_stimulus``
    keep numpy's ``Generator.poisson``; the calls :func:`tabled_call` declines go to
    :func:`tespike.golden.poisson_rejection.poisson_draws` (numpy's method as array passes)."""
    if sim.method == "per-clock":
        return sim.rng.poisson(lam[None, :], size=(clocks, lam.size))
    if not tabled_call(lam, clocks):
        return poisson_draws(sim.rng, np.broadcast_to(lam[None, :], (clocks, lam.size)))
    if sim.sampler is None:
        sim.sampler = PoissonSampler(sim.budget)
    return sim.sampler.draw(sim.rng, lam, clocks=clocks)


def tabled_call(lam, clocks, draws=None) -> bool:
    """Whether ``clocks`` per-clock draws of each mean in ``lam`` (``draws`` of them in all
    where the windows are padded to ``clocks``: :func:`tespike.golden.fastsim.window.window_draws`)
    go to the table sampler:
    at least SMALL_DRAW draws, and at least TABLE_DRAWS per distinct integer mean (a
    table costs 0.15-0.7 ms to build and a call of the sampler a fixed 0.2 ms or so,
    numpy's sampler 45-65 ns a draw at these means: the window paths of a wide-range
    scene make calls of a few hundred pixels with as many distinct means, which the
    untabled route, :func:`tespike.golden.poisson_rejection.poisson_draws`, draws for less).
    Decided from the means alone (never from the cache or a draw):
    both samplers have the Poisson law, so the choice changes a seed's stream only."""
    draws = lam.size * clocks if draws is None else draws
    if draws < SMALL_DRAW:
        return False
    g = lam.astype(np.int64)
    low, high = int(g.min()), int(g.max())
    if (high - low + 1) * TABLE_DRAWS <= draws:         # few enough whatever they are
        return True
    # count the distinct means: one bincount over their range where it is short, else a sort
    count = np.count_nonzero(np.bincount(g - low)) if high - low < 1 << 16 else distinct(g).size
    return draws >= TABLE_DRAWS * count


def walk_clocks(sim, sel, e, words, start=None):
    """Pixels ``sel`` on electrons ``e`` (clocks, n) by :func:`walk`, from the start of the
    interval or from ``start`` (a (1, n) :class:`tespike.golden.reference.PixelState`
    part-way through it, after a head) -> mask of the pixels settled there (their
    words, charges and msb remainders written; the others untouched, for the
    cycle-exact model)."""
    c = sim.config
    if start is None:
        acc0, count0, need = sim.carried[sel], 0, None
    else:
        acc0, count0 = start.acc[0], start.sfc[0]
        # TE: spikes still needed to overflow (none once it has: a count never reached)
        need = np.where(start.ovf[0], e.shape[0] + 1, c.p_max - count0) if c.is_te else None
    settled, spikes, charge, at = walk(c, acc0, e, need)
    done, total = sel[settled], spikes[settled]
    sim.carried[done] = charge[settled]
    if start is not None:
        count0 = count0[settled]
    if c.is_msb:
        if start is not None:
            sim.sfc[done] = count0                      # the head's counter: remainder and its spikes
        ml_words(sim, done, total, words)
        return settled
    if not c.is_te:
        ml_words(sim, done, count0 + total, words)
        return settled
    h = 0 if start is None else start.clock
    word = np.minimum(count0 + total, c.p_max)
    late = at[settled] < e.shape[0]                     # overflow in these clocks
    word[late] = overflow_clock_word(c, h + at[settled][late])
    if start is not None:
        early = start.ovf[0][settled]                   # overflowed in the head: its latched tick
        word[early] = overflow_word(c, start.m[0][settled][early])
    words[done] = word
    return settled


def walk(c, acc0, e, need=None):
    """Pixels from charge ``acc0`` (n,) over electrons ``e`` (clocks, n) from the start
    of an interval (or of its rest, after a head): the trajectory of the cycle-exact model in a few array passes over
    all clocks per phase instead of five per clock (whose Python cost dominates for
    few pixels).

    A pixel alternates two phases, each exact while its condition holds, and a phase
    ends at the first clock where it fails, from that clock's exact state:

    * **queue** (no clock clips the accumulator): the pixel is a queue whose arrivals
      are the crossings ``D_t = floor((a + e_1 + .. + e_t) / theta)`` (``a`` the charge
      the phase starts from) and which serves one a clock, so the backlog
      ``B_t = D_t - S_t`` (S_t spikes so far, ``B_0 = D_0``) follows Lindley,
      ``B_t = W_t - min(0, min_{1<=k<=t} W_k)`` with ``W_t = D_t - t``, and the charge
      is ``a + e_1 + .. + e_t - theta S_t``. It ends at the first clock whose charge
      so computed exceeds ``2^A - 1``: that clock's spike is right, its charge is
      ``2^A - 1``, and the **firing** phase starts from it;
    * **firing** (a spike in every clock): the charge is ``2^A - 1 - u_t`` with the
      deficit ``u_t = max(u_{t-1} + theta - e_t, 0)`` (Lindley again: the clip at
      ``2^A - 1`` is the reflection), so ``u_t = V_t - min(-u_0, min_{k<=t} V_k)``,
      ``V_t`` the sum of ``theta - e``. It ends at the first clock whose input leaves
      the charge below theta (no spike, charge ``x + e`` unclipped): the queue phase
      starts from it.

    Nothing is drawn or bounded: each phase is checked on the electrons themselves.
    Pixels still walking when :func:`walk_on` says the model is cheaper are left to the
    cycle-exact model on the same electrons. -> (settled mask, spikes, end charge, TE: the 0-based clock of
    spike ``need`` (per pixel; default 2^b1) or ``clocks`` where it did not fire), the
    last three valid where settled."""
    theta, top = c.threshold, c.acc_max
    L, n = e.shape
    clocks = np.arange(L)[:, None]
    done_clocks = np.zeros(n, np.int64)                 # clocks walked so far
    charge = np.array(acc0, np.int64)
    spikes = np.zeros(n, np.int64)
    at = np.full(n, L, np.int64)                        # TE: 0-based clock of spike 2^b1 (L: none)
    settled = np.zeros(n, bool)
    need = np.full(n, c.p_max, np.int64) if need is None else np.asarray(need, np.int64)
    active = np.arange(n)
    phase = 0
    while active.size and walk_on(phase, active.size, L):
        s0, a, before = done_clocks[active], charge[active], spikes[active]
        ea = e[:, active]
        later = clocks >= s0                            # the clocks still to walk
        cols = np.arange(active.size)
        if phase % 2 == 0:                              # queue: until the first clip
            level = np.cumsum(np.where(later, ea, 0), axis=0)
            level += a
            crossed = level // theta
            queue = crossed - np.maximum(clocks + 1 - s0, 0)
            low = np.minimum.accumulate(queue, axis=0)
            np.minimum(low, 0, out=low)
            fired = crossed - (queue - low)             # spikes since the phase began
            after = level - theta * fired
            clip = after > top
            stops = clip.any(axis=0)
            last = np.where(stops, np.argmax(clip, axis=0), L - 1)   # last clock walked right
            total = before + fired[last, cols]
            end = np.where(stops, top, after[last, cols])
            if c.is_te:
                reach = later & (fired + before[None] >= need[active][None]) & (clocks <= last)
                at[active] = np.minimum(at[active], np.where(reach.any(axis=0), np.argmax(reach, axis=0), L))
        else:                                           # firing: until the first clock without a spike
            deficit = np.cumsum(np.where(later, theta - ea, 0), axis=0)
            low = np.minimum.accumulate(deficit, axis=0)
            np.minimum(low, (a - top)[None], out=low)
            x = top - (deficit - low)
            prev = np.concatenate([a[None], x[:-1]], axis=0)
            miss = later & (prev + ea < theta)
            stops = miss.any(axis=0)
            last = np.where(stops, np.argmax(miss, axis=0), L - 1)
            total = before + last + 1 - s0 - stops      # a spike in every clock but the stopping one
            end = np.where(stops, prev[last, cols] + ea[last, cols], x[-1])
            if c.is_te:
                goal = need[active]
                reach = s0 + goal - before - 1              # clock of spike ``need`` if all fire
                hit = (before < goal) & (reach <= last - stops)
                at[active[hit]] = np.minimum(at[active[hit]], reach[hit])
        spikes[active], charge[active] = total, end
        done_clocks[active] = last + 1
        finished = active[~stops | (last == L - 1)]
        settled[finished] = True
        active = active[stops & (last < L - 1)]
        phase += 1
    return settled, spikes, charge, at


def run_clocks(sim, sel, e, words, start=None):
    """The cycle-exact model (:class:`tespike.golden.sensor.PixelArrayModel`, clock for clock
    the literal rule of SPEC section 3) on electrons ``e`` (clocks, n) of pixels
    ``sel``, from the start of the interval or from ``start`` (a
    :class:`tespike.golden.reference.PixelState` of shape (1, n) part-way through it)."""
    if sim.method == "fast" and 0 < sel.size <= WALK_PIXELS:
        settled = walk_clocks(sim, sel, e, words, start)
        if settled.all():
            return
        left = ~settled
        sel, e = sel[left], e[:, left]
        if start is not None:
            start = state_columns(start, left)
    array = PixelArrayModel(sim.config, (1, sel.size))
    if start is None:
        array.state.acc[0] = sim.carried[sel]
        array.state.sfc[0] = sim.sfc[sel]               # 0 except the msb remainder
    else:
        array.state = start
    w = array.feed(e.reshape(e.shape[0], 1, sel.size))
    words[sel] = w[0, 0]
    sim.carried[sel] = array.state.acc[0]
    if sim.config.is_msb:
        sim.sfc[sel] = array.state.sfc[0]


def state_columns(state, i):
    """Pixels ``i`` of a (1, n) :class:`tespike.golden.reference.PixelState` (copies)."""
    return PixelState(state.clock, *(a[:, i] for a in (state.acc, state.sfc, state.ovf, state.m)))


def fallback(sim, sel, window, rest, words, start=None, own=None):
    """Per-clock path for pixels whose window did not settle their outcome:
    the drawn window and rest total are kept (the rest spread as a uniform
    multinomial, which is its law given the total), so nothing is redrawn.
    ``start``: the pixels' state part-way through the interval (after a
    head, :mod:`.head`); by default the start of the interval. ``own``: each
    pixel's window length where windows of several lengths were padded into one
    block (:func:`tespike.golden.fastsim.window.window_rows`): its last ``own[j]`` rows."""
    if not sel.size:
        return
    w = window.shape[0]
    if own is not None and own.min() < w:              # (rare: one call per window length)
        for length in distinct(own).tolist():
            part = np.flatnonzero(own == length)
            fallback(sim, sel[part], window[w - length:, part], rest[part], words,
                     None if start is None else state_columns(start, part))
        return
    c = sim.config
    clocks = c.clocks_per_readout - (start.clock if start is not None else 0)
    head = sim.rng.multinomial(rest, np.full(clocks - w, 1.0 / (clocks - w)))
    e = np.minimum(np.concatenate([head.T, window], axis=0), c.input_max)
    sim.path_counts["fallback"] += sel.size
    run_clocks(sim, sel, e, words, start)
