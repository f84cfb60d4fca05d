"""``tespike stimulus``: scene -> per-clock electrons with simulate's noise model and seed."""

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.decode import decode_spikes
from tespike.golden.fastsim import scene_stimulus, simulate_scene
from tespike.golden.io import load_stream
from tespike.golden.noise import Sensor, SensorNoise
from tespike.golden.sensor import simulate
from tests.cli import assert_refused, run_tespike

SMALL_TE = SensorConfig(b1=2, b2=2, threshold=300)


@pytest.mark.parametrize("config", [SMALL_TE, SensorConfig(mode="ml", b1=2, b2=2, ml_bits=4)], ids=str)
@pytest.mark.parametrize("options", [{}, {"dark_current": "eq12"}, {"noise": False},
                                     {"sensor": Sensor(SensorNoise(dark_current="eq13", dsnu=0.3, hot_pixels=0.1,
                                                                   prnu=0.05, comparator_offset=0.05), 3)}],
                         ids=str)
def test_golden_on_the_stimulus_is_simulate_per_clock(config, options):
    """Same seed, same options: the cycle-exact model on the stimulus is simulate's per-clock stream."""
    scene = np.random.default_rng(0).uniform(0, 2.5, (5, 6, 7))
    scene[0, 0, 0], scene[2, 1, 1] = 0.0, 1e6              # dark and saturating pixels
    electrons = scene_stimulus(config, scene, seed=11, **options)
    assert electrons.shape == (5 * config.clocks_per_readout, 6, 7) and electrons.dtype == np.uint16
    assert np.array_equal(simulate(config, electrons),
                          simulate_scene(config, scene, seed=11, method="per-clock", **options))


def test_stream_statistics_agree_with_simulate():
    """The golden stream on the stimulus has the law of simulate's fast stream: mean spikes per
    light level agree within 5 standard errors, and so do their variances (within 25 %)."""
    config = SMALL_TE
    levels = np.array([0.002, 0.03, 0.2, 0.7, 1.5])
    scene = np.repeat(levels, 40 * 40 // len(levels)).reshape(1, 40, 40).repeat(6, axis=0)
    a = decode_spikes(simulate(config, scene_stimulus(config, scene, seed=1)), config)[1:]
    b = decode_spikes(simulate_scene(config, scene, seed=2), config)[1:]
    for level in levels:
        mask = np.broadcast_to(scene[1:] == level, a.shape)
        x, y = a[mask], b[mask]
        se = np.sqrt(x.var() / x.size + y.var() / y.size) + 1e-12
        assert abs(x.mean() - y.mean()) < 5 * se, (level, x.mean(), y.mean())
        if y.var() > 0.05:
            assert 0.75 < x.var() / y.var() < 1.33, (level, x.var(), y.var())


def test_command_is_deterministic_and_closes_the_loop(tmp_path):
    scene = np.random.default_rng(3).uniform(0, 1.2, (3, 4, 5)).astype(np.float32)
    np.save(tmp_path / "i.npy", scene)
    for name, seed in (("a.npy", 7), ("b.npy", 7), ("c.npy", 8)):
        result = run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy",
                             "--out", tmp_path / name, "--seed", seed)
        assert result.returncode == 0, result.stderr
        assert result.stdout.startswith(f"wrote {tmp_path / name}") and result.stderr == ""
    a, b, c = (np.load(tmp_path / n) for n in ("a.npy", "b.npy", "c.npy"))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.shape == (3 * 240, 4, 5) and a.dtype == np.uint16
    # stimulus -> golden == simulate --method per-clock, same seed, through the command line
    for command, extra in (("golden", ["--stimulus", tmp_path / "a.npy"]),
                           ("simulate", ["--scene", tmp_path / "i.npy", "--seed", 7, "--method", "per-clock"])):
        result = run_tespike(command, "--config", "te", *extra, "--out", tmp_path / f"{command}.npz")
        assert result.returncode == 0, result.stderr
    assert np.array_equal(load_stream(tmp_path / "golden.npz")[0], load_stream(tmp_path / "simulate.npz")[0])
    quiet = run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy", "--no-noise",
                        "--out", tmp_path / "d.npy", "--quiet")
    assert quiet.returncode == 0 and quiet.stdout == "" and quiet.stderr == ""


def test_refusals(tmp_path):
    np.save(tmp_path / "i.npy", np.full((4, 30, 40), 0.5))
    result = run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy",
                         "--out", tmp_path / "e.npy", "--max-bytes", 100000)
    assert_refused(result, "4 * 240 x 30 x 40", str(4 * 240 * 30 * 40 * 2), "--max-bytes")
    assert_refused(run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "e.npy", "--no-noise", "--dark-current", "eq12"),
                   "--no-noise")
    assert_refused(run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "none.npy",
                               "--out", tmp_path / "e.npy"), "none.npy")
    assert_refused(run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--out", tmp_path / "no" / "e.npy"), "does not exist")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["i.npy"]


def test_crop_and_readouts_keep_the_full_stimulus_electrons(tmp_path):
    scene = np.random.default_rng(5).uniform(0, 1.5, (4, 6, 8))
    scene[1, 2, 3] = 1e9                                     # saturating: the budget must be the full scene's
    np.save(tmp_path / "i.npy", scene)
    full = scene_stimulus(SensorConfig(), scene, seed=9)
    result = run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy", "--seed", 9,
                         "--crop", "1,2,3,4", "--readouts", 2, "--out", tmp_path / "e.npy")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("seed 9)")
    assert np.array_equal(np.load(tmp_path / "e.npy"), full[:2 * 240, 1:4, 2:6])
    assert_refused(run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy", "--crop", "0,0,0,1",
                               "--out", tmp_path / "f.npy"), "height and width must be >= 1 (got 0 x 1)")
    done = run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy", "--no-noise",
                       "--out", tmp_path / "g.npy")                  # (it printed "seed None")
    assert done.returncode == 0 and done.stdout.strip().endswith("no noise)"), done
    for crop in ("1,2,3", "4,0,3,1", "0,0,0,1"):
        assert_refused(run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy",
                                   "--crop", crop, "--out", tmp_path / "f.npy"), "--crop")
    assert_refused(run_tespike("stimulus", "--config", "te", "--scene", tmp_path / "i.npy",
                               "--readouts", 5, "--out", tmp_path / "f.npy"), "--readouts")
