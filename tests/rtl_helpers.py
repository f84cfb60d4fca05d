"""Helpers shared by the rtl tests: drive a PixelArray in the Amaranth simulator, make stimuli."""

from __future__ import annotations

import numpy as np
from amaranth.sim import Simulator

from tespike.golden.config import SensorConfig
from tespike.rtl.array import PixelArray


def pack(values, bits: int) -> int:
    """Pack integers into one bit vector, element i at bits [i*bits +: bits]."""
    out = 0
    for i, v in enumerate(np.asarray(values).ravel()):
        out |= int(v) << (i * bits)
    return out


def unpack(vector: int, bits: int, n: int) -> list[int]:
    mask = (1 << bits) - 1
    return [(vector >> (i * bits)) & mask for i in range(n)]


def rtl_array_words(config: SensorConfig, stimulus: np.ndarray, *, flat: bool = False,
                    extra_clocks: int = 1) -> tuple[np.ndarray, list[int]]:
    """Run PixelArray on a (T, H, W) stimulus from reset.

    Returns the (K, H, W) words captured whenever ``frame_valid`` was sampled high
    and the pixel clocks t (edge index) at which they were sampled.
    """
    T, H, W = stimulus.shape
    dut = PixelArray(config, H, W, flat=flat)
    e, wd = config.input_bits, config.word_bits
    words, times = [], []

    async def bench(ctx):
        for t in range(T + extra_clocks):
            ctx.set(dut.charge, pack(stimulus[t], e) if t < T else 0)
            *_, valid, frame = await ctx.tick().sample(dut.frame_valid, dut.frame)
            if valid:
                words.append(unpack(frame, wd, H * W))
                times.append(t)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return np.array(words, np.int64).reshape(-1, H, W), times


def mixed_stimulus(config: SensorConfig, rng, readouts: int, height: int, width: int) -> np.ndarray:
    """Poisson electrons per clock, each pixel at its own level from dark to far above design.

    Levels are in spikes per readout relative to the top code, so every config sees
    pixels below, near and above overflow (TE) or saturation (ML). Bursts of the
    largest input value (in about half the pixels) are mixed in to exercise the saturating accumulator.
    """
    L = config.clocks_per_readout
    top = config.p_max * config.alpha if config.is_te else config.ml_max
    levels = np.array([0.0, 0.05, 0.4, 0.9, 1.0, 1.3, 3.0, 40.0])
    level = rng.choice(levels, size=(height, width))
    mean = level * top * config.threshold / L
    stim = rng.poisson(np.broadcast_to(mean, (readouts * L, height, width)))
    bursty = rng.random((height, width)) < 0.5
    burst = (rng.random(stim.shape) < 0.003) & bursty
    stim = np.where(burst, config.input_max, stim)
    return np.minimum(stim, config.input_max).astype(np.int64)
