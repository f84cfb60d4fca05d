"""Every fault of a long command ends cleanly (issue 28, item 6): one line naming the file and
the cause, a non-zero exit, no traceback, no process left behind, no results folder mixing
two runs. (The classes of issue 12 are in test_cli_hardening.py, whose helpers these use.)
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tests.cli import ROOT, _checkout_env, assert_refused, run_python, run_tespike
from tests.processes import alive, descendants, interruptible
from tests.test_cli_hardening import TINY, small_tmpfs, snapshot

EVALUATE = ("evaluate", "--set", "none", "--methods", "tfp", "--repeats", "1", "--ml-count-config", "none")


def run_here(capsys, *args):
    """``tespike ARGS`` in this process (torch imported once): a CompletedProcess-like result."""
    from tespike.cosim.cli import main
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, captured.out, captured.err)


def tiny_scene(folder: Path, frames: int = 10) -> Path:
    path = folder / "sc.npy"
    np.save(path, np.random.default_rng(1).uniform(0.05, 1.0, (frames, 16, 20)))
    return path


# ------------------------------------------------------------------ a stop is never lost
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("when", ["before its output", "after its output"])
def test_a_stop_python_drops_in_a_finalizer_still_ends_the_command(capsys, tmp_path, monkeypatch, stop, when):
    """A stop whose exception is raised inside a finalizer (a ``__del__``, a weakref callback: Amaranth's
    and torch's run all the time) is printed and dropped by Python: ``demo`` went on, replaced the
    previous folder and exited 0. The command's handlers record each stop; one dropped is raised again
    before an output is renamed into place (nothing written) and when the command returns (its exit
    status and line say it was stopped)."""
    import signal

    from tespike.golden import io
    number = getattr(signal, stop)

    class Finalized:
        def __del__(self):
            signal.raise_signal(number)                # the handler raises here: Python drops it

    save = io.save_stream

    def saving(*args, **kwargs):
        if when == "before its output":
            Finalized()                                # made and finalized at once
        save(*args, **kwargs)
        if when == "after its output":
            Finalized()
    monkeypatch.setattr(io, "save_stream", saving)
    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: dropped.append(unraisable.exc_type.__name__))
    scene = tiny_scene(tmp_path)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)   # (as a terminal gives it: a test
    try:                                                                  # run in a background job has it ignored)
        result = run_here(capsys, "simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "s.npz",
                          "--seed", 1, "--quiet")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert dropped == ["KeyboardInterrupt" if stop == "SIGINT" else "Terminated"]   # (what Python drops)
    line = result.stderr.strip().splitlines()[-1]
    if stop == "SIGINT":
        assert result.returncode == 130 and line.startswith("tespike simulate: interrupted"), result.stderr
    else:
        assert result.returncode == 128 + number and line.startswith("tespike simulate: terminated by SIGTERM")
    assert (tmp_path / "s.npz").exists() == (when == "after its output")
    monkeypatch.setattr(io, "save_stream", save)
    assert run_here(capsys, "simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "t.npz",
                    "--seed", 1, "--quiet").returncode == 0            # (the next command starts afresh)


# ------------------------------------------------------------------ a results folder is one run's
def test_evaluate_refuses_a_previous_runs_folder_without_force_and_never_a_foreign_one(capsys, tmp_path):
    scene = tiny_scene(tmp_path)
    out = tmp_path / "ev"
    assert run_here(capsys, *EVALUATE, "--scene", scene, "--out", out, "--quiet").returncode == 0
    (out / "strips" / "old.png").write_bytes(b"an older run's picture")
    before = snapshot(tmp_path)
    assert_refused(run_here(capsys, *EVALUATE, "--scene", scene, "--out", out), "previous run", "--force")
    assert snapshot(tmp_path) == before
    done = run_here(capsys, *EVALUATE, "--scene", scene, "--out", out, "--force")
    assert done.returncode == 0, done.stderr
    progress = done.stderr.strip().splitlines()          # stderr is not a terminal: one line per step
    assert progress[0].startswith("evaluate: 1/4 sc ml-msb simulate") and progress[-1].startswith("evaluate: 4/4 "), progress
    assert sorted(os.listdir(out / "strips")) == ["sc.png"]          # the older picture went with its run
    assert not [name for name in os.listdir(tmp_path) if name.endswith(".part")]
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    before = snapshot(tmp_path)
    assert_refused(run_here(capsys, *EVALUATE, "--scene", scene, "--out", tmp_path / "mine", "--force"),
                   "'notes.txt'", "new or empty folder")
    assert snapshot(tmp_path) == before


def test_evaluate_force_never_deletes_a_file_of_the_strips_folder_no_evaluation_writes(capsys, tmp_path):
    """--force replaced the folder whole after checking its top level only: the run's own input
    scene and configuration, kept in OUT/strips/, were deleted by the swap (exit 0). Every file of
    strips/ must be a strip (a .png) for --force to replace it."""
    scene = tiny_scene(tmp_path)
    out = tmp_path / "ev"
    assert run_here(capsys, *EVALUATE, "--scene", scene, "--out", out, "--quiet").returncode == 0
    mine = out / "strips" / "mine.npy"
    mine.write_bytes(scene.read_bytes())
    (out / "strips" / "te.json").write_text(json.dumps({"b1": 4}))
    before = snapshot(tmp_path)
    assert_refused(run_here(capsys, *EVALUATE, "--scene", mine, "--te-config", out / "strips" / "te.json",
                            "--out", out, "--force"), "'strips/mine.npy'", "new or empty folder")
    assert snapshot(tmp_path) == before
    mine.unlink()
    (out / "strips" / "te.json").unlink()
    (out / "strips" / "deeper").mkdir()
    assert_refused(run_here(capsys, *EVALUATE, "--scene", scene, "--out", out, "--force"), "'strips/deeper'")


def test_atomic_folder_leaves_the_previous_run_whole_or_the_new_one_whole(tmp_path):
    from tespike.golden.atomic import atomic_folder
    out = tmp_path / "ev"
    (out / "strips").mkdir(parents=True)
    (out / "table.md").write_text("old")
    (out / "strips" / "a.png").write_text("old picture")
    before = snapshot(tmp_path)
    with pytest.raises(InputError, match=r"cannot write '.*ev/table\.csv': No space left on device"):
        with atomic_folder(out) as folder:
            (folder / "table.md").write_text("new")
            raise OSError(28, os.strerror(28), str(folder / "table.csv"))
    assert snapshot(tmp_path) == before                                # failing: untouched, no temporary
    with atomic_folder(out) as folder:
        (folder / "table.md").write_text("new")
    assert snapshot(tmp_path) == {"ev": before["ev"], "ev/table.md": (before["ev/table.md"][0], b"new")}
    stale = tmp_path / ".ev.999999999.abcdefgh.part"                  # left by a killed run
    stale.mkdir()
    with atomic_folder(out) as folder:
        (folder / "table.md").write_text("newer")
    assert not stale.exists() and (out / "table.md").read_text() == "newer"


def test_evaluate_on_a_full_disk_keeps_the_previous_results(capsys, tmp_path):
    scene = tiny_scene(tmp_path)
    with small_tmpfs(tmp_path / "small", "2m") as mount:
        out = mount / "ev"
        assert run_here(capsys, *EVALUATE, "--scene", scene, "--out", out, "--quiet").returncode == 0
        free = os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize
        (mount / "filler").write_bytes(b"\0" * (free - 24 * 1024))        # room for the tables, not the pictures
        before = snapshot(mount)
        result = run_here(capsys, *EVALUATE, "--scene", scene, "--out", out, "--force", "--progress", "off")
        assert_refused(result, str(out), "No space left")
        assert ".part" not in result.stderr
        assert snapshot(mount) == before


# ------------------------------------------------------------------ a store's evaluation
@pytest.fixture(scope="module")
def store(tmp_path_factory):
    folder = tmp_path_factory.mktemp("store")
    done = run_tespike("dataset", "--scene", "sun", "--frames", 10, "--height", 16, "--width", 20,
                       "--config", "te", "--out", folder / "s.zarr", "--quiet")
    assert done.returncode == 0, done.stderr
    return folder / "s.zarr"


def copy_store(store, folder):
    import shutil
    shutil.copytree(store, folder / "s.zarr")
    return folder / "s.zarr"


@pytest.mark.parametrize("damage", ["chunk", "array zarr.json", "sequence zarr.json", "flipped chunk byte"])
def test_a_damaged_store_file_is_named(capsys, tmp_path, store, damage):
    copy = copy_store(store, tmp_path)
    target = {"chunk": copy / "sun" / "light" / "c" / "0" / "0" / "0",
              "array zarr.json": copy / "sun" / "streams" / "te" / "zarr.json",
              "sequence zarr.json": copy / "sun" / "zarr.json",
              "flipped chunk byte": copy / "sun" / "light" / "c" / "0" / "0" / "0"}[damage]
    if damage.startswith("flipped"):       # Blosc decompressed it into other values: the CRC-32C refuses it
        data = bytearray(target.read_bytes())
        data[len(data) // 2] ^= 0xFF
        target.write_bytes(bytes(data))
    else:
        with open(target, "r+b") as handle:
            handle.truncate(20)
    result = run_here(capsys, "evaluate", "--store", copy, "--methods", "tfp", "--out", tmp_path / "ev")
    assert_refused(result, repr(str(target)), "is damaged")
    assert not (tmp_path / "ev").exists()


@pytest.mark.parametrize("where", ["root", "array"])
def test_a_store_json_nested_too_deeply_is_one_line(capsys, tmp_path, store, where):
    """A ``zarr.json`` of 100000 nested lists: Python's JSON parser raises RecursionError, which
    escaped as a traceback from ``evaluate --store`` and from ``dataset`` resuming the store."""
    copy = copy_store(store, tmp_path)
    target = copy / "zarr.json" if where == "root" else copy / "sun" / "streams" / "te" / "zarr.json"
    target.write_text("[" * 100000 + "]" * 100000)
    result = run_here(capsys, "evaluate", "--store", copy, "--methods", "tfp", "--out", tmp_path / "ev")
    assert_refused(result, repr(str(copy) if where == "root" else str(target)),
                   "nested too deeply" if where == "root" else "is damaged")
    if where == "root":
        result = run_here(capsys, "dataset", "--scene", "sun", "--frames", 10, "--height", 16, "--width", 20,
                          "--config", "te", "--out", copy)
        assert_refused(result, repr(str(copy)), "nested too deeply")


def test_ctrl_c_during_a_store_evaluation_on_workers_is_one_line_and_leaves_no_process(tmp_path, store):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.Popen([sys.executable, "-m", "tespike", "evaluate", "--store", str(store), "--workers", "2",
                                "--methods", "tfp,tfi", "--out", str(tmp_path / "ev")], env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                               preexec_fn=interruptible)
    first = process.stdout.readline()                  # printed once the cluster is up
    assert "local cluster of 2 worker processes" in first, first
    end = time.monotonic() + 60
    while len(started := descendants(process.pid)) < 3 and time.monotonic() < end:
        time.sleep(0.2)                                # the cluster's process and its workers
    assert len(started) >= 3, started
    time.sleep(0.5)
    os.killpg(process.pid, signal.SIGINT)              # as a terminal's Ctrl-C: the whole group
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert stderr.strip().splitlines() == ["tespike evaluate: interrupted"], stderr
    end = time.monotonic() + 30
    while any(alive(pid) for pid in started) and time.monotonic() < end:
        time.sleep(0.2)
    assert not [pid for pid in started if alive(pid)]
    assert not (tmp_path / "ev").exists()


# ------------------------------------------------------------------ rtl-sim's two files
def test_rtl_sim_names_the_vcd_when_its_disk_is_full(tmp_path):
    (tmp_path / "c.json").write_text(json.dumps({"b1": 1, "b2": 1, "threshold": 3, "acc_bits": 3}))
    np.save(tmp_path / "long.npy", np.full((TINY.clocks_per_readout * 4000, 2, 2), 3, np.uint8))
    (tmp_path / "other").mkdir()
    with small_tmpfs(tmp_path / "small", "200k") as mount:
        result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "long.npy",
                             "--out", tmp_path / "w.npz", "--vcd", mount / "W.vcd", "--gtkw",
                             tmp_path / "other" / "W.gtkw")
        assert_refused(result, str(mount / "W.vcd"), "No space left")
        assert "W.gtkw" not in result.stderr
        assert os.listdir(mount) == [] and os.listdir(tmp_path / "other") == []


def test_rtl_sim_commits_no_save_file_for_a_vcd_it_could_not_write_nor_beside_a_device(tmp_path):
    """The save file was committed before the VCD: --vcd /dev/full left W.gtkw (and /dev/full.gtkw
    by default) beside a refusal; --vcd /dev/null made /dev/null.gtkw."""
    (tmp_path / "c.json").write_text(json.dumps({"b1": 1, "b2": 1, "threshold": 3, "acc_bits": 3}))
    np.save(tmp_path / "e.npy", np.full((TINY.clocks_per_readout * 4, 2, 2), 3, np.uint8))
    args = ("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy", "--out", tmp_path / "w.npz")
    result = run_tespike(*args, "--vcd", "/dev/full", "--gtkw", tmp_path / "W.gtkw")
    assert_refused(result, "'/dev/full'", "No space left")
    assert sorted(os.listdir(tmp_path)) == ["c.json", "e.npy"]
    for device in ("/dev/full", "/dev/null"):
        run_tespike(*args, "--vcd", device)
        assert not os.path.exists(device + ".gtkw")


# ------------------------------------------------------------------ found by benchmarks/fault_sweep.py
def cut_in_half(source: Path, target: Path) -> Path:
    data = source.read_bytes()
    target.write_bytes(data[:len(data) // 2])
    return target


def flip_middle_byte(source: Path, target: Path) -> Path:
    data = bytearray(source.read_bytes())
    data[len(data) // 2] ^= 0xFF
    target.write_bytes(bytes(data))
    return target


@pytest.mark.parametrize("damage", [cut_in_half, flip_middle_byte])
def test_a_damaged_calibration_file_is_named(capsys, tmp_path, damage):
    """C.npz is read like S.npz (tespike.golden.io.open_npz): a truncated archive or a bad CRC was a traceback."""
    scene = tiny_scene(tmp_path)
    assert run_here(capsys, "simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "s.npz",
                    "--seed", 1, "--quiet").returncode == 0
    from tespike.golden.config import load_config
    from tespike.recon.calibration import Calibration, save_calibration
    maps = np.random.default_rng(2).uniform(0.5, 1.5, (16, 20))
    save_calibration(tmp_path / "c.npz", Calibration(maps * 1e-3, maps, load_config("te"), 8, 8, 0.03))
    bad = damage(tmp_path / "c.npz", tmp_path / "bad.npz")
    result = run_here(capsys, "reconstruct", "--stream", tmp_path / "s.npz", "--method", "tfp",
                      "--calibration", bad, "--out", tmp_path / "r.npy")
    assert_refused(result, f"calibration file {str(bad)!r}", "not a readable .npz archive")
    assert not (tmp_path / "r.npy").exists()


def test_a_weights_file_with_a_flipped_byte_is_refused_not_loaded(capsys, tmp_path):
    """torch.load checks no CRC: an altered byte of W.pt loaded as an altered weight."""
    from tespike.golden.config import load_config
    from tespike.recon.learned import weights_path
    scene = tiny_scene(tmp_path)
    assert run_here(capsys, "simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "s.npz",
                    "--seed", 1, "--quiet").returncode == 0
    bad = flip_middle_byte(weights_path(load_config("te"), "net"), tmp_path / "w.pt")
    result = run_here(capsys, "reconstruct", "--stream", tmp_path / "s.npz", "--method", "net",
                      "--weights", bad, "--out", tmp_path / "r.npy")
    assert_refused(result, f"--weights {str(bad)!r}", "fails its CRC check")
    assert not (tmp_path / "r.npy").exists()


def test_a_weights_file_with_bytes_after_its_end_is_refused(tmp_path):
    """torch.load, as every zip reader, ignored bytes after the archive's end record."""
    from tespike.golden.config import load_config
    from tespike.recon.learned import weights_path
    from tespike.recon.learning.weights import read_weights
    joined = tmp_path / "w.pt"
    joined.write_bytes(weights_path(load_config("te"), "net").read_bytes() + b"\n")
    with pytest.raises(InputError, match=r"weights '.*w\.pt' is not a tespike weights file \(a damaged archive: "
                                         r"1 bytes follow the archive's end\)"):
        read_weights(joined)
    shipped = weights_path(load_config("te"), "net").read_bytes()
    joined.write_bytes(shipped + shipped)                 # (torch read it as the second copy)
    with pytest.raises(InputError, match=rf"{len(shipped)} bytes come before the archive"):
        read_weights(joined)


def test_a_truncated_exr_frame_is_one_line_with_the_librarys_cause(tmp_path):
    """OpenEXR prints its fault on the process's stderr beside the exception: two lines, the useful one first."""
    from tespike.recon.scenes.hdr_io import write_exr
    (tmp_path / "frames").mkdir()
    rng = np.random.default_rng(0)
    for k in range(2):
        write_exr(tmp_path / "frames" / f"f{k}.exr", rng.uniform(0.1, 2.0, (8, 8, 3)).astype(np.float32))
    cut_in_half(tmp_path / "frames" / "f1.exr", tmp_path / "frames" / "f1.exr")
    result = run_tespike("scene", "--folder", tmp_path / "frames", "--out", tmp_path / "i.npy")
    assert_refused(result, f"cannot read EXR file {str(tmp_path / 'frames' / 'f1.exr')!r}", "corrupt")
    assert result.stdout == "" and not (tmp_path / "i.npy").exists()


def test_a_failed_dataset_build_leaves_no_store_or_says_what_it_resumes(capsys, tmp_path):
    """A store that holds no complete sequence is removed; one that does is kept, and the line says so."""
    from tespike.recon.scenes.hdr_io import write_hdr
    rng = np.random.default_rng(0)
    for name in ("a", "b"):
        (tmp_path / "hdr" / name).mkdir(parents=True)
        for k in range(2):
            write_hdr(tmp_path / "hdr" / name / f"f{k}.hdr", rng.uniform(0.1, 2.0, (8, 8, 3)).astype(np.float32))
    good = (tmp_path / "hdr" / "b" / "f1.hdr").read_bytes()
    cut_in_half(tmp_path / "hdr" / "b" / "f1.hdr", tmp_path / "hdr" / "b" / "f1.hdr")
    args = ("dataset", "--hdr", tmp_path / "hdr", "--config", "te", "--out", tmp_path / "d.zarr")
    assert_refused(run_here(capsys, *args), "f1.hdr", f"store {str(tmp_path / 'd.zarr')!r} keeps 1 complete",
                   "resumes")
    assert (tmp_path / "d.zarr" / "a").is_dir()
    (tmp_path / "hdr" / "b" / "f1.hdr").write_bytes(good)
    assert run_here(capsys, *args).returncode == 0               # the rerun resumes it
    for name in ("a", "b"):
        cut_in_half(tmp_path / "hdr" / name / "f1.hdr", tmp_path / "hdr" / name / "f1.hdr")
    assert_refused(run_here(capsys, *args[:-1], tmp_path / "new.zarr"), "f1.hdr")
    assert not (tmp_path / "new.zarr").exists()
    (tmp_path / "empty.zarr").mkdir()                             # a folder given empty stays, empty
    assert_refused(run_here(capsys, *args[:-1], tmp_path / "empty.zarr"), "f1.hdr")
    assert os.listdir(tmp_path / "empty.zarr") == []



def test_a_dataset_store_removed_during_the_run_is_said_so(capsys, monkeypatch, tmp_path):
    """It said the store "keeps 1 complete sequence(s); the same command resumes it", or gave Zarr's words."""
    import shutil
    import tespike.cosim.dataset.build as build

    def removed_midway(url, *args, starting=None, **kwargs):
        os.makedirs(url, exist_ok=True)         # the store made, the build started, then the folder removed
        starting()
        shutil.rmtree(url)
        raise RuntimeError(f"No array found in store file://{url} at path sun/light")
    monkeypatch.setattr(build, "build_dataset", removed_midway)
    out = tmp_path / "D.zarr"
    assert_refused(run_here(capsys, "dataset", "--scene", "sun", "--frames", 2, "--height", 16, "--width", 16,
                            "--config", "te", "--out", out), f"dataset store {str(out)!r} was removed during the run")


# ------------------------------------------------------------------ a signal after the output is in place
def test_a_signal_after_the_output_is_in_place_says_it_is_whole(capsys, monkeypatch, tmp_path):
    """Ctrl-C between the move into place and the end printed "interrupted" over a new, whole output."""
    import tespike.cosim.console as console
    np.save(tmp_path / "e.npy", np.full((TINY.clocks_per_readout * 3, 2, 2), 2, np.uint8))
    (tmp_path / "c.json").write_text(json.dumps(TINY.to_dict()))
    (tmp_path / "s.npz").write_bytes(b"previous run")

    def interrupted(args, message):
        raise KeyboardInterrupt
    monkeypatch.setattr(console, "report", interrupted)
    result = run_here(capsys, "golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                      "--out", tmp_path / "s.npz")
    assert_refused(result, "interrupted after writing", f"{str(tmp_path / 's.npz')!r} whole")
    assert np.load(tmp_path / "s.npz")["words"].shape == (3, 2, 2)
    monkeypatch.undo()                                     # the next run starts with nothing written
    (tmp_path / "bad.npy").write_bytes(b"")
    assert_refused(run_here(capsys, "golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "bad.npy",
                            "--out", tmp_path / "t.npz"), "bad.npy")


def test_only_a_finished_folder_counts_as_written_never_the_files_inside_its_temporary(tmp_path):
    from tespike.golden.atomic import atomic_folder, atomic_output, finished_outputs
    start = len(finished_outputs())
    with pytest.raises(KeyboardInterrupt):
        with atomic_folder(tmp_path / "ev") as folder:
            with atomic_output(folder / "table.md") as part:
                Path(part).write_text("new")
            raise KeyboardInterrupt
    assert finished_outputs(start) == []
    with atomic_folder(tmp_path / "ev") as folder:
        with atomic_output(folder / "table.md") as part:
            Path(part).write_text("new")
    assert finished_outputs(start) == [str(tmp_path / "ev")]


@pytest.mark.parametrize("folder", [False, True])
def test_a_stop_during_the_rename_comes_after_the_output_is_recorded(tmp_path, monkeypatch, folder):
    """SIGTERM (or Ctrl-C) between an output's rename and its record is held: the command stops
    after, naming the output as written, not with a replaced file it calls unwritten."""
    import tespike.golden.atomic as atomic

    class Stopped(Exception):
        pass

    def stop(signum, frame):
        raise Stopped
    real = {name: getattr(atomic.os, name) for name in ("replace", "rename")}

    def then_signalled(name):
        def move(*args, **kwargs):
            real[name](*args, **kwargs)
            os.kill(os.getpid(), signal.SIGTERM)     # its handler runs at the next bytecode
        return move
    previous = signal.signal(signal.SIGTERM, stop)
    try:
        start = len(atomic.finished_outputs())
        target = tmp_path / ("ev" if folder else "s.txt")
        for name in real:
            monkeypatch.setattr(atomic.os, name, then_signalled(name))
        with pytest.raises(Stopped):
            with (atomic.atomic_folder if folder else atomic.atomic_output)(target) as part:
                (Path(part) / "t.md" if folder else Path(part)).write_text("new")
        monkeypatch.undo()
        assert atomic.finished_outputs(start) == [str(target)]
        assert (target / "t.md" if folder else target).read_text() == "new"
        assert signal.getsignal(signal.SIGTERM) is stop
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_a_stop_while_the_command_prepares_is_its_one_line(tmp_path, monkeypatch, capsys):
    """SIGTERM while the command prepares its run (the import guard, the janitor's start) ends in
    the command's one line, as anywhere in the run: it escaped as a traceback before."""
    from tespike.cosim import cli, library_room

    monkeypatch.setattr(library_room, "guard_imports", lambda: os.kill(os.getpid(), signal.SIGTERM))
    np.save(tmp_path / "i.npy", np.full((1, 4, 4), 0.1))
    assert cli.main(["simulate", "--config", "te", "--scene", str(tmp_path / "i.npy"),
                     "--out", str(tmp_path / "s.npz")]) == 128 + signal.SIGTERM
    assert capsys.readouterr().err.splitlines() == ["tespike simulate: terminated by SIGTERM"]
    assert not (tmp_path / "s.npz").exists()


@pytest.mark.parametrize("kind", ["GUARDED", "HELD"])
def test_a_stop_while_a_guarded_library_loads_comes_once_it_has_loaded(tmp_path, monkeypatch, kind):
    """SIGTERM 0.9 s into ``evaluate --store`` met torch's import and raised inside code its C++
    start had called: pybind11 ended the process with std::terminate (SIGABRT, 77 lines). A guarded
    library loads with the stops held; the stop is raised once it has loaded, and the module
    keeps its own loader. The same for the held libraries (Dask's: a stop 0.3 s into ``dataset
    --workers 2`` left yaml half-initialised, and its next import on the way out a traceback)."""
    from tespike.cosim import cli, library_room
    assert {"dask", "distributed", "zarr", "yaml"} <= set(library_room.HELD)

    (tmp_path / "stopped_library.py").write_text(
        "import os, signal\nos.kill(os.getpid(), signal.SIGTERM)\nLOADED = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sys, "meta_path", [f for f in sys.meta_path if not isinstance(f, library_room._Guard)])
    monkeypatch.setattr(library_room, "GUARDED", ("stopped_library",) if kind == "GUARDED" else ())
    monkeypatch.setattr(library_room, "HELD", ("stopped_library",) if kind == "HELD" else ())
    monkeypatch.setattr(library_room.resources, "address_space_limit", lambda: None)    # (no room check here)
    monkeypatch.delitem(sys.modules, "stopped_library", raising=False)
    library_room.guard_imports()
    seen = []

    def stop(signum, frame):
        seen.append(sys.modules["stopped_library"])
        raise cli.Terminated(signum)
    previous = signal.signal(signal.SIGTERM, stop)
    try:
        with pytest.raises(cli.Terminated):
            import stopped_library  # noqa: F401
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert len(seen) == 1 and seen[0].LOADED
    assert type(seen[0].__loader__).__name__ == "SourceFileLoader" and seen[0].__spec__.loader is seen[0].__loader__


def test_a_signal_during_the_interpreters_exit_ends_it_with_the_commands_status(tmp_path):
    """After the command's line, Ctrl-C or SIGTERM end the process at once with the command's own exit
    status (torch's and Dask's exit handlers take a second: a KeyboardInterrupt raised in one printed
    a traceback; then, with the system's handlers back, the process died of the signal with no line,
    exit -2, as if stopped part-way); nohup's SIG_IGN stays."""
    for name in ("SIGINT", "SIGTERM"):
        for start, after in (("SIG_DFL", False), ("SIG_IGN", True)):
            code = (f"import os, signal, sys, time; signal.signal(signal.{name}, signal.{start}); "
                    "sys.argv = ['tespike', 'scene', '--list']; from tespike.cosim.cli import main; "
                    f"main(); os.kill(os.getpid(), signal.{name}); time.sleep(0.2); print('after the signal')")
            done = run_python(code)
            assert done.returncode == 0 and done.stderr == "" and "default" in done.stdout, (name, start, done)
            assert ("after the signal" in done.stdout) == after, (name, start, done.stdout[-80:])


def test_the_process_ends_with_the_commands_status_after_the_exit_handlers():
    """``tespike`` ends with ``os._exit`` once its threads are joined, its exit handlers run and its
    streams flushed (the interpreter's module teardown took 0.9 s after a demo); help and usage
    errors keep argparse's statuses."""
    code = ("import atexit, sys; atexit.register(lambda: print('exit handler ran'))\n"
            "sys.argv = ['tespike', {args}]\nfrom tespike.entry import run\nrun()\n")
    done = run_python(code.format(args="'scene', '--list'"))
    assert done.returncode == 0 and done.stdout.rstrip().endswith("exit handler ran") and done.stderr == "", done
    done = run_python(code.format(args="'--help'"))
    assert done.returncode == 0 and "usage" in done.stdout, done
    done = run_python(code.format(args="'scene', '--no-such-flag'"))
    assert done.returncode == 2 and "unrecognized arguments" in done.stderr, done


#: Python that makes importing ``tespike.cosim.cli`` (numpy loading) meet a Ctrl-C.
CLI_IMPORT_INTERRUPTED = ("import sys, types\n"
                          "cli = types.ModuleType('tespike.cosim.cli')\n"
                          "def stopped(name):\n"
                          "    raise KeyboardInterrupt\n"
                          "cli.__getattr__ = stopped\n"
                          "import tespike.cosim\n"
                          "sys.modules['tespike.cosim.cli'] = cli\n")


def test_ctrl_c_while_the_command_loads_is_one_line():
    """Ctrl-C in the first 0.2 s (numpy loading, before main's handling) printed a 20-line traceback."""
    code = CLI_IMPORT_INTERRUPTED + "import runpy\nrunpy.run_module('tespike', run_name='__main__')\n"
    done = run_python(code)
    assert done.returncode == 130 and done.stderr == "tespike: interrupted\n", done


@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGHUP"])
def test_a_signal_while_the_command_loads_is_one_line(signal_name):
    """SIGTERM or SIGHUP in the first 0.2 s (numpy loading, before the command's handlers) ended
    the process silently (exit 143). The entry point holds them from its first line; the command's
    own handlers take over once it runs (the second run: its line names the command)."""
    # (the signal's default action first, as in a terminal: under nohup SIGHUP is ignored, and stays so)
    default = f"import signal\nsignal.signal(signal.{signal_name}, signal.SIG_DFL)\n"
    code = (default + "import sys, types, os, signal\n"
            "cli = types.ModuleType('tespike.cosim.cli')\n"
            "def stopped(name):\n"
            f"    os.kill(os.getpid(), signal.{signal_name})\n"
            "    raise AttributeError(name)\n"
            "cli.__getattr__ = stopped\n"
            "import tespike.cosim\n"
            "sys.modules['tespike.cosim.cli'] = cli\n"
            "import runpy\nrunpy.run_module('tespike', run_name='__main__')\n")
    done = run_python(code)
    number = getattr(signal, signal_name)
    assert done.returncode == 128 + number and done.stderr == f"tespike: terminated by {signal_name}\n", done
    code = (default + "import os, signal, sys\n"
            "import tespike.cosim.commands.scene_cmd as scene\n"
            f"scene.run = lambda args: os.kill(os.getpid(), signal.{signal_name})\n"
            "sys.argv = ['tespike', 'scene', '--list']\n"
            "from tespike.entry import main\nsys.exit(main())\n")
    done = run_python(code)
    assert done.returncode == 128 + number and done.stderr == f"tespike scene: terminated by {signal_name}\n", done


def test_the_installed_script_goes_through_the_same_early_ctrl_c_handling():
    """The console script called ``tespike.cosim.cli:main``, which imports numpy before any handling:
    Ctrl-C in the installed ``tespike``'s first 0.2 s was a traceback. It now calls the light entry
    that ``python3 -m tespike`` uses; this runs the script's own code (pip writes
    ``sys.exit(main())`` after importing the entry point's function)."""
    import tomllib
    script = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]["tespike"]
    module, function = script.split(":")
    assert module == "tespike.entry"
    code = CLI_IMPORT_INTERRUPTED + f"from {module} import {function}\nsys.exit({function}())\n"
    done = run_python(code)
    assert done.returncode == 130 and done.stderr == "tespike: interrupted\n", done
    heavy = run_python(f"import sys; import {module}; print(sorted(m for m in ('numpy', 'torch', 'tespike.cosim.cli') "
                       "if m in sys.modules))")
    assert heavy.stdout.strip() == "[]", heavy          # nothing heavy before the handling is in place


def test_ctrl_c_while_the_arguments_are_read_is_one_line(monkeypatch, capsys):
    """Outside the command's own handling (building the parser, reading the arguments) Ctrl-C was a traceback."""
    import tespike.cosim.cli as cli
    from tespike.entry import main

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "build_parser", stopped)
    monkeypatch.setattr(sys, "argv", ["tespike", "scene", "--list"])
    assert main() == 130
    assert capsys.readouterr().err == "tespike: interrupted\n"


def test_an_import_that_fails_in_c_under_an_address_space_limit_is_out_of_memory(monkeypatch, capsys):
    """``import dask`` under ``ulimit -v`` 800 MB failed with CPython's SystemError ("returned NULL
    without setting an exception": an allocation failed in C) and a traceback. Under a limit it is
    the out-of-memory line; without one it stays a traceback (a bug to report, not a fault of the
    machine)."""
    from tespike.cosim import cli
    from tespike.golden import resources

    def failed(args):
        raise SystemError("<function _find_and_load at 0x7f> returned NULL without setting an exception")
    args = cli.build_parser("scene").parse_args(["scene", "--list"])
    args.run = failed
    monkeypatch.setattr(resources, "address_space_limit", lambda: 800 << 20)
    assert cli._run(args) == (1, False)
    assert capsys.readouterr().err.splitlines() == [
        "tespike scene: error: out of memory within the address-space limit (ulimit -v) of 800 MB "
        "(<function _find_and_load at 0x7f> returned NULL without setting an exception)"]
    monkeypatch.setattr(resources, "address_space_limit", lambda: None)
    with pytest.raises(SystemError):
        cli._run(args)


def test_the_import_guard_reads_the_address_space_limit_at_each_check(tmp_path, monkeypatch):
    """The guard took ``address_space_limit`` by name when it was first imported: a command run in a
    test process while a test had that function patched (900 MB) left the guard reading 900 MB for
    every later command, and ``train`` was refused for want of room ("38 MB is left"), a failure that
    depended on the order the test files ran in. The guard now reads the limit at each check."""
    from tespike.cosim import library_room
    from tespike.golden import resources

    (tmp_path / "roomy_library.py").write_text("LOADED = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "roomy_library", raising=False)
    monkeypatch.setattr(library_room, "GUARDED", ("roomy_library",))
    monkeypatch.setattr(resources, "address_space_limit", lambda: 0)     # no room at all
    with pytest.raises(MemoryError, match="roomy_library"):
        library_room._Guard().find_spec("roomy_library", None)
    monkeypatch.setattr(resources, "address_space_limit", lambda: None)  # unlimited: no check
    assert library_room._Guard().find_spec("roomy_library", None) is not None


def test_a_trial_import_that_fails_in_c_refuses_the_library(tmp_path, monkeypatch):
    """Under ``ulimit -v`` 617 MB torch's trial import in a child failed with CPython's SystemError
    (an allocation that failed in C), read as "another failure": the import here went ahead and
    aborted the process (std::bad_alloc). A SystemError in the trial means no room."""
    from tespike.cosim import library_room

    (tmp_path / "starved_library.py").write_text("raise SystemError('error return without exception set')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    refusal = library_room._refusal("starved_library", 600 << 20)
    assert refusal is not None and refusal.startswith("starved_library cannot be loaded: it does not fit in")


def test_an_interrupted_commands_line_names_each_file_written_once(tmp_path):
    """train rewrites best.pt and curves.png at every validation: its Ctrl-C line listed them once
    per validation ('best.pt', 'curves.png', 'best.pt', 'curves.png', ...)."""
    from tespike.cosim.cli import _after
    from tespike.golden.atomic import finished_outputs
    from tespike.golden.io import atomic_output
    since = len(finished_outputs())
    for _ in range(3):
        for name in ("best.pt", "curves.png"):
            with atomic_output(tmp_path / name) as tmp:
                Path(tmp).write_bytes(b"x")
    line = _after(since, KeyboardInterrupt())
    assert line == f" after writing {str(tmp_path / 'best.pt')!r}, {str(tmp_path / 'curves.png')!r} whole"


@pytest.mark.parametrize("command", ["simulate", "reconstruct"])
def test_an_input_cut_short_while_mapped_is_named_not_a_bare_bus_error(tmp_path, command):
    """Inputs are read through memory maps; another program cutting one short (np.save onto the same
    path) made the next read a bus error: the process died with no line of its own. The fault
    handler's dump goes to the janitor, which names the file that shrank."""
    scene = tmp_path / "I.npy"
    np.save(scene, np.full((6, 64, 64), 0.3, np.float32))
    target, loader = scene, "load_scene"
    args = ["simulate", "--config", "te", "--scene", str(scene), "--out", str(tmp_path / "out.npz")]
    if command == "reconstruct":
        assert run_tespike("simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "S.npz",
                           "--seed", "1").returncode == 0
        target, loader = tmp_path / "S.npz", "load_stream"
        args = ["reconstruct", "--stream", str(target), "--method", "tfp", "--out", str(tmp_path / "R.npy")]
    result = run_python(f"""
import os, sys
from tespike.golden import io
read = io.{loader}
def read_then_cut(path, **kw):
    loaded = read(path, **kw)
    os.truncate(path, 300)                   # (another program cuts the mapped file short)
    return loaded
io.{loader} = read_then_cut
sys.argv = ["tespike", *{args!r}]
from tespike.cosim.cli import main
sys.exit(main())
""")
    assert result.returncode in (-signal.SIGBUS, 128 + signal.SIGBUS), result
    assert_refused(result, f"input file {str(target)!r} was cut short while it was read", "Bus error")
    assert result.stderr.startswith(f"tespike {command}: error: "), result.stderr   # (as its refusals start)
    assert sorted(os.listdir(tmp_path)) == sorted(["I.npy"] + (["S.npz"] if command == "reconstruct" else []))


@pytest.mark.parametrize("buffered", [True, False])
@pytest.mark.parametrize("args", [("scene", "--list"), ("--help",), ("--version",), ()])
def test_a_full_standard_output_is_one_line_naming_it(tmp_path, buffered, args):
    """``tespike ... > log`` on a full disk: Python's exit-time "Exception ignored" (exit 120), or
    a line naming no file, or (argparse drops its write errors) exit 0 with the help lost."""
    env = {**_checkout_env(), "PYTHONUNBUFFERED": "" if buffered else "1"}
    with open("/dev/full", "w") as full:
        result = subprocess.run([sys.executable, "-m", "tespike", *args], stdout=full, stderr=subprocess.PIPE,
                                text=True, env=env, timeout=120, cwd=tmp_path)
    assert_refused(result, "standard output", "No space left")


def test_a_full_standard_output_after_the_output_is_written_says_it_is_whole(tmp_path):
    out = tmp_path / "I.npy"
    with open("/dev/full", "w") as full:
        result = subprocess.run([sys.executable, "-m", "tespike", "scene", "--frames", "2", "--height", "8",
                                 "--width", "8", "--out", out], stdout=full, stderr=subprocess.PIPE, text=True,
                                env=_checkout_env(), timeout=120)
    assert_refused(result, "standard output", f"after writing {str(out)!r} whole")
    assert np.load(out).shape == (2, 8, 8)


def test_a_reader_that_goes_away_ends_the_command_quietly():
    """``tespike scene --list | head -0``: no message (as a shell tool killed by SIGPIPE)."""
    reader = subprocess.Popen([sys.executable, "-m", "tespike", "scene", "--list"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, env=_checkout_env())
    reader.stdout.close()                          # the reader is gone before the list is written
    _, err = reader.communicate(timeout=120)
    assert reader.returncode == 141 and err == b"", (reader.returncode, err)


def _started_with_closed(fds, *args, cwd):
    """``tespike args`` started with the descriptors ``fds`` closed (``>&-``, ``2>&-``)."""
    def close():
        for fd in fds:
            os.close(fd)
    return subprocess.run([sys.executable, "-m", "tespike", *map(str, args)], stdin=subprocess.DEVNULL,
                          stdout=subprocess.DEVNULL if 1 not in fds else None, stderr=subprocess.PIPE,
                          text=True, env=_checkout_env(), timeout=300, cwd=cwd, preexec_fn=close)


def test_a_command_started_without_stdout_refuses_to_print_or_runs_quietly(tmp_path):
    """``score >&-`` exited 0 with its table lost; ``simulate >&- 2>&-`` exited 1 having written
    nothing (the cleanup process's pipe took descriptors 1 and 2)."""
    scene = tiny_scene(tmp_path, frames=4)
    assert run_tespike("simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "S.npz",
                       "--seed", 1, "-q").returncode == 0
    assert run_tespike("reconstruct", "--stream", tmp_path / "S.npz", "--method", "tfp",
                       "--out", tmp_path / "R.npy", "-q").returncode == 0
    result = _started_with_closed([1], "score", "--reference", scene, "--estimate", tmp_path / "R.npy",
                                  cwd=tmp_path)
    assert_refused(result, "standard output", "closed")
    # refused before the run: it had written S.npz whole, then failed to say so (exit 2 after the work)
    result = _started_with_closed([1], "simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "S0.npz",
                                  "--seed", 1, cwd=tmp_path)
    assert_refused(result, "standard output: closed", "give --quiet")
    assert not (tmp_path / "S0.npz").exists()
    for fds in ([1], [1, 2]):
        out = tmp_path / f"S{len(fds)}.npz"
        result = _started_with_closed(fds, "simulate", "--config", "te", "--scene", scene, "--out", out,
                                      "--seed", 1, "-q", cwd=tmp_path)
        assert result.returncode == 0 and out.is_file(), result.stderr
        assert np.array_equal(np.load(out)["words"], np.load(tmp_path / "S.npz")["words"])


@pytest.mark.parametrize("given", ["", "nosuch/.."])
def test_an_output_folder_naming_no_folder_of_its_own_is_refused_and_nothing_is_removed(tmp_path, given):
    """``--out ''`` and ``--out nosuch/..`` were absent to the checks and the current folder to the
    writer, which replaced it whole: the run's inputs went with it (exit 0)."""
    (tmp_path / "keep.txt").write_text("mine")
    scene = tiny_scene(tmp_path, frames=2)
    for args in (("view", "--input", scene, "--each", "--out", given),
                 ("evaluate", "--scene", scene, "--methods", "tfp", "--out", given),
                 ("demo", "--out", given)):
        result = subprocess.run([sys.executable, "-m", "tespike", *map(str, args)], capture_output=True, text=True,
                                env=_checkout_env(), timeout=300, cwd=tmp_path)
        assert_refused(result, f"--out {given!r}")
        assert (tmp_path / "keep.txt").read_text() == "mine" and scene.is_file()


def test_evaluate_under_an_ascii_locale_prints_its_table_escaped(tmp_path):
    """Its table holds "PSNR-μ": under an ASCII standard output the print ended a finished run in a
    UnicodeEncodeError traceback, exit 1. The command's stdout writes what it cannot encode escaped."""
    np.save(tmp_path / "I.npy", np.full((4, 16, 16), 0.3, np.float32))
    done = run_tespike("evaluate", "--set", "none", "--scene", tmp_path / "I.npy", "--methods", "tfp",
                       "--ml-count-config", "none", "--progress", "off", "--out", tmp_path / "ev",
                       env={"PYTHONIOENCODING": "ascii"})
    assert done.returncode == 0 and not done.stderr, done.stderr
    assert "PSNR-\\u03bc" in done.stdout and "| TFP_TE |" in done.stdout
    assert (tmp_path / "ev" / "table.md").read_text(encoding="utf-8").count("PSNR-μ") == 2


def test_the_janitor_names_an_input_written_whole_again_after_the_fault(tmp_path):
    """An input cut short and written whole again (``cp`` onto it) killed the command with a bus
    error, and by the time the janitor looked the file had its size back: its line named no file
    ("the process ended on a fatal signal (Bus error)"). It compares the modification time too."""
    from tespike.golden.atomic import _JANITOR_CODE
    path = tmp_path / "I.npy"
    path.write_bytes(b"\0" * 4096)
    seen = os.stat(path).st_mtime_ns
    os.utime(path, ns=(seen, seen + 1_000_000_000))          # written again since it was mapped

    def janitor(mtime):
        lines = b"m%s %d %d\nFatal Python error: Bus error\n\n" % (os.fsencode(str(path)).hex().encode(), 4096, mtime)
        return subprocess.run([sys.executable, "-I", "-S", "-c", _JANITOR_CODE], input=lines,
                              capture_output=True, timeout=30).stderr.decode()
    assert f"input file {str(path)!r} changed while it was read (Bus error" in janitor(seen)
    assert "the process ended on a fatal signal (Bus error)" in janitor(seen + 1_000_000_000)
