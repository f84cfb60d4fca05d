"""Cycle-exact model of a TE or ML pixel array (SPEC sections 3 and 4), run in chunks.

:class:`PixelArray` carries the state between chunks of any length, so a run
split anywhere gives the identical stream, and memory stays bounded by the
chunk size however many readouts a run has.
"""

from __future__ import annotations

from typing import Iterable, Iterator

import numpy as np

from .config import SensorConfig
from .io import check_stimulus
from .reference import PixelState, step_reference

#: Pixel clocks x pixels processed at once by :func:`simulate` (bounds memory).
DEFAULT_CHUNK_ELEMENTS = 1 << 22


class PixelArray:
    """An H x W array of TE or ML pixels that consumes per-clock electrons."""

    def __init__(self, config: SensorConfig, shape: tuple[int, int]):
        self.config = config
        self.shape = tuple(shape)
        self.state = PixelState.zeros(self.shape)

    def feed(self, electrons: np.ndarray) -> np.ndarray:
        """Consume (T, H, W) electrons of any T; return the words of the readouts completed."""
        check_stimulus(electrons, self.config, whole_readouts=False)
        if electrons.shape[1:] != self.shape:
            raise ValueError(f"chunk shape {electrons.shape[1:]} != array shape {self.shape}")
        words, self.state = step_reference(self.config, electrons, self.state)
        return words


def iter_chunks(stimulus: np.ndarray, config: SensorConfig,
                chunk_elements: int = DEFAULT_CHUNK_ELEMENTS) -> Iterator[np.ndarray]:
    """Split (T, H, W) into whole-readout chunks of about ``chunk_elements`` values."""
    T, H, W = stimulus.shape
    L = config.clocks_per_readout
    step = max(1, chunk_elements // max(1, H * W * L)) * L
    for start in range(0, T, step):
        yield stimulus[start:start + step]


def simulate(config: SensorConfig, stimulus: np.ndarray,
             chunks: Iterable[np.ndarray] | None = None) -> np.ndarray:
    """Stimulus (T, H, W), T a multiple of L -> readout words (T / L, H, W), int64."""
    check_stimulus(stimulus, config)
    array = PixelArray(config, stimulus.shape[1:])
    parts = [array.feed(chunk) for chunk in (chunks if chunks is not None else iter_chunks(stimulus, config))]
    if not parts:
        return np.zeros((0,) + stimulus.shape[1:], np.int64)
    return np.concatenate(parts)
