"""Synthesis and store evaluation on real Dask clusters on 127.0.0.1: a LocalCluster of two
worker processes (``--workers 2``), and ``dask scheduler`` + ``dask worker`` processes started
here, one of which is killed in the middle of a run. Every result must be bit-identical to
the in-process run."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.recon.dataset import compare_stores
from tespike.recon.scenes.hdr_io import write_exr

from .cli import ROOT, run_tespike

pytest.importorskip("distributed")

#: Built-in scenes of the runs: 2 tiles per frame (300 > 256 columns), so both
#: synthesis and evaluation have several tasks per sequence.
SCENES = ("moderate", "lights", "sun", "decades")
SIZE = ("--frames", "40", "--height", "24", "--width", "300")


def hdr_root(root):
    rng = np.random.default_rng(4)
    for name in ("clip-a", "clip-b"):
        (root / name).mkdir(parents=True)
        for k in range(12):
            write_exr(root / name / f"{k:04d}.exr", (rng.random((20, 270, 3)) ** 5 * 50).astype(np.float32))
    return root


def dataset_args(hdr, out, *extra):
    scenes = [a for s in SCENES for a in ("--scene", s)]
    return ("dataset", "--hdr", hdr, *scenes, *SIZE, "--config", "te", "--config", "ml",
            "--out", out, "--seed", "11", *extra)


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The in-process run everything is compared with: the store and its table."""
    base = tmp_path_factory.mktemp("serial")
    hdr = hdr_root(base / "hdr")
    result = run_tespike(*dataset_args(hdr, base / "s.zarr"), timeout=1800)
    assert result.returncode == 0, result.stderr
    result = run_tespike("evaluate", "--store", base / "s.zarr", "--methods", "tfp,tfi", "--out",
                         base / "ev", timeout=1800)
    assert result.returncode == 0, result.stderr
    return {"hdr": hdr, "store": base / "s.zarr", "table": (base / "ev" / "table.csv").read_text(),
            "results": (base / "ev" / "results.csv").read_text()}


def test_local_cluster_of_two_workers_gives_the_same_store_and_table(serial, tmp_path):
    result = run_tespike(*dataset_args(serial["hdr"], tmp_path / "s.zarr", "--workers", "2"), timeout=1800)
    assert result.returncode == 0, result.stderr
    assert "local cluster of 2 worker processes" in result.stdout
    assert compare_stores(serial["store"], tmp_path / "s.zarr") == []
    result = run_tespike("evaluate", "--store", tmp_path / "s.zarr", "--methods", "tfp,tfi", "--workers", "2",
                         "--out", tmp_path / "ev", timeout=1800)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "ev" / "table.csv").read_text() == serial["table"]
    assert (tmp_path / "ev" / "results.csv").read_text() == serial["results"]


class Cluster:
    """``dask scheduler`` and ``dask worker`` processes on 127.0.0.1, stopped by :meth:`close`."""

    def __init__(self, folder):
        self.folder = folder
        self.file = folder / "scheduler.json"
        self.env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.processes = []
        self.scheduler = self._start("scheduler", "--host", "127.0.0.1", "--port", "0", "--dashboard-address", "127.0.0.1:0",
                                     "--scheduler-file", self.file)
        deadline = time.monotonic() + 300             # a loaded machine starts Python slowly
        while not self.file.is_file():
            assert time.monotonic() < deadline and self.scheduler.poll() is None, "no scheduler"
            time.sleep(0.1)
        time.sleep(0.2)                               # the file is written whole, then read
        self.address = json.loads(self.file.read_text())["address"]
        from distributed import Client
        self.client = Client(self.address, timeout=60)

    def _start(self, *args):
        log = open(self.folder / f"{args[0]}-{len(self.processes)}.log", "w")
        process = subprocess.Popen([sys.executable, "-m", "dask", *map(str, args)], stdout=log,
                                   stderr=subprocess.STDOUT, env=self.env, cwd=self.folder)
        self.processes.append(process)
        return process

    def add_worker(self, count=1):
        """Start ``count`` worker processes (no nanny: a killed worker stays dead)."""
        before = len(self.client.scheduler_info()["workers"])
        started = [self._start("worker", self.address, "--nthreads", "1", "--no-nanny",
                               "--dashboard-address", "127.0.0.1:0",
                               "--host", "127.0.0.1") for _ in range(count)]
        self.client.wait_for_workers(before + count, timeout=120)
        return started

    def live_workers(self) -> list:
        """The worker processes started here that still run."""
        return [p for p in self.processes[1:] if p.poll() is None]

    def kill_when_running(self, worker, prefix, run, timeout=300) -> bool:
        """Kill ``worker`` (its process) as soon as it holds a task whose key starts with ``prefix``;
        False where ``run`` ended first (its tasks were too quick to be caught: the caller runs again)."""
        address = next(a for a, pid in self.client.run(os.getpid).items() if pid == worker.pid)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if run.poll() is not None:
                return False
            if any(str(k).startswith(prefix) for k in self.client.processing().get(address, ())):
                os.kill(worker.pid, signal.SIGKILL)
                worker.wait(timeout=30)
                return True
            time.sleep(0.01)
        raise AssertionError(f"the worker never ran a {prefix!r} task")

    def close(self):
        try:
            self.client.close()
        finally:
            for process in reversed(self.processes):
                if process.poll() is None:
                    process.terminate()
            for process in self.processes:
                try:
                    process.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()


def tespike_process(*args, **environ):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **environ)
    return subprocess.Popen([sys.executable, "-m", "tespike", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def finish(process, timeout=1800):
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        raise
    assert process.returncode == 0, err
    return out


#: Runs of :func:`test_a_worker_killed_mid_run_costs_only_a_retry` that may end before a worker is caught.
ATTEMPTS = 4


def test_a_worker_killed_mid_run_costs_only_a_retry(serial, tmp_path):
    """A worker killed while it holds a simulation task, then one holding a scoring task: the runs
    end as the in-process ones. A run whose tasks all ended before the worker was caught holding
    one (a fast machine) is made again, up to ATTEMPTS times."""
    cluster = Cluster(tmp_path)
    runs = []
    try:
        cluster.add_worker(2)
        for attempt in range(ATTEMPTS):
            shutil.rmtree(tmp_path / "s.zarr", ignore_errors=True)
            doomed = cluster.live_workers()[0]
            run = tespike_process(*dataset_args(serial["hdr"], tmp_path / "s.zarr", "--scheduler", cluster.address))
            runs.append(run)
            if cluster.kill_when_running(doomed, "sim-", run):
                break
            finish(run)
        else:
            pytest.fail(f"no simulation task was caught running in {ATTEMPTS} runs")
        finish(run)
        assert compare_stores(serial["store"], tmp_path / "s.zarr") == []
        assert not list((tmp_path / "s.zarr").rglob("*.partial"))

        cluster.add_worker()                           # two workers again, then kill one mid-evaluation
        for attempt in range(ATTEMPTS):
            shutil.rmtree(tmp_path / "ev", ignore_errors=True)
            run = tespike_process("evaluate", "--store", tmp_path / "s.zarr", "--methods", "tfp,tfi",
                                  "--out", tmp_path / "ev", DASK_SCHEDULER_ADDRESS=cluster.address)
            runs.append(run)
            if cluster.kill_when_running(cluster.live_workers()[0], "score-", run):
                break
            finish(run)
        else:
            pytest.fail(f"no scoring task was caught running in {ATTEMPTS} runs")
        assert f"the Dask cluster at {cluster.address}" in finish(run)    # Dask's own setting
        assert (tmp_path / "ev" / "table.csv").read_text() == serial["table"]
        assert (tmp_path / "ev" / "results.csv").read_text() == serial["results"]
    finally:
        for run in runs:
            if run.poll() is None:
                run.kill()
                run.communicate()
        cluster.close()


def test_unreachable_scheduler_is_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT", "2s")
    result = run_tespike("dataset", "--scene", "sun", "--config", "te", "--out", tmp_path / "s.zarr",
                         "--scheduler", "tcp://127.0.0.1:9", timeout=120)
    assert result.returncode == 2, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the Dask scheduler" in lines[0], result.stderr


def test_an_address_that_answers_but_is_not_dask_and_an_empty_one_are_named(tmp_path, monkeypatch):
    """A server that answers in another protocol (HTTP here) was reported as "out of memory" (Dask
    read its reply as a frame length of exabytes); --scheduler '' ran on this process silently."""
    import socket
    import threading
    monkeypatch.setenv("DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT", "5s")
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)

    def answer():
        while True:
            try:
                peer, _ = server.accept()
            except OSError:
                return
            peer.recv(1000)
            peer.sendall(b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\n")
            peer.close()
    threading.Thread(target=answer, daemon=True).start()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    try:
        result = run_tespike("dataset", "--scene", "sun", "--config", "te", "--out", tmp_path / "s.zarr",
                             "--scheduler", address, timeout=120)
    finally:
        server.close()
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"tespike dataset: error: {address!r} answers, but is not a Dask scheduler (its reply is not Dask's "
        "protocol)"], result
    result = run_tespike("dataset", "--scene", "sun", "--config", "te", "--out", tmp_path / "s.zarr",
                         "--scheduler", "", timeout=120)
    assert result.returncode == 2 and "--scheduler '': an empty value" in result.stderr
    assert not (tmp_path / "s.zarr").exists()


def test_a_local_cluster_ends_at_once_with_a_command_killed_outright():
    """SIGKILL to the command: its local cluster (a session of its own) sees its pipe close with
    its command gone and ends its whole session at once, without a graceful close nobody awaits."""
    import signal
    import subprocess
    import sys
    import time
    script = ("from tespike.cosim.dataset.cluster import _start_local_cluster\n"
              "process, address = _start_local_cluster(2, lambda: None)\n"
              "print(process.pid, flush=True)\n"
              "import time; time.sleep(120)\n")
    command = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)

    def session(sid):                                       # live processes (a zombie has ended)
        out = subprocess.run(["ps", "-o", "pid=,stat=", "-s", str(sid)], capture_output=True, text=True).stdout
        return [line.split()[0] for line in out.splitlines() if line.split() and not line.split()[1].startswith("Z")]

    cluster = None
    try:
        cluster = int(command.stdout.readline())
        assert len(session(cluster)) >= 3                       # the cluster's process and its workers
        command.kill()
        command.wait(10)
        start = time.monotonic()
        while session(cluster) and time.monotonic() - start < 20:
            time.sleep(0.05)
        assert not session(cluster), session(cluster)
        assert time.monotonic() - start < 8.0                   # at once, not after a 10 s graceful close
                                                                # (slack for a loaded machine)
    finally:
        if cluster is not None and session(cluster):
            os.killpg(cluster, signal.SIGKILL)


def test_a_local_cluster_that_lost_every_worker_ends_the_run_in_one_line(monkeypatch):
    """Starved of memory, a local cluster's workers die and their nannies with them, and the tasks
    would wait for ever: with no worker for NO_WORKER_SECONDS the run ends, naming the cause its
    error output gives; with workers, a task slower than that is waited for."""
    import distributed

    from tespike.cosim.dataset import cluster
    from tespike.golden.errors import InputError

    class Future:                                     # finishes ``seconds`` after it is made
        def __init__(self, seconds):
            self.done_at = time.monotonic() + seconds

        def result(self, timeout=None):
            return "done"

    class Completed:
        def __init__(self, futures):
            self.left = list(futures)

        def is_empty(self):
            return not self.left

        def next_batch(self, block=False):
            batch = [f for f in self.left if time.monotonic() >= f.done_at]
            self.left = [f for f in self.left if f not in batch]
            return batch

    class Client:
        def __init__(self, workers, seconds):
            self.workers, self.seconds = workers, seconds

        def compute(self, tasks, retries=0):
            return [Future(self.seconds) for _ in tasks]

        def scheduler_info(self):
            return {"workers": dict.fromkeys(range(self.workers))}

        def cancel(self, futures):
            pass

    monkeypatch.setattr(distributed, "as_completed", Completed)
    monkeypatch.setattr(cluster, "NO_WORKER_SECONDS", 0.3)
    monkeypatch.setattr(cluster, "POLL_SECONDS", 0.01)
    runner = cluster.Runner(workers=2)
    runner.cluster = type("Process", (), {})()
    runner.cluster.errors = ["2026-11-26 10:00:00,000 - distributed.nanny - ERROR - Failed to start process",
                             "MemoryError: Unable to allocate internal buffer."]
    runner.client = Client(0, 60.0)
    with pytest.raises(InputError, match="lost all its 2 worker processes and could not restart them: "
                                         "MemoryError: Unable to allocate internal buffer"):
        list(runner([object(), object()]))
    runner.client = Client(2, 0.6)
    assert list(runner([object()])) == [(0, "done")]


def test_a_cluster_whose_reader_thread_cannot_start_leaves_no_process_and_no_pipe(monkeypatch):
    """Under ``ulimit -v`` the thread that reads the cluster's errors could not start: the command
    printed its line, then the interpreter's exit warned of three unclosed pipes, and the cluster's
    process was left to notice its closed stdin. Now the cluster goes, its pipes closed."""
    import threading

    from tespike.cosim.dataset import cluster

    started = []
    real_popen = subprocess.Popen

    def popen(*args, **kwargs):
        started.append(real_popen(*args, **kwargs))
        return started[-1]

    def cannot_start(self):
        raise RuntimeError("can't start new thread")
    monkeypatch.setattr(subprocess, "Popen", popen)
    monkeypatch.setattr(threading.Thread, "start", cannot_start)
    with pytest.raises(RuntimeError, match="can't start new thread"):
        cluster._start_local_cluster(1, lambda: None)
    (process,) = started
    assert process.returncode is not None
    assert process.stdin.closed and process.stdout.closed and process.stderr.closed


def _fake_distributed(tmp_path, loop_dies: bool):
    """A ``distributed`` package whose LocalCluster never starts: its "IO loop" thread dies at once
    (``loop_dies``, as Dask's did starved of memory) or runs on, and the start waits for ever."""
    package = tmp_path / "fake" / "distributed"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(
        "import threading, time\n"
        "class LocalCluster:\n"
        "    def __init__(self, **options):\n"
        f"        threading.Thread(target=time.sleep, args=({0.2 if loop_dies else 3600},), name='IO loop',\n"
        "                         daemon=True).start()\n"
        "        threading.Event().wait()\n")
    return dict(os.environ, PYTHONPATH=str(tmp_path / "fake"))


def test_a_cluster_whose_event_loop_thread_dies_while_it_starts_ends_in_one_line(tmp_path):
    """Starved of memory, Dask's event loop thread died while the cluster started and the start
    waited for it for ever, saying nothing: the command said "did not start in 120 s" (the fault
    sweep's 120 s ran out first). The cluster's process now ends at once with one line."""
    from tespike.cosim.dataset.cluster import LOCAL_CLUSTER
    process = subprocess.Popen([sys.executable, "-c", LOCAL_CLUSTER, "2"], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=_fake_distributed(tmp_path, loop_dies=True), start_new_session=True)
    try:
        process.wait(30)
    finally:
        process.kill()
        out, err = process.communicate()
    assert process.returncode == -signal.SIGKILL and out == ""
    assert err.strip() == "RuntimeError: the cluster's event loop thread ended before the cluster started"


def test_a_cluster_that_never_starts_is_given_up_in_one_line(tmp_path, monkeypatch):
    from tespike.cosim.dataset import cluster
    monkeypatch.setattr(cluster, "START_SECONDS", 2)
    real_popen = subprocess.Popen
    started = []

    def popen(*args, **kwargs):
        started.append(real_popen(*args, **dict(kwargs, env=_fake_distributed(tmp_path, loop_dies=False))))
        return started[-1]
    monkeypatch.setattr(subprocess, "Popen", popen)
    with pytest.raises(InputError, match=r"^a local Dask cluster of 2 worker processes did not start in 2 s$"):
        cluster._start_local_cluster(2, lambda: None)
    (process,) = started
    assert process.returncode is not None                  # its session ended, nothing left running


def test_a_ctrl_c_while_the_cluster_shuts_down_is_not_lost():
    """A Ctrl-C recorded after the last task (while the local cluster shut down) was dropped with the
    handler: evaluate --store and dataset then replaced their results and exited 0."""
    from tespike.cosim.dataset.cluster import Runner
    runner = Runner(workers=2)              # not entered: no cluster to stop, the handler's record alone
    runner._interrupts.pending = True
    with pytest.raises(KeyboardInterrupt):
        runner.__exit__(None, None, None)
    runner._interrupts.pending = True       # leaving on an error already: that error is the run's
    runner.__exit__(ValueError, ValueError("x"), None)


def test_an_ignored_ctrl_c_stays_ignored_while_the_cluster_runs():
    """A ``nohup`` or background job's SIGINT is ignored; the cluster's handler had replaced it, so a
    Ctrl-C to the group stopped a run the user had shielded (tespike leaves an ignored signal ignored)."""
    import signal

    from tespike.cosim.dataset.cluster import _Interrupts
    for start, recorded in ((signal.SIG_IGN, False), (signal.default_int_handler, True)):
        previous = signal.signal(signal.SIGINT, start)
        try:
            interrupts = _Interrupts()
            interrupts.install()
            assert (signal.getsignal(signal.SIGINT) == interrupts._record) == recorded
            interrupts.restore()
            assert signal.getsignal(signal.SIGINT) is start
        finally:
            signal.signal(signal.SIGINT, previous)


def test_a_scheduler_address_of_no_reachable_form_is_refused_at_once():
    """A port past 65535 waited 30 s and said "timed out"; inproc:// spoke of Python's unpacking."""
    from tespike.cosim.dataset.cluster import check_scheduler_address
    for good in ("tcp://127.0.0.1:8786", "127.0.0.1:8786", "tls://host:1", "host"):
        check_scheduler_address(good)
    for bad, words in (("tcp://127.0.0.1:99999", "port in 1..65535"), ("inproc://x", "inproc:// is not"),
                       ("tcp://:80", "HOST:PORT"), ("http://h:1", "http:// is not")):
        with pytest.raises(InputError, match=words):
            check_scheduler_address(bad)


def test_dasks_warnings_in_this_process_are_quieted():
    """"Couldn't gather 1 keys, rescheduling" (a worker died out of memory) reached stderr before the
    command's one line: only ``distributed`` was set to ERROR, and Dask's logging configuration gives
    ``distributed.client`` a WARNING level of its own, which the parent's does not override."""
    import importlib
    import logging

    from tespike.cosim.dataset.cluster import _quiet_distributed_logs
    importlib.import_module("distributed.client")       # (its import configures Dask's loggers)
    _quiet_distributed_logs()
    for name in ("distributed", "distributed.client", "distributed.worker", "distributed.scheduler"):
        assert logging.getLogger(name).getEffectiveLevel() >= logging.ERROR, name
