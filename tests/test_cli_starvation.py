"""A command starved of memory, file handles or disk ends in one line naming the resource and
the cause (issue 28, item 6): no traceback, no process left, nothing half-written.
(``benchmarks/fault_sweep.py --only starve`` starves every long command at many levels.)
"""

import os
import resource
import signal
import subprocess
import sys

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tests.cli import ROOT, assert_refused
from tests.test_cli_clean_endings import run_here
from tests.test_cli_hardening import small_tmpfs


def run_limited(code: str, limits: dict, timeout: float = 120, env: dict | None = None) -> subprocess.CompletedProcess:
    """``python -c code`` (this checkout's tespike) under the resource ``limits``, SIGXFSZ ignored
    as a starved shell's command would have it (a write past RLIMIT_FSIZE then fails with EFBIG);
    ``env``: variables to set besides (None: to unset; a command run in this process, as
    ``run_here`` runs them, set ``OPENBLAS_NUM_THREADS`` here)."""
    def starve():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        for which, value in limits.items():
            resource.setrlimit(which, (value, value))
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **(env or {}))
    env = {name: value for name, value in env.items() if value is not None}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env,
                          preexec_fn=starve, timeout=timeout)


def start_address_space(blas_threads: int | None = 1) -> int:
    """Bytes of address space a process that has imported the command takes here, with numpy's
    OpenBLAS on ``blas_threads`` threads (None: its default, one a core, each reserving about
    40 MB): the command starts one under an address-space limit (``tespike.entry``)."""
    code = ("import tespike.cosim.cli\n"
            "print([l for l in open('/proc/self/status') if l.startswith('VmPeak')][0].split()[1])")
    done = run_limited(code, {}, env={"OPENBLAS_NUM_THREADS": None if blas_threads is None else str(blas_threads)})
    assert done.returncode == 0, done.stderr
    return int(done.stdout) * 1024


ENTRY = "import sys; sys.argv = ['tespike', *{args!r}]; from tespike.entry import main; sys.exit(main())"


def test_an_address_space_too_small_to_start_is_one_line():
    """Below what numpy needs to load, the start was numpy's 40-line ImportError, OpenBLAS's own
    lines and exit from C, or a MemoryError traceback, depending on the limit."""
    need = start_address_space()
    for share in (0.3, 0.6, 0.9):
        limit = int(need * share)
        done = run_limited(ENTRY.format(args=["scene", "--list"]), {resource.RLIMIT_AS: limit})
        assert_refused(done, "tespike: error: out of memory: Python and numpy cannot start",
                       f"address-space limit (ulimit -v) of {limit >> 20} MB")
        assert done.returncode == 1 and done.stdout == ""
    done = run_limited(ENTRY.format(args=["scene", "--list"]), {resource.RLIMIT_AS: need + (64 << 20)})
    assert done.returncode == 0 and "default" in done.stdout, done.stderr      # room to start: it starts


def test_under_a_limit_the_command_starts_in_the_room_one_blas_thread_needs():
    """Numpy's OpenBLAS reserved about 40 MB a core at import: near that start's size a failed
    reservation hung the start, killed it with SIGSEGV, or left CPython's SystemError traceback
    ("error return without exception set"). Under a limit the command starts one BLAS thread."""
    one, default = start_address_space(1), start_address_space(None)
    from tespike.entry import START_MARGIN
    limit = (one + START_MARGIN + default) // 2     # (room for the start's first arrays, below the default's)
    if limit - one < START_MARGIN + (2 << 20) or limit >= default:
        pytest.skip("one BLAS thread takes no less room here (one core)")
    done = run_limited(ENTRY.format(args=["scene", "--list"]), {resource.RLIMIT_AS: limit})
    assert done.returncode == 0 and "default" in done.stdout, done.stderr
    done = run_limited(ENTRY.format(args=["scene", "--list"]), {resource.RLIMIT_AS: limit},
                       env={"OPENBLAS_NUM_THREADS": str(os.cpu_count())})   # the user's own count is kept
    assert_refused(done, "cannot start")


def test_a_command_runs_numpy_s_blas_on_one_thread_unless_the_user_chose_a_count():
    """OpenBLAS's threads spin on the other cores after numpy's import: 9 % of a dim pan's
    ``simulate`` wall time (``benchmarks/bench_startup.py``). A command starts it on one
    thread, with or without a limit; a count the user set is kept."""
    if (os.cpu_count() or 1) < 2:
        pytest.skip("OpenBLAS starts no thread of its own on one core")
    code = (ENTRY.format(args=["scene", "--list"]).replace("sys.exit(main())", "main()")
            + "; print(open('/proc/self/status').read().split('Threads:')[1].split()[0])")
    threads = []
    for count in (None, 2):
        done = run_limited(code, {}, env={"OPENBLAS_NUM_THREADS": None if count is None else str(count)})
        assert done.returncode == 0, done.stderr
        threads.append(int(done.stdout.split()[-1]))
    assert threads == [1, 2]


def test_a_trial_start_that_crashes_is_out_of_memory(monkeypatch):
    """The trial start in a child was read as short of memory only where its stderr said so: one killed
    by SIGSEGV, or ending in CPython's SystemError (a C extension's failed allocation), let the command
    start and meet the same end itself, in a traceback or silently."""
    import tespike.entry as entry
    monkeypatch.setattr(entry, "_address_space_limit", lambda: 200 << 20)
    for code, stderr, starved in ((-11, "", True), (1, "SystemError: error return without exception set", True),
                                  (1, "MemoryError", True), (0, "", False),
                                  (1, "ModuleNotFoundError: No module named 'tespike'", False)):
        done = subprocess.CompletedProcess([], code, "", stderr)
        monkeypatch.setattr(subprocess, "run", lambda *args, done=done, **kwargs: done)
        refusal = entry._address_space_refusal()
        assert (refusal is not None) == starved, (code, stderr)
        assert refusal is None or refusal.endswith("cannot start within the address-space limit (ulimit -v) of 200 MB")


def test_torch_without_room_is_out_of_memory_in_one_line(tmp_path):
    """Room for numpy but not for torch: ``reconstruct --method net`` printed the ImportError's traceback
    ("libtorch_cpu.so: failed to map segment from shared object"), or, with a little more room, died of
    SIGABRT (torch's import throws std::bad_alloc from C++). Torch is now tried in a child first."""
    import numpy as np
    np.save(tmp_path / "e.npy", np.full((240 * 3, 4, 4), 2, np.uint8))
    limit = start_address_space() + (80 << 20)
    args = ["golden", "--config", "te", "--stimulus", str(tmp_path / "e.npy"), "--out", str(tmp_path / "s.npz"), "-q"]
    assert run_limited(ENTRY.format(args=args), {resource.RLIMIT_AS: limit}).returncode == 0
    args = ["reconstruct", "--stream", str(tmp_path / "s.npz"), "--method", "net", "--out", str(tmp_path / "r.npy")]
    done = run_limited(ENTRY.format(args=args), {resource.RLIMIT_AS: limit})
    assert_refused(done, "tespike reconstruct: error: out of memory within the address-space limit",
                   "torch cannot be loaded: it does not fit in")
    assert not (tmp_path / "r.npy").exists() and not [p for p in os.listdir(tmp_path) if p.endswith(".part")]


@pytest.mark.parametrize("words", ["could not create a primitive", "could not execute a primitive"])
def test_onednn_failing_under_an_address_space_limit_is_out_of_memory(capsys, monkeypatch, words):
    """oneDNN's words when it could not allocate (a convolution's primitive made, or run: train at
    85 % of its peak, during the backward pass) are out of memory under a limit, a bug otherwise."""
    import tespike.cosim.commands.scene_cmd as scene_cmd
    import tespike.golden.resources as resources

    def starved(args):
        raise RuntimeError(words)
    monkeypatch.setattr(scene_cmd, "run", starved)
    monkeypatch.setattr(resources, "address_space_limit", lambda: 900 << 20)
    assert_refused(run_here(capsys, "scene", "--list"), "tespike scene: error: out of memory within the "
                   "address-space limit (ulimit -v) of 900 MB", words)
    monkeypatch.setattr(resources, "address_space_limit", lambda: None)
    with pytest.raises(RuntimeError, match=words):
        run_here(capsys, "scene", "--list")


def test_only_an_import_error_about_memory_is_read_as_out_of_memory(capsys, monkeypatch):
    """The out-of-memory reading must not hide a genuine import bug (a missing module stays a traceback)."""
    import tespike.cosim.commands.scene_cmd as scene_cmd

    def unmappable(args):
        raise ImportError("libtorch_cpu.so: failed to map segment from shared object")
    monkeypatch.setattr(scene_cmd, "run", unmappable)
    assert_refused(run_here(capsys, "scene", "--list"), "tespike scene: error: out of memory", "failed to map")

    def missing(args):
        raise ImportError("No module named 'tespike.golden.nothing'")
    monkeypatch.setattr(scene_cmd, "run", missing)
    with pytest.raises(ImportError, match="nothing"):
        run_here(capsys, "scene", "--list")


def test_a_cluster_the_open_file_limit_cannot_hold_is_refused_before_it_starts(tmp_path):
    """With ``ulimit -n 12`` the local cluster's start hung for ever (its process then outlived the
    command); with 20 or 32 it said "cannot start ... (exit status 1)", naming no cause."""
    code = ("import sys; sys.argv = ['tespike', 'dataset', '--scene', 'sun', '--frames', '2', '--height', '8', "
            f"'--width', '8', '--config', 'te', '--workers', '2', '--out', {str(tmp_path / 'd.zarr')!r}]\n"
            "from tespike.entry import main; sys.exit(main())")
    for handles in (12, 32):
        done = run_limited(code, {resource.RLIMIT_NOFILE: handles}, timeout=60)
        assert_refused(done, "local Dask cluster of 2 worker processes needs about",
                       f"the limit (ulimit -n) is {handles}")
        assert not (tmp_path / "d.zarr").exists()


def test_a_cluster_that_fails_to_start_names_the_cause_from_its_errors():
    from tespike.cosim.dataset.cluster import _failed_start
    errors = ["Traceback (most recent call last):\n", '  File "x.py", line 1\n',
              "OSError: [Errno 24] Too many open files\n", "\n",
              "The above exception was the direct cause of the following exception:\n",
              "RuntimeError: Nanny failed to start.\n"]
    assert str(_failed_start(2, 1, errors)) == ("cannot start a local Dask cluster of 2 worker processes: "
                                                "OSError: [Errno 24] Too many open files")
    assert str(_failed_start(3, 1, ["RuntimeError: Cluster failed to start: bad port\n"])).endswith(": bad port")
    assert str(_failed_start(2, 1, [])).endswith("processes: exit status 1")
    logged = ["Traceback (most recent call last):\n", "MemoryError\n",
              "2026-11-26 10:27:45,233 - distributed.process - INFO - reaping stray process <SpawnProcess>\n"]
    assert str(_failed_start(2, 1, logged)).endswith("processes: MemoryError")    # the cause, not Dask's log
    nanny = ["RuntimeError: can't start new thread\n", "AssertionError: Status.starting\n",
             "RuntimeError: Nanny failed to start.\n", logged[-1]]
    assert str(_failed_start(2, 1, nanny)).endswith(": RuntimeError: can't start new thread "
                                                    "(out of memory or of processes)")


def test_a_local_cluster_whose_start_hangs_ends_with_the_command(tmp_path):
    """With 12 file handles Dask's start spins for ever; the cluster's process read its stdin (the
    command's end) only after the start, so it outlived a killed command. It now watches from the start."""
    from tespike.cosim.dataset.cluster import LOCAL_CLUSTER

    def starve():
        resource.setrlimit(resource.RLIMIT_NOFILE, (12, 12))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.Popen([sys.executable, "-c", LOCAL_CLUSTER, "2"], stdin=subprocess.PIPE,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                               start_new_session=True, preexec_fn=starve)
    try:
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            pass
        process.stdin.close()                    # the command ended
        process.wait(timeout=20)
    finally:
        try:
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        process.wait()


def test_a_full_disk_under_the_training_log_names_the_log(capsys, tmp_path):
    """log.csv is appended through a buffer: the full disk surfaced at its close as an OSError naming
    no file ("tespike train: error: No space left on device")."""
    with small_tmpfs(tmp_path / "small", "1m") as mount:
        (mount / "filler").write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize))
        result = run_here(capsys, "train", "--config", "te", "--steps", "1", "--batch", "1", "--crop", "16",
                          "--workers", "0", "--pool", "1", "--validate-every", "0", "--out", mount / "t.pt")
        assert_refused(result, f"{str(mount / 't.run' / 'log.csv')!r}", "No space left on device")
        assert sorted(os.listdir(mount)) == ["filler"]            # no weights, no run folder left


def test_a_fault_after_an_output_is_in_place_says_it_is_whole(capsys, monkeypatch, tmp_path):
    """train writes its weights, then its checkpoint: a full disk at the checkpoint read as if the run
    had written nothing, over new, whole weights."""
    import tespike.cosim.commands.scene_cmd as scene_cmd
    from tespike.golden.io import atomic_output

    def writes_then_fails(args):
        with atomic_output(tmp_path / "w.pt") as part:
            open(part, "wb").write(b"weights")
        raise OSError(28, os.strerror(28), str(tmp_path / "t.run" / "checkpoint.pt"))
    monkeypatch.setattr(scene_cmd, "run", writes_then_fails)
    assert_refused(run_here(capsys, "scene", "--list"), "checkpoint.pt", "No space left on device",
                   f"(after writing {str(tmp_path / 'w.pt')!r} whole)")


def test_no_usable_temporary_directory_names_the_folder_and_the_cause(capsys, monkeypatch, tmp_path):
    """Python's tempfile says "No usable temporary directory found in [...]" whatever the cause (a full
    disk, a file-size limit): the line now names the folder and the errno's words."""
    import tespike.cosim.commands.scene_cmd as scene_cmd

    def no_temporary(args):
        raise FileNotFoundError(2, f"No usable temporary directory found in ['{mount}', '/tmp']")
    monkeypatch.setattr(scene_cmd, "run", no_temporary)
    with small_tmpfs(tmp_path / "small", "64k") as mount:
        (mount / "filler").write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize))
        monkeypatch.setenv("TMPDIR", str(mount))
        assert_refused(run_here(capsys, "scene", "--list"),
                       f"cannot write a temporary file in {str(mount)!r}: No space left on device")


@pytest.mark.parametrize("room", [0, 12 * 1024])
def test_a_full_disk_under_a_dataset_store_names_the_store(capsys, tmp_path, room):
    """Zarr writes a store's files itself: a full disk was "tespike dataset: error: No space left on
    device", naming nothing; the half-made store goes, as for any failed first build."""
    with small_tmpfs(tmp_path / "small", "1m") as mount:
        (mount / "filler").write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize - room))
        result = run_here(capsys, "dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                          "--config", "te", "--out", mount / "d.zarr")
        assert_refused(result, f"cannot write dataset store {str(mount / 'd.zarr')!r}: No space left on device")
        assert os.listdir(mount) == ["filler"]


def test_running_out_of_file_handles_names_the_limit(tmp_path):
    """The system's words ("Too many open files") name no file and no limit: the line says which
    limit was reached and its value (training's data workers, torch's libraries and the run's
    files need more handles than a starved shell gives), and a read that failed for want of
    handles does not call the file unreadable."""
    code = ENTRY.format(args=["train", "--config", "te", "--steps", "1", "--batch", "1", "--crop", "32",
                              "--workers", "1", "--progress", "off", "--out", str(tmp_path / "T.pt")])
    refused = 0
    for handles in (8, 10, 12, 16):              # (where the command starves depends on the machine)
        done = run_limited(code, {resource.RLIMIT_NOFILE: handles}, timeout=120)
        if done.returncode == 0:
            continue
        refused += 1
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        assert f"too many open files (this process may hold {handles}: the open-file limit, ulimit -n)" \
            in lines[0], lines[0]
        # at 8 and 10 the import of multiprocessing's module failed: its path was named as the file
        assert ".py'" not in lines[0] and "site-packages" not in lines[0], lines[0]
        # ... and, out of handles for rmtree's walk, the run folder of a run that saved nothing was left
        assert not (tmp_path / "T.run").exists()
    assert refused
    from tespike.golden import atomic, io
    error = atomic._write_error("out.npz", OSError(24, "Too many open files"))
    assert "cannot write 'out.npz': too many open files (this process may hold" in str(error)
    scene = tmp_path / "I.npy"
    np.save(scene, np.zeros((1, 2, 2)))
    real = np.load

    def starved(*args, **kwargs):
        raise OSError(24, "Too many open files")
    try:
        np.load = starved
        with pytest.raises(InputError, match="cannot read scene file .*: too many open files"):
            io.load_npy(scene, "scene")
    finally:
        np.load = real


def test_intact_weights_read_without_file_handles_are_not_called_damaged(monkeypatch):
    """Under ulimit -n 6 the shipped te.pt was "not a tespike weights file (a damaged archive: [Errno 24] ...)"."""
    import errno
    import zipfile
    from tespike.recon.learning import weights
    from tespike.recon.learned import weights_path
    from tespike.golden.config import SensorConfig

    def starved(*args, **kwargs):
        raise OSError(errno.EMFILE, "Too many open files")
    monkeypatch.setattr(zipfile, "ZipFile", starved)
    with pytest.raises(InputError, match=r"cannot read weights file .*te.pt.: too many open files \(this process may hold"):
        weights.read_torch_file(weights_path(SensorConfig.preset("te")), "weights", "tespike weights file")


def test_a_fatal_signal_under_an_address_space_limit_names_the_limit():
    """torch's backward died of a segmentation fault at ulimit -v of about 1 GB: the line named no memory."""
    code = ("import ctypes, time; from tespike.golden.atomic import start_janitor; "
            "start_janitor(report_faults=True); time.sleep(0.3); ctypes.string_at(0)")
    done = run_limited(code, {resource.RLIMIT_AS: 3 << 30})
    assert done.returncode == -signal.SIGSEGV
    assert "fatal signal (Segmentation fault), under an address-space limit (ulimit -v) of 3072 MB: most " \
           "likely out of memory" in done.stderr, done.stderr


def test_a_write_cut_at_the_file_size_limit_names_the_limit(tmp_path):
    """numpy's write past ``ulimit -f`` is short, not EFBIG: it was called a full disk."""
    out = tmp_path / "I.npy"
    done = run_limited(ENTRY.format(args=["scene", "--frames", "24", "--out", str(out)]),
                       {resource.RLIMIT_FSIZE: 100 << 10})
    assert_refused(done, f"cannot write {str(out)!r}: File too large", "ulimit -f: 102400 bytes")
    assert os.listdir(tmp_path) == []


def test_yosys_past_the_file_size_limit_names_the_limit_in_one_line(tmp_path):
    """Amaranth's Yosys writes its work as it runs: past ``ulimit -f`` every command that writes Verilog
    (verilog, synthesize, cocotb, rtl-sim on Icarus) died with wasmtime's "File too large (os error 27)"
    inside two tracebacks."""
    out = tmp_path / "a.v"
    done = run_limited(ENTRY.format(args=["verilog", "--config", "te", "--height", "4", "--width", "4",
                                          "--out", str(out)]), {resource.RLIMIT_FSIZE: 300 << 10})
    assert_refused(done, "Amaranth's Yosys (WebAssembly) could not write its work: File too large",
                   "ulimit -f: 307200 bytes")
    assert not out.exists()


def test_a_demo_that_yosys_cannot_run_in_is_refused_before_its_work(tmp_path):
    """Between about 1.5 and 4.2 GB of address space the demo ran its scene, golden model, RTL and
    every reconstruction (a minute or more), then failed on Yosys's reservation for the hardware cost."""
    done = run_limited(ENTRY.format(args=["demo", "--frames", "10", "--height", "32", "--width", "32", "--crop", "11",
                                          "--repeats", "1", "--out", str(tmp_path / "d"), "-q"]),
                       {resource.RLIMIT_AS: 2200 << 20})
    assert_refused(done, "out of memory within the address-space limit (ulimit -v) of 2200 MB",
                   "Amaranth's Yosys (WebAssembly) reserves 4.1 GiB of address space for the hardware cost "
                   "(--no-hw-cost leaves it out)")
    assert os.listdir(tmp_path) == []


def test_yosys_without_its_address_space_is_out_of_memory_in_one_line(tmp_path):
    """Amaranth's Yosys (WebAssembly) reserves about 4 GiB as it starts: under a smaller ``ulimit -v``
    every command that writes Verilog died with two tracebacks, Yosys's inside Amaranth's."""
    out = tmp_path / "a.v"
    done = run_limited(ENTRY.format(args=["verilog", "--config", "te", "--height", "2", "--width", "2",
                                          "--out", str(out)]), {resource.RLIMIT_AS: 3 << 30})
    assert_refused(done, "out of memory within the address-space limit (ulimit -v)",
                   "Yosys (WebAssembly) could not reserve its address space")
    assert done.returncode == 1 and not out.exists()


def test_evaluate_out_of_file_handles_leaves_no_temporary_and_names_no_read_file_as_written(tmp_path):
    """Out of file handles, ``evaluate`` left its hidden results folder ``.E.<pid>.<x>.part`` for good
    (``rmtree`` itself needs handles, and the janitor had been told it was gone), and called a
    matplotlib font it was reading a file it "cannot write"."""
    import time
    scene = tmp_path / "I.npy"
    np.save(scene, np.full((12, 32, 32), 0.3, np.float32))
    outcomes = set()
    for handles in range(8, 16):
        out = tmp_path / f"E{handles}"
        done = run_limited(ENTRY.format(args=["evaluate", "--set", "none", "--scene", str(scene), "--methods", "tfp",
                                              "--out", str(out), "--progress", "off"]),
                           {resource.RLIMIT_NOFILE: handles}, timeout=300)
        if done.returncode:
            assert_refused(done, "too many open files", "ulimit -n")
            assert "cannot write" not in done.stderr or str(out) in done.stderr, done.stderr
            assert not out.exists()
        outcomes.add(done.returncode == 0)
        deadline = time.monotonic() + 10                     # (the janitor's removal, where it had to)
        while [p for p in os.listdir(tmp_path) if p.startswith(".")] and time.monotonic() < deadline:
            time.sleep(0.1)
        assert [p for p in os.listdir(tmp_path) if p.startswith(".")] == [], handles
    assert False in outcomes, "no limit tried ran out of handles: lower the range"


def test_a_tool_killed_at_the_file_size_limit_is_named_so(tmp_path):
    """Yosys past ``ulimit -f`` (killed by SIGXFSZ, printing nothing) was "yosys failed: []"."""
    from tespike.cosim.children import ended
    assert ended(3) == "exit status 3" and ended(-signal.SIGKILL) == "killed by SIGKILL"
    done = run_limited(ENTRY.format(args=["prove", "--config", "te", "--only", "pixel", "--depth", "1",
                                          "--traces", str(tmp_path / "tr")]), {resource.RLIMIT_FSIZE: 300 << 10})
    assert_refused(done, "yosys failed: killed by SIGXFSZ", "ulimit -f: 307200 bytes")


def test_a_full_temporary_folder_or_the_file_size_limit_names_the_tools_file(tmp_path):
    """prove with $TMPDIR nearly full ended in "No space left on device" naming no file, or in
    yosys-smtbmc's "gave no verdict: ## 0:00:00 Solver: z3"; under ``ulimit -f`` in "File too large"
    naming none: the harness file a write failed on is named, and a tool's failure says its work
    folder's file system is full."""
    from tests.cli import run_tespike
    args = ("prove", "--config", "te", "--only", "pixel", "--depth", "1", "--traces", tmp_path / "tr")
    done = run_limited(ENTRY.format(args=[str(a) for a in args]), {resource.RLIMIT_FSIZE: 2 << 10})
    assert_refused(done, "tespike-prove-", "top.il': File too large", "ulimit -f: 2048 bytes")
    with small_tmpfs(tmp_path / "small", "2m") as mount:
        (mount / "t").mkdir()
        filler = mount / "filler"
        for keep in (4096, 120_000):                         # the harness cannot be written; a tool cannot write
            filler.write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize - keep))
            done = run_tespike(*args, env={"TMPDIR": str(mount / "t")})
            assert_refused(done, str(mount / "t"))
            assert "No space left on device" in done.stderr or "is full" in done.stderr, done.stderr
            assert os.listdir(mount / "t") == [], "the run's temporaries were left"
            filler.unlink()
        if __import__("shutil").which("iverilog") is None:
            return
        # iverilog cut short by the full disk exits 0: vvp's "sim.vvp:832: syntax error" was the line
        import json

        from tests.test_cli_hardening import TINY
        (tmp_path / "c.json").write_text(json.dumps(TINY.to_dict()))
        np.save(tmp_path / "E.npy", np.full((TINY.clocks_per_readout * 40, 4, 4), 2, np.uint8))
        filler.write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize - 100_000))
        done = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "E.npy",
                           "--out", tmp_path / "S.npz", "--backend", "icarus", env={"TMPDIR": str(mount / "t")})
        assert_refused(done, str(mount / "t"))
        assert "No space left on device" in done.stderr or "is full" in done.stderr, done.stderr


def test_a_full_disk_under_the_traces_or_the_build_cache_names_it(tmp_path):
    """A counterexample trace on a full disk named the solver's temporary (``shutil.copyfile`` names its
    source) and left an empty --traces folder; a cocotb build into a full cache named no file."""
    from tests.cli import run_tespike
    with small_tmpfs(tmp_path / "small", "2m") as mount:
        filler = mount / "filler"
        filler.write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize - 4096))
        done = run_tespike("prove", "--config", "te", "--only", "pixel", "--depth", "1", "--traces", mount / "tr")
        assert_refused(done, f"cannot write {str(mount / 'tr' / 'te-stream.vcd')!r}: No space left on device")
        assert os.listdir(mount) == ["filler"]
        filler.unlink()
        pytest.importorskip("cocotb")
        if __import__("shutil").which("iverilog") is None:
            pytest.skip("Icarus Verilog is not installed")
        filler.write_bytes(b"\0" * (os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize - 200_000))
        done = run_tespike("cocotb", "--config", "te", "--height", "4", "--width", "4", "--simulator", "icarus", "-q",
                           env={"TESPIKE_CACHE": str(mount / "cache")})
        assert_refused(done, "cannot write the icarus build", str(mount / "cache" / "cocotb"), "No space left on device")
        assert [name for name in os.listdir(mount / "cache" / "cocotb") if not name.endswith(".lock")] == []


@pytest.mark.parametrize("handles", [7, 64])
def test_the_runs_temporary_folder_goes_with_it_even_without_a_janitor(tmp_path, handles):
    """Out of file handles the janitor cannot start: the run's own temporary folder, which only the
    janitor removed, stayed in $TMPDIR after every run, successful ones included."""
    scene = tmp_path / "I.npy"
    np.save(scene, np.full((2, 4, 4), 0.1, np.float32))
    temporary = tmp_path / "t"
    temporary.mkdir()
    done = run_limited(ENTRY.format(args=["simulate", "--config", "te", "--scene", str(scene), "--seed", "1",
                                          "--out", str(tmp_path / "S.npz"), "-q"]),
                       {resource.RLIMIT_NOFILE: handles}, env={"TMPDIR": str(temporary)})
    assert done.returncode == 0, done.stderr
    assert os.listdir(temporary) == []
