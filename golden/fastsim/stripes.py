"""Stripes of a frame (interleaved rows) and the worker processes that simulate them.

The noisy fast simulator (:func:`tespike.golden.fastsim.simulate_scene`) splits a frame
into stripes that depend on its shape only, gives each its own generator
(children of the seed) and simulator, and runs them on forked processes;
docs/simulator.md ("Stripes and worker processes") has the measurements.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError, is_count
from ..io import scan_light
from ..light import check_seed

#: Stripes of a noisy fast simulation (:func:`stripe_slices`): a power of two,
#: at most MAX_STRIPES, each of at least STRIPE_PIXELS pixels (a stripe's
#: readout has a fixed cost) and STRIPE_ROWS rows.
STRIPE_PIXELS = 1 << 16
STRIPE_ROWS = 16
MAX_STRIPES = 8


def stripe_slices(height: int, width: int) -> list[slice]:
    """Row slices of the stripes of a ``height`` x ``width`` frame: stripe i of n holds
    rows i, i + n, i + 2n, ... (interleaved, so that each stripe sees the same mix of
    sky and ground, bright and dark: a scene's costly part is shared evenly by the
    workers). A function of the shape only (never of the worker count), so a seed
    gives one result. A power of two, so that 2, 4 or 8 workers get equal shares; a
    frame of fewer than 2 x STRIPE_PIXELS pixels (e.g. 256 x 256) or 2 x STRIPE_ROWS
    rows is one stripe."""
    most = int(min(MAX_STRIPES, height // STRIPE_ROWS, height * width // STRIPE_PIXELS))
    n = 1 << (most.bit_length() - 1) if most > 1 else 1
    return [slice(i, height, n) for i in range(n)]


def spawn_generators(seed, n: int) -> list[np.random.Generator]:
    """``n`` independent generators from ``seed`` (int, None, SeedSequence, BitGenerator
    or Generator): ``Generator.spawn`` for a generator (children of its bit generator's
    kind), else an SFC64 generator on each child of ``SeedSequence(seed).spawn``: numpy's
    Poisson and Gamma draws, most of a striped frame's time, are 5-16 % cheaper on SFC64
    than on PCG64 (docs/simulator.md). The parent generator's own stream is not advanced."""
    check_seed(seed)
    if isinstance(seed, np.random.BitGenerator):
        seed = np.random.Generator(seed)
    if isinstance(seed, np.random.Generator):
        return seed.spawn(n)
    if not isinstance(seed, np.random.SeedSequence):
        seed = np.random.SeedSequence(seed)
    return [np.random.Generator(np.random.SFC64(child)) for child in seed.spawn(n)]


def worker_count(workers, limit: int) -> int:
    """Worker processes: ``None`` -> the cores this process may run on, at most ``limit``;
    otherwise a positive integer (capped at ``limit``: more would idle)."""
    if workers is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        return max(1, min(cores, limit))
    if not is_count(workers, 1):
        raise InputError(f"workers {workers!r}: must be a positive integer")
    return min(int(workers), limit)


#: Exit status of a worker that met light :func:`tespike.golden.io.scan_light` refuses.
BAD_LIGHT_STATUS = 3


def run_stripes(rows, sims, scene, dtype, *, workers, progress, what: str = "scene") -> np.ndarray:
    """Words ``(K, H, W)`` of ``scene`` from one simulator per stripe (``sims[i]``
    reads out rows ``rows[i]``), each walked through the readouts in order; with
    several workers, ``workers - 1`` forked processes take stripes ``j, j + workers,
    ...`` and write their words into a shared anonymous memory map (processes, not
    threads: the simulator's Python work holds the GIL for a large share of its time).
    A worker stops at its next readout once this process is gone (killed outright: it
    had no chance to end them). A worker tells its exit status on a pipe just before it
    exits, and is reaped on a thread (:func:`_reap_beside`) while this process goes on.

    Each process checks the light of its stripes, readout by readout, just before it
    simulates them (values in cache; a scan of the whole scene before the workers
    start was 5-10 ms of one core). Bad light anywhere stops every worker, and the
    refusal is that of a scan of the whole scene in readout order (the same line
    whichever worker met it first); ``what`` names the scene in it."""
    import mmap
    K, H, W = scene.shape
    workers = worker_count(workers, len(rows)) if hasattr(os, "fork") else worker_count(workers, 1)
    dtype = np.dtype(dtype)
    if workers == 1:
        words = np.empty((K, H, W), dtype)
    else:
        words = np.frombuffer(mmap.mmap(-1, max(1, K * H * W * dtype.itemsize)), dtype,
                              count=K * H * W).reshape(K, H, W)

    def run(mine, readouts, parent=None):
        # light in the scene's own dtype: readout converts it to float64 once (electrons_per_readout)
        for k in readouts:
            if parent is not None and os.getppid() != parent:
                os._exit(1)                              # a worker whose command was killed outright
            light = np.asarray(scene[k])
            for i in mine:
                words[k, rows[i]] = sims[i].readout(light[rows[i]], what)     # (which checks it)

    if workers > 1:
        _join_reapers()
    children, parent = {}, os.getpid()                  # pid -> (its first stripe, its "done" pipe)
    bad_light = None
    try:
        for j in range(1, workers):
            done, told = os.pipe()
            try:
                pid = os.fork()
            except OSError:                              # no more processes: this one does the rest
                os.close(done)
                os.close(told)
                break
            if pid == 0:                                 # worker: its stripes, then leave at once
                os.close(done)
                status = 1
                try:
                    run(range(j, len(rows), workers), range(K), parent)
                    status = 0
                except InputError:                       # bad light: this process tells it
                    status = BAD_LIGHT_STATUS
                except Exception:                        # (an interrupt: exit 1 quietly)
                    import traceback
                    traceback.print_exc()
                finally:
                    _tell(told, status)
                    os._exit(status)
            os.close(told)
            children[pid] = (j, done)
        readouts = (progress or iter)(range(K))         # (after the fork: a bar may start a thread)
        taken = {j for j, _ in children.values()}
        run([i for i in range(len(rows)) if i % workers not in taken], readouts)
    except BaseException as exc:
        for pid in children:
            os.kill(pid, 9)
        if not isinstance(exc, InputError):
            raise
        bad_light = exc                                  # (refused below, as the ordered scan does)
    finally:
        ended = []
        status = {j: _worker_status(pid, done, ended) for pid, (j, done) in children.items()}
        if ended:
            _reap_beside(ended)
    if bad_light is not None or BAD_LIGHT_STATUS in status.values():
        for k in range(K):                              # the refusal of the first bad readout
            scan_light(np.asarray(scene[k:k + 1]), what)
        raise bad_light or RuntimeError("a simulation worker refused light a scan of the scene passes")
    failed = [j for j, code in status.items() if code != 0]
    if failed:
        raise RuntimeError(f"simulation worker(s) {failed} failed (their stripes have no words)")
    return words


def _tell(told: int, status: int) -> None:
    """A worker's exit status, written on its "done" pipe just before it exits."""
    try:
        os.write(told, bytes([status]))
    except OSError:                                      # (its command is gone: nobody to tell)
        pass


def _worker_status(pid: int, done: int, ended: list) -> int:
    """A worker's exit status: the byte it wrote on its "done" pipe just before exiting (``pid``
    appended to ``ended``, to be reaped beside this process's own work: a worker's exit, the
    teardown of its address space, took 3-4 ms the command waited for), else, where it ended
    without one (killed), what ``waitpid`` tells (the negative signal number)."""
    try:
        told = os.read(done, 1)
    finally:
        os.close(done)
    if told:
        ended.append(pid)
        return told[0]
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])


#: Name of the thread that reaps workers once they have said they are done (:func:`_reap_beside`).
REAPER_NAME = "tespike-reap-stripe-workers"


def _reap_beside(pids: list) -> None:
    """Reap workers that have said they are done, on a thread of this process (not a daemon:
    the interpreter's exit, and ``tespike``'s, joins it, so no worker outlives the command)."""
    import threading

    def reap():
        for pid in pids:
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:
                pass
    threading.Thread(target=reap, name=REAPER_NAME).start()


def _join_reapers() -> None:
    """Wait for the reapers of earlier runs (their workers exit within milliseconds), so that
    no thread of this module is running when this process forks again (a fork copies one thread)."""
    import threading
    for thread in threading.enumerate():
        if thread.name == REAPER_NAME:
            thread.join()
