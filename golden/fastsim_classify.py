"""Which path each pixel-readout of the fast simulator takes, and what that path needs.

A path is chosen from the light and the carried charge only, never from a
pixel's own random draws (so the choice cannot bias the result; docs/simulator.md
has the derivation). :class:`PathLevels` holds the light levels every bound
reduces to (each bound is monotone in the light, so each test is one comparison
with a level found once by bisection) and returns, for each classification,
everything the paths need: the path code per pixel, the window (or head) length
and the queue's backlog bound. Nothing is stored between calls.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from .config import SensorConfig
from .light import log_poisson_tail_above, log_poisson_tail_below
from .reference import msb_index

#: The paths of :class:`golden.fastsim.SceneSimulator` (path codes index this tuple).
SIMULATION_PATHS = ("lazy", "event", "bright", "queue", "full", "head", "clock")
LAZY, EVENT, BRIGHT, QUEUE, FULL, HEAD, CLOCK = range(len(SIMULATION_PATHS))

#: Largest backlog bound the queue path accepts, and its shortest window.
MAX_BACKLOG = 64
MIN_WINDOW = 8

#: Interval mean, in thresholds, up to which dim light takes the lazy path.
LAZY_THRESHOLDS = 2.0

#: Pixels of one path processed as one group whatever their window lengths.
SMALL_GROUP = 256


class Plan(NamedTuple):
    """One readout's classification: ``path`` (n,) int8 codes into SIMULATION_PATHS;
    ``length`` (n,) the window (queue, full) or head length in clocks, rounded
    (:func:`round_window`; 0 elsewhere); ``b_max`` (n,) the queue's backlog bound
    entering its window (0 elsewhere)."""
    path: np.ndarray
    length: np.ndarray
    b_max: np.ndarray


class PathLevels:
    """The light levels and bounds that decide the paths of one configuration
    at one error budget (log probability per bounded event). Read-only once
    made; :func:`path_levels` shares one between the stripes of a scene."""

    def __init__(self, config: SensorConfig, budget: float):
        c = self.config = config
        self.budget = budget
        cap = min(c.threshold, c.input_max)
        #: event: P(some clock > min(theta, 2^E - 1) electrons) below budget
        self.mean_event = _largest_below(lambda m: log_poisson_tail_above(m, cap + 1), budget, cap + 1)
        # lazy: an interval mean of at most 2 theta (two crossings a readout or fewer:
        # one Gamma draw per crossing, about 25 ns with its bookkeeping, against the
        # event path's Poisson draw per readout, about 40 ns; measured best between
        # 1.5 and 3 theta on the panorama pans of docs/simulator.md) that surely cannot
        # fire the 2^b1 spikes of a TE overflow in one interval, and event light per
        # clock (at most one crossing a clock, so each crossing is a spike in its clock)
        self.mean_lazy = min(c.threshold * LAZY_THRESHOLDS, self.mean_event * c.clocks_per_readout)
        if c.is_te:
            self.mean_lazy = min(self.mean_lazy, _largest_below(
                lambda m: log_poisson_tail_above(m, (c.p_max - 1) * c.threshold),
                budget, (c.p_max - 1) * c.threshold))
        self.mean_unclipped = _largest_below(lambda m: log_poisson_tail_above(m, c.input_max + 1),
                                             budget, c.input_max + 1)
        self.lam_bright = np.inf
        if c.input_max >= c.threshold:
            self.lam_bright = _smallest_below(lambda m: log_poisson_tail_below(m, c.threshold - 1),
                                              budget, c.threshold)
        # queue: L exp(-s (acc_max + 2 - theta)) below budget with s = 2 (1 - rho)
        h = c.acc_max + 2 - c.threshold
        self.rho_queue = 1.0 - (np.log(c.clocks_per_readout) - budget) / (2.0 * h)
        if c.is_te:
            ovf_clock = c.p_max - 1                       # spike in every clock
            self.bright_word = ((1 << c.d) | (ovf_clock // c.clocks_per_tick + 1)
                                if c.p_max <= c.clocks_per_readout else c.clocks_per_readout)
        else:
            self.bright_word = min(c.clocks_per_readout, c.ml_max)
        if c.is_msb:
            # word and remainder of every counter value 0..2^ml_bits - 1 (at most 64 Ki entries)
            count = np.arange(c.ml_max + 1, dtype=np.int64)
            self.msb_word = msb_index(count)
            self.msb_rest = count - np.where(count > 0, np.left_shift(1, np.maximum(self.msb_word - 1, 0)), 0)
            self.msb_word.flags.writeable = self.msb_rest.flags.writeable = False

    def classify(self, lazy, n_lazy, lam, mean, dark, acc) -> Plan:
        """Paths of one readout: ``lazy`` the lazy pixels' mask (``n_lazy`` of
        them, decided by the lazy path itself), ``lam`` photo-electrons per clock,
        ``mean`` with dark electrons, ``dark`` the interval's dark electrons,
        ``acc`` the carried charge (all flat, n)."""
        theta = self.config.threshold
        n = lam.size
        # the other pixels' paths: on them alone where they are few (gathers),
        # else on the whole frame (whole-array passes are cheaper than gathers)
        few = 2 * n_lazy > n
        idx = np.flatnonzero(~lazy) if few else slice(None)
        code = np.full(n - n_lazy if few else n, CLOCK, np.int8)
        code[(acc[idx] < theta) & (mean[idx] <= self.mean_event)] = EVENT
        # bright: every clock >= theta electrons (photo-electrons alone suffice)
        code[lam[idx] >= self.lam_bright] = BRIGHT
        if few:
            path = np.full(n, LAZY, np.int8)
            path[idx] = code
        else:
            path = code
            if n_lazy:
                path[lazy] = LAZY
        length = b_max = _NONE
        rest = np.flatnonzero(path == CLOCK)
        if rest.size:
            length, b_max = np.zeros(n), np.zeros(n)
            self._classify_middle(rest, lam[rest], mean[rest], dark[rest], acc[rest], path, length, b_max)
            rest = rest[path[rest] == CLOCK]
            if rest.size:
                self._classify_head(rest, lam[rest], mean[rest], dark[rest], acc[rest], path, length)
        return Plan(path, length, b_max)

    def _classify_middle(self, idx, lam, mean, dark, acc, path, length, b_max):
        """Queue or full path for pixels ``idx`` near one threshold per clock, where
        allowed; their window lengths (rounded) and queue backlog bounds are written
        into ``length`` and ``b_max``."""
        theta = self.config.threshold
        ok = (dark == 0) & (mean <= self.mean_unclipped)
        rho = lam / theta
        # queue: below the threshold per clock, the accumulator surely never clips
        queue = ok & (acc < theta) & (rho < self.rho_queue)
        if queue.any():
            sel = idx[queue]
            keep, bound, window = self.queue_plan(rho[queue])
            path[sel[keep]] = QUEUE
            length[sel[keep]] = round_window(window[keep])
            b_max[sel[keep]] = bound[keep]
        # full: above the threshold per clock, a spike in every clock surely
        full = ok & (lam > theta)
        if full.any():
            sel = idx[full]
            keep, window = self.full_plan(lam[full], acc[full])
            path[sel[keep]] = FULL
            length[sel[keep]] = round_window(window[keep])

    def full_plan(self, lam, acc):
        """Full path at ``lam`` > theta electrons per clock from charge ``acc`` ->
        (where the bound makes a spike in every clock sure, window length): the
        walk held at ``acc_max`` never goes below 0 (Lundberg, ``s = 2 (lam -
        theta) / lam``: ``exp(-s (acc + 1)) + L exp(-s (acc_max + 1))`` below budget)."""
        c = self.config
        theta = c.threshold
        s_full = 2.0 * (lam - theta) / lam
        fire = np.logaddexp(-s_full * (acc + 1.0), np.log(c.clocks_per_readout) - s_full * (c.acc_max + 1.0))
        gap = lam - theta
        window = 1.3 * -self.budget / s_full / gap + 16.0 * lam / gap ** 2
        return fire < self.budget, window

    def queue_plan(self, rho):
        """Queue path at ``rho`` thresholds per clock -> (where the bound allows the
        path, b_max <= MAX_BACKLOG; backlog bound b_max; window length)."""
        L = self.config.clocks_per_readout
        theta = self.config.threshold
        s_queue = 2.0 * (1.0 - rho)                        # Lundberg exponent (see _queue_walk)
        # P(backlog >= b at the window) <= L exp(-s ((b - 1) theta + 1)): b_max + 1 is unlikely
        b_max = np.floor(((np.log(L) - self.budget) / s_queue - 1.0) / theta) + 1.0
        b_max = np.maximum(b_max, 0.0)
        # the Lindley recursion drains b_max in about b_max / (1 - rho) clocks
        return b_max <= MAX_BACKLOG, b_max, (b_max + 3.0) / (1.0 - rho)

    def _classify_head(self, idx, lam, mean, dark, acc, path, length):
        """Head path for pixels ``idx`` a few clocks away from a cheap path: a carried
        backlog (``acc >= theta``) under light that surely drains it, then the
        event path; or light above one threshold per clock with too little
        charge yet for the full path's bound, which a few clocks supply.
        ``length`` gets the head's length (a multiple of MIN_WINDOW)."""
        c = self.config
        theta, L = c.threshold, c.clocks_per_readout
        ok = dark == 0
        # drain: while acc >= theta every clock fires and acc falls by theta - e
        drain = ok & (acc >= theta) & ((mean <= self.mean_event)
                                       | ((mean <= self.mean_unclipped) & (lam < self.rho_queue * theta)))
        clocks = np.zeros(idx.size)
        clocks[drain] = 2.0 * (acc[drain] - theta + 1) / (theta - lam[drain]) + 4.0
        # charge: the full path's bound needs acc >= a_full (each of its two
        # terms below budget - log 2), reached at about lam - theta per clock
        charge = ok & (lam > theta) & (mean <= self.mean_unclipped)
        if charge.any():
            lc = lam[charge]
            s_full = 2.0 * (lc - theta) / lc
            a_full = np.ceil((np.log(2.0) - self.budget) / s_full)
            top_ok = np.log(2.0 * L) - s_full * (c.acc_max + 1.0) < self.budget
            clocks[charge] = 1.5 * np.maximum(a_full - acc[charge], 0.0) / (lc - theta) + 8.0
            charge[charge] = top_ok & (a_full <= c.acc_max)
        size = round_window(clocks)
        head = (drain | charge) & (size <= L // 2)
        path[idx[head]] = HEAD
        length[idx[head]] = size[head]


_NONE = np.zeros(0)


@functools.lru_cache(maxsize=16)
def path_levels(config: SensorConfig, budget: float) -> PathLevels:
    """:class:`PathLevels` of ``config`` at ``budget``, made once per process
    (its bisections cost about 10 ms; the stripes of a scene share one budget)."""
    return PathLevels(config, budget)


def round_window(clocks: np.ndarray) -> np.ndarray:
    """Window or head lengths rounded up to multiples of MIN_WINDOW, at least
    MIN_WINDOW: pixels of one length are one block, and few lengths mean few blocks."""
    return MIN_WINDOW * np.maximum(1.0, np.ceil(clocks / MIN_WINDOW))


def groups(sel, size):
    """Pixels ``sel`` (any index array) grouped by window (or head) length ``size``, one block per
    length; a few pixels go together at their longest length (a longer
    window or head is as exact, only dearer, and one call costs less than
    several small ones) -> [(length, pixels)]."""
    if sel.size <= SMALL_GROUP:
        return [(int(size.max()), sel)] if sel.size else []
    return [(int(w), sel[size == w]) for w in np.unique(size)]


def _largest_below(bound, budget, hi):
    """Largest m in [0, hi] (to 2^-64 of the bracket) with bound(m) < budget, bound increasing."""
    lo = 0.0
    if not bound(np.array([lo]))[0] < budget:
        return -1.0
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        if bound(np.array([mid]))[0] < budget:
            lo = mid
        else:
            hi = mid
    return lo


def _smallest_below(bound, budget, lo):
    """Smallest m >= lo with bound(m) < budget (to 2^-64 of the bracket), bound decreasing."""
    hi = max(2.0 * lo, 1.0)
    while not bound(np.array([hi]))[0] < budget:
        hi *= 2.0
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        if bound(np.array([mid]))[0] < budget:
            hi = mid
        else:
            lo = mid
    return hi
