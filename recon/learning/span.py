"""The span of readouts a learned method sees around its key moment: the one rule of every
learned method, in training (:mod:`tespike.recon.engine.batches`) and at inference
(:mod:`tespike.recon.learning.infer`) alike."""

from __future__ import annotations

import numpy as np

from tespike.golden.errors import InputError, is_count


def check_span(length, key, span) -> None:
    """A stream of ``length`` >= 1 readouts, a ``key`` readout inside it and a ``span`` >= 1, refused in
    one line otherwise (a key past the stream had repeated its last readout, 2.5 given floats)."""
    if not (is_count(length, 1) and is_count(span, 1)):
        raise InputError(f"readouts {length!r} and span {span!r}: must be integers >= 1")
    if not (is_count(key) and key < length):
        raise InputError(f"key readout {key!r}: must be an integer in 0 .. {length - 1} (the stream's readouts)")


def key_span(length: int, key: int, span: int) -> np.ndarray:
    """Readout indices of the ``span`` readouts centred on ``key`` in a stream of ``length``,
    the first or last readout repeated past either end (so a stream of one readout works)."""
    check_span(length, key, span)
    return np.clip(np.arange(span) + key - span // 2, 0, length - 1)


def span_inside(length: int, key: int, span: int) -> np.ndarray:
    """(span,) bool: which readouts of :func:`key_span` lie in the stream (the others repeat an end)."""
    check_span(length, key, span)
    times = np.arange(span) + key - span // 2
    return (times >= 0) & (times < length)
