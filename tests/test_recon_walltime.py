"""The run time every report gives: each timed call runs once (torch's ``Timer.timeit`` ran two more)."""

from __future__ import annotations

import math

from tespike.recon.walltime import median_seconds


def test_each_repeat_calls_once_and_the_result_is_a_calls_own():
    calls = []
    seconds, result = median_seconds(lambda: calls.append(len(calls)) or len(calls), 3)
    assert len(calls) == 3 and result == 3 and seconds >= 0
    calls.clear()
    assert median_seconds(lambda: calls.append(1) or len(calls), 2, warm_up=True)[1] == 3 and len(calls) == 3


def test_the_median_not_the_mean():
    import time
    pauses = iter([0.0, 0.2, 0.0])
    seconds, _ = median_seconds(lambda: time.sleep(next(pauses)), 3)
    assert seconds < 0.1


def test_no_repeat_gives_nan_and_one_untimed_call():
    calls = []
    seconds, result = median_seconds(lambda: calls.append(1) or "r", 0)
    assert math.isnan(seconds) and result == "r" and len(calls) == 1
