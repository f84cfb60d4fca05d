"""Run time of a reconstruction: the median wall time of repeated calls, each call timed once.

Every report of the project times a reconstruction with :func:`median_seconds` (the evaluation's
tables, the demo's RTL rows, the benchmarks). Each call is timed alone: the callers time whole
reconstructions (0.01-10 s), where one call is the unit the reports speak of and a shared machine's
load makes the median the robust figure. Around each call the CUDA device is synchronised when
torch has initialised it (work queued before the call is not counted, work the call queued is),
and the call runs with the caller's torch thread count, as ``torch.utils.benchmark.Timer`` does.
Written here rather than by ``Timer.timeit(1)``: that runs the statement twice more as its own
warm-up on every call, so a reconstruction timed 3 times ran 9 times.
"""

from __future__ import annotations

import statistics
import time

from tespike.golden.errors import InputError, is_count


def median_seconds(function, repeats: int, *, warm_up: bool = False) -> tuple[float, object]:
    """Median wall time of ``repeats`` calls of ``function()`` and the result of one call.

    ``warm_up``: one untimed call first (one-time costs: tables, the allocator); the result
    returned is always a call's own (the last, or the warm-up's when ``repeats`` is 0).
    """
    import torch

    if not callable(function):
        raise InputError(f"median_seconds: {function!r} is not a function to time")
    if not is_count(repeats):                            # (2.5 had been a TypeError, 0 a NaN median)
        raise InputError(f"median_seconds repeats {repeats!r}: must be an integer >= 0")

    def synchronise() -> None:
        if torch.cuda.is_available() and torch.cuda.is_initialized():
            torch.cuda.synchronize()

    result = function() if warm_up or repeats < 1 else None
    times = []
    for _ in range(repeats):
        synchronise()
        start = time.perf_counter()
        result = function()
        synchronise()
        times.append(time.perf_counter() - start)
    return (statistics.median(times) if times else float("nan")), result
