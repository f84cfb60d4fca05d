"""The event and bright paths: one draw of the interval's total electrons.

``event``    ``acc < theta`` and no clock can get more than ``min(theta, 2^E - 1)``
             electrons (bound). Then no clock holds two threshold crossings, so
             every crossing is a spike in its own clock and no input saturates:
             the interval total ``T ~ Poisson(expected) + dark`` fixes the spike
             count ``floor((acc + T) / theta)`` and the residual
             ``(acc + T) mod theta``; given T the electrons sit in iid uniform
             positions over the L clocks, so the clock of the ``2^b1``-th spike
             (TE overflow) is ``floor(L * Beta(n, T - n + 1))`` with
             ``n = 2^b1 * theta - acc``, the n-th of T uniform order statistics.
             Where the overflow is sure (light at least ``mean_overflow``, no dark
             electrons), the n-th electron comes first instead: at light-time
             ``G ~ Gamma(n)`` of the interval's ``expected`` (a Poisson process), in
             clock ``floor(L G / expected)``, and ``T = n + Poisson(expected - G)``
             (the electrons after it, independent of it): one Gamma draw and the
             Poisson draw, where the Beta costs two Gammas besides.
``bright``   every clock surely gets at least ``theta`` electrons: a spike in every
             clock (word known), the accumulator only grows, so it ends at
             ``min(acc + sum(e) - L theta, 2^A - 1)``; ``sum(e)`` is
             ``Poisson(expected) + dark`` when no input can saturate, ``L (2^E - 1)``
             when every input surely does, and need not be drawn at all when
             the accumulator surely ends full.
"""

from __future__ import annotations

import numpy as np

from ..config import SensorConfig
from ..light import log_poisson_tail_above, log_poisson_tail_below
from ..poisson_rejection import poisson_draws
from .clock import clock_path
from .bisection import largest_below, smallest_below
from .codes import BRIGHT, CLOCK, EVENT
from .words import NO_PIXELS, firing_words, gather, is_mask, ml_words, overflow_clock_word, put


def interval_levels(config: SensorConfig, budget: float) -> tuple[float, float, float]:
    """-> (``mean_event``: largest interval mean per clock at which no clock surely
    gets more than ``min(theta, 2^E - 1)`` electrons; ``mean_unclipped``: at which no
    input saturates; ``lam_bright``: smallest photo-electrons per clock at which every
    clock surely gets ``theta``, infinite where inputs saturate below theta)."""
    c = config
    cap = min(c.threshold, c.input_max)
    mean_event = largest_below(lambda m: log_poisson_tail_above(m, cap + 1), budget, cap + 1)
    mean_unclipped = largest_below(lambda m: log_poisson_tail_above(m, c.input_max + 1),
                                   budget, c.input_max + 1)
    lam_bright = np.inf
    if c.input_max >= c.threshold:
        lam_bright = smallest_below(lambda m: log_poisson_tail_below(m, c.threshold - 1), budget, c.threshold)
    return mean_event, mean_unclipped, lam_bright


def saturation_levels(config: SensorConfig, budget: float) -> tuple[float, float]:
    """-> (``lam_top``: smallest photo-electrons per clock at which every clock's input
    surely saturates at ``2^E - 1``; ``lam_full``: at which every clock surely gets
    ``theta + 2^A - 1``, so that the accumulator is surely full after the first clock,
    infinite where inputs saturate below that). Each bound falls with the light, so each
    test is one comparison with its level."""
    c = config
    top = c.input_max
    lam_top = smallest_below(lambda m: log_poisson_tail_below(m, top - 1), budget, float(top))
    lam_full = np.inf
    if top >= c.threshold + c.acc_max:
        k = c.threshold + c.acc_max
        lam_full = smallest_below(lambda m: log_poisson_tail_below(m, k - 1), budget, float(k))
    return lam_top, lam_full


def overflow_level(config: SensorConfig, budget: float) -> float:
    """Smallest interval mean at which a TE pixel surely gets the ``2^b1 theta`` electrons
    of an overflow (from an empty accumulator, so from any charge below theta)."""
    c = config
    if not c.is_te:
        return np.inf
    n = c.p_max * c.threshold
    return smallest_below(lambda m: log_poisson_tail_below(m, n - 1), budget, float(n))


def classify_interval(levels, lam, mean, acc):
    """-> the path codes (int8) of pixels: event from the light with dark electrons per
    clock ``mean`` and the charge ``acc``, bright from the photo-electrons per clock
    ``lam`` alone (bright first), CLOCK for the others (the other families decide).
    Made by arithmetic on the masks: a masked store costs about 4 ns an element on a
    scene's random pattern of paths (branches mispredicted), the arithmetic a tenth."""
    bright = lam >= levels.lam_bright
    event = acc < levels.config.threshold
    event &= mean <= levels.mean_event
    event &= ~bright
    code = event.view(np.int8) * np.int8(EVENT - CLOCK)
    code += bright.view(np.int8) * np.int8(BRIGHT - CLOCK)
    code += np.int8(CLOCK)
    return code


#: The event path runs on the whole frame under a mask (:func:`.interval.event_path`)
#: where it holds at least 1 / EVENT_MASK_SHARE of the pixels (passes over the others
#: then cost less than gathering and scattering its own). Words identical either way;
#: 1.4 (a share of 0.71) against 2 took 3 % less CPU on the vestibule pan (TE, where the
#: path holds about 60 % of a readout), the same on the St Fagans pan (75 %) and the
#: drifting log-uniform scene (benchmarks/bench_fastsim_knob.py, interleaved readouts).
EVENT_MASK_SHARE = 1.4


def event_pixels(on_path: np.ndarray, count: int):
    """How the event path takes its ``count`` pixels of the frame mask ``on_path``: the whole frame
    (``slice(None)``: no gather or scatter), the mask where they are most of it (:func:`event_path`
    runs over the frame), else their flat indices."""
    if count == on_path.size:
        return slice(None)
    if count * EVENT_MASK_SHARE >= on_path.size:
        return on_path
    return np.flatnonzero(on_path)


def event_path(sim, sel, expected, dark, words):
    """Event path of pixels ``sel``: flat indices, ``slice(None)`` for the whole frame,
    or a boolean mask of the frame where the path holds most pixels. A mask runs the
    path over the whole frame with the other pixels' means at 0 (a Poisson draw of mean
    0 is 0 and consumes no random numbers, so the draws are those of the gathered
    pixels, in the same order) and writes back under the mask: whole-array passes
    instead of two gathers and two scatters of most of the frame."""
    c = sim.config
    theta, L = c.threshold, c.clocks_per_readout
    masked = is_mask(sel)
    acc0 = gather(sim.carried, sel)
    mean = expected * sel if masked else expected[sel]  # (half the time of np.where)
    sure = NO_PIXELS
    if c.is_te and not sim.dark_model:
        sure = np.flatnonzero(mean >= sim.levels.mean_overflow)
    if sure.size:                                      # the overflow electron first (module docstring)
        need = c.p_max * theta - acc0[sure]
        light_time = sim.rng.standard_gamma(need.astype(np.float64))
        sure_mean = mean[sure]
        reached = light_time < sure_mean               # surely (bound); else drawn as below
        sure, need, light_time, sure_mean = sure[reached], need[reached], light_time[reached], sure_mean[reached]
        if isinstance(sel, slice):
            mean = mean.copy()                          # (a view of expected)
        mean[sure] = sure_mean - light_time            # the electrons after it
    total = poisson_draws(sim.rng, mean)               # (vectorised PTRS: golden.poisson_rejection)
    if sim.dark_model:
        total += gather(dark, sel)
    if sure.size:
        total[sure] += need
    level = acc0 + total
    spikes = level // theta                            # (np.divmod is 3x slower on int64)
    residual = level - spikes * theta
    if not c.is_te:
        put(sim.carried, sel, residual)
        ml_words(sim, sel, spikes, words)
        return
    if sure.size:                                      # their words now; not among the Beta draws
        at = np.minimum((light_time / sure_mean * L).astype(np.int64), L - 1)
        spikes[sure] = -1
    over = spikes >= c.p_max
    if masked:
        over &= sel                                 # (the others' charge alone may pass 2^b1 theta)
    over = np.flatnonzero(over)
    if sure.size:
        spikes[sure] = overflow_clock_word(c, at)
    if over.size:
        n = c.p_max * theta - acc0[over]               # electron that makes the 2^b1-th spike
        t = total[over]
        position = sim.rng.beta(n, t - n + 1)          # n-th of t uniform order statistics
        at = np.minimum((position * L).astype(np.int64), L - 1)
        spikes[over] = overflow_clock_word(c, at)
    put(sim.carried, sel, residual)                    # after acc0 (maybe a view) is used
    put(words, sel, spikes)


def bright_path(sim, sel, expected, lam, dark, words):
    """Bright path of pixels ``sel`` (flat indices); inputs that may or may not
    saturate (rare) go per clock."""
    c = sim.config
    theta, L, top, acc_max = c.threshold, c.clocks_per_readout, c.input_max, c.acc_max
    acc0 = sim.carried[sel]
    lam_s = lam[sel]
    end = np.full(sel.size, acc_max, np.int64)
    levels = sim.levels
    # every clock saturated at 2^E - 1: a deterministic sum
    all_top = lam_s >= levels.lam_top
    # accumulator surely full after the first clock: nothing to draw
    full = lam_s >= levels.lam_full
    # no input can saturate: the sum is Poisson(expected) + dark
    unclipped = (lam_s + dark[sel] / L if sim.dark_model else lam_s) <= levels.mean_unclipped
    need = ~full & ~all_top
    if (need & ~unclipped).any():
        # inputs that may or may not saturate: per clock (exact), rare in practice
        mixed = need & ~unclipped
        sim.path_counts["bright"] -= int(mixed.sum())
        sim.path_counts["clock"] += int(mixed.sum())
        clock_path(sim, sel[mixed], expected, dark, words)
        need &= unclipped
        keep = ~mixed
    else:
        keep = np.ones(sel.size, bool)
    top_sel = all_top & ~full
    end[top_sel] = np.minimum(acc0[top_sel] + L * (top - theta), acc_max)
    if need.any():
        total = sim.rng.poisson(expected[sel][need]) + dark[sel][need]
        # under the sure event total >= L theta; max(.., 0) only guards the
        # 2^-64 failure event against an illegal negative state
        end[need] = np.clip(acc0[need] + total - L * theta, 0, acc_max)
    sim.carried[sel[keep]] = end[keep]
    firing_words(sim, sel[keep], words)
