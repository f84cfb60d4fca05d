"""Whole scenes: the noisy fast simulation striped over worker processes, and the per-clock stimulus.

:func:`simulate_scene` is the library's entry point (``tespike simulate``):
the noisy fast method runs one :class:`SceneSimulator` per stripe
(:func:`stripe_simulators`, :mod:`.stripes`), the per-clock method and
``noise=False`` one simulator in this process. :func:`iter_scene_stimulus`
gives the electrons the per-clock method draws.
"""

from __future__ import annotations

import numpy as np

from ..config import SensorConfig
from ..errors import InputError
from ..io import check_scene, word_dtype
from ..noise import check_noise_switch, pixel_noise
from ..resources import keep_freed_memory
from .simulator import SceneSimulator, check_method
from .stripes import run_stripes, spawn_generators, stripe_slices, worker_count


def stripe_simulators(config: SensorConfig, shape: tuple[int, int], *, seed=None,
                      dark_current: str | None = None, total_pixel_readouts: int | None = None,
                      sensor=None):
    """(row slices, one noisy fast :class:`SceneSimulator` per stripe) of an H x W frame.

    Stripe i draws from child i of ``seed`` (:func:`spawn_generators`); a single
    stripe is one simulator on the seed's own generator, exactly
    ``SceneSimulator(rng=seed)``. Pixels are independent given the light, so
    the stripes have the law of one simulator over the frame; each stripe's
    error budget counts ``total_pixel_readouts`` (the whole scene), so the
    2^-64 bound for the whole stream is unchanged. ``sensor``'s maps are drawn for
    the whole frame; each stripe gets its rows of them.
    """
    config = SensorConfig.required(config, "stripe_simulators")
    H, W = shape
    rows = stripe_slices(H, W)
    rngs = [seed] if len(rows) == 1 else spawn_generators(seed, len(rows))
    frame = pixel_noise(dark_current, sensor, (H, W))
    return rows, [SceneSimulator(config, (len(range(H)[r]), W), rng=rng, pixels=frame.rows(r, W),
                                 total_pixel_readouts=total_pixel_readouts or H * W)
                  for r, rng in zip(rows, rngs)]


def simulate_scene(config: SensorConfig, scene: np.ndarray, *, seed=None,
                   dark_current: str | None = None, noise: bool = True,
                   progress=None, method: str = "fast",
                   workers: int | None = 1, sensor=None, what: str = "scene") -> np.ndarray:
    """Scene light ``(K, H, W)`` -> readout words ``(K, H, W)`` (smallest word dtype).

    ``seed``: int, numpy Generator or ``None`` (fresh entropy). ``method="per-clock"``
    draws electrons per pixel clock everywhere (slow; the reference the fast
    paths are tested against). ``progress``: None, or a function that wraps the
    iterable of readout indices and reports as it is walked (``tespike simulate`` passes a
    tqdm bar, :func:`tespike.cosim.console.bar`). The noisy fast method simulates horizontal
    stripes (:func:`stripe_simulators`) on ``workers`` processes (this one and
    forked ones; ``None``: the cores available, at most the stripe count; 1 by
    default, so a library caller that runs threads of its own, e.g. torch,
    never forks unless it asks to; ``tespike simulate`` asks for the cores);
    the words depend on the seed and the frame's shape, not on ``workers``.
    ``method="per-clock"`` and ``noise=False`` run one :class:`SceneSimulator` in
    this process (the per-clock electrons of :func:`iter_scene_stimulus`).
    ``sensor``: a :class:`tespike.golden.noise.Sensor` (non-idealities with their per-pixel
    maps from its sensor seed), instead of ``dark_current``. The light is checked one
    readout at a time as it is simulated (a negative or non-finite value refused in one
    line, ``what`` naming the scene): a caller need not scan it first.
    """
    config = SensorConfig.required(config, "simulate_scene")
    scene = check_scene(scene, scan_values=False)       # values: one readout at a time
    K, H, W = scene.shape
    check_method(method)
    noise = check_noise_switch(noise)
    if progress is not None and not callable(progress):
        raise InputError(f"progress {progress!r}: must be None or a function that wraps the readouts' "
                         "iterable (e.g. tqdm)")
    keep_freed_memory()                                 # (speed only: see golden.resources)
    if noise and method == "fast":
        rows, sims = stripe_simulators(config, (H, W), seed=seed, dark_current=dark_current,
                                       total_pixel_readouts=scene.size or None, sensor=sensor)
        return run_stripes(rows, sims, scene, word_dtype(config), workers=workers, progress=progress,
                           what=what)
    worker_count(workers, 1)                            # (refuses a bad count; one process here)
    sim = SceneSimulator(config, (H, W), rng=seed, dark_current=dark_current, noise=noise,
                         method=method, total_pixel_readouts=scene.size or None, sensor=sensor)
    words = np.empty((K, H, W), word_dtype(config))
    for k in (progress or iter)(range(K)):
        words[k] = sim.readout(scene[k], what)              # (which checks it)
    return words


def simulate_sequence(config: SensorConfig, light: np.ndarray, rng, noise_sensor=None) -> np.ndarray:
    """:func:`simulate_scene` in the form the evaluation harness calls its source of streams,
    ``simulate(config, light, rng[, noise_sensor])`` (:func:`tespike.recon.evaluate.evaluate` takes
    that source as an argument: the demo gives it streams recorded before)."""
    return simulate_scene(config, light, seed=rng, sensor=noise_sensor)


def iter_scene_stimulus(config: SensorConfig, scene: np.ndarray, *, seed=None,
                        dark_current: str | None = None, noise: bool = True, sensor=None):
    """Yield the per-clock electrons ``(L, H, W)`` of each readout interval of ``scene``.

    The noise model and seed semantics of :func:`simulate_scene`: the electrons
    are the very ones ``simulate_scene(..., seed=seed, method="per-clock")``
    draws, so :func:`tespike.golden.sensor.simulate` on their concatenation returns
    that call's words bit for bit, and has the law of the fast method's words
    (same seed, other random numbers: the fast paths draw per interval).
    One readout interval is held at a time.
    """
    scene = check_scene(scene, scan_values=False)
    K, H, W = scene.shape
    sim = SceneSimulator(config, (H, W), rng=seed, dark_current=dark_current, noise=noise,
                         method="per-clock", total_pixel_readouts=scene.size or None, sensor=sensor)
    for k in range(K):
        yield sim.clock_stimulus(scene[k], "scene")


def scene_stimulus(config: SensorConfig, scene: np.ndarray, **options) -> np.ndarray:
    """:func:`iter_scene_stimulus` as one ``(K L, H, W)`` array (for crops: it holds
    ``K L H W`` values)."""
    config = SensorConfig.required(config, "scene_stimulus")
    from ..light import stimulus_dtype
    scene = check_scene(scene, scan_values=False)
    K, H, W = scene.shape
    L = config.clocks_per_readout
    out = np.empty((K * L, H, W), stimulus_dtype(config))
    for k, e in enumerate(iter_scene_stimulus(config, scene, **options)):
        out[k * L:(k + 1) * L] = e
    return out
