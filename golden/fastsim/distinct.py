"""Distinct values of an array by one sort, without ``np.unique``.

``np.unique``'s first call in a process imports ``numpy.ma`` (10-40 ms of CPU, in
the parent and again in each forked worker of a scene), more than a readout of a
small stripe costs; the simulator's few distinct-value questions (window lengths,
spikes still needed, integer means) are answered here by one sort instead.
"""

from __future__ import annotations

import numpy as np


def distinct(values) -> np.ndarray:
    """The distinct values of ``values`` (any shape), sorted; one value without a sort where
    all are equal (the common case of the TE spikes still needed: ``2^b1`` for every pixel)."""
    flat = np.ravel(values)
    if flat.size and (flat == flat[0]).all():
        return flat[:1].copy()
    return distinct_counts(flat)[0]


def distinct_counts(values) -> tuple[np.ndarray, np.ndarray]:
    """(the distinct values of ``values``, sorted; how often each occurs)."""
    v = np.sort(np.ravel(values))
    if not v.size:
        return v, np.zeros(0, np.int64)
    first = np.flatnonzero(np.concatenate(([True], v[1:] != v[:-1])))
    return v[first], np.diff(np.append(first, v.size))
