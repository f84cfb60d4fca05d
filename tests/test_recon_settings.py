"""tespike.recon.settings: one validated dataclass of sizes and switches."""

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.recon.settings import ReconSettings


def test_defaults_and_radius():
    s = ReconSettings()
    assert (s.window, s.radius, s.search, s.device, s.dtype) == (9, 4, "stream", "cpu", "float32")
    assert ReconSettings(window=1).radius == 0
    s = ReconSettings(window=np.int64(5), chunk_elements=np.uint32(100))
    assert (type(s.window), s.window, type(s.chunk_elements)) == (int, 5, int)


@pytest.mark.parametrize("field,value,words", [
    ("window", 0, "odd integer"), ("window", 8, "odd integer"), ("window", 9.0, "odd integer"),
    ("window", True, "odd integer"), ("chunk_elements", 0, ">= 1"), ("estimator", "mid", "ratio"),
    ("search", "both", "stream"), ("device", "cuda:3", "not a usable"), ("device", "meta", "no data"),
    ("device", "cpu:1", "one CPU device"),
    ("dtype", "float16", "float32"),
])
def test_refusals_name_field_and_value(field, value, words):
    with pytest.raises(InputError, match=field) as info:
        ReconSettings(**{field: value})
    assert words in str(info.value) and repr(value) in str(info.value)
