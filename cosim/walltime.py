"""Run time of torch code: the median of repeated calls, measured by ``torch.utils.benchmark``.

``torch.utils.benchmark.Timer`` synchronises CUDA around each call and runs it with
the caller's torch thread count (``num_threads``; its default of 1 would time
another setting than the one reported). Each repeat is one ``timeit(1)``: the
callers time whole reconstructions (0.01-10 s), where one call is the unit the
reports speak of and a shared machine's load makes the median the robust figure.
Measured here (2 shared cores): an empty call reads 0.4 us (0.14 us by a bare
``perf_counter`` pair), and each repeat costs about 14 ms outside the measurement
(the Timer's set-up), nothing against the 3 ms - 2 s being timed.
"""

from __future__ import annotations

import statistics


def median_seconds(function, repeats: int, *, warm_up: bool = False) -> tuple[float, object]:
    """Median wall time of ``repeats`` calls of ``function()`` and the result of one call.

    ``warm_up``: one untimed call first (one-time costs: tables, the allocator); the result
    returned is always a call's own (the last, or the warm-up's when ``repeats`` is 0).
    """
    import torch
    from torch.utils.benchmark import Timer

    box = {}

    def call():
        box["result"] = function()

    if warm_up or repeats < 1:
        call()
    timer = Timer(stmt="call()", globals={"call": call}, num_threads=torch.get_num_threads())
    times = [timer.timeit(1).median for _ in range(repeats)]
    return (statistics.median(times) if times else float("nan")), box.get("result")
