"""tespike.recon.engine: dead leaves, clips (families, peak, length), the pool's schedule, samples' edge padding."""

import math
import multiprocessing

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.recon.engine.batches import ClipPool, draw_batch, draw_sample
from tespike.recon.engine.clips import Clip, EngineRecipe, clip_light, draw_length, make_clip
from tespike.recon.engine.deadleaves import DeadLeavesParams, _power_law, dead_leaves
import torch

from tespike.recon.decoding import decode_light
from tespike.recon.learning.span import key_span, span_inside

SMALL = EngineRecipe(height=24, width=24, long=(6, 12), short=(1, 5))


def test_dead_leaves_is_positive_finite_moving_and_deterministic():
    a = dead_leaves(np.random.default_rng(3), 6, 40, 48)
    b = dead_leaves(np.random.default_rng(3), 6, 40, 48)
    assert a.shape == (6, 40, 48) and np.array_equal(a, b)
    assert np.isfinite(a).all() and a.min() > 0
    assert not np.array_equal(a[0], a[-1])                  # objects or camera moved


def test_dead_leaves_radiance_spans_the_decades_asked_for():
    params = DeadLeavesParams(decades=(5.0, 5.0), sources=(0, 0), texture=(0.0, 0.0), objects=(200, 200))
    light = dead_leaves(np.random.default_rng(0), 1, 96, 96, params)
    decades = math.log10(np.percentile(light, 99.5) / np.percentile(light, 0.5))
    assert 3.5 < decades < 5.5


def test_power_law_sizes_follow_their_law():
    r = _power_law(np.random.default_rng(1), 3.0, 1.0, 100.0, 200_000)
    assert r.min() >= 1.0 and r.max() <= 100.0
    # p(r) ~ r^-3 on [1, 100]: P(r > 2) = (2^-2 - 100^-2) / (1 - 100^-2)
    expected = (0.25 - 1e-4) / (1 - 1e-4)
    assert abs(np.mean(r > 2) - expected) < 4 * math.sqrt(expected * (1 - expected) / r.size)


def test_clip_is_a_pure_function_of_recipe_config_and_index():
    config = SensorConfig()
    a, b, c = make_clip(SMALL, config, 5), make_clip(SMALL, config, 5), make_clip(SMALL, config, 6)
    assert np.array_equal(a.words, b.words) and np.array_equal(a.light, b.light)
    assert a.light.shape != c.light.shape or not np.array_equal(a.light, c.light)
    other_seed = make_clip(EngineRecipe(**{**SMALL.to_dict(), "seed": 1}), config, 5)
    assert other_seed.light.shape != a.light.shape or not np.array_equal(other_seed.light, a.light)


def test_noisy_clips_carry_their_sensors_calibration():
    """noise_fraction 1: every clip has a random sensor in NOISE_DRAW and its exact calibration
    (mean dark rate and gain: a pixel sees gain x I + dark), target the scene light; noise_fraction 0
    draws nothing more (the clips recipes always gave)."""
    from tespike.golden.noise import Sensor
    from tespike.golden.config import DESIGN_ELECTRONS
    from tespike.recon.engine.clips import NOISE_DRAW
    config = SensorConfig()
    noisy = EngineRecipe(**{**SMALL.to_dict(), "noise_fraction": 1.0})
    plain = make_clip(SMALL, config, 3)
    light, _, _ = clip_light(SMALL, 3)
    assert np.array_equal(plain.light, light.astype(np.float32)) and plain.sensor is None and plain.dark is None
    levels = []
    for i in range(6):
        clip = make_clip(noisy, config, i)
        assert isinstance(clip.sensor, Sensor)
        n = clip.sensor.noise
        levels.append(n.dark_level)
        assert n.dark_current in NOISE_DRAW["dark_current"] and 0.05 <= n.dark_level <= 6.0
        assert 0 <= n.prnu <= 0.05 and 0 <= n.dsnu <= 0.5
        scene, _, _ = clip_light(noisy, i)
        assert np.array_equal(clip.light, scene.astype(np.float32))
        # the maps against the simulator's own per-pixel noise: its gain, and the mean of its dark draws
        pixels = clip.sensor.pixels(clip.dark.shape)
        assert np.allclose(pixels.photo(np.ones(clip.dark.size)), clip.gain.reshape(-1), rtol=1e-6)
        draws = np.random.default_rng(i)
        drawn = sum(pixels.dark(clip.dark.size, draws) for _ in range(2000)) / (2000 * DESIGN_ELECTRONS)
        assert np.allclose(drawn, clip.dark.reshape(-1), rtol=0.25)
        assert clip.dark.min() > 0 and 0.8 < clip.gain.min() <= clip.gain.max() < 1.2
    assert len(set(levels)) == 6
    with pytest.raises(InputError, match="noise_fraction"):
        EngineRecipe(noise_fraction=1.5)
    with pytest.raises(InputError, match="noisy_input"):
        EngineRecipe(noisy_input="median")


def test_peaks_lengths_and_families_are_drawn_in_their_ranges():
    recipe = EngineRecipe(height=16, width=16, long=(30, 40), short=(1, 9), short_fraction=0.5,
                          peak=(0.01, 3.0))
    families, peaks, lengths = set(), [], []
    for i in range(40):
        light, family, _ = clip_light(recipe, i)
        families.add(family)
        peaks.append(float(light.max()))
        lengths.append(light.shape[0])
    assert families == {"deadleaves", "panorama"}
    assert min(peaks) >= 0.01 * (1 - 1e-12) and max(peaks) <= 3.0 * (1 + 1e-12)
    assert min(peaks) < 0.1 and max(peaks) > 0.5            # spread over the range
    assert all(1 <= k <= 9 or 30 <= k <= 40 for k in lengths)
    assert 1 <= sum(k <= 9 for k in lengths) <= 39
    rng = np.random.default_rng(0)
    assert {draw_length(rng, EngineRecipe(short=(1, 1), short_fraction=1.0)) for _ in range(5)} == {1}


def test_user_folder_family(tmp_path):
    from tespike.recon.scenes import write_hdr
    folder = tmp_path / "seq"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(5):
        write_hdr(folder / f"f{k:03d}.hdr", rng.uniform(0.01, 3.0, (30, 28, 3)).astype(np.float32))
    recipe = EngineRecipe(height=24, width=24, long=(8, 8), short_fraction=0.0, weights=(("deadleaves", 0.0),),
                          folders=(str(folder),))
    light, family, _ = clip_light(recipe, 0)
    assert family == "folder" and light.shape == (8, 24, 24)
    with pytest.raises(InputError, match="smaller than"):
        clip_light(EngineRecipe(**{**recipe.to_dict(), "height": 40}), 0)


def test_user_panoramas_join_the_training_panoramas(tmp_path):
    """A folder's .exr/.hdr panoramas are camera sources (the held-out courtyard left out or refused)."""
    from tespike.recon.engine.clips import TRAIN_PANORAMAS, panorama_files
    from tespike.recon.scenes import write_hdr
    folder = tmp_path / "panos"
    folder.mkdir()
    image = np.full((64, 128, 3), 0.2, np.float32)
    image[20:30, 40:60] = 50.0                       # a bright patch: the clip must come from this file
    write_hdr(folder / "patch.hdr", image)
    write_hdr(folder / "courtyard.hdr", image)
    (folder / "notes.txt").write_text("not a panorama")
    files = panorama_files(folder)
    assert files == (str((folder / "patch.hdr").resolve()),)
    recipe = EngineRecipe(height=16, width=16, long=(4, 4), short_fraction=0.0, weights=(("panorama", 1.0),),
                          panoramas=files)
    light, family, _ = clip_light(recipe, 0)
    assert family == "panorama" and light.shape == (4, 16, 16)
    assert EngineRecipe.from_dict(recipe.to_dict()) == recipe
    with pytest.raises(InputError, match="held out"):
        EngineRecipe(panoramas=TRAIN_PANORAMAS + (str(folder / "courtyard.hdr"),))
    with pytest.raises(InputError, match="nor an .exr/.hdr file"):
        EngineRecipe(panoramas=(str(folder / "missing.hdr"),))
    with pytest.raises(InputError, match="holds no .exr/.hdr panorama"):
        panorama_files(tmp_path / "panos" / "..")
    with pytest.raises(InputError, match="not a folder"):
        panorama_files(folder / "patch.hdr")


def test_recipe_refusals():
    with pytest.raises(InputError, match="held out"):
        EngineRecipe(panoramas=("courtyard",))
    with pytest.raises(InputError, match="unknown"):
        EngineRecipe(weights=(("clouds", 1.0),))
    with pytest.raises(InputError, match="peak"):
        EngineRecipe(peak=(0.0, 1.0))
    with pytest.raises(InputError, match="unknown engine recipe key"):
        EngineRecipe.from_dict({"frames": 3})


def test_key_span_repeats_the_ends_as_inference_does():
    assert span_inside(1, 0, 5).tolist() == [False, False, True, False, False]
    assert span_inside(10, 1, 5).tolist() == [False, True, True, True, True]
    assert key_span(1, 0, 5).tolist() == [0, 0, 0, 0, 0]
    assert key_span(10, 1, 5).tolist() == [0, 0, 1, 2, 3]
    assert key_span(10, 9, 5).tolist() == [7, 8, 9, 9, 9]
    assert key_span(10, 5, 5).tolist() == [3, 4, 5, 6, 7]


def test_sample_is_the_padded_span_around_its_key():
    K, H, W = 7, 10, 12
    words = np.arange(K * H * W, dtype=np.int64).reshape(K, H, W)
    clip = Clip(words.astype(np.float32), words, "test", 0)
    rng = np.random.default_rng(4)
    for _ in range(20):
        state = rng.bit_generator.state
        sample, truth, inside, calibration = draw_sample(clip, 5, 8, rng)
        replay = np.random.default_rng()
        replay.bit_generator.state = state
        key = int(replay.integers(K))
        y, x = int(replay.integers(H - 7)), int(replay.integers(W - 7))
        expected = words[key_span(K, key, 5), y:y + 8, x:x + 8]
        flips = [axis for axis in (-1, -2) if replay.integers(2)]
        if flips:
            expected = np.flip(expected, flips)
        assert np.array_equal(sample, expected)
        assert np.array_equal(truth[0], expected[2])       # the key moment sits in the middle
        assert inside.tolist() == [0 <= t < K for t in range(key - 2, key + 3)]
        assert np.array_equal(calibration[0], np.zeros((8, 8))) and np.array_equal(calibration[1], np.ones((8, 8)))
    dark, gain = np.arange(H * W, dtype=np.float32).reshape(H, W), np.arange(H * W, dtype=np.float32).reshape(H, W) + 1
    noisy = Clip(words.astype(np.float32), words, "test", 0, None, dark, gain)
    for _ in range(10):            # the calibration is cropped and flipped with the words
        sample, _, _, calibration = draw_sample(noisy, 5, 8, rng)
        assert np.array_equal(calibration[0], sample[2] % (H * W)) and np.array_equal(calibration[1], calibration[0] + 1)


def test_batches_give_noisy_clips_the_input_inference_gives_them():
    """With noisy_input "law" a noisy clip's batch input is inference's input for its stream under its
    sensor's calibration (law_input of the whole stream: mean rate and gain, less the dark law's upper
    tail), cut at the sample's readouts, crop and flips; with "mean" the same clip (the same words) is
    (decoded - dark) / gain with its exact maps."""
    import dataclasses
    import types

    from tespike.recon.learning.infer import law_input

    config = SensorConfig()
    recipe = EngineRecipe(**{**SMALL.to_dict(), "noise_fraction": 1.0, "long": (20, 24), "short_fraction": 0.0,
                             "noisy_input": "law"})
    clip = next(c for c in (make_clip(recipe, config, i) for i in range(12))
                if c.sensor.noise.dark_current == "eq13")
    assert clip.calibration.dark_law is not None and clip.calibration.dark_readouts == 256
    pool = types.SimpleNamespace(clips=[clip], law_inputs={})
    light, _, _ = draw_batch(pool, config, 5, 16, 3, np.random.default_rng(3))
    whole = law_input(clip.words, config, clip.calibration).numpy()
    mean_rate = (decode_light(clip.words, config).numpy() - clip.dark) / clip.gain
    rng = np.random.default_rng(3)
    tail_removed = False
    for b in range(3):
        rng.integers(1)                                   # the clip drawn
        state = rng.bit_generator.state
        words, _, _, _ = draw_sample(clip, 5, 16, rng)
        replay = np.random.default_rng()
        replay.bit_generator.state = state
        key = int(replay.integers(clip.words.shape[0]))
        y, x = int(replay.integers(24 - 15)), int(replay.integers(24 - 15))
        flips = [axis for axis in (-1, -2) if replay.integers(2)]
        times = key_span(clip.words.shape[0], key, 5)
        cut = lambda a: np.flip(a[times, y:y + 16, x:x + 16], flips) if flips else a[times, y:y + 16, x:x + 16]
        assert np.array_equal(light[b].numpy(), cut(whole))
        tail_removed |= bool((cut(mean_rate) - cut(whole) > 1e-3).any())
    assert tail_removed                                   # eq. 13's tail: not the mean-rate input
    assert (light.numpy() < 0).any()                     # the dark subtracted, not floored
    mean_only = make_clip(dataclasses.replace(recipe, noisy_input="mean"), config, clip.index)
    assert mean_only.calibration is None and np.array_equal(mean_only.words, clip.words)
    assert np.array_equal(mean_only.dark, clip.dark) and np.array_equal(mean_only.gain, clip.gain)
    light, _, _ = draw_batch(types.SimpleNamespace(clips=[mean_only], law_inputs={}), config, 5, 16, 2,
                             np.random.default_rng(4))
    rng = np.random.default_rng(4)
    for b in range(2):
        rng.integers(1)
        words, _, _, calibration = draw_sample(mean_only, 5, 16, rng)
        expected = (decode_light(words, config, dtype=torch.float32).numpy() - calibration[0]) / calibration[1]
        assert np.allclose(light[b].numpy(), expected, rtol=1e-6, atol=1e-7)


def test_pool_schedule_depends_on_the_step_only():
    config = SensorConfig()
    straight = ClipPool(SMALL, config, capacity=3, refresh=2, workers=0)
    straight.advance_to(7)
    late = ClipPool(SMALL, config, capacity=3, refresh=2, step=7, workers=0)
    assert [c.index for c in straight.clips] == [c.index for c in late.clips]
    assert sorted(c.index for c in late.clips) == [3, 4, 5]
    a = draw_batch(straight, config, 5, 16, 3, np.random.default_rng(0))
    b = draw_batch(late, config, 5, 16, 3, np.random.default_rng(0))
    assert all(np.array_equal(x.numpy(), y.numpy()) for x, y in zip(a, b))
    assert a[0].shape == (3, 5, 16, 16) and a[1].shape == (3, 1, 16, 16) and a[2].shape == (3, 5)


def test_worker_processes_make_the_same_clips():
    config = SensorConfig()
    local = ClipPool(SMALL, config, capacity=2, refresh=1, workers=0)
    remote = ClipPool(SMALL, config, capacity=2, refresh=1, workers=1)
    try:
        local.advance_to(2)
        remote.advance_to(2)
        for a, b in zip(local.clips, remote.clips):
            assert a.index == b.index and np.array_equal(a.words, b.words)
    finally:
        remote.close()


def _killed_after_its_first_line(script: str, after_kill=None) -> tuple[int, str, str]:
    """(pid, first line on stdout, stderr) of a Python ``script`` run in a session of its own and
    killed outright (SIGKILL) once it has printed that line; ``after_kill(line)`` runs before its
    stderr is read to the end (once every process holding it has ended)."""
    import os
    import signal
    import subprocess
    import sys
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        line = proc.stdout.readline().strip()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(30)
        if after_kill is not None:
            after_kill(line)
        return proc.pid, line, proc.stderr.read()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_a_killed_trainer_leaves_no_worker_and_no_notice(tmp_path):
    """A trainer killed outright (SIGKILL: nothing of it runs) leaves neither its clip worker
    (which watches its parent) nor a line on stderr (the resource tracker still removes the
    pool's semaphores, without its UserWarning)."""
    import subprocess
    import time
    script = ("import os, sys, time\n"
              "from tespike.golden.config import SensorConfig\n"
              "from tespike.recon.engine.batches import ClipPool\n"
              "from tespike.recon.engine.clips import EngineRecipe\n"
              f"pool = ClipPool(EngineRecipe(**{SMALL.__dict__!r}), SensorConfig(), capacity=2, refresh=1, workers=1)\n"
              "pool.advance_to(1)\n"
              "print(os.getpid(), flush=True)\n"
              "time.sleep(60)\n")
    pid, line, err = _killed_after_its_first_line(script)
    assert line == str(pid)
    assert err == "", err
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        left = subprocess.run(["ps", "-o", "pid=", "-s", str(pid)], capture_output=True, text=True).stdout.split()
        if not left:
            break
        time.sleep(0.2)
    assert not left, f"processes of the killed trainer still running: {left}"


def test_a_trainer_killed_before_its_worker_has_its_start_up_data_leaves_no_traceback():
    """The instant a CI run met by chance, made certain: the trainer is killed right after starting
    its clip worker, before handing it its start-up data. The worker's start-up fails in Python's
    own code ("EOFError: Ran out of input"), and its traceback went to the user's terminal."""
    import signal
    import subprocess
    import sys
    script = ("import os, signal\n"
              "from multiprocessing import util\n"
              "spawn = util.spawnv_passfds\n"
              "def spawn_then_die(path, args, passfds):\n"
              "    spawn(path, args, passfds)\n"
              "    if any('spawn_main' in str(arg) for arg in args):   # (the worker, not the resource tracker)\n"
              "        os.kill(os.getpid(), signal.SIGKILL)\n"
              "util.spawnv_passfds = spawn_then_die\n"
              "from tespike.golden.config import SensorConfig\n"
              "from tespike.recon.engine.batches import ClipSource\n"
              "from tespike.recon.engine.clips import EngineRecipe\n"
              f"ClipSource(EngineRecipe(**{SMALL.__dict__!r}), SensorConfig(), workers=1)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          start_new_session=True)
    assert done.returncode == -signal.SIGKILL and done.stderr == "", done.stderr


def test_what_workers_write_on_stderr_is_relayed_while_the_trainer_lives_only():
    """The workers' stderr is a pipe the trainer relays: a trainer killed outright in the instant
    between starting a worker and handing it its start-up data had left that worker's start-up
    traceback ("EOFError: Ran out of input") on the terminal. Here a child started inside the relay
    writes while the trainer lives (relayed, in order with the trainer's own line) and another
    after the trainer was killed (nowhere)."""
    import time
    from tests.processes import alive
    child = "import sys, time; time.sleep({}); sys.stderr.write({!r}); sys.stderr.flush()"
    script = ("import os, subprocess, sys, time\n"
              "from tespike.recon.engine.batches import _children_stderr_relayed\n"
              "with _children_stderr_relayed():\n"
              f"    early = subprocess.Popen([sys.executable, '-c', {child.format(0, 'relayed|')!r}])\n"
              f"    late = subprocess.Popen([sys.executable, '-c', {child.format(3, 'after the kill|')!r}],\n"
              "                            stdout=subprocess.DEVNULL)\n"
              "    early.wait()\n"
              "    sys.stderr.write('own|')\n"
              "sys.stderr.write('restored|'); sys.stderr.flush()\n"
              "time.sleep(0.3)\n"
              "print(late.pid, flush=True)\n"
              "time.sleep(60)\n")

    def late_has_written(line: str) -> None:
        deadline = time.monotonic() + 30
        while alive(int(line)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not alive(int(line))
    _, _, err = _killed_after_its_first_line(script, late_has_written)
    assert err == "relayed|own|restored|", err


def test_ctrl_c_while_the_workers_start_ends_the_start_and_leaves_no_worker():
    """Ctrl-C is held, not ignored, while the clip workers start (they must not answer it
    themselves): one that comes then is answered once the start is over (it was lost, and a
    run went on for its minutes), and no worker outlives the pool."""
    import subprocess
    import sys
    script = ("import multiprocessing, os, signal\n"
              "from multiprocessing import context\n"
              "from tespike.golden.config import SensorConfig\n"
              "from tespike.recon.engine.batches import ClipSource\n"
              "from tespike.recon.engine.clips import EngineRecipe\n"
              "signal.signal(signal.SIGINT, signal.default_int_handler)\n"   # (a background job ignores it)
              "start = context.SpawnContext.Pool\n"
              "def pressed_while_starting(self, *args, **kwargs):\n"
              "    os.kill(os.getpid(), signal.SIGINT)\n"
              "    return start(self, *args, **kwargs)\n"
              "context.SpawnContext.Pool = pressed_while_starting\n"
              "try:\n"
              f"    ClipSource(EngineRecipe(**{SMALL.__dict__!r}), SensorConfig(), workers=1)\n"
              "    print('not interrupted')\n"
              "except KeyboardInterrupt:\n"
              "    print('interrupted')\n"
              "print('workers left', len(multiprocessing.active_children()))\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.stdout == "interrupted\nworkers left 0\n", (done.stdout, done.stderr)
    assert done.stderr == "", done.stderr


def test_a_pool_whose_start_fails_leaves_no_worker(monkeypatch):
    """A pool whose start fails after its workers started (a handler thread that cannot start,
    out of memory) never reaches the source: the source finds and ends those workers itself, and
    the pool's worker handler starts none in their place."""
    import threading
    import time
    from multiprocessing import pool as pools

    from tespike.recon.engine.batches import ClipSource

    start = threading.Thread.start

    def last_handler_fails(thread):                     # the pool's third thread, its workers started
        if getattr(thread, "_target", None) is pools.Pool._handle_results:
            raise RuntimeError("can't start new thread")
        start(thread)
    before = set(multiprocessing.active_children())
    monkeypatch.setattr(threading.Thread, "start", last_handler_fails)
    with pytest.raises(RuntimeError, match="can't start new thread"):
        ClipSource(SMALL, SensorConfig(), workers=1)
    monkeypatch.undo()
    time.sleep(0.5)                                     # no worker started in their place
    assert set(multiprocessing.active_children()) <= before
    handler = getattr(pools.Pool._handle_workers, "__func__")
    assert not any(getattr(getattr(t, "_target", None), "__func__", None) is handler and t.is_alive()
                   for t in threading.enumerate())


def test_a_pool_whose_terminate_refuses_still_ends_its_workers(monkeypatch):
    """Starved of memory, a pool thread can die; ``Pool.terminate`` then raises its own
    AssertionError, which hid the error being handled under a traceback: the source kills
    its workers itself and raises nothing of its own."""
    import time
    from multiprocessing import pool as pools

    from tespike.recon.engine.batches import ClipSource

    def refuse(self):                      # as the real one fails: its finaliser spent, no worker ended
        self._terminate.cancel()
        raise AssertionError("Cannot have cache with result_hander not alive")
    source = ClipSource(SMALL, SensorConfig(), workers=1)
    workers = list(source.pool._pool)
    monkeypatch.setattr(pools.Pool, "terminate", refuse)
    try:
        pool = source.pool
        source.close()
        assert source.pool is None
        assert all(not process.is_alive() for process in workers)
        time.sleep(0.5)                                 # no worker started in their place
        assert all(process in workers for process in pool._pool), "the pool started new workers"
    finally:
        monkeypatch.undo()
        for process in workers:
            if process.is_alive():
                process.kill()


def test_a_result_thread_starved_of_memory_ends_the_wait_in_its_fault_without_a_traceback(monkeypatch, capfd):
    """Under ``ulimit -v`` the pool's result-handler thread died of a MemoryError while a clip's bytes
    came in: Python printed its 13-line traceback before the command's line, and a trainer waiting
    for that clip would have waited for ever. The wait now raises the thread's fault, and the thread
    prints nothing."""
    import threading
    from multiprocessing import connection

    from tespike.recon.engine.batches import ClipSource
    real = connection._ForkingPickler.loads

    def starved(*args, **kwargs):
        if "_handle_results" in threading.current_thread().name:
            raise MemoryError
        return real(*args, **kwargs)
    monkeypatch.setattr(connection._ForkingPickler, "loads", starved)
    source = ClipSource(SMALL, SensorConfig(), workers=1)
    try:
        with pytest.raises(MemoryError):
            next(source)
    finally:
        monkeypatch.undo()
        source.close()
    assert "Traceback" not in capfd.readouterr().err


def test_a_workers_stderr_stays_quiet_while_a_broken_pipe_is_handled():
    """A SIGKILLed trainer's pipe closes before its workers get another parent: the pool's first line
    of the BrokenPipeError traceback ("Process SpawnPoolWorker-1:") reached the user's terminal."""
    import io
    import os

    from tespike.recon.engine.batches import _WhileParent
    text = io.StringIO()
    stderr = _WhileParent(text, os.getppid())
    stderr.write("a clip's own fault\n")
    try:
        raise BrokenPipeError(32, "Broken pipe")
    except BrokenPipeError:
        stderr.write("Process SpawnPoolWorker-1:\n")
    assert text.getvalue() == "a clip's own fault\n"
    _WhileParent(text, -1).write("after the trainer is gone\n")
    assert text.getvalue() == "a clip's own fault\n"
