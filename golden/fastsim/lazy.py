"""The lazy path: dim light, no draw until the next threshold crossing.

Taken by a pixel-readout with an interval mean of at most ``2 theta``
(:data:`LAZY_THRESHOLDS`), no dark electrons and ``acc < theta``; the path
classifies its own pixels (:func:`lazy_path`) before the others are classified
(:mod:`.plan`). In light-time (tau grows by the interval's expected electrons)
the electrons are a unit-rate Poisson process, so the crossing ``n = theta - acc``
electrons after a sync comes ``Gamma(n)`` later, then ``Gamma(theta)`` from
crossing to crossing; an interval only subtracts its mean from what remains.
The charge between syncs is drawn only when a pixel leaves the path
(:func:`sync`) or the simulator's ``acc`` is read (:func:`lazy_charge`); a pixel
that leaves for event light at a crossing in the interval needs none
(:func:`cross_out`: the electrons after the crossing are a fresh Poisson draw).
"""

from __future__ import annotations

import numpy as np

from ..config import SensorConfig
from ..light import log_poisson_tail_above
from .bisection import largest_below
from ..poisson_rejection import poisson_draws
from .words import NO_PIXELS, ml_words, overflow_clock_word

#: Interval mean, in thresholds, up to which dim light takes the lazy path.
LAZY_THRESHOLDS = 2.0


def lazy_level(config: SensorConfig, budget: float, mean_event: float) -> float:
    """Largest interval mean of the lazy path: at most ``LAZY_THRESHOLDS`` thresholds (two
    crossings a readout or fewer: one Gamma draw per crossing, about 25 ns with its
    bookkeeping, against the event path's Poisson draw per readout, about 40 ns;
    measured best between 1.5 and 3 theta on the panorama pans of docs/simulator.md),
    event light per clock (``mean_event``, at most one crossing a clock, so each
    crossing is a spike in its clock) and, TE, light that surely cannot fire the 2^b1
    spikes of an overflow in one interval."""
    c = config
    mean = min(c.threshold * LAZY_THRESHOLDS, mean_event * c.clocks_per_readout)
    if c.is_te:
        mean = min(mean, largest_below(lambda m: log_poisson_tail_above(m, (c.p_max - 1) * c.threshold),
                                       budget, (c.p_max - 1) * c.threshold))
    return mean


class LazyState:
    """The lazy pixels of a simulator (flat, n): ``mask`` which are on the path,
    ``remaining`` the light-time still to the next threshold crossing, ``span``
    the light-time from the last sync to that crossing (values of pixels off the
    path are never read)."""

    def __init__(self, n: int):
        self.mask = np.zeros(n, bool)
        self.remaining = np.zeros(n)
        self.span = np.zeros(n)


def lazy_path(sim, expected, dark, words):
    """Dim light (interval mean at most ``levels.mean_lazy``, 2 theta; no dark electrons,
    ``acc < theta``): no random draw until the next threshold crossing.

    Each interval only subtracts expected from the light-time remaining; an
    interval that reaches it fires that spike (a crossing is a spike in its own
    clock, as on the event path) and the charge restarts from 0 at the crossing
    electron: a sync, whose next crossing is ``Gamma(theta)`` later (memoryless),
    maybe again within the interval (a further spike). TE overflow needs
    ``(2^b1 - 1) theta`` electrons after a crossing in one interval, surely not at
    this light (bound). Pixels that leave it are settled by :func:`cross_out` where
    it can, else synced. -> the pixels this readout settled here (a flat mask: those
    on the path and those that crossed out)."""
    c = sim.config
    theta = c.threshold
    state = sim.lazy
    eligible = (expected <= sim.levels.mean_lazy) & (sim.carried < theta)
    if sim.dark_model:
        eligible &= dark == 0
    changed = np.flatnonzero(eligible != state.mask)  # (one pass; few pixels change)
    done = NO_PIXELS
    if changed.size:
        was = state.mask[changed]
        leave = changed[was]
        if leave.size:
            leave, done = cross_out(sim, leave, expected, dark, words)
            sync(sim, leave)
        enter = changed[~was]
        if enter.size:
            need = theta - sim.carried[enter]
            # one scalar shape where every pixel enters from an empty accumulator (the whole frame at the
            # first readout): numpy draws the same values from it, in about half the time
            state.span[enter] = state.remaining[enter] = (
                sim.rng.standard_gamma(float(theta), enter.size) if need.min() == theta
                else sim.rng.standard_gamma(need))
    state.mask = eligible
    # a whole-frame pass, no gather: the other pixels' values are never read
    np.subtract(state.remaining, expected, out=state.remaining)
    hit = eligible & (state.remaining <= 0.0)
    cross = np.flatnonzero(hit)
    if c.is_msb:                                       # msb reads out a remainder left
        ml_words(sim, np.flatnonzero(eligible & ~hit & (sim.sfc > 0)), 0, words)
    if cross.size:
        spikes = np.ones(cross.size, np.int64)
        span = sim.rng.standard_gamma(float(theta), cross.size)
        remaining = state.remaining[cross] + span
        again = np.flatnonzero(remaining <= 0.0)
        while again.size:                              # another crossing in the interval
            spikes[again] += 1
            span[again] = sim.rng.standard_gamma(float(theta), again.size)
            remaining[again] += span[again]
            again = again[remaining[again] <= 0.0]
        sim.carried[cross] = 0
        state.remaining[cross] = remaining
        state.span[cross] = span
        if c.is_te:
            words[cross] = spikes
        else:
            ml_words(sim, cross, spikes, words)
    if done.size:                                      # settled here too, lazy no more
        eligible = eligible.copy()
        eligible[done] = True
    return eligible


def cross_out(sim, leave, expected, dark, words):
    """Lazy pixels ``leave`` that leave the path for brighter event light (at most ``mean_event``
    a clock, no dark electrons), settled here by where their next crossing falls, which the
    path already holds:

    * in this interval (``remaining <= expected``): the crossing at light-time ``remaining``
      is a spike and restarts the charge from 0; the electrons after it are
      ``Poisson(expected - remaining)``, a Poisson process independent of the past, which the
      event path's arithmetic turns into spikes, the charge left and, TE, the clock of an
      overflow (the ``(2^b1 - 1) theta``-th of them, an order statistic of uniform
      light-times after the crossing). No charge is drawn, as :func:`sync` would (a
      Binomial, about 110 ns a pixel);
    * past it (where the lazy level is below a threshold, e.g. 2^b1 = 2): no spike, and the
      charge is drawn at the interval's end (:func:`sync` after ``expected`` has passed).
      Drawn at its start, the crossing known to lie past the interval would be forgotten
      and the interval's electrons drawn afresh (spikes where there are none).

    -> (the pixels left to :func:`sync` at the interval's start, those settled)."""
    c = sim.config
    theta, L = c.threshold, c.clocks_per_readout
    at = sim.lazy.remaining[leave]
    mean = expected[leave]
    event = mean <= sim.levels.mean_event * L
    if sim.dark_model:
        event &= dark[leave] == 0
    if not event.any():
        return leave, NO_PIXELS
    out = event & (at <= mean)
    quiet = leave[event & ~out]
    settled = leave[out]
    if quiet.size:                                      # no crossing in the interval
        sim.lazy.remaining[quiet] -= expected[quiet]
        sync(sim, quiet)
        if c.is_msb:
            ml_words(sim, quiet, 0, words)
    if not settled.size:
        return leave[~event], quiet
    at, mean = at[out], mean[out]
    after = poisson_draws(sim.rng, mean - at)           # electrons after the crossing electron
    fired = after // theta
    sim.carried[settled] = after - fired * theta
    spikes = fired + 1
    done = np.concatenate([settled, quiet]) if quiet.size else settled
    if not c.is_te:
        ml_words(sim, settled, spikes, words)
        return leave[~event], done
    over = np.flatnonzero(spikes >= c.p_max)
    if over.size:
        n = (c.p_max - 1) * theta                      # electrons after the crossing to spike 2^b1
        t = after[over]
        light_time = at[over] + (mean[over] - at[over]) * sim.rng.beta(n, t - n + 1)
        clock = np.minimum((light_time / mean[over] * L).astype(np.int64), L - 1)
        spikes[over] = overflow_clock_word(c, clock)
    words[settled] = spikes
    return leave[~event], done


def sync(sim, sel):
    """Lazy pixels ``sel`` leave the path with their charge drawn (:func:`lazy_charge`)."""
    if not sel.size:
        return
    sim.carried[sel] += lazy_charge(sim, sel, sim.rng)
    sim.lazy.mask[sel] = False


def lazy_charge(sim, sel, rng):
    """Electrons lazy pixels ``sel`` have gathered since their sync, drawn with
    ``rng``: given the crossing at light-time ``span`` after the sync, of which
    ``span - remaining`` has passed, the ``n - 1`` electrons before it are iid
    uniform over the span, so ``Binomial(n - 1, (span - remaining) / span)`` of them
    have come."""
    n = sim.config.threshold - sim.carried[sel]
    span = sim.lazy.span[sel]
    elapsed = span - sim.lazy.remaining[sel]
    return rng.binomial(n - 1, np.where(span > 0, elapsed / np.where(span > 0, span, 1.0), 0.0))
