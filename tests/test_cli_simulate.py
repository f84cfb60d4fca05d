import json

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_words
from tespike.golden.fastsim import simulate_scene
from tespike.golden.io import load_stream
from tests.cli import assert_refused, run_tespike


def _no_output(tmp_path):
    return not list(tmp_path.glob("s.np[yz]*")) and not list(tmp_path.glob(".s.np[yz]*"))


def test_simulate_writes_spec_stream_reproducibly(tmp_path):
    config = SensorConfig(b1=2, b2=2, threshold=30)
    (tmp_path / "c.json").write_text(json.dumps({"b1": 2, "b2": 2, "threshold": 30}))
    scene = np.random.default_rng(0).uniform(0, 1.5, (4, 3, 5)).astype(np.float32)
    np.save(tmp_path / "i.npy", scene)
    for name, seed in (("a.npz", 5), ("b.npz", 5), ("c.npz", 6)):
        result = run_tespike("simulate", "--config", tmp_path / "c.json", "--scene", tmp_path / "i.npy",
                             "--out", tmp_path / name, "--seed", seed)
        assert result.returncode == 0 and result.stderr == "", result.stderr
    with np.load(tmp_path / "a.npz") as npz:
        words = npz["words"]
        assert json.loads(str(npz["config"])) == config.to_dict()
    assert words.shape == (4, 3, 5) and words.dtype.kind in "iu"
    check_words(words, config)
    assert np.array_equal(words, simulate_scene(config, scene, seed=5))   # the library, same seed
    assert np.array_equal(words, load_stream(tmp_path / "b.npz")[0])
    assert not np.array_equal(words, load_stream(tmp_path / "c.npz")[0])


def test_simulate_options(tmp_path):
    np.save(tmp_path / "i.npy", np.full((3, 2, 2), 0.2))
    for extra in (["--no-noise"], ["--dark-current", "eq12"], ["--dark-current", "eq13"],
                  ["--method", "per-clock"]):
        seed = [] if extra == ["--no-noise"] else ["--seed", "1"]
        result = run_tespike("simulate", "--config", "ml", "--scene", tmp_path / "i.npy",
                             "--out", tmp_path / "s.npz", *seed, *extra)
        assert result.returncode == 0, (extra, result.stderr)
        words, config = load_stream(tmp_path / "s.npz")
        assert config == SensorConfig(mode="ml") and words.shape == (3, 2, 2)
    # noise-free: 8400 electrons per readout, threshold 328: cumulative 8400,
    # 16800, 25200 -> 25, 51, 76 spikes, the residual carried
    run_tespike("simulate", "--config", "ml", "--scene", tmp_path / "i.npy", "--out", tmp_path / "s.npz",
                "--no-noise")
    assert load_stream(tmp_path / "s.npz")[0][:, 0, 0].tolist() == [25, 26, 25]


@pytest.mark.parametrize("scene, words", [
    (np.full((2, 2, 2), -1e-3), ["negative"]),
    (np.full((2, 2, 2), np.nan), ["non-finite"]),
    (np.full((2, 2, 2), -np.inf), ["non-finite"]),
    (np.zeros((2, 2)), ["shape"]),
    (np.zeros((2, 2, 2), bool), ["dtype"]),
    (np.zeros((2, 2, 2), complex), ["dtype"]),
    (np.zeros((2, 2, 2), np.int32), ["dtype int32", "float"]),
])
def test_simulate_refuses_bad_scene_without_output(tmp_path, scene, words):
    np.save(tmp_path / "i.npy", scene)
    result = run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy", "--out", tmp_path / "s.npz")
    assert_refused(result, *words)
    assert _no_output(tmp_path)


def test_simulate_refuses_bad_files_and_config(tmp_path):
    np.save(tmp_path / "i.npy", np.zeros((1, 1, 1)))
    (tmp_path / "c.json").write_text('{"b1": 4, "threshold": 0}')
    assert_refused(run_tespike("simulate", "--config", tmp_path / "c.json", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "s.npz"), "'threshold'")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "missing.npy",
                               "--out", tmp_path / "s.npz"), "missing.npy")
    (tmp_path / "text.npy").write_text("not an array")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "text.npy",
                               "--out", tmp_path / "s.npz"), "text.npy")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "nodir" / "s.npz"), "nodir")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "s.npz", "--seed", "-3"), "--seed")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "s.npz", "--no-noise", "--dark-current", "eq12"), "eq12")
    for extra in (["--method", "per-clock"], ["--no-noise"]):      # (one process: --workers was ignored)
        assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                                   "--out", tmp_path / "s.npz", "--workers", "2", *extra), "--workers 2", extra[0])
    for command, out in (("simulate", "s.npz"), ("stimulus", "s.npy")):   # (the seed was reported and changed nothing)
        assert_refused(run_tespike(command, "--config", "te", "--scene", tmp_path / "i.npy",
                                   "--out", tmp_path / out, "--no-noise", "--seed", "7"), "--seed", "--no-noise")
    assert _no_output(tmp_path)


def test_simulate_with_a_sensor_noise_file(tmp_path):
    """--noise / --sensor-seed: the library's stream for that Sensor; clashes refused in one line."""
    from tespike.golden.noise import Sensor, SensorNoise
    noise = SensorNoise(dark_current="eq12", dark_level=2.0, dsnu=0.3, hot_pixels=0.05, prnu=0.05)
    (tmp_path / "n.json").write_text(noise.to_json())
    scene = np.full((3, 4, 5), 0.05)
    np.save(tmp_path / "i.npy", scene)
    common = ("simulate", "--config", "te", "--scene", tmp_path / "i.npy", "--seed", "2",
              "--noise", tmp_path / "n.json")
    for name, extra in (("a.npz", ()), ("b.npz", ("--sensor-seed", "7"))):
        result = run_tespike(*common, "--out", tmp_path / name, *extra)
        assert result.returncode == 0, result.stderr
    config = SensorConfig()
    assert np.array_equal(load_stream(tmp_path / "a.npz")[0], simulate_scene(config, scene, seed=2,
                                                                             sensor=Sensor(noise, 0)))
    assert np.array_equal(load_stream(tmp_path / "b.npz")[0], simulate_scene(config, scene, seed=2,
                                                                             sensor=Sensor(noise, 7)))
    assert_refused(run_tespike(*common, "--out", tmp_path / "s.npz", "--dark-current", "eq13"), "--dark-current")
    assert_refused(run_tespike(*common, "--out", tmp_path / "s.npz", "--sensor-seed", "-1"), "--sensor-seed")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "s.npz", "--sensor-seed", "1"), "--noise")
    (tmp_path / "mapless.json").write_text('{"dark_current": "eq12"}')          # no per-pixel map to draw
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy", "--out",
                               tmp_path / "s.npz", "--noise", tmp_path / "mapless.json", "--sensor-seed", "3"),
                   "--sensor-seed", "would be ignored")
    (tmp_path / "bad.json").write_text('{"prnu": 3}')
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "s.npz", "--noise", tmp_path / "bad.json"), "prnu")
    assert _no_output(tmp_path)


@pytest.mark.parametrize("config", ["te", "ml", "edge"])
def test_simulate_extreme_light(tmp_path, config):
    if config == "edge":
        (tmp_path / "c.json").write_text(json.dumps({"mode": "ml", "b1": 1, "b2": 1, "clocks_per_tick": 1,
                                                     "threshold": 3, "acc_bits": 2, "input_bits": 1}))
        config = tmp_path / "c.json"
    scene = np.zeros((3, 3, 6))
    scene[:, 0] = [0, 1e-7, 1, 1e3, 1e30, 1e300]
    scene[:, 1] = np.logspace(-12, 0, 6)                          # twelve decades in one frame
    scene[:, 2] = np.logspace(-6, 6, 6)
    np.save(tmp_path / "i.npy", scene)
    result = run_tespike("simulate", "--config", config, "--scene", tmp_path / "i.npy",
                         "--out", tmp_path / "s.npz", "--seed", "3")
    assert result.returncode == 0 and result.stderr == "", result.stderr
    words, cfg = load_stream(tmp_path / "s.npz")                  # checks every code legal
    assert words.shape == (3, 3, 6) and not words[:, 0, 0].any()


def test_simulate_msb_camera_from_json_then_reconstruct(tmp_path):
    """The check's path: ``{"mode": "ml", "ml_readout": "msb"}`` -> msb words (0..8, 4-bit
    word in the smallest dtype) equal to the library's, reconstructed by TFP and TFI."""
    (tmp_path / "c.json").write_text(json.dumps({"mode": "ml", "ml_readout": "msb"}))
    scene = np.geomspace(1e-4, 3.0, 5 * 3 * 4).reshape(5, 3, 4)
    np.save(tmp_path / "i.npy", scene)
    result = run_tespike("simulate", "--config", tmp_path / "c.json", "--scene", tmp_path / "i.npy",
                         "--out", tmp_path / "s.npz", "--seed", 3)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    words, config = load_stream(tmp_path / "s.npz")
    assert config == SensorConfig.preset("ml-msb") and words.dtype == np.uint8
    assert np.array_equal(words, simulate_scene(config, scene, seed=3)) and words.max() == 8
    for method in ("tfp", "tfi"):
        result = run_tespike("reconstruct", "--stream", tmp_path / "s.npz", "--method", method,
                             "--out", tmp_path / f"r_{method}.npy")
        assert result.returncode == 0, result.stderr
        images = np.load(tmp_path / f"r_{method}.npy")
        assert images.shape == scene.shape and np.isfinite(images).all()


def test_the_success_line_counts_one_readout_as_one(tmp_path):
    np.save(tmp_path / "i.npy", np.full((1, 2, 2), 0.3, np.float32))
    result = run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy", "--out", tmp_path / "s.npz")
    assert result.stdout.strip().endswith(": 1 readout of 2 x 2 TE words"), result.stdout
