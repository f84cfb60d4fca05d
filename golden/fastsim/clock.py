"""The per-clock path: electrons drawn per pixel clock, then the queue of crossings or the cycle-exact model.

Taken by pixels no shortcut covers (light within about 10 % of one threshold
per clock, where charge backs up and the accumulator can clip), by every
pixel with ``method="per-clock"`` or ``noise=False``, and as the fallback of
the window paths (:mod:`.window`) and the head (:mod:`.head`) where a drawn
window did not settle the outcome. Where few pixels take it, the queue of
crossings over all clocks in a few array passes (:func:`walk_clocks`), kept where no
clock clipped; else the cycle-exact model :class:`golden.sensor.PixelArray`.
Nothing here classifies: the path is what is left when the others decline.
"""

from __future__ import annotations

import numpy as np

from ..light import deterministic_clock_electrons, log_poisson_tail_below
from ..poisson import PoissonSampler
from ..sensor import PixelArray
from .words import ml_words

#: Per-clock draws of one call below which numpy's sampler is used (no table).
SMALL_DRAW = 4096

#: Pixel clocks x pixels of per-clock electrons held at once (bounds memory).
CLOCK_CHUNK_ELEMENTS = 1 << 21

#: Pixels up to which the per-clock path first tries the unclipped walk
#: (:func:`walk_clocks`): a few array passes over all clocks instead of the
#: cycle-exact model's five per clock, whose Python cost dominates for few pixels.
WALK_PIXELS = 512


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
            e = clock_electrons(sim, expected[part], dark[part])
        else:
            e, sim.fraction[part] = deterministic_clock_electrons(c, expected[part], sim.fraction[part])
            e = np.ascontiguousarray(e.T)
        yield part, e


def clock_electrons(sim, expected, dark):
    """Random electrons ``(L, n)`` of one interval, the law of
    :func:`golden.light.clock_electrons` (Poisson per clock, dark electrons
    multinomial over the clocks, saturated at ``2^E - 1``; no draw where
    every clock surely saturates)."""
    c = sim.config
    L, top = c.clocks_per_readout, c.input_max
    lam = expected / L
    sure = log_poisson_tail_below(lam, top - 1) < sim.budget
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

    The fast method draws them with :class:`golden.poisson.PoissonSampler`
    (tables of the integer part of the mean, 3-5x cheaper than numpy's
    sampler per draw; same law to float64 precision, tables cut where the
    tail is below the per-clock budget); ``method="per-clock"``, the
    reference the shortcuts are tested against, and ``clock_stimulus``
    keep numpy's ``Generator.poisson``, as do calls of fewer than SMALL_DRAW
    draws (a table costs about 0.25 ms to build, 10^4 draws' worth)."""
    if sim.method == "per-clock" or lam.size * clocks < SMALL_DRAW:
        return sim.rng.poisson(lam[None, :], size=(clocks, lam.size))
    if sim.sampler is None:
        sim.sampler = PoissonSampler(sim.budget)
    return sim.sampler.draw(sim.rng, lam, clocks=clocks)


def walk_clocks(sim, sel, e, words):
    """Pixels ``sel`` from the start of the interval on electrons ``e`` (L, n), where
    no clock clips the accumulator: there the pixel is a queue whose arrivals are the
    crossings ``D_t = floor((acc0 + e_1 + .. + e_t) / theta)`` and which serves one a
    clock, so the backlog ``B_t = D_t - S_t`` (S_t spikes so far, ``B_0 = D_0``)
    follows Lindley, ``B_t = W_t - min(0, min_{1<=k<=t} W_k)`` with ``W_t = D_t - t``,
    and the charge is ``acc0 + e_1 + .. + e_t - theta S_t``. A pixel whose charge so
    computed never exceeds ``2^A - 1`` had the very trajectory of the cycle-exact
    model (its ``min`` never acted); the others are left to it, on the same
    electrons (a check of the outcome, not a bound: nothing is drawn again).
    -> mask of the pixels settled here."""
    c = sim.config
    theta = c.threshold
    acc0 = sim.carried[sel]
    level = np.cumsum(e, axis=0)
    level += acc0
    crossed = level // theta
    queue = crossed - np.arange(1, e.shape[0] + 1)[:, None]
    low = np.minimum.accumulate(queue, axis=0)
    np.minimum(low, 0, out=low)
    spikes = crossed - (queue - low)                    # S_t = D_t - B_t
    charge = level - theta * spikes
    ok = charge.max(axis=0) <= c.acc_max
    done, total = sel[ok], spikes[-1, ok]
    sim.carried[done] = charge[-1, ok]
    if not c.is_te:
        ml_words(sim, done, total, words)
        return ok
    over = total >= c.p_max
    at = np.argmax(spikes[:, ok] >= c.p_max, axis=0)   # the clock of spike 2^b1 (0-based)
    words[done] = np.where(over, (1 << c.d) | (at // c.clocks_per_tick + 1), total)
    return ok


def run_clocks(sim, sel, e, words, start=None):
    """The cycle-exact model (:class:`golden.sensor.PixelArray`, clock for clock
    the literal rule of SPEC section 3) on electrons ``e`` (clocks, n) of pixels
    ``sel``, from the start of the interval or from ``start`` (a
    :class:`golden.reference.PixelState` of shape (1, n) part-way through it)."""
    if start is None and sim.method == "fast" and 0 < sel.size <= WALK_PIXELS:
        settled = walk_clocks(sim, sel, e, words)
        if settled.all():
            return
        sel, e = sel[~settled], e[:, ~settled]
    array = PixelArray(sim.config, (1, sel.size))
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


def fallback(sim, sel, window, rest, words, start=None):
    """Per-clock path for pixels whose window did not settle their outcome:
    the drawn window and rest total are kept (the rest spread as a uniform
    multinomial, which is its law given the total), so nothing is redrawn.
    ``start``: the pixels' state part-way through the interval (after a
    head, :mod:`.head`); by default the start of the interval."""
    if not sel.size:
        return
    c = sim.config
    clocks = c.clocks_per_readout - (start.clock if start is not None else 0)
    w = window.shape[0]
    head = sim.rng.multinomial(rest, np.full(clocks - w, 1.0 / (clocks - w)))
    e = np.minimum(np.concatenate([head.T, window], axis=0), c.input_max)
    sim.path_counts["fallback"] += sel.size
    run_clocks(sim, sel, e, words, start)
