"""``tespike view``: tone-mapped PNGs of scenes, streams, reconstructions and stimuli."""

import numpy as np
from matplotlib.image import imread

from tespike.golden.config import SensorConfig
from tespike.golden.fastsim import scene_stimulus, simulate_scene
from tespike.golden.io import save_stream
from tespike.recon.mulaw import MU, tone_map
from tests.cli import assert_refused, run_tespike


def _files(tmp_path):
    light = np.random.default_rng(0).uniform(0.01, 1.0, (5, 12, 16)).astype(np.float32)
    np.save(tmp_path / "I.npy", light)
    config = SensorConfig()
    save_stream(tmp_path / "S.npz", simulate_scene(config, light, seed=0), config)
    np.save(tmp_path / "E.npy", scene_stimulus(config, light[:2], seed=0))
    return light


def test_contact_sheets_of_every_kind(tmp_path):
    _files(tmp_path)
    for name, extra in (("I.npy", []), ("S.npz", ["--frames", "0:3"]), ("E.npy", ["--config", "te"])):
        out = tmp_path / f"{name}.png"
        result = run_tespike("view", "--input", tmp_path / name, "--out", out, *extra)
        assert result.returncode == 0, result.stderr
        assert result.stdout.startswith(f"wrote {out}")
        assert out.read_bytes()[:4] == b"\x89PNG"
        image = imread(out)
        assert image.ndim == 3 and image.shape[0] > 50


def test_one_png_per_frame_is_the_tone_mapped_light(tmp_path):
    light = _files(tmp_path)
    result = run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "frames", "--each",
                         "--peak", 2.0, "--quiet")
    assert result.returncode == 0 and result.stdout == "", result.stderr
    names = sorted(p.name for p in (tmp_path / "frames").iterdir())
    assert names == [f"frame_{k:04d}.png" for k in range(5)]
    image = imread(tmp_path / "frames" / "frame_0003.png")
    assert image.shape[:2] == (12, 16)
    assert np.allclose(image[..., 0], tone_map(light[3], 2.0), atol=1.5 / 255)


def test_refusals(tmp_path):
    _files(tmp_path)
    assert_refused(run_tespike("view", "--input", tmp_path / "E.npy", "--out", tmp_path / "e.png"), "--config")
    assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "i.png",
                               "--frames", "7"), "frame 7")
    for spec in ("0:99", "-1:", "1:-1", "3:3", "5:2"):     # (a Python slice clipped or wrapped them: exit 0)
        assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "i.png",
                                   f"--frames={spec}"), f"--frames {spec!r}", "0 <= a < b")
    assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "i.jpg"), ".png")
    # a device takes any name (docs/cli.md): /dev/full was refused for its name, not its room
    assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", "/dev/full"),
                   "cannot write '/dev/full': No space left on device")
    assert_refused(run_tespike("view", "--input", tmp_path / "x.npy", "--out", tmp_path / "i.png"), "x.npy")
    assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "i.png",
                               "--peak", "-1"), "--peak")
    ml = SensorConfig(mode="ml")                       # (its estimators are one: the pictures were the same)
    save_stream(tmp_path / "M.npz", simulate_scene(ml, np.load(tmp_path / "I.npy"), seed=0), ml)
    assert_refused(run_tespike("view", "--input", tmp_path / "M.npz", "--out", tmp_path / "m.png",
                               "--estimator", "midpoint"), "--estimator", "TE decoders", "M.npz")
    np.save(tmp_path / "long.npy", np.ones((241, 2, 2), np.float32))     # (1700 frames: 50 s, a 69630-px PNG)
    assert_refused(run_tespike("view", "--input", tmp_path / "long.npy", "--out", tmp_path / "i.png",
                               "--frames", "all"), "selects 241 frames; a contact sheet shows at most 240", "--each")
    assert not list(tmp_path.glob("*.png")) and not list(tmp_path.glob(".*"))


def test_an_option_that_would_be_ignored_is_refused(tmp_path):
    """--config reads a stimulus, --estimator decodes a stream, --columns lays out a sheet: given
    where it has no effect, each is refused rather than silently ignored."""
    _files(tmp_path)
    view = ("view", "--out", tmp_path / "v.png")
    assert_refused(run_tespike(*view, "--input", tmp_path / "S.npz", "--config", "ml"), "--config", "S.npz")
    assert_refused(run_tespike(*view, "--input", tmp_path / "I.npy", "--estimator", "midpoint"), "--estimator")
    assert_refused(run_tespike(*view, "--input", tmp_path / "E.npy", "--config", "te", "--estimator", "ratio"),
                   "--estimator")
    assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "f", "--each",
                               "--columns", "3"), "--columns")
    assert not list(tmp_path.glob("*.png")) and not (tmp_path / "f").exists()
    # --each names a folder: one named like a contact sheet was made as a folder called v.png
    assert_refused(run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "v.png", "--each"),
                   "v.png", "--each writes a folder")
    assert not (tmp_path / "v.png").exists()
    result = run_tespike(*view, "--input", tmp_path / "S.npz", "--estimator", "midpoint", "--columns", "2")
    assert result.returncode == 0, result.stderr


def test_the_default_mu_is_the_metrics_mu():
    from tespike.cosim.cli import build_parser
    assert build_parser("view").parse_args(["view", "--input", "x.npy", "--out", "y.png"]).mu == MU


def test_each_never_leaves_an_earlier_runs_frames_beside_its_own(tmp_path):
    """--each into a folder of an earlier run left its extra frame files beside the new ones: one folder,
    two runs. Frames this run replaces are fine (the same run again); others are refused, nothing written."""
    _files(tmp_path)
    args = ("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "frames", "--each")
    assert run_tespike(*args).returncode == 0                                   # frames 0..4
    again = run_tespike(*args)
    assert again.returncode == 0, again.stderr                                  # replaces them all
    before = {p.name: p.read_bytes() for p in (tmp_path / "frames").iterdir()}
    assert_refused(run_tespike(*args, "--frames", "0:2"), "frame_0002.png", "2 more frame file(s)",
                   "mix two runs")
    assert {p.name: p.read_bytes() for p in (tmp_path / "frames").iterdir()} == before


def test_each_replaces_its_folder_whole_and_keeps_what_is_not_its_own(tmp_path):
    """--each wrote frame by frame into the folder: killed part-way through a second run, the folder
    held the new run's first frames beside the old run's last. The frames are now written into a
    temporary folder swapped in at the end; a folder holding anything but frames this run writes
    again is refused, so the swap removes nothing of the user's."""
    _files(tmp_path)
    args = ("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "frames", "--each")
    assert run_tespike(*args).returncode == 0
    first = {p.name: p.read_bytes() for p in (tmp_path / "frames").iterdir()}
    (tmp_path / "frames" / "notes.txt").write_text("mine")
    assert_refused(run_tespike(*args), "notes.txt", "not a frame")
    (tmp_path / "frames" / "notes.txt").unlink()
    again = run_tespike(*args, "--mu", "50")
    assert again.returncode == 0, again.stderr
    second = {p.name: p.read_bytes() for p in (tmp_path / "frames").iterdir()}
    assert second.keys() == first.keys() and second != first
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]


def test_each_killed_leaves_the_previous_frames_whole(tmp_path):
    """A run killed while writing frames leaves the earlier run's folder as it was."""
    import signal
    import subprocess
    import sys
    import time
    _files(tmp_path)
    np.save(tmp_path / "long.npy", np.random.default_rng(0).uniform(0, 1, (400, 24, 24)).astype(np.float32))
    args = ["view", "--input", str(tmp_path / "long.npy"), "--out", str(tmp_path / "frames"), "--each"]
    assert run_tespike(*args).returncode == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "frames").iterdir()}
    process = subprocess.Popen([sys.executable, "-m", "tespike", *args, "--mu", "50"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and process.poll() is None:   # kill it once it writes frames
        if any(len(list(p.glob("frame_*.png"))) > 20 for p in tmp_path.glob(".frames.*.part")):
            process.send_signal(signal.SIGKILL)
            break
        time.sleep(0.01)
    process.wait()
    assert process.returncode == -signal.SIGKILL, "the run ended before it could be killed mid-way"
    assert {p.name: p.read_bytes() for p in (tmp_path / "frames").iterdir()} == before


def test_a_tiny_peak_maps_everything_to_white_without_a_warning(tmp_path):
    """--peak 1e-320 (subnormal) made light / peak overflow: numpy's two-line RuntimeWarning."""
    _files(tmp_path)
    done = run_tespike("view", "--input", tmp_path / "I.npy", "--out", tmp_path / "w.png", "--peak", "1e-320")
    assert done.returncode == 0 and done.stderr == "", done.stderr
