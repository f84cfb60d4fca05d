"""Pictures and reports people look at: PNG figures and text (the tone map is :mod:`tespike.recon.mulaw`'s).

numpy and matplotlib only (no torch), so ``tespike view``, the demo's pictures and
the benchmarks' plots share one way of saving a figure without importing the
evaluation or the network. Files are written atomically
(:func:`tespike.golden.io.atomic_output`): a failed write leaves nothing.
"""

from __future__ import annotations

from pathlib import Path

from tespike.golden.errors import InputError, is_positive_number
from tespike.golden.io import atomic_output

#: Range of the error maps people are shown (absolute difference of mu-law images).
ERROR_RANGE = 0.25


def save_figure(fig, path: str | Path, dpi: int = 100, **options) -> None:
    """Write a matplotlib figure as PNG to ``path`` (atomically) and close it."""
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure
    if not isinstance(fig, Figure):                      # (None had been an AttributeError)
        raise InputError(f"save_figure: {type(fig).__name__} is no matplotlib figure")
    if not is_positive_number(dpi):
        plt.close(fig)
        raise InputError(f"save_figure dpi {dpi!r}: must be a finite number > 0")
    try:
        with atomic_output(path) as tmp:
            fig.savefig(tmp, format="png", dpi=dpi, **options)
    finally:
        plt.close(fig)


def write_text(path: str | Path, text: str) -> None:
    """Write a UTF-8 text file (a report, a table) atomically."""
    if not isinstance(text, str):                        # (bytes had been pathlib's TypeError)
        raise InputError(f"write_text: the text must be a str, not {type(text).__name__}")
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
