import json

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.reference import step_reference
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
    assert_refused(result, *words, f"stimulus file {str(tmp_path / 'e.npy')!r}")      # the file named
    assert not list(tmp_path.glob("s.npz*")) and not list(tmp_path.glob(".s.npz*"))


def test_golden_refuses_bad_config(tmp_path):
    (tmp_path / "c.json").write_text('{"b1": 4, "gain": 2}')
    np.save(tmp_path / "e.npy", np.zeros((240, 1, 1), np.int32))
    result = run_tespike("golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz")
    assert_refused(result, "'gain'")
    assert not (tmp_path / "s.npz").exists()


@pytest.mark.parametrize("stimulus, words", [
    (np.zeros((240, 2, 2), np.complex64), ["complex"]),
    (np.zeros((240, 2, 2, 1), np.int32), ["shape"]),
    (np.zeros((240, 0, 2), np.int32), ["H and W"]),
    (np.full((240, 2, 2), 2 ** 40, np.int64), [str(2 ** 40), "input_bits"]),
    (np.full((240, 2, 2), -5, np.int8), ["-5", "negative"]),
])
def test_golden_refuses_more_bad_stimuli(tmp_path, stimulus, words):
    np.save(tmp_path / "e.npy", stimulus)
    result = run_tespike("golden", "--config", "te", "--stimulus", tmp_path / "e.npy", "--out", tmp_path / "s.npz")
    assert_refused(result, *words, f"stimulus file {str(tmp_path / 'e.npy')!r}")
    assert not list(tmp_path.glob("*s.npz*"))


def test_golden_refuses_missing_and_garbage_files(tmp_path):
    result = run_tespike("golden", "--config", "te", "--stimulus", tmp_path / "nope.npy", "--out", tmp_path / "s.npz")
    assert_refused(result, "does not exist")
    (tmp_path / "junk.npy").write_bytes(b"not an npy file")
    result = run_tespike("golden", "--config", "te", "--stimulus", tmp_path / "junk.npy", "--out", tmp_path / "s.npz")
    assert_refused(result, "junk.npy")
    result = run_tespike("golden", "--config", "te", "--stimulus", tmp_path / "junk.npy",
                         "--out", tmp_path / "missing-dir" / "s.npz")
    assert_refused(result)


def test_golden_huge_T_from_memory_mapped_file(tmp_path):
    """Thousands of readouts streamed from disk in small chunks, with a progress bar, equal to the reference."""
    config = SensorConfig(b1=1, b2=1, threshold=3, acc_bits=3)            # L = 2
    T = config.clocks_per_readout * 20000
    stim = np.lib.format.open_memmap(tmp_path / "e.npy", mode="w+", dtype=np.uint8, shape=(T, 2, 3))
    rng = np.random.default_rng(7)
    stim[:] = rng.integers(0, 8, size=(T, 2, 3))
    stim.flush()
    (tmp_path / "c.json").write_text(config.to_json())
    result = run_tespike("golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--chunk-elements", 6000, "--progress", "on")
    assert result.returncode == 0, result.stderr
    assert "readout" in result.stderr                                    # the tqdm bar
    with np.load(tmp_path / "s.npz") as npz:
        words = npz["words"]
    assert words.shape == (20000, 2, 3) and words.dtype == np.uint8
    assert np.array_equal(words, step_reference(config, np.asarray(stim))[0])


def test_golden_quiet_for_short_runs(tmp_path):
    np.save(tmp_path / "e.npy", np.ones((240, 2, 2), np.uint16))
    result = run_tespike("golden", "--config", "te", "--stimulus", tmp_path / "e.npy", "--out", tmp_path / "s.npz")
    assert result.returncode == 0 and result.stderr == ""
