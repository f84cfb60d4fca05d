"""Which path each pixel-readout of the fast simulator takes, and what that path needs.

A path is chosen from the light and the carried charge only, never from a
pixel's own random draws (so the choice cannot bias the result; docs/simulator.md
has the derivation). :class:`PathLevels` holds the light levels every bound
reduces to, each found once by its path family's module (each bound is
monotone in the light, so each test is one comparison with a level);
:meth:`PathLevels.classify` asks the families in turn (lazy pixels are
decided by the lazy path itself, :mod:`.lazy`; then :mod:`.interval`,
:mod:`.window`, :mod:`.head`; what is left goes per clock, :mod:`.clock`) and
returns everything the paths need. Nothing is stored between calls.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from ..config import SensorConfig
from .head import classify_head
from .interval import classify_interval, interval_levels, overflow_level, saturation_levels
from .lazy import lazy_level
from .window import classify_window, queue_level
from .codes import CLOCK, LAZY


class Plan(NamedTuple):
    """One readout's classification: ``path`` (n,) int8 codes into SIMULATION_PATHS;
    ``length`` (n,) the window (queue, full) or head length in clocks, rounded
    (:func:`tespike.golden.fastsim.window.round_window`; 0 elsewhere); ``b_max`` (n,) the
    queue's backlog bound entering its window (0 elsewhere)."""
    path: np.ndarray
    length: np.ndarray
    b_max: np.ndarray


class PathLevels:
    """The light levels and bounds that decide the paths of one configuration
    at one error budget (log probability per bounded event). Read-only once
    made; :func:`path_levels` shares one between the stripes of a scene."""

    def __init__(self, config: SensorConfig, budget: float):
        self.config = config
        self.budget = budget
        self.mean_event, self.mean_unclipped, self.lam_bright = interval_levels(config, budget)
        self.mean_overflow = overflow_level(config, budget)
        self.lam_top, self.lam_full = saturation_levels(config, budget)
        self.mean_lazy = lazy_level(config, budget, self.mean_event)
        self.rho_queue = queue_level(config, budget)

    def classify(self, lazy_mask, n_lazy, lam, mean, dark, acc) -> Plan:
        """Paths of one readout: ``lazy_mask`` the lazy pixels' mask (``n_lazy`` of
        them, decided by the lazy path itself), ``lam`` photo-electrons per clock,
        ``mean`` with dark electrons, ``dark`` the interval's dark electrons,
        ``acc`` the carried charge (all flat, n)."""
        n = lam.size
        # the other pixels' paths: on them alone where they are few (gathers),
        # else on the whole frame (whole-array passes are cheaper than gathers)
        few = 2 * n_lazy > n
        idx = np.flatnonzero(~lazy_mask) if few else slice(None)
        code = classify_interval(self, lam[idx], mean[idx], acc[idx])
        if few:
            path = np.full(n, LAZY, np.int8)
            path[idx] = code
        else:
            path = code
            if n_lazy:                                  # LAZY is code 0: a product, no masked store
                path *= ~lazy_mask
        length = b_max = _NONE
        rest = np.flatnonzero(path == CLOCK)
        if rest.size:
            length, b_max = np.zeros(n), np.zeros(n)
            classify_window(self, rest, lam[rest], mean[rest], dark[rest], acc[rest], path, length, b_max)
            rest = rest[path[rest] == CLOCK]
            if rest.size:
                classify_head(self, rest, lam[rest], mean[rest], dark[rest], acc[rest], path, length)
        return Plan(path, length, b_max)


_NONE = np.zeros(0)


@functools.lru_cache(maxsize=16)
def path_levels(config: SensorConfig, budget: float) -> PathLevels:
    """:class:`PathLevels` of ``config`` at ``budget``, made once per process
    (its bisections cost about 10 ms; the stripes of a scene share one budget)."""
    return PathLevels(config, budget)
