import json

import numpy as np
import pytest

from golden.config import SensorConfig
from golden.reference import step_reference
from tests.cli import assert_refused, run_tespike


def test_golden_command_writes_spec_stream(tmp_path, rng):
    config = SensorConfig(b1=2, b2=2, threshold=20)
    (tmp_path / "c.json").write_text(json.dumps({"b1": 2, "b2": 2, "threshold": 20}))
    stim = rng.integers(0, 40, size=(config.clocks_per_readout * 4, 3, 2)).astype(np.int16)
    np.save(tmp_path / "e.npy", stim)
    result = run_tespike("golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz")
    assert result.returncode == 0, result.stderr
    with np.load(tmp_path / "s.npz") as npz:
        assert np.array_equal(npz["words"], step_reference(config, stim)[0])
        assert json.loads(str(npz["config"])) == config.to_dict()


@pytest.mark.parametrize("stimulus, words", [
    (np.zeros((240, 2, 2), np.float32), ["float"]),
    (np.zeros((240, 2, 2), bool), ["bool"]),
    (np.zeros((239, 2, 2), np.int32), ["239", "multiple"]),
    (np.full((240, 2, 2), -1, np.int32), ["-1"]),
    (np.full((240, 2, 2), 65536, np.int32), ["65536"]),
    (np.zeros((240, 4), np.int32), ["shape"]),
])
def test_golden_refuses_bad_stimulus_without_output(tmp_path, stimulus, words):
    np.save(tmp_path / "e.npy", stimulus)
    result = run_tespike("golden", "--config", "te", "--stimulus", tmp_path / "e.npy", "--out", tmp_path / "s.npz")
    assert_refused(result, *words)
    assert not list(tmp_path.glob("s.npz*")) and not list(tmp_path.glob(".s.npz*"))


def test_golden_refuses_bad_config(tmp_path):
    (tmp_path / "c.json").write_text('{"b1": 4, "gain": 2}')
    np.save(tmp_path / "e.npy", np.zeros((240, 1, 1), np.int32))
    result = run_tespike("golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz")
    assert_refused(result, "'gain'")
    assert not (tmp_path / "s.npz").exists()
