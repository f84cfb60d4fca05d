"""Lane counts and stimuli shared by the streaming-readout tests (SPEC section 6, ``--lanes N``)."""

from __future__ import annotations

from tespike.golden.config import SensorConfig
from tespike.golden.beats import min_lanes

#: Array shape of the streaming runs: 6 pixels, rows != columns.
STREAM_SHAPE = (2, 3)


def lane_counts(config: SensorConfig, shape=STREAM_SHAPE) -> list[int]:
    """Lane counts worth running: the smallest legal N, one that does not divide H*W, N = H*W, N > H*W."""
    pixels = shape[0] * shape[1]
    smallest = min_lanes(config, *shape)
    candidates = [smallest, 4, pixels, pixels + 1]
    return sorted({n for n in candidates if n >= smallest})
