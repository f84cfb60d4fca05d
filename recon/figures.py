"""Saving figures: one PNG writer for every plot of the project (atomic: never half-written)."""

from __future__ import annotations

from pathlib import Path

from golden.io import atomic_output


def save_figure(fig, path: str | Path, dpi: int = 110) -> None:
    """Write matplotlib ``fig`` to ``path`` as PNG, atomically."""
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
