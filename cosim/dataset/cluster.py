"""Where dataset work runs: in this process, on a local cluster, or on an existing Dask cluster.

:class:`Runner` takes ``dask.delayed`` tasks and yields their results as they
finish. ``workers=1`` (the default) runs them one after another in this
process with Dask's synchronous scheduler: no server, no extra process.
``workers=N > 1`` starts a :class:`distributed.LocalCluster` of N worker
processes, one thread each, listening on 127.0.0.1 only (their HTTP status
servers too, on free ports), in a process and session of its own (a Ctrl-C
interrupts this process alone, quietly), and stops it at the end. ``scheduler=ADDRESS`` (or Dask's own ``scheduler-address`` setting, e.g.
``DASK_SCHEDULER_ADDRESS``) sends the same tasks to a running cluster started
with ``dask scheduler`` / ``dask worker`` (docs/distributed.md).

On a cluster, a task whose worker dies is run again on another worker (Dask
reschedules it; :data:`RETRIES` more attempts are allowed for tasks that
raise); every task here is idempotent, so a retry changes nothing but time.
"""

from __future__ import annotations

import contextlib
import os
import re
from typing import Iterator, Sequence

from tespike.golden.errors import InputError

#: Extra attempts for a task that raised (a worker that dies is handled by the scheduler).
RETRIES = 2
#: Seconds between two looks for finished tasks (and for a Ctrl-C) while a cluster runs.
POLL_SECONDS = 0.1


def check_cluster_options(workers: int | None, scheduler: str | None) -> None:
    """Refuse ``--workers`` outside the commands' one range (1..MAX_WORKERS) and ``--workers``
    together with ``--scheduler``."""
    from tespike.golden.resources import check_workers_argument
    if workers is not None and type(workers) is not int:
        raise InputError(f"--workers {workers!r} must be an integer")
    check_workers_argument(workers)
    if scheduler is not None and not scheduler.strip():       # ("" ran on this process without a word)
        raise InputError("--scheduler '': give the Dask scheduler's address (e.g. tcp://host:8786), "
                         "or leave the option out")
    if workers is not None and scheduler:
        raise InputError("--workers and --scheduler exclude each other "
                         "(an existing cluster has its own workers)")
    if scheduler:
        check_scheduler_address(scheduler)


#: Address schemes of a Dask scheduler another process can reach (inproc:// lives in one process).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")


def check_scheduler_address(address: str) -> None:
    """Refuse a ``--scheduler`` that names no reachable scheduler by its form alone: a scheme another
    process cannot reach, no host, or a port outside 1..65535 (each waited 30 s and said "timed out",
    or spoke of Python's unpacking)."""
    from urllib.parse import urlsplit
    text = address.strip()
    parts = urlsplit(text if "://" in text else f"tcp://{text}")
    if parts.scheme not in SCHEDULER_SCHEMES:
        raise InputError(f"--scheduler {address!r}: a scheduler's address is {'/'.join(SCHEDULER_SCHEMES)}://HOST:PORT "
                         f"({parts.scheme}:// is not one another process can reach)")
    try:
        port = parts.port
    except ValueError:
        port = -1
    if not parts.hostname or port is not None and not 1 <= port <= 65535:
        raise InputError(f"--scheduler {address!r}: give HOST:PORT with a port in 1..65535 (e.g. tcp://host:8786)")


#: The local cluster's own process: started in a session of its own, so a terminal's Ctrl-C
#: (sent to the whole foreground group) never reaches its workers (each printed its traceback:
#: 63 lines for two); it prints the scheduler's address, then runs until its stdin closes,
#: which happens however this command ends (a SIGKILL included), so no worker outlives it.
#: A watcher thread reads stdin from the start: only an orderly stop writes "close" before the
#: pipe closes; a cluster still starting when the command ends (a start that hangs: with few file
#: handles Dask's scheduler spins for ever), one whose command is gone (killed outright: its pipe
#: closes before it is seen as gone, and a graceful close took 4.5 s), or one that does not close
#: in 30 s, ends with its whole session at once. A guard thread ends it too, with one line, if
#: the event loop thread Dask starts first ("IO loop") dies before the cluster has started: starved
#: of memory, that thread died and the start waited for it for ever, silently (the command said
#: "did not start in 120 s").
LOCAL_CLUSTER = """
import logging, os, signal, sys, threading
started, ended, closed = threading.Event(), threading.Event(), threading.Event()
command = os.getppid()
def end_at_once():                                # its own group (its workers) where it leads one
    os.killpg(0, signal.SIGKILL) if os.getpgrp() == os.getpid() else os.kill(os.getpid(), signal.SIGKILL)
def watch():
    orderly = sys.stdin.read() == "close"         # (only the command's own stop writes it: EOF alone is its death)
    ended.set()
    if not orderly or not started.is_set() or os.getppid() != command or not closed.wait(30):
        end_at_once()
threading.Thread(target=watch, daemon=True).start()
loops, start_thread = [], threading.Thread.start
def start_noting_loops(thread):                   # the start waits for its event loop thread: if that thread
    start_thread(thread)                          # dies (out of memory), it waits for ever, saying nothing
    if thread.name == "IO loop":
        loops.append(thread)
threading.Thread.start = start_noting_loops
def guard():
    while not started.wait(0.05):
        if loops and not any(loop.is_alive() for loop in loops):
            sys.stderr.write("RuntimeError: the cluster's event loop thread ended before the cluster started\\n")
            sys.stderr.flush()
            end_at_once()
threading.Thread(target=guard, daemon=True).start()
from distributed import LocalCluster
cluster = LocalCluster(n_workers=int(sys.argv[1]), threads_per_worker=1, processes=True, host="127.0.0.1",
                       dashboard_address="127.0.0.1:0", worker_dashboard_address="127.0.0.1:0",
                       silence_logs=logging.CRITICAL)
started.set()
print(cluster.scheduler_address, flush=True)
ended.wait()
cluster.close(timeout=10)
closed.set()
"""
#: Seconds a local cluster is given to start (an idle 2-core machine starts 2 workers in about
#: 1 s, one with three busy processes in about 4: a start that takes 60 s has hung, as Dask's did
#: starved of memory), and to stop before its processes are killed.
START_SECONDS = 60
STOP_SECONDS = 30
#: Seconds a local cluster may run tasks with no worker left before the run is given up (its
#: nannies restart a dead worker within a few seconds; starved of memory, the nannies die too).
NO_WORKER_SECONDS = 20
#: Open files a local cluster's process needs: about this many, plus FILES_PER_WORKER per
#: worker (measured: 2 workers start with 40 open files, not with 38; 4 with 64, not with 56).
CLUSTER_FILES = 28
FILES_PER_WORKER = 8
#: What a failed start's error output says when the system, not Dask, was short of something.
STARVED = ("Too many open files", "No space left on device", "File too large", "Cannot allocate memory",
           "MemoryError", "No usable temporary directory", "failed to map segment", "can't start new thread")


#: Dask's log lines ("2026-01-01 10:00:00,000 - distributed.process - INFO - ...") and a traceback's
#: last line ("OSError: ...", "distributed.comm.core.CommClosedError: ...").
_LOG_LINE = re.compile(r"\d{4}-\d\d-\d\d [\d:,]+ - [\w.]+ - [A-Z]+ - ")
_EXCEPTION_LINE = re.compile(r"[\w.]*(Error|Exception|Interrupt|Exit)\b")


def _check_file_handles(workers: int) -> None:
    """Refuse a cluster the open-file limit (``ulimit -n``) cannot hold: its start fails a few
    layers down in Dask ("Nanny failed to start"), or, with very few, hangs."""
    import resource
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    needed = CLUSTER_FILES + FILES_PER_WORKER * workers
    if soft != resource.RLIM_INFINITY and soft < needed:
        raise InputError(f"a local Dask cluster of {workers} worker processes needs about {needed} open files, "
                         f"but the limit (ulimit -n) is {soft}: raise it or use fewer --workers")


def _failed_start(workers: int, returncode, errors: list[str]) -> InputError:
    """One line for a cluster that did not start: the cause from its error output (:func:`_cause`)."""
    return InputError(f"cannot start a local Dask cluster of {workers} worker processes: "
                      f"{_cause(errors, returncode)[:240]}")


def _cause(errors: list[str], returncode=None) -> str:
    """The cause a cluster's error output gives: the deepest starvation it names, else its last
    exception or line; under an address-space limit, with that limit when memory is not named."""
    every = [_LOG_LINE.sub("", line).strip() for line in errors if line.strip()]     # a worker's, logged
    lines = [line.strip() for line in errors if line.strip() and not _LOG_LINE.match(line)]
    exceptions = [line for line in lines if _EXCEPTION_LINE.match(line)]
    starved = next((line for line in reversed(every) if any(word in line for word in STARVED)), None)
    cause = starved or (exceptions or lines or [f"exit status {returncode}"])[-1]
    cause = cause.removeprefix("RuntimeError: Cluster failed to start: ")
    if cause.endswith("can't start new thread"):          # a thread's stack did not fit
        cause += " (out of memory or of processes)"
    if "No usable temporary directory" in cause:
        from tespike.golden.paths import temporary_directory_fault
        cause = temporary_directory_fault() or cause
    from tespike.golden.resources import address_space_text
    limit = address_space_text()
    if starved is None and limit:                       # its processes died where memory ran out
        cause = f"most likely out of memory{limit} (its last error: {cause[:120]})"
    return cause


def _start_local_cluster(workers: int, interrupted):
    """(process, scheduler address) of a local cluster of ``workers`` processes (:data:`LOCAL_CLUSTER`);
    ``interrupted()`` is called while it starts (a Ctrl-C ends the wait at once)."""
    import collections
    import select
    import subprocess
    import sys
    import threading
    import time
    _check_file_handles(workers)
    process = subprocess.Popen([sys.executable, "-c", LOCAL_CLUSTER, str(workers)], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    errors: collections.deque[str] = collections.deque(maxlen=400)      # its last lines, read as they come
    reader = threading.Thread(target=lambda: errors.extend(process.stderr), daemon=True)
    process.errors, process.reader = errors, reader                     # (read again if its workers die)
    try:
        reader.start()                 # (a thread that cannot start, out of memory: the cluster goes too)
        end = time.monotonic() + START_SECONDS
        while not select.select([process.stdout], [], [], POLL_SECONDS)[0]:
            interrupted()
            if time.monotonic() > end:
                from tespike.golden.resources import address_space_text
                limit = address_space_text()
                raise InputError(f"a local Dask cluster of {workers} worker processes did not start "
                                 f"in {START_SECONDS} s" + (f" (most likely out of memory{limit})" if limit else ""))
        address = process.stdout.readline().strip()
    except BaseException:
        _stop_local_cluster(process, at_once=True)
        raise
    if not address:                    # it ended: what its start left (half-started workers) goes too
        _stop_local_cluster(process, at_once=True)
        reader.join(5)
        raise _failed_start(workers, process.returncode, list(errors))
    return process, address


def _stop_local_cluster(process, at_once: bool = False) -> None:
    """Close its stdin (the cluster closes itself) and wait; kill its session's processes if it
    hangs, or ``at_once`` (a run that failed or was interrupted: nothing of theirs is wanted)."""
    import signal
    import subprocess
    if not at_once:                                     # an orderly stop: the cluster closes itself
        with contextlib.suppress(OSError, ValueError):
            process.stdin.write("close")
    for pipe in (process.stdin, process.stdout):
        with contextlib.suppress(OSError):
            pipe.close()
    try:
        if at_once:
            raise subprocess.TimeoutExpired(process.args, 0)
        process.wait(timeout=STOP_SECONDS)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(OSError):
            os.killpg(process.pid, signal.SIGKILL)     # its own session: only the processes it started
        process.wait()
    if process.reader.ident is not None:               # (started: its error output read to the end, or left)
        process.reader.join(5)
    if not process.reader.is_alive():
        with contextlib.suppress(OSError):
            process.stderr.close()


class _Interrupts:
    """Ctrl-C while a cluster runs: recorded by the handler, raised as KeyboardInterrupt at
    :meth:`check` (between tasks, after the start). Raised wherever the main thread happened
    to be, it landed inside Dask's start-up (which then hung) or in a garbage-collection
    callback (where Python prints it and goes on)."""

    def __init__(self):
        self.pending = False
        self.previous = None

    def _record(self, signum, frame):
        self.pending = True

    def install(self) -> None:
        """Record Ctrl-C from now on (in the main thread; an ignored Ctrl-C, a ``nohup`` or background
        job's, stays ignored, as everywhere in tespike)."""
        import signal
        import threading
        if threading.current_thread() is threading.main_thread() and self.previous is None \
                and signal.getsignal(signal.SIGINT) not in (signal.SIG_IGN, None):
            self.previous = signal.signal(signal.SIGINT, self._record)

    def check(self) -> None:
        if self.pending:
            self.pending = False
            raise KeyboardInterrupt

    def restore(self) -> None:
        """The handler before :meth:`install` again (a Ctrl-C recorded meanwhile stays pending for
        :meth:`check`)."""
        import signal
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)
            self.previous = None


def _quiet_distributed_logs() -> None:
    """Dask's warnings in this process (a key it could not gather from a worker that died, and
    reschedules) broke the command's one line: ``distributed`` and every logger of it that Dask's
    logging configuration gives a level of its own (``distributed.client`` is set to WARNING, which
    the parent's level does not override) print errors only."""
    import logging
    loggers = logging.root.manager.loggerDict
    for name in ["distributed", *(n for n in loggers if n.startswith("distributed."))]:
        logger = logging.getLogger(name)
        if name == "distributed" or logger.level != logging.NOTSET:
            logger.setLevel(max(logger.level, logging.ERROR))


class Runner:
    """Context manager: ``with Runner(workers, scheduler) as run: for i, r in run(tasks): ...``."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        check_cluster_options(workers, scheduler)
        import dask
        self.address = scheduler or (dask.config.get("scheduler-address", None) if workers is None else None)
        self.workers = 1 if workers is None else workers
        self.client = None
        self.cluster = None
        self._interrupts = _Interrupts()

    @property
    def where(self) -> str:
        if self.address:
            return f"the Dask cluster at {self.address}"
        if self.cluster is not None:
            return f"a local cluster of {self.workers} worker processes"
        return "this process"

    def __enter__(self) -> "Runner":
        if self.address is None and self.workers == 1:
            return self                       # Dask's synchronous scheduler: Ctrl-C as anywhere else
        self._interrupts.install()
        try:
            if self.address:
                import dask
                from distributed import Client
                try:             # Dask's own connect timeout (distributed.comm.timeouts.connect, 30 s)
                    self.client = Client(self.address,
                                         timeout=dask.config.get("distributed.comm.timeouts.connect"))
                except (OSError, TimeoutError, ValueError) as exc:
                    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                    raise InputError(f"cannot reach the Dask scheduler {self.address!r}: {first}") from None
                except MemoryError:  # a server that answers, but not Dask: its reply read as a frame length
                    raise InputError(f"{self.address!r} answers, but is not a Dask scheduler (its reply is "
                                     "not Dask's protocol)") from None
            else:
                from distributed import Client
                self.cluster, address = _start_local_cluster(self.workers, self._interrupts.check)
                _quiet_distributed_logs()
                self.client = Client(address)
            self._interrupts.check()          # a Ctrl-C during the start ends the run here
        except BaseException as exc:
            self.__exit__(type(exc), exc, None)
            raise
        return self

    def __exit__(self, kind=None, *exc) -> None:
        try:
            if self.client is not None:
                self.client.close()
            if self.cluster is not None:
                _stop_local_cluster(self.cluster, at_once=kind is not None)
        finally:
            self.client = self.cluster = None
            self._interrupts.restore()
        if kind is None:                   # a Ctrl-C while the cluster shut down is the run's, not lost
            self._interrupts.check()

    def _result(self, future):
        """A finished future's result, looking for a Ctrl-C meanwhile: gathering it from a worker that
        died (out of memory) reschedules it, and a plain ``result()`` then blocked past any Ctrl-C."""
        while True:
            self._interrupts.check()
            try:
                return future.result(timeout=POLL_SECONDS * 10)
            except TimeoutError:
                continue

    def __call__(self, tasks: Sequence) -> Iterator[tuple[int, object]]:
        """Run ``dask.delayed`` tasks; yield (index in ``tasks``, result) as each finishes.

        An exception of a task is raised here (its original type: an
        :class:`InputError` stays one) after the other tasks are cancelled.
        """
        tasks = list(tasks)
        if self.client is None:
            import dask
            for index, task in enumerate(tasks):
                yield index, dask.compute(task, scheduler="sync")[0]
            return
        import time

        from distributed import as_completed
        futures = self.client.compute(tasks, retries=RETRIES)
        index_of = {id(future): index for index, future in enumerate(futures)}
        try:
            finished = as_completed(futures)
            workers_seen = time.monotonic()
            while not finished.is_empty():
                self._interrupts.check()
                batch = finished.next_batch(block=False)
                if not batch:
                    time.sleep(POLL_SECONDS)
                    if self.cluster is None or self.client.scheduler_info().get("workers"):
                        workers_seen = time.monotonic()
                    elif time.monotonic() - workers_seen > NO_WORKER_SECONDS:
                        raise InputError(f"the local Dask cluster lost all its {self.workers} worker processes "
                                         f"and could not restart them: {_cause(list(self.cluster.errors))}")
                for future in batch:
                    yield index_of[id(future)], self._result(future)
        finally:
            self.client.cancel(futures)
