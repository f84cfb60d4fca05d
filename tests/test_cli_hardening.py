"""Classes of fault every sub-command must survive (issue 12), one test per class.

Each refusal: exactly one line on stderr, non-zero exit, no traceback, no new
file (hidden temporaries included) and no existing file changed. Paths:
devices, FIFOs, symlinks, hard links, directories, an output equal to an input;
signals; stale temporaries; corrupt and hostile files; argument errors.
"""

import contextlib
import json
import os
import signal
import stat
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.recon.scenes.hdr_io import write_hdr
from tests.cli import ROOT, _checkout_env, assert_refused, run_tespike
from tests.processes import interruptible

TINY = SensorConfig(b1=1, b2=1, threshold=3, acc_bits=3)          # L = 2
TINY_JSON = json.dumps({"b1": 1, "b2": 1, "threshold": 3, "acc_bits": 3})


def snapshot(folder):
    """Every entry under ``folder`` (hidden ones too) with its bytes, for "nothing changed"."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in dirnames + filenames:
            path = os.path.join(dirpath, name)
            info = os.lstat(path)
            data = Path(path).read_bytes() if stat.S_ISREG(info.st_mode) else None
            out[os.path.relpath(path, folder)] = (stat.S_IFMT(info.st_mode), data)
    return out


@pytest.fixture
def files(tmp_path):
    """A config, stimulus, scene and stream in tmp_path."""
    (tmp_path / "c.json").write_text(TINY_JSON)
    rng = np.random.default_rng(3)
    np.save(tmp_path / "e.npy", rng.integers(0, 6, size=(TINY.clocks_per_readout * 5, 3, 4)).astype(np.uint8))
    np.save(tmp_path / "i.npy", rng.uniform(0, 1, size=(5, 3, 4)))
    result = run_tespike("golden", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--quiet")
    assert result.returncode == 0 and result.stdout == "", result
    return tmp_path


def refused_without_change(folder, args, *words):
    before = snapshot(folder)
    result = run_tespike(*args)
    assert_refused(result, *words)
    assert snapshot(folder) == before
    return result


# ------------------------------------------------------------------ output paths
def golden_args(folder, out, stimulus=None, config=None):
    return ("golden", "--config", config or folder / "c.json", "--stimulus", stimulus or folder / "e.npy",
            "--out", out)


def test_a_file_output_ending_in_a_separator_is_refused(files):
    """``--out o.npz/`` names a directory that does not exist: it was written as the file ``o.npz``."""
    refused_without_change(files, golden_args(files, str(files / "o.npz") + "/"), "o.npz/", "names a directory")


@pytest.mark.parametrize("flag", ["--stimulus", "--config"])
def test_output_equal_to_an_input_is_refused_naming_both(files, flag):
    target = files / ("e.npy" if flag == "--stimulus" else "c.json")
    os.symlink(target, files / "link")
    os.link(target, files / "hard")
    for out in (target, files / "link", files / "hard", files / "sub" / ".." / target.name):
        (files / "sub").mkdir(exist_ok=True)
        refused_without_change(files, golden_args(files, out), flag, "--out", "same file")


def test_output_equal_to_input_in_every_command(files):
    cases = [
        ("simulate", "--config", "te", "--scene", files / "i.npy", "--out", files / "i.npy"),
        ("simulate", "--config", files / "c.json", "--scene", files / "i.npy", "--out", files / "c.json"),
        ("reconstruct", "--stream", files / "s.npz", "--method", "tfp", "--out", files / "s.npz"),
        ("rtl-sim", "--config", files / "c.json", "--stimulus", files / "e.npy", "--out", files / "e.npy"),
        ("rtl-sim", "--config", files / "c.json", "--stimulus", files / "e.npy", "--out", files / "w.npz",
         "--vcd", files / "w.vcd", "--gtkw", files / "c.json"),
        ("rtl-sim", "--config", "te", "--stimulus", files / "e.npy", "--out", files / "w.vcd",
         "--vcd", files / "w.vcd"),
        ("verilog", "--config", files / "c.json", "--height", 2, "--width", 2, "--out", files / "c.json"),
    ]
    for args in cases:
        refused_without_change(files, args, "same file")


def test_output_directory_refused_before_any_file_is_written(files):
    (files / "d.vcd").mkdir()
    (files / "d").mkdir()
    refused_without_change(files, golden_args(files, files / "d"), "directory")
    # rtl-sim --vcd DIR used to write DIR.gtkw before refusing
    refused_without_change(files, ("rtl-sim", "--config", files / "c.json", "--stimulus", files / "e.npy",
                                   "--out", files / "x.npz", "--vcd", files / "d.vcd"), "--vcd", "directory")
    refused_without_change(files, ("rtl-sim", "--config", files / "c.json", "--stimulus", files / "e.npy",
                                   "--out", files / "x.npz", "--vcd", files / "w.vcd", "--gtkw", files / "d"),
                           "--gtkw", "directory")
    refused_without_change(files, golden_args(files, files / "missing" / "s.npz"), "does not exist")
    (files / "table.md").mkdir()
    refused_without_change(files, ("evaluate", "--set", "none", "--scene", files / "i.npy", "--out", files),
                           "table.md")
    refused_without_change(files, ("evaluate", "--set", "none", "--scene", files / "i.npy",
                                   "--out", files / "i.npy"), "not a directory")


def test_symlinked_output_writes_the_target(files):
    os.symlink("real.npz", files / "link.npz")                   # dangling until written
    result = run_tespike(*golden_args(files, files / "link.npz"))
    assert result.returncode == 0, result.stderr
    assert os.path.islink(files / "link.npz") and (files / "real.npz").is_file()
    with np.load(files / "real.npz") as a, np.load(files / "s.npz") as b:
        assert np.array_equal(a["words"], b["words"])


def test_character_device_output_is_written_through_never_replaced(files):
    result = run_tespike(*golden_args(files, "/dev/null"))
    assert result.returncode == 0, result.stderr
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    # /dev/full: the device is written to, and the full disk is named
    result = run_tespike(*golden_args(files, "/dev/full"))
    assert_refused(result, "/dev/full", "No space left")
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_fifo_output_is_written_through_or_refused_without_reader(files):
    fifo = files / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()))
    reader.start()
    result = run_tespike(*golden_args(files, fifo), timeout=60)
    reader.join(timeout=60)
    assert result.returncode == 0, result.stderr
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert received and received[0] == (files / "s.npz").read_bytes()
    result = run_tespike(*golden_args(files, fifo), timeout=60)       # no reader: refused, no hang
    assert_refused(result, "pipe", "no reader")
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_standard_output_as_the_output_carries_the_file_alone(files):
    """``--out /dev/stdout`` into a pipe was refused ("directory '/dev' is not writable": realpath
    names no file for a pipe); the file now goes down the pipe, and the success line to stderr (it
    would have followed the file's bytes)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "tespike", *map(str, golden_args(files, "/dev/stdout"))],
                          capture_output=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == (files / "s.npz").read_bytes()
    assert done.stderr.decode().startswith("wrote /dev/stdout")


def test_outputs_get_the_mode_of_the_umask(files):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for mask, mode in ((0o022, 0o644), (0o077, 0o600), (0o002, 0o664)):
        out = files / f"m{mask:o}.npz"
        subprocess.run([sys.executable, "-m", "tespike", *map(str, golden_args(files, out))], env=env,
                       check=True, capture_output=True, preexec_fn=lambda mask=mask: os.umask(mask))
        assert stat.S_IMODE(os.stat(out).st_mode) == mode
    (files / "keep.npz").write_bytes(b"old")
    os.chmod(files / "keep.npz", 0o640)                  # an existing file keeps its mode
    assert run_tespike(*golden_args(files, files / "keep.npz")).returncode == 0
    assert stat.S_IMODE(os.stat(files / "keep.npz").st_mode) == 0o640


def test_read_only_output_and_directory_named_not_the_temporary(files):
    if os.geteuid() == 0:
        pytest.skip("root writes read-only files and directories")
    (files / "ro").mkdir()
    os.chmod(files / "ro", 0o555)
    result = run_tespike(*golden_args(files, files / "ro" / "s.npz"))
    assert_refused(result, "ro", "not writable")
    assert ".part" not in result.stderr


# ------------------------------------------------------------------ signals and stale temporaries
def long_rtl_run(folder, session=False):
    """An rtl-sim run with a VCD, long enough to be interrupted while writing (``session``: in a
    session and process group of its own)."""
    np.save(folder / "long.npy", np.full((TINY.clocks_per_readout * 4000, 2, 2), 3, np.uint8))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "tespike", "rtl-sim", "--config", str(folder / "c.json"),
                             "--stimulus", str(folder / "long.npy"), "--out", str(folder / "w.npz"),
                             "--vcd", str(folder / "w.vcd")], env=env, stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, preexec_fn=interruptible,
                            start_new_session=session)


def wait_for_part(folder, process, timeout=120):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if any(name.endswith(".part") for name in os.listdir(folder)):
            return
        assert process.poll() is None, process.communicate()
        time.sleep(0.05)
    pytest.fail("no temporary appeared")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_termination_signals_remove_the_temporaries(files, signum):
    before = set(os.listdir(files))
    process = long_rtl_run(files)
    wait_for_part(files, process)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signum
    assert len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr, stderr
    assert set(os.listdir(files)) == before | {"long.npy"}


def _parts(folder):
    return [name for name in os.listdir(folder) if name.endswith(".part")]


def _gone(folder, timeout=10.0):
    """Whether the temporaries under ``folder`` are gone within ``timeout`` seconds (the
    janitor removes them once the killed run's pipe closes: a few milliseconds)."""
    end = time.monotonic() + timeout
    while _parts(folder) and time.monotonic() < end:
        time.sleep(0.02)
    return not _parts(folder)


@pytest.mark.parametrize("group", [False, True], ids=["the command", "its process group"])
def test_sigkill_leaves_no_temporary(files, group):
    """Killed outright (no handler runs), alone or with its whole process group: the
    janitor (golden.atomic) removes the run's temporaries; no output appears."""
    before = set(os.listdir(files))
    process = long_rtl_run(files, session=group)
    wait_for_part(files, process)
    assert all(name.startswith((".w.vcd.", ".w.gtkw.", ".w.npz.")) for name in _parts(files))
    os.killpg(process.pid, signal.SIGKILL) if group else process.kill()
    process.communicate()
    assert _gone(files), _parts(files)
    assert set(os.listdir(files)) == before | {"long.npy"}


def test_a_run_folder_left_by_a_kill_of_the_run_and_its_janitor_goes_with_the_next_run(tmp_path):
    """Killed outright together with its janitor (a container's or the out-of-memory killer's
    SIGKILL of every process), a run left its ``$TMPDIR/tespike-run-XXXXXXXX`` folder, which no later
    run removed: they piled up. The next run removes every such folder no live run holds (flock), and
    leaves a held one, another user's names, and links alone."""
    temporary = tmp_path / "t"
    temporary.mkdir()
    env = {"TMPDIR": str(temporary)}
    scene = tmp_path / "I.npy"
    np.save(scene, np.full((2, 4, 4), 0.1, np.float32))
    command = ["simulate", "--config", "te", "--scene", scene, "--seed", "1", "--out", tmp_path / "S.npz", "-q"]
    process = subprocess.Popen([sys.executable, "-c", "import sys, time\n"
                                "from tespike.golden.atomic import _Janitor, run_temporaries\n"
                                "print(run_temporaries(), flush=True)\n"
                                "print(_Janitor._process.pid, flush=True)\ntime.sleep(60)"],
                               stdout=subprocess.PIPE, text=True, env={**_checkout_env(), **env})
    try:
        live = Path(process.stdout.readline().strip())
        janitor = int(process.stdout.readline())
        assert live.parent == temporary and live.name.startswith("tespike-run-"), live
        (live / "work").write_text("in use")
        stale = temporary / "tespike-run-ab_cd123"
        (stale / "abc-folder").mkdir(parents=True)
        (stale / "abc-folder" / "x").write_text("left")
        (temporary / "tespike-run-other-name-kept").mkdir()
        (temporary / "elsewhere").mkdir()
        (temporary / "tespike-run-linklink").symlink_to(temporary / "elsewhere")
        process.kill()                                  # the process and its janitor, both
        os.kill(janitor, signal.SIGKILL)
        process.wait()
        time.sleep(0.2)
        assert live.exists() and stale.exists()
        (temporary / "tespike-run-held1234").mkdir()   # a live run's (held below)
        holder = subprocess.Popen([sys.executable, "-c", "import fcntl, os, sys, time\n"
                                   f"fd = os.open({str(temporary / 'tespike-run-held1234')!r}, os.O_RDONLY)\n"
                                   "fcntl.flock(fd, fcntl.LOCK_SH); print(1, flush=True); time.sleep(60)"],
                                  stdout=subprocess.PIPE, text=True)
        try:
            holder.stdout.readline()
            done = run_tespike(*command, env=env)
            assert done.returncode == 0, done.stderr
        finally:
            holder.kill()
            holder.wait()
    finally:
        process.kill()
        process.wait()
    assert sorted(os.listdir(temporary)) == ["elsewhere", "tespike-run-held1234", "tespike-run-linklink",
                                             "tespike-run-other-name-kept"]


@pytest.mark.parametrize("fault", ["handles", "no flock"])
def test_a_run_folder_that_cannot_be_locked_is_not_left_behind(tmp_path, fault):
    """Out of file handles between making the run folder and locking it, or on a file system without
    ``flock``: the folder is removed and the run goes on without one (an unlocked folder would be
    taken by another run's sweep; a failed lock had made eight folders and left them)."""
    starve = ("def starved(path):\n    raise OSError(errno.EMFILE, 'Too many open files')\n"
              "atomic._lock_run_folder = starved\n") if fault == "handles" else (
              "import fcntl\ndef no_lock(fd, how):\n    raise OSError(errno.ENOLCK, 'No locks available')\n"
              "fcntl.flock = no_lock\n")
    done = subprocess.run([sys.executable, "-c", "import errno, os\n"
                           "from tespike.golden import atomic\n" + starve +
                           "print(atomic.run_temporaries())"],
                          capture_output=True, text=True, env={**_checkout_env(), "TMPDIR": str(tmp_path)})
    assert done.returncode == 0 and done.stdout.strip() == "None", done
    assert os.listdir(tmp_path) == []


def test_sigkill_while_a_results_folder_is_built_keeps_the_previous_one(tmp_path):
    """``atomic_folder`` (evaluate, demo) killed outright mid-build: the previous results stay
    whole and the half-built hidden folder goes."""
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "table.md").write_text("previous run")
    script = ("import os, sys, time\n"
              "from tespike.golden.atomic import atomic_folder\n"
              "with atomic_folder(%r) as tmp:\n"
              "    (tmp / 'table.md').write_text('half')\n"
              "    print('building', flush=True)\n"
              "    time.sleep(60)\n") % str(tmp_path / "out")
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                               env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert process.stdout.readline() == "building\n"
    assert _parts(tmp_path)
    process.kill()
    process.communicate()
    assert _gone(tmp_path), _parts(tmp_path)
    assert os.listdir(tmp_path) == ["out"] and (tmp_path / "out" / "table.md").read_text() == "previous run"


def test_temporary_left_by_a_killed_run_is_removed_by_the_next_run(files):
    """Where no janitor could run (power loss, the janitor killed too): the next run at that path
    removes a temporary whose process is gone, and never takes it for output."""
    stale = files / ".w.vcd.999999999.abcdefgh.part"
    stale.write_bytes(b"half a VCD")
    np.save(files / "short.npy", np.zeros((TINY.clocks_per_readout, 1, 1), np.uint8))
    result = run_tespike("rtl-sim", "--config", files / "c.json", "--stimulus", files / "short.npy",
                         "--out", files / "w.npz", "--vcd", files / "w.vcd")
    assert result.returncode == 0, result.stderr
    assert not _parts(files) and (files / "w.vcd").read_bytes() != b"half a VCD"


def test_the_janitor_ends_with_a_run_that_ends_normally(tmp_path):
    """A run that ends normally leaves no janitor behind (it is reaped at exit)."""
    script = ("import os\n"
              "from tespike.golden.atomic import _Janitor, atomic_output\n"
              "with atomic_output(os.path.join(%r, 'o.bin')) as tmp:\n"
              "    open(tmp, 'wb').write(b'x')\n"
              "print(_Janitor._process.pid)\n") % str(tmp_path)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert done.returncode == 0 and done.stderr == "", done.stderr
    janitor = int(done.stdout)
    with pytest.raises(ProcessLookupError):
        os.kill(janitor, 0)
    assert os.listdir(tmp_path) == ["o.bin"]


def test_stale_temporary_of_a_live_process_is_kept(tmp_path):
    from tespike.golden.io import atomic_output
    live = tmp_path / f".o.npy.{os.getppid()}.abcdefgh.part"
    dead = tmp_path / ".o.npy.999999999.abcdefgh.part"
    other = tmp_path / ".other.npy.999999999.abcdefgh.part"
    for path in (live, dead, other):
        path.write_bytes(b"x")
    with atomic_output(tmp_path / "o.npy") as tmp:
        Path(tmp).write_bytes(b"new")
    assert live.exists() and other.exists() and not dead.exists()
    assert (tmp_path / "o.npy").read_bytes() == b"new"


# ------------------------------------------------------------------ full disk, in-process
def test_full_disk_names_the_users_path(tmp_path, monkeypatch):
    from tespike.golden.io import atomic_output, save_images

    def full(*args, **kwargs):
        raise OSError("655360 requested and 522208 written")
    monkeypatch.setattr(np, "save", full)
    with pytest.raises(InputError, match=r"cannot write '.*r\.npy': short write .*disk full"):
        save_images(tmp_path / "r.npy", np.zeros((1, 2, 2)))
    import errno
    with pytest.raises(InputError, match=r"cannot write '.*o\.txt': No space left on device"):
        with atomic_output(tmp_path / "o.txt") as tmp:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), tmp)
    assert os.listdir(tmp_path) == []


@contextlib.contextmanager
def small_tmpfs(folder, size):
    """A tmpfs of ``size`` mounted at ``folder`` (skips the test where mounting is not permitted)."""
    folder.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                          capture_output=True)
    if done.returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=True)


def test_small_tmpfs_full_disk(tmp_path, files):
    with small_tmpfs(tmp_path / "small", "16k") as mount:
        np.save(files / "big.npy", np.zeros((TINY.clocks_per_readout * 20000, 2, 2), np.uint8))
        result = run_tespike(*golden_args(files, mount / "s.npz", stimulus=files / "big.npy"))
        assert_refused(result, str(mount / "s.npz"))
        assert ".part" not in result.stderr
        assert os.listdir(mount) == []


# ------------------------------------------------------------------ bad inputs: one line each
@pytest.mark.parametrize("text, words", [
    ("[" * 100000 + "]" * 100000, ["nested too deeply"]),
    ('{"b1": ' + "9" * 5000 + "}", ["too long"]),
    ('{"b1": 1' + "0" * 3000 + "}", ["'b1'", "characters"]),
    ('{"alpha": null}', ["'alpha'", "null"]),
    ('{"threshold": null}', ["'threshold'", "null"]),
    ('{"acc_bits": null, "b1": 4}', ["'acc_bits'", "null"]),
    ('{"clocks_per_tick": null}', ["'clocks_per_tick'", "null"]),
    ('{"mode": null}', ["'mode'", "null"]),
    ('{"b1": 2, "b1": 3}', ["'b1'", "twice"]),
    (b'{"mode": "te\xff"}', ["UTF-8"]),
    ("", ["empty"]),
], ids=["nested", "5000-digits", "3000-digits", "null-alpha", "null-threshold", "null-acc_bits",
        "null-clocks_per_tick", "null-mode", "duplicate", "not-utf8", "empty"])
def test_bad_configuration_files(files, text, words):
    path = files / "bad.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    refused_without_change(files, golden_args(files, files / "o.npz", config=path), *words)


def test_fifo_device_and_directory_inputs_are_refused_not_read(files):
    fifo = files / "fifo"
    os.mkfifo(fifo)
    cases = [
        (golden_args(files, files / "o.npz", config=fifo), ["fifo", "FIFO"]),
        (golden_args(files, files / "o.npz", stimulus=fifo), ["fifo", "FIFO"]),
        (("simulate", "--config", "te", "--scene", fifo, "--out", files / "o.npz"), ["FIFO"]),
        (("reconstruct", "--stream", fifo, "--method", "tfp", "--out", files / "o.npy"), ["FIFO"]),
        (("evaluate", "--set", "none", "--scene", fifo, "--out", files / "ev"), ["FIFO"]),
        (golden_args(files, files / "o.npz", stimulus="/dev/null"), ["/dev/null", "character device"]),
        (golden_args(files, files / "o.npz", config="/dev/null"), ["/dev/null"]),
        (("reconstruct", "--stream", "/dev/null", "--method", "tfp", "--out", files / "o.npy"), ["/dev/null"]),
        (golden_args(files, files / "o.npz", stimulus=files), ["directory"]),
        # a kernel pseudo-file is 0 bytes to stat and holds text: not called empty
        (("simulate", "--config", "te", "--scene", "/proc/self/status", "--out", files / "o.npz"),
         ["/proc/self/status", "pseudo-file", "not a file of data"]),
        (golden_args(files, files / "o.npz", config="/proc/self/status"), ["/proc/self/status", "pseudo-file"]),
    ]
    for args, words in cases:
        refused_without_change(files, args, *words)


def test_empty_arrays_and_zero_sizes(files):
    (files / "empty.npy").write_bytes(b"")
    np.save(files / "t0.npy", np.zeros((0, 2, 2), np.uint8))
    np.save(files / "k0.npy", np.zeros((0, 2, 2), np.float32))
    np.savez(files / "k0.npz", words=np.zeros((0, 2, 2), np.uint8), config=np.array(TINY.to_json()))
    np.savez(files / "h0.npz", words=np.zeros((3, 0, 2), np.uint8), config=np.array(TINY.to_json()))
    cases = [
        (golden_args(files, files / "o.npz", stimulus=files / "empty.npy"), ["empty"]),
        (golden_args(files, files / "o.npz", stimulus=files / "t0.npy"), ["T = 0"]),
        (("rtl-sim", "--config", files / "c.json", "--stimulus", files / "t0.npy", "--out", files / "o.npz"),
         ["T = 0"]),
        (("simulate", "--config", "te", "--scene", files / "k0.npy", "--out", files / "o.npz"), ["K = 0"]),
        (("evaluate", "--set", "none", "--scene", files / "k0.npy", "--out", files / "ev"), ["K = 0"]),
        (("reconstruct", "--stream", files / "k0.npz", "--method", "tfp", "--out", files / "o.npy"), ["empty"]),
        (("reconstruct", "--stream", files / "h0.npz", "--method", "tfi", "--out", files / "o.npy"), ["empty"]),
    ]
    for args, words in cases:
        refused_without_change(files, args, *words)


def corrupt_streams(folder):
    """name -> bytes of a broken S.npz: truncated, bad CRC, unknown compression, encrypted, a .npy."""
    good = (folder / "s.npz").read_bytes()
    with zipfile.ZipFile(folder / "s.npz") as archive:
        info = archive.getinfo("words.npy")
    local = info.header_offset
    start = local + 30 + int.from_bytes(good[local + 26:local + 28], "little") + \
        int.from_bytes(good[local + 28:local + 30], "little")
    out = {"truncated": good[:len(good) // 2]}
    crc = bytearray(good)
    crc[start + info.file_size - 1] ^= 0xFF                     # last data byte of 'words.npy'
    out["bad-crc"] = bytes(crc)
    for name, offset_local, offset_central, value in (("compression", 8, 10, 99), ("encrypted", 6, 8, 1)):
        data = bytearray(good)
        for header in (local, *[i for i in range(len(good)) if good.startswith(b"PK\x01\x02", i)]):
            offset = offset_local if header == local else offset_central
            data[header + offset:header + offset + 2] = value.to_bytes(2, "little")
        out[name] = bytes(data)
    np.save(folder / "plain.npy", np.zeros((2, 2, 2), np.uint8))
    out["npy"] = (folder / "plain.npy").read_bytes()
    return out


@pytest.mark.parametrize("kind", ["truncated", "bad-crc", "compression", "encrypted", "npy"])
def test_corrupt_stream_files(files, kind):
    (files / "bad.npz").write_bytes(corrupt_streams(files)[kind])
    refused_without_change(files, ("reconstruct", "--stream", files / "bad.npz", "--method", "tfp",
                                   "--out", files / "o.npy"), "bad.npz")


@pytest.mark.parametrize("args, words", [
    (("reconstruct", "--method", "tfp", "--threads", "0"), ["--threads", "1.."]),
    (("reconstruct", "--method", "tfp", "--threads", str(10 ** 30)), ["--threads"]),
    (("reconstruct", "--method", "tfp", "--threads", "-3"), ["--threads"]),
    (("scene", "--peak", "1e39"), ["peak", "float32"]),
    (("scene", "--peak", "1e-50"), ["peak", "float32"]),
    (("scene", "--peak", "nan"), ["--peak"]),
    (("scene", "--peak", "-1"), ["--peak"]),
    (("scene", "--crop", "8x8"), ["--crop", "--folder"]),
    (("scene", "--downscale", "2"), ["--downscale", "--folder"]),
    (("verilog", "--config", "te", "--height", "100000", "--width", "100000"), ["65536"]),
    (("verilog", "--config", "te", "--height", "257", "--width", "256"), ["65536"]),
    (("evaluate", "--set", "none", "--methods", ""), ["--methods"]),
    (("evaluate", "--set", "none", "--methods", " , "), ["--methods"]),
    (("scene", "--frames", "2", "--height", "8", "--width", "8", "--sources", str(10 ** 11)),
     ["--sources", "memory"]),                                     # (it ran out of memory naming no option)
    (("evaluate", "--set", "none", "--methods", "tfp", "--metrics", "fovvideovdp", "--vdp-frames", "1000"),
     ["--vdp-frames 1000", "scored frame"]),                       # (it was cut to the frames there are)
    (("golden", "--config", "te", "--stimulus"), ["--stimulus", "--help"]),
    (("golden", "--config", "te"), ["required", "--help"]),
    (("simulate", "--seed", "abc"), ["--seed", "--help"]),
    (("simulate", "--config", "te", "--scene", "i.npy", "--out", ".npz"), ["'.npz'", "name before .npz"]),
    (("simulate", "--seed", "1_0"), ["--seed", "invalid int value: '1_0'"]),     # int('1_0') is 10
    (("simulate", "--seed", " 7"), ["--seed", "invalid int value"]),
    (("prove", "--depth", "\u0661"), ["--depth", "invalid int value"]),            # an Arabic-Indic 1
    (("scene", "--peak", "1_0.5"), ["--peak", "invalid float value: '1_0.5'"]),
    (("scene", "--peak", "1e400"), ["--peak", "invalid float value: '1e400'"]),     # (had been "--peak inf")
    (("calibrate", "--dark", "d.npz", "--flat", "f.npz", "--flat-light=-1e999", "--out", "c.npz"),
     ["--flat-light", "invalid float value: '-1e999'"]),
    (("nonsense",), ["nonsense", "--help"]),
    (("simulate", "--config", "ml", "--config=te", "--scene", "i.npy", "--out", "o.npz"),
     ["--config", "more than once"]),
    (("scene", "--frames", "3", "--frames", "4"), ["--frames", "more than once"]),
    (("simulate", "--config", "te", "--conf", "ml", "--scene", "i.npy", "--out", "o.npz"),   # (an abbreviation
     ["--config / --conf", "more than once"]),                                               # argparse takes)
    (("simulate", "--config", "te", "--scene", "i.npy", "--out", "a.npz", "--ou=b.npz"), ["--out / --ou", "more than once"]),
    (("scene", "--folder", "hdr", "--seed", "5"), ["--seed", "built-in scenes only"]),
    (("reconstruct", "--method", "tfp", "--search", "stream"), ["--search", "'tfi' only"]),   # (tfi's default, dropped)
    (("score", "--reference", "i.npy", "--estimate", "i.npy", "--metrics", "psnr_mu,psnr_mu"),   # (one column)
     ["'psnr_mu' is named more than once"]),
    (("evaluate", "--repeats", "101"), ["--repeats 101", "1..100"]),
    (("view", "--frames", "0,0,1", "--each"), ["frame 0", "more than once"]),      # (wrote 2 files, said 3)
    (("view", "--frames", "0,1", "--columns", "3"), ["--columns 3", "at most 2"]),       # (was cut to 2)
    (("scene", "--grayscale", "rec709"), ["--grayscale", "--folder only"]),
    (("train", "--seed", "-1"), ["seed = -1", "0..2^63 - 1"]),
    (("train", "--seed", str(10 ** 23)), ["seed", "0..2^63 - 1"]),
    (("train", "--device", "bogus"), ["device = 'bogus'", "not a usable torch device"]),
    (("train", "--device", "cpu:1"), ["device = 'cpu:1'", "one CPU device"]),       # (torch ignores the index)
    (("reconstruct", "--method", "tfp", "--device", "cpu:7"), ["device = 'cpu:7'", "one CPU device"]),
    (("scene", "--folder", ""), ["--folder '': an empty value"]),           # (read as not given: a built-in scene)
    (("scene", "--crop", ""), ["--crop '': an empty value"]),
    (("evaluate", "--store", ""), ["--store '': an empty value"]),          # (read as no store)
    (("evaluate", "--set", "none", "--ml-count-config", ""), ["--ml-count-config '': an empty value"]),
    (("rtl-sim", "--config", "te", "--stimulus", "e.npy", "--out", "w.npy", "--vcd", ""), ["--vcd '': an empty value"]),
    (("evaluate", "--set", "none", "--methods", "tfp,,tfi"), ["--methods 'tfp,,tfi'", "empty"]),   # (dropped)
    (("evaluate", "--set", "none", "--methods", "tfp,"), ["--methods 'tfp,'", "empty"]),
    (("evaluate", "--set", "none", "--methods", "tfp,tfp"), ["'tfp' is named more than once"]),
    (("score", "--reference", "i.npy", "--estimate", "i.npy", "--metrics", ",psnr_mu"), ["--metrics", "empty"]),
])
def test_argument_errors_are_one_line(files, args, words):
    extra = {"reconstruct": ("--stream", files / "s.npz", "--out", files / "o.npy"),
             "train": ("--out", files / "W.pt", "--steps", 1, "--validate-every", 0),
             "scene": ("--out", files / "o.npy"), "verilog": ("--out", files / "o.v"),
             "evaluate": ("--scene", files / "i.npy", "--out", files / "ev"),
             "view": ("--input", files / "s.npz", "--out", files / ("frames" if "--each" in args else "v.png"))
             }.get(args[0], ())
    result = refused_without_change(files, (*args, *extra), *words)
    assert "usage:" not in result.stderr


def test_reconstruct_refuses_stream_with_zero_height_like_the_others(files):
    np.savez(files / "h0.npz", words=np.zeros((3, 0, 2), np.uint8), config=np.array(TINY.to_json()))
    for method in ("tfp", "tfi"):
        refused_without_change(files, ("reconstruct", "--stream", files / "h0.npz", "--method", method,
                                       "--out", files / "o.npy"), "h0.npz")


# ------------------------------------------------------------------ what still works
def test_pickles_never_loaded(files):
    np.save(files / "obj.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    refused_without_change(files, golden_args(files, files / "o.npz", stimulus=files / "obj.npy"),
                           "obj.npy' holds Python objects (dtype object), not numbers")
    np.savez(files / "obj.npz", words=np.array([None], dtype=object), config=np.array(TINY.to_json()))
    refused_without_change(files, ("reconstruct", "--stream", files / "obj.npz", "--method", "tfp",
                                   "--out", files / "o.npy"), "obj.npz")


def test_an_illegal_word_names_its_stream_file(files):
    with np.load(files / "s.npz") as npz:
        words = npz["words"].copy()
    words[0, 0, 0] = np.iinfo(words.dtype).max               # no word of this configuration
    np.savez(files / "bad.npz", words=words, config=np.array(TINY.to_json()))
    refused_without_change(files, ("reconstruct", "--stream", files / "bad.npz", "--method", "tfp",
                                   "--out", files / "o.npy"), "stream file", "bad.npz", "is not a legal")


def test_a_stream_whose_config_lacks_a_key_is_refused(files):
    """A stream records the full configuration it was made with (SPEC section 6): one missing a key
    is refused naming it, not decoded with that key's default."""
    with np.load(files / "s.npz") as npz:
        words = npz["words"].copy()
    partial = json.loads(TINY.to_json())
    del partial["threshold"]
    np.savez(files / "part.npz", words=words, config=np.array(json.dumps(partial)))
    refused_without_change(files, ("reconstruct", "--stream", files / "part.npz", "--method", "tfp",
                                   "--out", files / "o.npy"), "part.npz", "lacks key 'threshold'")


@pytest.mark.parametrize("text, words", [('{"dsnu": -0.2}', "dsnu = -0.2"),
                                         ('{"dark_current": "eq99"}', "'eq99' unknown")])
def test_noise_file_value_refusals_name_the_file(files, text, words):
    """A value's own check (range, model name) named neither the file nor the flag."""
    (files / "n.json").write_text(text)
    refused_without_change(files, ("simulate", "--config", "te", "--scene", files / "i.npy", "--noise",
                                   files / "n.json", "--out", files / "o.npz"), "sensor noise file", "n.json", words)


def test_noise_file_refuses_a_key_given_twice(files):
    (files / "n.json").write_text('{"prnu": 0.01, "prnu": 0.02}')
    refused_without_change(files, ("simulate", "--config", "te", "--scene", files / "i.npy", "--noise",
                                   files / "n.json", "--out", files / "o.npz"), "n.json", "'prnu' is given twice")


def test_npy_without_its_header_is_named_as_such(files):
    """A file without the .npy magic is said to lack it (numpy alone would call it a pickle)."""
    (files / "x.npy").write_bytes(b"x")
    (files / "zip.npy").write_bytes((files / "s.npz").read_bytes())
    for name, words in (("x.npy", ("no .npy header",)), ("zip.npy", ("holds an archive",))):
        result = refused_without_change(files, golden_args(files, files / "o.npz", stimulus=files / name),
                                        name, *words)
        assert "pickle" not in result.stderr
        refused_without_change(files, ("view", "--input", files / name, "--out", files / "o.png"), name, *words)


def test_view_and_the_light_front_end_never_overwrite_an_input(files):
    """view checks its outputs against its inputs (same path, a link, a frame file of --each), and
    simulate / stimulus count --noise among their inputs."""
    (files / "i.png").write_bytes((files / "i.npy").read_bytes())
    os.symlink(files / "i.npy", files / "link.png")
    (files / "d").mkdir()
    os.symlink(files / "i.npy", files / "d" / "frame_0001.png")
    for args, words in ((("--input", files / "i.png", "--out", files / "i.png"), ("--input",)),
                        (("--input", files / "i.npy", "--out", files / "link.png"), ("--input",)),
                        (("--input", files / "i.npy", "--out", files / "d", "--each"), ("frame 1", "--input")),
                        (("--input", files / "i.npy", "--out", files / "i.npy"), ("--input",))):  # (was: "a .png")
        refused_without_change(files, ("view", *args), *words, "refusing to overwrite an input")
    (files / "hdr").mkdir()
    write_hdr(files / "hdr" / "f0.hdr", np.ones((4, 4, 3), np.float32))             # (was: "the .npy format")
    refused_without_change(files, ("scene", "--folder", files / "hdr", "--out", files / "hdr" / "f0.hdr"),
                           "a frame of --folder", "refusing to overwrite an input")
    (files / "n.npz").write_text('{"prnu": 0.01}')
    for command in ("simulate", "stimulus"):
        refused_without_change(files, (command, "--config", "te", "--scene", files / "i.npy", "--noise",
                                       files / "n.npz", "--out", files / "n.npz"), "--noise", "refusing")


def test_big_endian_and_fortran_inputs_equal_native(files):
    native = np.load(files / "e.npy")
    np.save(files / "be.npy", native.astype(">u2"))
    np.save(files / "f.npy", np.asfortranarray(native.astype(np.int32)))
    for name in ("be", "f"):
        assert run_tespike(*golden_args(files, files / f"{name}.npz",
                                        stimulus=files / f"{name}.npy")).returncode == 0
        assert (files / f"{name}.npz").read_bytes() == (files / "s.npz").read_bytes()
    with np.load(files / "s.npz") as npz:
        words = npz["words"]
    np.savez(files / "sbe.npz", words=np.asfortranarray(words.astype(">u2")), config=np.array(TINY.to_json()))
    for stream in ("s", "sbe"):
        assert run_tespike("reconstruct", "--stream", files / f"{stream}.npz", "--method", "tfi",
                           "--out", files / f"r_{stream}.npy").returncode == 0
    assert (files / "r_s.npy").read_bytes() == (files / "r_sbe.npy").read_bytes()


def test_equal_seeds_give_byte_identical_outputs(files):
    for name in ("a", "b"):
        assert run_tespike("simulate", "--config", "te", "--scene", files / "i.npy", "--seed", 5,
                           "--out", files / f"{name}.npz").returncode == 0
    assert (files / "a.npz").read_bytes() == (files / "b.npz").read_bytes()


# ------------------------------------------------------------------ the command line itself
def test_version_help_quiet_and_the_wrote_line(files):
    result = run_tespike("--version")
    assert result.returncode == 0 and result.stdout.startswith("tespike ")
    result = run_tespike()
    assert result.returncode == 0 and "COMMAND" in result.stdout and result.stderr == ""
    result = run_tespike(*golden_args(files, files / "o.npz"))
    assert result.returncode == 0 and result.stderr == ""
    assert result.stdout.strip().splitlines() == [f"wrote {files / 'o.npz'}: 5 readouts of 3 x 4 TE words"]
    result = run_tespike("reconstruct", "--stream", files / "s.npz", "--method", "tfp", "--out", files / "r.npy")
    assert result.returncode == 0 and len(result.stdout.splitlines()) == 1 and "r.npy" in result.stdout
    for args in (golden_args(files, files / "o.npz"),
                 ("reconstruct", "--stream", files / "s.npz", "--method", "tfp", "--out", files / "r.npy"),
                 ("simulate", "--config", "te", "--scene", files / "i.npy", "--out", files / "o.npz", "--seed", 1),
                 ("scene", "--frames", 2, "--height", 8, "--width", 8, "--out", files / "sc.npy")):
        result = run_tespike(*args, "--quiet")
        assert result.returncode == 0 and result.stdout == "" and result.stderr == "", result


def test_progress_bars_only_on_a_terminal_or_when_asked(files):
    np.save(files / "long.npy", np.ones((TINY.clocks_per_readout * 400, 3, 4), np.uint8))
    args = golden_args(files, files / "o.npz", stimulus=files / "long.npy") + ("--chunk-elements", 96)
    result = run_tespike(*args)
    assert result.returncode == 0 and result.stderr == ""             # stderr is a pipe here
    result = run_tespike(*args, "--progress", "on")
    assert result.returncode == 0 and "golden" in result.stderr


def test_stimulus_follows_the_progress_flag(files, monkeypatch, capsys):
    """``stimulus`` draws its bar as ``--progress`` says (it read the terminal alone before)."""
    import tqdm

    from tespike.cosim import cli

    bars = []
    monkeypatch.setattr(tqdm, "tqdm", lambda iterable, **kw: bars.append(kw["desc"]) or iterable)
    for choice, expected in (("on", ["stimulus"]), ("off", []), ("auto", [])):   # (stderr is not a terminal)
        bars.clear()
        assert cli.main(["stimulus", "--config", "te", "--scene", str(files / "i.npy"), "--seed", "1",
                         "--out", str(files / f"e_{choice}.npy"), "--quiet", "--progress", choice]) == 0
        assert bars == expected, choice
    capsys.readouterr()


def test_refusal_after_a_warning_is_still_one_line(monkeypatch, capsys):
    import warnings
    import types

    from tespike.cosim import cli

    def run(args):
        warnings.warn("divide by zero", RuntimeWarning)
        raise InputError("shape (2, 3) must be (K, H, W)")
    fake = types.SimpleNamespace(HELP="fake", add_arguments=lambda parser: None, run=run)
    monkeypatch.setattr(cli, "_available_commands", lambda only=None: {"fake": fake})
    assert cli.main(["fake"]) == cli.EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["tespike fake: error: shape (2, 3) must be (K, H, W)"]

    def run_oom(args):
        raise RuntimeError("[enforce fail at alloc_cpu.cpp:117] DefaultCPUAllocator: can't allocate memory: "
                           "you tried to allocate 21474836480 bytes.")
    fake.run = run_oom
    assert cli.main(["fake"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "out of memory" in err


# ------------------------------------------------------------------ bounded memory
def test_metrics_in_small_bands_equal_whole_frames(monkeypatch, rng):
    from tespike.recon import metrics
    gt = rng.uniform(0.01, 1, size=(3, 23, 19))
    pred = gt * rng.uniform(0.8, 1.2, size=gt.shape)
    per_frame = {"psnr_mu": metrics.psnr_mu, "ssim_mu": metrics.ssim_mu, "psnr_pu21": metrics.psnr_pu21}
    whole = {name: fn(pred, gt) for name, fn in per_frame.items()}
    whole_peak = metrics.ssim_mu(pred, gt, peak=2.0)
    monkeypatch.setattr(metrics, "CHUNK_PIXELS", 40)          # bands of 2 rows, one frame at a time
    for name, fn in per_frame.items():
        assert np.allclose(fn(pred, gt), whole[name], rtol=1e-12, atol=1e-14), name
    assert np.allclose(metrics.ssim_mu(pred, gt, peak=2.0), whole_peak, rtol=1e-12)
    assert np.allclose(metrics.ssim_mu(pred[1], gt[1]), whole["ssim_mu"][1], rtol=1e-12)


def test_evaluate_refuses_up_front_when_memory_is_short(files, monkeypatch):
    from tespike.golden import resources
    from tespike.recon.evaluate import evaluate
    monkeypatch.setattr(resources, "available_memory", lambda: 1 << 20)
    with pytest.raises(InputError, match=r"needs about .* of memory, but only 1\.0 MB is available"):
        evaluate([("x", np.ones((4, 16, 16)))], lambda config, light, rng: None, methods=["tfp"],
                 progress=False)


def test_reconstruct_streams_words_and_images_through_memory_maps(files):
    from tespike.golden.io import load_stream
    from tespike.recon.methods import reconstruct
    words, config = load_stream(files / "s.npz", memory_map=True)
    assert isinstance(words, np.memmap)
    assert run_tespike("reconstruct", "--stream", files / "s.npz", "--method", "tfi",
                       "--out", files / "r.npy").returncode == 0
    assert np.array_equal(np.load(files / "r.npy"), reconstruct(np.array(words), config, "tfi"))


# ------------------------------------------------------------------ issue 20: defaults, room, full disks
def run_in_process(capsys, *args):
    from tespike.cosim.cli import main
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_demo_replaces_only_a_previous_demos_folder(tmp_path):
    """An evaluation's results folder holds names a demo also writes (table.md, strips/): the demo
    replaced it whole, deleting its strips; a strip no demo writes is now refused, a demo's kept."""
    from tespike.cosim.demo import DEMO_SCENE, check_demo_folder
    evaluation = tmp_path / "eval"
    (evaluation / "strips").mkdir(parents=True)
    for name in ("table.md", "table.csv", "results.csv", "strips/video.png"):
        (evaluation / name).write_text("x")
    with pytest.raises(InputError, match="holds 'strips/video.png', which no demo writes.*new or empty folder"):
        check_demo_folder(evaluation)
    (evaluation / "strips" / "video.png").rename(evaluation / "strips" / f"{DEMO_SCENE}.png")
    check_demo_folder(evaluation)                                       # a previous demo's names: replaced
    check_demo_folder(tmp_path / "new")                                 # new
    (tmp_path / "empty").mkdir()
    check_demo_folder(tmp_path / "empty")                               # empty


def test_demo_defaults_follow_the_flags_they_depend_on(tmp_path):
    """--frames 12 alone is a valid demo (--rtl-readouts follows it); an explicit conflict is refused."""
    from tespike.cosim.demo import check_options
    common = dict(seed=0, backend="amaranth", repeats=1, window=9, sensors=("te",))
    assert check_options(tmp_path / "d", frames=12, height=96, width=128, crop=None, rtl_readouts=None,
                         **common) == (16, 12)
    assert check_options(tmp_path / "d", frames=40, height=12, width=128, crop=None, rtl_readouts=None,
                         **common) == (12, 16)
    with pytest.raises(InputError, match="--height 10"):
        check_options(tmp_path / "d", frames=4, height=10, width=128, crop=None, rtl_readouts=None, **common)
    result = run_tespike("demo", "--frames", 12, "--rtl-readouts", 13, "--out", tmp_path / "d")
    assert_refused(result, "--rtl-readouts 13", "12 frames")
    assert result.stdout == "" and os.listdir(tmp_path) == []


@pytest.mark.parametrize("args, words", [
    (("--frames", 10000000), ["--frames 10000000", "limit"]),
    (("--repeats", 10 ** 9), ["--repeats"]),
    (("--out", "missing/d"), ["does not exist"]),
])
def test_demo_refuses_what_cannot_run_before_any_work(tmp_path, args, words):
    os.chdir(tmp_path)
    result = run_tespike("demo", *args)
    assert_refused(result, *words)
    assert result.stdout == "" and os.listdir(tmp_path) == []


def test_demo_refuses_up_front_when_memory_or_disk_is_short(tmp_path, capsys, monkeypatch):
    import shutil as shutil_module

    from tespike.golden import resources
    monkeypatch.setattr(resources, "available_memory", lambda: 1 << 20)
    code, out, err = run_in_process(capsys, "demo", "--frames", 4, "--out", tmp_path / "d")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "needs about" in err and "of memory" in err and not (tmp_path / "d").exists()
    monkeypatch.setattr(resources, "available_memory", lambda: None)
    usage = shutil_module.disk_usage(tmp_path)
    monkeypatch.setattr(shutil_module, "disk_usage", lambda path: usage._replace(free=1000))
    code, out, err = run_in_process(capsys, "demo", "--frames", 4, "--out", tmp_path / "d")
    assert code == 2 and out == "" and "but only 1000 B is free on its file system" in err
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("command", ["simulate", "golden", "stimulus", "reconstruct", "rtl-sim", "scene"])
def test_commands_refuse_outputs_the_disk_cannot_hold(files, capsys, monkeypatch, command):
    import shutil as shutil_module
    usage = shutil_module.disk_usage(files)
    monkeypatch.setattr(shutil_module, "disk_usage", lambda path: usage._replace(free=10))
    args = {"simulate": ("--config", files / "c.json", "--scene", files / "i.npy"),
            "golden": ("--config", files / "c.json", "--stimulus", files / "e.npy"),
            "stimulus": ("--config", files / "c.json", "--scene", files / "i.npy"),
            "reconstruct": ("--stream", files / "s.npz", "--method", "tfp"),
            "rtl-sim": ("--config", files / "c.json", "--stimulus", files / "e.npy"),
            "scene": ("--name", "default", "--frames", 2, "--height", 12, "--width", 16)}[command]
    before = snapshot(files)
    out_name = "o.npz" if command in ("simulate", "golden", "rtl-sim") else "o.npy"
    code, out, err = run_in_process(capsys, command, *args, "--out", files / out_name)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert "but only 10 B is free on its file system" in err and out_name in err
    assert snapshot(files) == before


def test_memory_mapped_output_on_a_full_disk_is_one_line_and_leaves_nothing(files, capsys, monkeypatch):
    """The reservation fails (ENOSPC) before any write through the map (which would die of SIGBUS)."""
    import errno

    from tespike.cosim import headroom as room

    def full(fd, offset, length):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(os, "posix_fallocate", full)
    monkeypatch.setattr(room, "require_disk", lambda *args, **kwargs: None)     # past the estimate
    before = snapshot(files)
    for args in (("reconstruct", "--stream", files / "s.npz", "--method", "tfi"),
                 ("stimulus", "--config", files / "c.json", "--scene", files / "i.npy")):
        code, out, err = run_in_process(capsys, *args, "--out", files / "o.npy")
        assert code == 2 and out == "" and err.strip().splitlines() == [
            f"tespike {args[0]}: error: cannot write {str(files / 'o.npy')!r}: No space left on device"]
        assert snapshot(files) == before


def test_reconstruct_into_a_small_tmpfs(files, capsys, monkeypatch):
    """A real full file system: the up-front check refuses, and past it (the output's old copy
    takes the room) the reservation does; never SIGBUS, never a .part left."""
    with small_tmpfs(files / "small", "1M") as mount:
        light = np.random.default_rng(1).uniform(0, 1, (20, 96, 128)).astype(np.float32)
        np.save(files / "big.npy", light)
        assert run_tespike("simulate", "--config", "te", "--scene", files / "big.npy", "--out",
                           files / "big.npz").returncode == 0
        (mount / "filler").write_bytes(b"\0" * (600 << 10))
        result = run_tespike("reconstruct", "--stream", files / "big.npz", "--method", "tfp",
                             "--out", mount / "r.npy")
        assert_refused(result, str(mount / "r.npy"), "is free on its file system")
        assert sorted(os.listdir(mount)) == ["filler"]
        from tespike.cosim import headroom as room          # past the estimate: the reservation refuses (no SIGBUS)
        monkeypatch.setattr(room, "require_disk", lambda *args, **kwargs: None)
        code, out, err = run_in_process(capsys, "reconstruct", "--stream", files / "big.npz", "--method",
                                        "tfp", "--out", mount / "r.npy")
        assert code == 2 and out == "" and err.strip().splitlines() == [
            f"tespike reconstruct: error: cannot write {str(mount / 'r.npy')!r}: No space left on device"]
        assert sorted(os.listdir(mount)) == ["filler"]


def test_stimulus_never_overwrites_its_scene(files):
    refused_without_change(files, ("stimulus", "--config", files / "c.json", "--scene", files / "i.npy",
                                   "--out", files / "i.npy"), "--scene", "same file")


def test_generated_arrays_and_their_stimuli_are_bounded_up_front(files):
    refused_without_change(files, ("cocotb", "--config", "te", "--height", 100000, "--width", 100000),
                           "at most 65536")
    refused_without_change(files, ("cocotb", "--config", "te", "--height", 2, "--width", 2,
                                   "--readouts", 10 ** 12), "of memory")
    refused_without_change(files, ("view", "--input", "/dev/zero", "--out", files / "v.png"),
                           "character device")


def test_dataset_checks_its_options_before_printing_or_creating_the_store(files):
    for args, word in ((("--chunk-frames", 0), "--chunk-frames"), (("--frames", 10 ** 8), "limit"),
                       (("--seed", -1), "--seed"),
                       # Zarr allocates a chunk whole: 'out of memory' after the start line, no option named
                       (("--chunk-frames", 10 ** 11), "--chunk-frames 100000000000")):
        result = refused_without_change(files, ("dataset", "--config", "te", "--scene", "default",
                                                "--out", files / "store", *args), word)
        assert result.stdout == ""
    refused_without_change(files, ("dataset", "--config", "te", "--scene", "default", "--frames", 2,
                                   "--out", files / "c.json"), "not a directory")


def test_train_refuses_before_making_its_run_folder(files):
    common = ("train", "--config", "te", "--out", files / "w.pt", "--steps", 1)
    refused_without_change(files, (*common, "--crop", 100000), "crop = 100000", "engine's clips")
    refused_without_change(files, (*common, "--crop", 36), "crop = 36", "pyramid factor")
    refused_without_change(files, (*common, "--pool", 0), "pool = 0")
    refused_without_change(files, (*common, "--workers", -1), "workers = -1")
    refused_without_change(files, (*common, "--method", "nope"), "unknown learned method")


def test_an_unknown_flag_is_named_by_its_sub_command(capsys):
    """One line naming the flag and the sub-command whose --help lists the right ones."""
    from tespike.cosim.cli import main
    with pytest.raises(SystemExit) as stop:
        main(["train", "--out", "w.pt", "--sequences", "2"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err == ("tespike train: error: unrecognized arguments: --sequences 2 "
                   "(see tespike train --help)\n")


def test_the_version_is_looked_up_only_when_asked(monkeypatch, capsys):
    """Building the parser (every run) skips the package-metadata lookup (about 30 ms)."""
    import tespike.cosim.cli as cli

    def lookup():
        raise AssertionError("version looked up")
    monkeypatch.setattr(cli, "version", lookup)
    cli.build_parser("simulate")
    cli.build_parser()
    monkeypatch.setattr(cli, "version", lambda: "9.9")
    with pytest.raises(SystemExit) as stop:
        cli.main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out == "tespike 9.9\n"
    for argv in (["--version", "extra"], ["--vers", "-q"]):      # nothing after it is dropped silently
        with pytest.raises(SystemExit) as stop:
            cli.main(argv)
        assert stop.value.code == 2 and "--version takes nothing else" in capsys.readouterr().err


def test_scene_and_train_never_write_over_a_frame_they_read(tmp_path):
    """scene --folder and train --hdr / --panoramas compared --out with nothing they read: each wrote its
    output over one of the folder's frames (rc 0); train's run folder files likewise over an input there."""
    from tespike.recon.scenes import write_hdr
    for folder in ("video", "hdr/seq", "pano"):
        (tmp_path / folder).mkdir(parents=True)
    for k in range(2):
        write_hdr(tmp_path / f"video/{k:03d}.hdr", np.full((32, 48, 3), 0.01 + k, np.float32))
        write_hdr(tmp_path / f"hdr/seq/{k:03d}.hdr", np.full((64, 64, 3), 0.02 + k, np.float32))
    write_hdr(tmp_path / "pano/p.hdr", np.full((64, 128, 3), 0.05, np.float32))
    (tmp_path / "link.npy").symlink_to(tmp_path / "video/001.hdr")
    (tmp_path / "run.run").mkdir()
    (tmp_path / "run.run/log.csv").write_text('{"mode": "te"}')
    (tmp_path / "frame.npy").symlink_to(tmp_path / "video/000.hdr")
    (tmp_path / "frame.pt").symlink_to(tmp_path / "hdr/seq/000.hdr")
    (tmp_path / "pano.pt").symlink_to(tmp_path / "pano/p.hdr")
    refused_without_change(tmp_path, ("scene", "--folder", tmp_path / "video", "--out", tmp_path / "frame.npy"),
                           "a frame of --folder", "refusing to overwrite an input")
    refused_without_change(tmp_path, ("scene", "--folder", tmp_path / "video", "--out", tmp_path / "video/000.hdr"),
                           "a frame of --folder", "refusing to overwrite an input")   # (before its format)
    refused_without_change(tmp_path, ("scene", "--folder", tmp_path / "video", "--out", tmp_path / "link.npy"),
                           "a frame of --folder", "001.hdr")
    budget = ("--steps", 1, "--crop", 32, "--batch", 1, "--workers", 0, "--pool", 1)
    refused_without_change(tmp_path, ("train", "--config", "te", "--hdr", tmp_path / "hdr/seq",
                                      "--out", tmp_path / "frame.pt", *budget), "a frame of --hdr")
    refused_without_change(tmp_path, ("train", "--config", "te", "--panoramas", tmp_path / "pano",
                                      "--out", tmp_path / "pano.pt", *budget), "a panorama of --panoramas")
    refused_without_change(tmp_path, ("train", "--config", tmp_path / "run.run/log.csv", "--out", tmp_path / "run.pt",
                                      *budget), "the run folder's log.csv", "--config")


@pytest.mark.parametrize("shape", ["(2, -8, 8)", "(-2, 8, 8)"])
def test_npy_header_with_a_negative_dimension_is_named(files, shape):
    """A header shape with an odd count of negative dimensions passed numpy's own check and failed
    memory-mapping it with a traceback (OverflowError) in every reader that maps its file."""
    header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}"
    header = header + " " * (118 - len(header)) + "\n"
    (files / "neg.npy").write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode()
                                    + b"\0" * 512)
    refused_without_change(files, ("simulate", "--config", "te", "--scene", files / "neg.npy",
                                   "--out", files / "o.npz"), "scene file", "neg.npy")
    refused_without_change(files, ("golden", "--config", files / "c.json", "--stimulus", files / "neg.npy",
                                   "--out", files / "o.npz"), "stimulus file", "neg.npy")


def test_npy_with_bytes_after_its_array_is_named(files):
    """np.load reads an .npy array and ignores whatever follows it: a file with bytes after its
    array (two arrays concatenated, a corrupt write) was simulated as if whole."""
    for name in ("i.npy", "e.npy"):
        with open(files / name, "ab") as handle:
            handle.write(b"\0" * 7)
    refused_without_change(files, ("simulate", "--config", "te", "--scene", files / "i.npy",
                                   "--out", files / "o.npz"), "scene file", "i.npy", "7 bytes after")
    refused_without_change(files, ("golden", "--config", files / "c.json", "--stimulus", files / "e.npy",
                                   "--out", files / "o.npz"), "stimulus file", "e.npy", "7 bytes after")


def test_output_path_with_a_control_character_is_refused(files):
    """The success line names the outputs: a newline in --out split it in two (a reader of the line
    took half a path); a control character in an output path is refused, quoted on one line."""
    result = refused_without_change(files, golden_args(files, files / "a\nb.npz"), "control character", "'\\n'")
    assert len(result.stderr.strip().splitlines()) == 1
    refused_without_change(files, ("demo", "--out", files / "d\tx"), "control character", "'\\t'")
    # a right-to-left override printed the success line reversed from it on; a C1 control is one too
    refused_without_change(files, golden_args(files, files / "\u202eb.npz"), "control character", "'\\u202e'")
    refused_without_change(files, golden_args(files, files / "\x85b.npz"), "control character", "'\\x85'")


def test_a_read_only_output_file_is_refused_even_for_root(files):
    """A file whose mode grants no one write access is refused for every user: root's os.access
    said yes and the file was replaced."""
    (files / "kept.npz").write_bytes(b"mine")
    os.chmod(files / "kept.npz", 0o444)
    refused_without_change(files, golden_args(files, files / "kept.npz"), "kept.npz", "read-only")
    assert (files / "kept.npz").read_bytes() == b"mine"


def test_scene_list_refuses_the_options_it_would_ignore(files):
    """scene --list printed the list and ignored --out (and every other option) without a word."""
    refused_without_change(files, ("scene", "--list", "--out", files / "i2.npy"), "--list", "--out given")
    refused_without_change(files, ("scene", "--list", "--downscale", "2"), "--downscale given")
    listed = run_tespike("scene", "--list")
    assert listed.returncode == 0 and listed.stdout.startswith("default")


@pytest.mark.parametrize("keep", [0.5, 0.99])
def test_a_npy_input_cut_short_says_so(tmp_path, keep):
    """A .npy file cut short was refused in numpy's words ("mmap length is greater than file
    size", "cannot reshape array"); it says now how many of the bytes its header promises it holds."""
    np.save(tmp_path / "i.npy", np.zeros((4, 8, 8), np.float32))
    whole = (tmp_path / "i.npy").read_bytes()
    (tmp_path / "i.npy").write_bytes(whole[:int(len(whole) * keep)])
    for command, out in ((("simulate", "--config", "te", "--scene"), "o.npz"), (("view", "--input"), "o.png")):
        done = run_tespike(*command, tmp_path / "i.npy", "--out", tmp_path / out)
        assert_refused(done, f"'{tmp_path / 'i.npy'}' is cut short: {int(len(whole) * keep)} of the "
                             f"{len(whole)} bytes its header promises (float32 (4, 8, 8))")


def test_progress_is_a_flag_of_the_commands_that_draw_progress_only():
    """A command that draws no progress refused --progress as unknown; one that does takes it
    (eight commands took it and ignored it, and scene --list took -q and printed its list)."""
    from tespike.cosim.cli import _available_commands, build_parser
    for name, module in _available_commands().items():
        flags = build_parser(name)._subparsers._group_actions[0].choices[name]._option_string_actions
        assert ("--progress" in flags) == bool(getattr(module, "PROGRESS", False)), name
        if getattr(module, "PROGRESS", False):
            assert "progress" in Path(module.__file__).read_text().replace("PROGRESS = True", ""), name
    assert_refused(run_tespike("score", "--estimate", "x.npy", "--reference", "x.npy", "--progress", "on"),
                   "unrecognized arguments: --progress")
    assert_refused(run_tespike("scene", "--list", "-q"), "--list", "--quiet given")


def test_the_demo_and_dataset_library_refuse_sizes_runners_and_sources_that_are_none(tmp_path):
    """run_demo's crop of 11.5 passed the checks and failed inside the RTL crop, a seed of 1.5 or True
    and repeats of 2.5 passed; build_dataset with a run of None made the store and then failed with a
    TypeError, and a text where the sources belong was an AttributeError."""
    from tespike.cosim.dataset.build import build_dataset, scene_sources
    from tespike.cosim.demo import check_options
    from tespike.golden.config import SensorConfig
    from tespike.golden.errors import InputError
    common = dict(frames=24, height=64, width=64, seed=0, crop=None, rtl_readouts=None, backend="amaranth",
                  repeats=3, window=9, sensors=("te",))
    for key, value, low in (("crop", 11.5, 1), ("rtl_readouts", 1.5, 1), ("repeats", 2.5, 1), ("repeats", True, 1),
                            ("seed", 1.5, 0), ("seed", None, 0), ("crop", "20", 1)):
        flag = "--" + key.replace("_", "-")
        with pytest.raises(InputError, match=f"^{flag} {value!r}: must be an integer >= {low}$"):
            check_options(tmp_path / "d", **{**common, key: value})
    url = tmp_path / "s.zarr"
    with pytest.raises(InputError, match="^run: must run the build's tasks"):
        build_dataset(url, scene_sources(["sun"], 2, 8, 8), {"te": SensorConfig()}, 0, None)
    with pytest.raises(InputError, match=r"^sources: must be a sequence of Source"):
        build_dataset(url, "abc", {"te": SensorConfig()}, 0, lambda tasks: tasks)
    assert not url.exists()
