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
from .codes import CLOCK


class Plan(NamedTuple):
    """One readout's classification: ``path`` int8 codes into SIMULATION_PATHS, of the whole
    frame (n,) where ``pixels`` is None, else of the pixels ``pixels`` (flat indices,
    ascending; every other pixel lazy: a readout whose pixels are mostly lazy is planned
    and dispatched on the others alone, no pass over the frame); ``length`` (n,) the window
    (queue, full) or head length in clocks, rounded
    (:func:`tespike.golden.fastsim.window.round_window`); ``b_max`` (n,) the queue's backlog
    bound entering its window. ``length`` and ``b_max`` are the simulator's own arrays, valid
    at this readout's queue, full and head pixels only (the paths that read them)."""
    path: np.ndarray
    length: np.ndarray
    b_max: np.ndarray
    pixels: np.ndarray | None = None


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

    def classify(self, pixels, lazy_mask, n_lazy, lam, mean, dark, acc, length, b_max) -> Plan:
        """Paths of one readout: ``lazy_mask`` the lazy pixels' mask (``n_lazy`` of
        them, decided by the lazy path itself), ``pixels`` the others' flat indices where
        they are fewer (the caller's choice: ``2 n_lazy > n``; else None), ``lam``
        photo-electrons per clock, ``mean`` with dark electrons (both read at ``pixels``
        only where given), ``dark`` the interval's dark electrons, ``acc`` the carried
        charge (all flat, n); ``length`` and ``b_max`` (n,) the simulator's arrays the
        window and head lengths and backlog bounds go into (written at those pixels only:
        nothing else reads them)."""
        # the other pixels' paths: on them alone where they are few (gathers),
        # else on the whole frame (whole-array passes are cheaper than gathers)
        if pixels is not None:
            path = classify_interval(self, lam[pixels], mean[pixels], acc[pixels])
            at = np.flatnonzero(path == CLOCK)          # (positions in path)
            rest = pixels[at]
        else:
            path = classify_interval(self, lam, mean, acc)
            if n_lazy:                                  # LAZY is code 0: a product, no masked store
                path *= ~lazy_mask
            at = rest = np.flatnonzero(path == CLOCK)
        if rest.size:
            classify_window(self, at, rest, lam[rest], mean[rest], dark[rest], acc[rest], path, length, b_max)
            keep = path[at] == CLOCK
            at, rest = at[keep], rest[keep]
            if rest.size:
                classify_head(self, at, rest, lam[rest], mean[rest], dark[rest], acc[rest], path, length)
        return Plan(path, length, b_max, pixels)


@functools.lru_cache(maxsize=16)
def path_levels(config: SensorConfig, budget: float) -> PathLevels:
    """:class:`PathLevels` of ``config`` at ``budget``, made once per process
    (its bisections cost about 10 ms; the stripes of a scene share one budget)."""
    return PathLevels(config, budget)
