"""golden.io: the stimulus reader is memory-mapped and checks every slice."""

import numpy as np
import pytest

from golden.config import SensorConfig
from golden.errors import InputError
from golden.io import check_stimulus, load_stimulus


def test_load_stimulus_is_memory_mapped(tmp_path):
    np.save(tmp_path / "e.npy", np.ones((480, 2, 3), np.uint16))
    stim = load_stimulus(tmp_path / "e.npy", SensorConfig())
    assert isinstance(stim, np.memmap) and not stim.flags.writeable
    assert stim.shape == (480, 2, 3)


def test_bad_value_far_into_a_large_file_is_found(tmp_path, monkeypatch):
    stim = np.zeros((240 * 40, 1, 1), np.int32)
    stim[-1, 0, 0] = 70000
    np.save(tmp_path / "e.npy", stim)
    with pytest.raises(InputError, match="70000"):
        load_stimulus(tmp_path / "e.npy", SensorConfig())
    stim[-1, 0, 0] = -3
    np.save(tmp_path / "e.npy", stim)
    with pytest.raises(InputError, match="-3"):
        load_stimulus(tmp_path / "e.npy", SensorConfig())


def test_T_rule_checked_on_the_whole_file(tmp_path):
    np.save(tmp_path / "e.npy", np.zeros((241, 1, 1), np.uint8))
    with pytest.raises(InputError, match="multiple"):
        load_stimulus(tmp_path / "e.npy", SensorConfig())


def test_dtype_that_cannot_hold_a_bad_value_is_not_scanned():
    class Exploding(np.ndarray):
        def min(self, *a, **k):
            raise AssertionError("scanned")
        max = min
    stim = np.zeros((240, 1, 1), np.uint16).view(Exploding)
    assert check_stimulus(stim, SensorConfig()) is stim                    # uint16 with E = 16
    with pytest.raises(AssertionError, match="scanned"):
        check_stimulus(stim, SensorConfig(input_bits=12))                  # uint16 can exceed 2^12 - 1
    with pytest.raises(AssertionError, match="scanned"):
        check_stimulus(np.zeros((240, 1, 1), np.int16).view(Exploding), SensorConfig())   # may be negative
