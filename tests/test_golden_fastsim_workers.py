"""Horizontal stripes and worker processes of the fast simulator (golden.fastsim.simulate_scene).

The words depend on the seed and the frame's shape, never on the worker count;
a striped frame has the law of the cycle-exact model (same tests as
tests/test_golden_fastsim.py: mean decoded value within 4 combined standard
errors, code histogram TVD < 0.05); per-clock and noise-free runs are not
striped (they are the electrons of ``tespike stimulus``).
"""

import os
import re

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.decode import decode_spikes
from tespike.golden.errors import InputError
from tespike.golden.fastsim import (MAX_STRIPES, STRIPE_PIXELS, STRIPE_ROWS, SceneSimulator, scene_stimulus,
                            simulate_scene, stripe_simulators, stripe_slices)
from tespike.golden.io import load_stream
from tespike.golden.stimulus import poisson_stimulus
from tespike.golden.sensor import simulate
from tests.cli import assert_refused, run_tespike
from tests.processes import children

SMALL = SensorConfig(b1=2, b2=2, threshold=100)                            # L = 12, one threshold/clock at I = 0.029
SMALL_MSB = SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, b1=2, b2=2, threshold=5)   # saturates, L = 12


def _log_uniform(shape, seed):
    """Light log-uniform over 1e-4 .. 10 x design (every path of the fast simulator)."""
    return (10.0 ** np.random.default_rng(seed).uniform(-4, 1, shape)).astype(np.float32)


@pytest.mark.parametrize("height, width, count", [
    (384, 512, 2), (1080, 1920, 8), (4096, 4096, MAX_STRIPES), (128, 128, 1), (256, 256, 1),
    (256, 512, 2), (512, 512, 4), (31, 10 ** 6, 1), (40, 4096, 2), (1, 1, 1), (1000, 200, 2), (1000, 100, 1),
])
def test_stripes_depend_on_the_shape_only(height, width, count):
    rows = stripe_slices(height, width)
    assert len(rows) == count
    owners = np.zeros(height, int)                     # every row in exactly one stripe
    for r in rows:
        owners[r] += 1
    assert (owners == 1).all()
    sizes = [len(range(height)[r]) for r in rows]
    assert max(sizes) - min(sizes) <= 1
    if count > 1:
        assert min(sizes) >= STRIPE_ROWS and min(sizes) * width >= STRIPE_PIXELS


def test_stripes_share_a_sky_over_ground_scene_evenly():
    # a pan's costly rows (bright sky, detailed ground) lie together: interleaved
    # rows give every stripe, and so every worker, the same mix of them
    H, W = 384, 512
    light = np.where(np.arange(H)[:, None] < H // 3, 2.0, 1e-3) * np.ones((1, W))
    shares = [light[r].mean() for r in stripe_slices(H, W)]
    assert len(shares) == 2 and max(shares) / min(shares) < 1.02


@pytest.mark.parametrize("config, height", [(SensorConfig(), 128), (SensorConfig.preset("ml-msb"), 128),
                                            (SMALL, 256)], ids=str)
def test_worker_count_does_not_change_the_words(config, height):
    # log-uniform light: every path (paper configs: lazy, event, bright, queue, full, head, per clock)
    scene = _log_uniform((2, height, 1024), 0)                           # 2 or 4 stripes
    assert len(stripe_slices(height, 1024)) == height // 64
    one = simulate_scene(config, scene, seed=3, workers=1)
    assert np.array_equal(one, simulate_scene(config, scene, seed=3, workers=2))
    assert np.array_equal(one, simulate_scene(config, scene, seed=3, workers=None))   # the cores available
    assert not np.array_equal(one, simulate_scene(config, scene, seed=4, workers=2))
    if config != SMALL:
        return
    assert np.array_equal(one, simulate_scene(config, scene, seed=3, workers=3))
    assert np.array_equal(one, simulate_scene(config, scene, seed=3, workers=4))
    dark = simulate_scene(config, scene, seed=3, workers=1, dark_current="eq13")
    assert np.array_equal(dark, simulate_scene(config, scene, seed=3, workers=2, dark_current="eq13"))
    # a Generator as the seed: its spawned children, the same for any worker count
    a = simulate_scene(config, scene, seed=np.random.default_rng(8), workers=1)
    assert np.array_equal(a, simulate_scene(config, scene, seed=np.random.default_rng(8), workers=2))


def test_stripes_draw_independent_numbers():
    scene = np.full((2, 256, 1024), 0.3)
    words = simulate_scene(SensorConfig(), scene, seed=1)
    stripes = [words[:, r] for r in stripe_slices(256, 1024)]
    assert len(stripes) == 4
    assert all(not np.array_equal(a, b) for i, a in enumerate(stripes) for b in stripes[i + 1:])
    # the children are spawned: the parent generator's own stream is not used up
    rng = np.random.default_rng(5)
    simulate_scene(SensorConfig(), scene, seed=rng)
    assert rng.random() == np.random.default_rng(5).random()


def test_one_stripe_is_one_simulator_on_the_seed():
    # small frames are not split: exactly SceneSimulator(rng=seed), as before striping
    config = SensorConfig()
    scene = _log_uniform((3, 40, 30), 1)
    assert len(stripe_slices(40, 30)) == 1
    for seed in (7, np.random.default_rng(7)):
        words = simulate_scene(config, scene, seed=seed, workers=2)
        sim = SceneSimulator(config, (40, 30), rng=np.random.default_rng(7), total_pixel_readouts=scene.size)
        assert np.array_equal(words, np.stack([sim.readout(scene[k].astype(np.float64)) for k in range(3)]))


def test_every_stripe_keeps_the_whole_scene_budget():
    config = SensorConfig()
    total = 64 * 384 * 512
    rows, sims = stripe_simulators(config, (384, 512), seed=0, total_pixel_readouts=total)
    assert rows == stripe_slices(384, 512) and [s.shape for s in sims] == [(192, 512)] * 2
    whole = SceneSimulator(config, (384, 512), total_pixel_readouts=total).budget
    assert all(s.budget == whole for s in sims)


def _histogram(words, config):
    return np.bincount(words.ravel().astype(np.int64), minlength=1 << config.word_bits) / words.size


@pytest.mark.parametrize("config", [SMALL, SMALL_MSB], ids=str)
def test_striped_frame_has_the_law_of_the_cycle_exact_model(config):
    # seven levels laid diagonally ((3 row + col) mod 7), so a stripe fed its
    # neighbour's rows, or words written one stripe off, would change the law;
    # light steps in time carry backlogged, full and msb-remainder states
    levels = np.array([0.0, 7e-4, 4e-3, 0.02, 0.028, 0.035, 0.3])
    H, W = 64, 2048
    rows, cols = np.mgrid[0:H, 0:W]
    level = (3 * rows + cols) % len(levels)
    steps = np.array([1.0, 1.0, 3.0, 0.0, 1.0, 0.5])
    scene = steps[:, None, None] * levels[level][None]
    assert len(stripe_slices(H, W)) == 2
    fast = simulate_scene(config, scene, seed=21, workers=2)
    exact = simulate(config, poisson_stimulus(config, scene, 22))
    a_all, b_all = decode_spikes(fast, config).mean(axis=0), decode_spikes(exact, config).mean(axis=0)
    for i in range(len(levels)):
        for half in stripe_slices(H, W):                                 # each stripe on its own
            mask = level[half] == i
            a, b = a_all[half][mask], b_all[half][mask]
            se = np.sqrt(a.var() / a.size + b.var() / b.size)
            diff = a.mean() - b.mean()
            z = 0.0 if diff == 0 else diff / max(se, 1e-12)
            tvd = 0.5 * np.abs(_histogram(fast[:, half][:, mask], config)
                               - _histogram(exact[:, half][:, mask], config)).sum()
            assert abs(z) < 4 and tvd < 0.05, (levels[i], half, z, tvd)


def test_per_clock_and_noise_free_are_not_striped():
    # the electrons of `tespike stimulus --seed N` are those `simulate --method per-clock --seed N` draws
    scene = _log_uniform((2, 64, 2048), 2) * 0.03
    assert len(stripe_slices(64, 2048)) == 2
    per_clock = simulate_scene(SMALL, scene, seed=4, method="per-clock", workers=2)
    assert np.array_equal(per_clock, simulate(SMALL, scene_stimulus(SMALL, scene, seed=4)))
    noise_free = simulate_scene(SMALL, scene, noise=False, workers=2)
    assert np.array_equal(noise_free, simulate(SMALL, poisson_stimulus(SMALL, scene, noise=False)))


@pytest.mark.parametrize("workers", [0, -1, 1.5, True, "2"])
def test_bad_worker_counts_are_refused(workers):
    for method in ("fast", "per-clock"):
        with pytest.raises(InputError, match="workers"):
            simulate_scene(SensorConfig(), np.zeros((1, 2, 2)), seed=0, method=method, workers=workers)


def test_bad_light_is_refused_as_a_scan_of_the_whole_scene_refuses_it():
    """Each process checks its own stripes' light as it simulates them; the refusal names
    the first bad readout in order, whichever process met bad light first (row 41 lies in
    the second stripe, a forked worker's with two workers; row 40 in the first)."""
    cases = [([((2, 41, 7), np.nan), ((1, 40, 3), -1.0)], "negative light value (-1.0)"),
             ([((1, 41, 7), np.nan), ((2, 40, 3), -1.0)], "non-finite light value (nan)")]
    for bad, first in cases:
        scene = np.full((3, 64, 2048), 0.2)
        for where, value in bad:
            scene[where] = value
        for workers in (1, 2):
            with pytest.raises(InputError, match=re.escape(f"scene 'I.npy' holds a {first}")):
                simulate_scene(SensorConfig(), scene, seed=0, workers=workers, what="scene 'I.npy'")


def test_a_failed_worker_is_an_error(monkeypatch):
    parent, readout = os.getpid(), SceneSimulator.readout

    def broken_in_workers(self, light, what="light"):
        if os.getpid() != parent:
            raise ValueError("broken on purpose")
        return readout(self, light, what)

    monkeypatch.setattr(SceneSimulator, "readout", broken_in_workers)
    with pytest.raises(RuntimeError, match=r"worker\(s\) \[1\] failed"):
        simulate_scene(SensorConfig(), np.full((2, 64, 2048), 0.1), seed=0, workers=2)
    assert simulate_scene(SensorConfig(), np.full((2, 64, 2048), 0.1), seed=0, workers=1).shape == (2, 64, 2048)


def test_a_worker_killed_without_a_word_is_an_error(monkeypatch):
    """A worker tells its status on a pipe before it exits (its teardown is reaped beside the
    command's own work); one that dies without telling (killed) is read from waitpid."""
    import signal
    parent, readout = os.getpid(), SceneSimulator.readout

    def killed_in_workers(self, light, what="light"):
        if os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        return readout(self, light, what)

    monkeypatch.setattr(SceneSimulator, "readout", killed_in_workers)
    with pytest.raises(RuntimeError, match=r"worker\(s\) \[1\] failed"):
        simulate_scene(SensorConfig(), np.full((2, 64, 2048), 0.1), seed=0, workers=2)


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")
def test_workers_are_reaped():
    from tespike.golden.fastsim.stripes import _join_reapers
    before = set(children(os.getpid()))
    for workers in (2, 4):
        simulate_scene(SensorConfig(), np.full((2, 256, 1024), 0.1), seed=0, workers=workers)
    _join_reapers()
    assert set(children(os.getpid())) == before


def test_cli_workers_give_the_same_file(tmp_path):
    np.save(tmp_path / "i.npy", _log_uniform((2, 64, 2048), 3))            # 2 stripes
    for workers in (1, 2):
        result = run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                             "--out", tmp_path / f"s{workers}.npz", "--seed", 6, "--workers", workers)
        assert result.returncode == 0 and result.stderr == "", result.stderr
    assert (tmp_path / "s1.npz").read_bytes() == (tmp_path / "s2.npz").read_bytes()
    assert np.array_equal(load_stream(tmp_path / "s1.npz")[0],
                          simulate_scene(SensorConfig(), np.load(tmp_path / "i.npy"), seed=6))


@pytest.mark.parametrize("value, words", [("0", ["--workers 0", "1.."]), ("-2", ["--workers -2"]),
                                          (str(10 ** 30), ["--workers"]), ("two", ["--workers"])])
def test_cli_bad_workers_refused_in_one_line(tmp_path, value, words):
    np.save(tmp_path / "i.npy", np.zeros((1, 2, 2)))
    result = run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy",
                         "--out", tmp_path / "s.npz", "--workers", value)
    assert_refused(result, *words)
    assert not list(tmp_path.glob("*s.npz*"))


def test_a_worker_that_cannot_be_forked_leaves_its_stripes_to_this_process(monkeypatch):
    """No more processes (fork fails): the stripes it would have taken are run
    here, and the words are those of any other worker count."""
    scene = _log_uniform((2, 256, 1024), 4)                               # 4 stripes
    expected = simulate_scene(SensorConfig(), scene, seed=2, workers=1)
    real_fork, forks = os.fork, []

    def fork_once():
        if forks:
            raise OSError(11, "Resource temporarily unavailable")
        forks.append(1)
        return real_fork()
    monkeypatch.setattr(os, "fork", fork_once)
    assert np.array_equal(simulate_scene(SensorConfig(), scene, seed=2, workers=4), expected)
    assert forks == [1]


def test_workers_stop_when_the_command_is_killed_outright():
    """A command killed with SIGKILL cannot end its workers: each stops at its next readout
    instead of simulating the rest of its stripes for nobody."""
    import signal
    import subprocess
    import sys
    import time
    script = ("import os, sys, numpy as np\n"
              "from tespike.golden.config import SensorConfig\n"
              "from tespike.golden.fastsim import simulate_scene\n"
              "scene = np.broadcast_to(np.float32(0.05), (4000, 64, 2048))\n"   # 2 stripes, about a minute
              "print(os.getpid(), flush=True)\n"
              "simulate_scene(SensorConfig(), scene, seed=0, workers=2)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)

    def session():
        out = subprocess.run(["ps", "-o", "pid=", "-s", str(proc.pid)], capture_output=True, text=True).stdout
        return [int(p) for p in out.split()]

    try:
        assert proc.stdout.readline().strip() == str(proc.pid)
        deadline = time.monotonic() + 60
        while len(session()) < 2 and time.monotonic() < deadline:      # the worker is forked
            time.sleep(0.1)
        assert len(session()) == 2, session()
        time.sleep(0.5)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 10
        while session() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not session(), f"workers still simulating after the command was killed: {session()}"
        assert proc.stderr.read() == ""
    finally:
        for pid in session():
            os.kill(pid, signal.SIGKILL)
