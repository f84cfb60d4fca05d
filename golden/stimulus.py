"""The per-clock electron stimulus of a whole scene: the naive loop's input.

:func:`poisson_stimulus` draws every pixel clock's electrons by the light front end's law
(:mod:`tespike.golden.light`), with a sensor's non-idealities (:mod:`tespike.golden.noise`):
the reference that the cycle-exact model (:func:`tespike.golden.sensor.simulate`) and the RTL
run on, and that the fast simulator (:mod:`tespike.golden.fastsim`) is tested against. Above
both modules, since it uses both.
"""

from __future__ import annotations

import numpy as np

from .config import SensorConfig
from .io import check_scene
from .light import (as_generator, check_dark_current, clock_electrons, deterministic_clock_electrons,
                    electrons_per_readout, log_budget, stimulus_dtype)
from .noise import pixel_noise


def poisson_stimulus(config: SensorConfig, scene: np.ndarray, rng=None, *,
                     dark_current: str | None = None, noise: bool = True, sensor=None) -> np.ndarray:
    """Scene light ``(K, H, W)`` -> per-clock electrons ``(K * L, H, W)``.

    The stimulus for the cycle-exact model (:func:`tespike.golden.sensor.simulate`) and
    the RTL. ``rng``: a numpy Generator or a seed. ``noise=False`` gives the
    deterministic stimulus of :func:`tespike.golden.light.deterministic_clock_electrons` (and refuses
    dark current, which is random by nature). The dtype is the smallest unsigned
    one that holds ``2^input_bits - 1``. Memory is ``K * L * H * W`` values: use
    it for crops, not whole videos (:mod:`tespike.golden.fastsim` simulates those).
    ``sensor``: a :class:`tespike.golden.noise.Sensor` (non-idealities and their per-pixel
    maps), instead of ``dark_current``.
    """
    config = SensorConfig.required(config, "poisson_stimulus")
    scene = check_scene(scene)
    check_dark_current(dark_current)
    pixels = pixel_noise(dark_current, sensor, scene.shape[1:], noise=noise)
    rng = as_generator(rng)
    K, H, W = scene.shape
    L = config.clocks_per_readout
    budget = log_budget(scene.size, L)
    out = np.empty((K * L, H, W), stimulus_dtype(config))
    fraction = np.zeros(H * W)
    for k in range(K):
        expected = pixels.photo(electrons_per_readout(scene[k].reshape(-1)))
        if noise:
            e = clock_electrons(config, expected, pixels.dark(expected.size, rng), rng, budget)
        else:
            e, fraction = deterministic_clock_electrons(config, expected, fraction)
        out[k * L:(k + 1) * L] = e.T.reshape(L, H, W)
    return out
