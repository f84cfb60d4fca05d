"""Fast light-to-stream simulator, distributed like the cycle-exact model (SPEC sections 3, 6).

:func:`simulate_scene` gives readout words with the same distribution as
:func:`tespike.golden.sensor.simulate` driven by :func:`tespike.golden.stimulus.poisson_stimulus`
(accumulator starting at 0, residual carried across readouts), but draws
random numbers per readout interval instead of per pixel clock wherever the
dynamics allow. Each pixel-readout takes one path, chosen from its light and
its carried charge only (never from a random draw of its own, so the choice
cannot bias the result); docs/simulator.md has the derivation. One module per
path family, each classifying and running its paths:

:mod:`.lazy`      ``lazy``: dim light, no draw until the next threshold crossing.
:mod:`.interval`  ``event`` (at most one crossing a clock: the interval's total
                  fixes the spikes) and ``bright`` (a spike in every clock):
                  one draw of the interval's total.
:mod:`.window`    ``queue`` and ``full``: light near one threshold per clock,
                  settled by a window of its last clocks (Lundberg bounds).
:mod:`.head`      ``head``: a few clocks per clock, then a cheap path from there.
:mod:`.clock`     ``clock``: per-clock electrons, the unclipped queue of
                  crossings or the cycle-exact model; every path's fallback.

:mod:`.plan` puts the families' levels and classifications together,
:class:`SceneSimulator` (:mod:`.simulator`) holds the state and dispatches
each readout's pixels, :mod:`.words` turns spike counts into words (ML msb:
the counter ``min(sfc + spikes, 2^ml_bits - 1)`` from the carried remainder,
the word its bit_length), :mod:`.scene` runs whole scenes and
:mod:`.stripes` splits frames into stripes on worker processes.

"Surely" means: each such event fails with probability below
``2^-64 / (CHECKS x pixel-readouts x L)`` (:func:`tespike.golden.light.log_budget`,
rigorous tail bounds in :mod:`tespike.golden.light`); a pixel-readout relies on at
most CHECKS of them, so the law of the whole output stream differs from the
exact one by less than 2^-64 in total variation. With ``noise=False`` nothing is
random and every pixel takes the per-clock path on the deterministic
stimulus of :func:`tespike.golden.light.deterministic_clock_electrons`.
"""

from .codes import SIMULATION_PATHS
from .scene import iter_scene_stimulus, scene_stimulus, simulate_scene, simulate_sequence, stripe_simulators
from .simulator import CHECKS, SIMULATION_METHODS, SceneSimulator
from .stripes import MAX_STRIPES, STRIPE_PIXELS, STRIPE_ROWS, spawn_generators, stripe_slices, worker_count
from .window import MAX_BACKLOG, MIN_WINDOW, lindley_ends

__all__ = ["CHECKS", "MAX_BACKLOG", "MAX_STRIPES", "MIN_WINDOW", "SIMULATION_METHODS", "SIMULATION_PATHS",
           "STRIPE_PIXELS", "STRIPE_ROWS", "SceneSimulator", "iter_scene_stimulus",
           "lindley_ends", "scene_stimulus", "simulate_scene", "simulate_sequence", "spawn_generators",
           "stripe_simulators",
           "stripe_slices", "worker_count"]
