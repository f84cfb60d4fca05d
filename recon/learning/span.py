"""The span of readouts a learned method sees around its key moment: the one rule of every
learned method, in training (:mod:`tespike.recon.engine.batches`) and at inference
(:mod:`tespike.recon.learning.infer`) alike."""

from __future__ import annotations

import numpy as np


def key_span(length: int, key: int, span: int) -> np.ndarray:
    """Readout indices of the ``span`` readouts centred on ``key`` in a stream of ``length``,
    the first or last readout repeated past either end (so a stream of one readout works)."""
    return np.clip(np.arange(span) + key - span // 2, 0, length - 1)


def span_inside(length: int, key: int, span: int) -> np.ndarray:
    """(span,) bool: which readouts of :func:`key_span` lie in the stream (the others repeat an end)."""
    times = np.arange(span) + key - span // 2
    return (times >= 0) & (times < length)
