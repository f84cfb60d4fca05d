"""Pictures and reports people look at: the mu-law tone map of light images, PNG figures, text.

numpy and matplotlib only (no torch), so ``tespike view``, the demo's pictures and
the benchmarks' plots share one tone map and one way of saving a figure without
importing the evaluation or the network. Files are written atomically
(:func:`tespike.golden.io.atomic_output`): a failed write leaves nothing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tespike.golden.io import atomic_output

#: The paper's mu-law constant (its eq. 11).
MU = 5000.0
#: Range of the error maps people are shown (absolute difference of mu-law images).
ERROR_RANGE = 0.25


def tone_map(light: np.ndarray, peak: float, mu: float = MU) -> np.ndarray:
    """Divide by the ground truth's peak, clip to [0, 1], mu-law (paper eq. 11); float64.

    The numpy twin of :func:`tespike.recon.learning.mulaw.compress` (the metrics' and the learned
    methods' torch mu-law), kept because ``tespike view``, the demo's pictures and the
    benchmarks' plots run without importing torch (1.7 s of every start, measured here)."""
    h = np.clip(np.asarray(light, np.float64) / peak, 0.0, 1.0)
    return np.log1p(mu * h) / math.log1p(mu)


def save_figure(fig, path: str | Path, dpi: int = 100, **options) -> None:
    """Write a matplotlib figure as PNG to ``path`` (atomically) and close it."""
    import matplotlib.pyplot as plt
    try:
        with atomic_output(path) as tmp:
            fig.savefig(tmp, format="png", dpi=dpi, **options)
    finally:
        plt.close(fig)


def write_text(path: str | Path, text: str) -> None:
    """Write a UTF-8 text file (a report, a table) atomically."""
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
