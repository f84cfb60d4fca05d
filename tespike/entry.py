"""The ``tespike`` command's entry point (the installed script and ``python3 -m tespike``).

It imports nothing heavy, so the command's clean endings hold from its first instant:
Ctrl-C while numpy loads (the first 0.2 s) is one line, not a traceback, and a process
whose address space (``ulimit -v``) cannot hold Python and numpy is refused in one line
instead of numpy's 40-line import error or OpenBLAS's messages and exit from C.
"""

import sys

#: Address space a started command needs beyond what importing it takes (its first arrays).
START_MARGIN = 16 << 20
#: Seconds the trial start may take (a few tenths normally).
PROBE_SECONDS = 60
#: What a failed start or import prints when the address space, not the code, was at fault (CPython's
#: SystemError there is an allocation that failed in C: "error return without exception set").
NO_ROOM_WORDS = ("alloc", "memory", "Memory", "map segment", "pthread_create", "can't start new thread",
                 "SystemError")


class _Stopped(BaseException):
    """SIGTERM or SIGHUP before the command's own handling is in place."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _stop_early(signum, frame):
    raise _Stopped(signum)


#: Marks the handler the command's own (tespike.cosim.cli) replaces once it runs.
_stop_early.tespike_early = True


def _hold_early_signals() -> None:
    """SIGTERM and SIGHUP while numpy loads end in one line too (the process ended silently, exit
    143, when the signal came in its first 0.2 s); the command installs its own handlers later."""
    import signal
    for name in ("SIGTERM", "SIGHUP"):
        number = getattr(signal, name, None)
        if number is not None and signal.getsignal(number) in (signal.SIG_DFL, None):
            signal.signal(number, _stop_early)


def _stopped(exc: _Stopped) -> int:
    import signal
    print(f"tespike: terminated by {signal.Signals(exc.signum).name}", file=sys.stderr)
    return 128 + exc.signum


def _fill_closed_descriptors() -> None:
    """Give a closed standard descriptor (``tespike ... >&- 2>&-``) the null device, so that no pipe
    or file the command opens takes its number (the cleanup process's pipe became stdout and stderr,
    and the command ended with exit 1 and no line); a closed stdout stays ``None`` in ``sys``, for the
    command to refuse writing to it (:func:`tespike.cosim.console.name_standard_output`), and a closed
    stderr swallows the command's lines (they cannot be shown; the exit status still tells)."""
    import os
    for number in (0, 1, 2):
        try:
            os.fstat(number)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != number:
                os.dup2(null, number)
                os.close(null)
    if sys.stderr is None:
        sys.stderr = open(os.devnull, "w")


def main() -> int:
    """Run ``tespike`` with the process's arguments; the exit status."""
    _fill_closed_descriptors()
    _hold_early_signals()
    _one_blas_thread()
    try:
        refusal = _address_space_refusal()
        if refusal:
            print(f"tespike: error: {refusal}", file=sys.stderr)
            return 1
        from tespike.cosim.cli import main as command
    except KeyboardInterrupt:          # while numpy loads, before the command's own handling
        print("tespike: interrupted", file=sys.stderr)
        return 130
    except _Stopped as exc:
        return _stopped(exc)
    except MemoryError:
        print(f"tespike: error: {_starved()}", file=sys.stderr)
        return 1
    except ImportError as exc:         # a library that could not be mapped into the address space
        if _address_space_limit() is None or not any(word in str(exc) for word in NO_ROOM_WORDS):
            raise
        print(f"tespike: error: {_starved()}", file=sys.stderr)
        return 1
    try:
        return command()
    except KeyboardInterrupt:          # while the arguments are read, outside the command's handling
        print("tespike: interrupted", file=sys.stderr)
        return 130
    except _Stopped as exc:
        return _stopped(exc)


def run() -> None:
    """The installed ``tespike`` and ``python3 -m tespike``: :func:`main`, then the process ends
    with its status once what Python's exit does for the command is done (:func:`_leave`)."""
    try:
        code = main()
    except SystemExit as exc:          # (argparse's help and usage errors; what Python would print)
        code = exc.code
        if code is not None and not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
    _leave(0 if code is None else code)


def _leave(code: int) -> None:
    """End the process with ``code`` after the part of Python's exit a command needs: its non-daemon
    threads joined (``threading._shutdown``, as the interpreter's exit calls it), the exit handlers
    run (the janitor's, multiprocessing's, weakref finalizers, logging's) and the standard streams
    flushed; then ``os._exit``. The interpreter's module teardown that would follow frees memory the
    system frees anyway: it took 25 ms of a 0.55 s ``simulate`` and 0.9 s after a ``demo`` (torch's
    modules), and Ctrl-C during it ended the process by the signal, silently (the handlers are the
    system's by then), after the command had ended and said so. Every file the commands write is
    closed before they return (``with`` blocks, atomic outputs renamed into place)."""
    import atexit
    import threading
    shutdown = getattr(threading, "_shutdown", None)
    if shutdown is not None:
        shutdown()
    atexit._run_exitfuncs()
    end_process(code)


def end_process(code: int) -> None:
    """Flush the standard streams and end the process at once with ``code`` (120 where a flush of
    a run that succeeded fails, as Python's exit reports it); also what a stop during the exit
    handlers does once the command has ended (``tespike.cosim.cli``)."""
    import os
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            code = code or 120
    os._exit(code)


def _address_space_limit() -> int | None:
    """The soft RLIMIT_AS in bytes (``ulimit -v``), None when unlimited (as
    ``tespike.golden.resources.address_space_limit``, which cannot be imported here:
    ``tespike.golden`` loads numpy)."""
    import resource
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else soft


def _one_blas_thread() -> None:
    """Numpy's OpenBLAS starts on one thread unless the user chose a count (``OPENBLAS_NUM_THREADS``).
    tespike's numpy work is elementwise (no BLAS call that threads would speed up; torch has its
    own), and the threads OpenBLAS starts at import spin on the other cores until the first fork
    or for about 0.1 s: a quarter of the other core's time through a 0.25 s ``tespike simulate``,
    whose janitor and stripe worker then waited for a core (9 % of its wall time on a dim pan,
    ``benchmarks/bench_startup.py``). Under an address-space limit each thread also reserved tens
    of MB at import, and near the limit a failed reservation hung the start, crashed it (SIGSEGV)
    or left a C extension returning no exception (``SystemError``)."""
    import os
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _starved() -> str:
    limit = _address_space_limit()
    where = f" within the address-space limit (ulimit -v) of {limit >> 20} MB" if limit is not None else ""
    return f"out of memory: Python and numpy cannot start{where}"


def _address_space_refusal() -> str | None:
    """Under an address-space limit only: whether the command can start, tried in a child
    process (about 0.2 s). Numpy's OpenBLAS reserves about 40 MB per core at import and, when
    that fails, prints its own lines and may end the process from C, past any handling here."""
    if _address_space_limit() is None:
        return None
    import os
    import subprocess
    probe = f"import mmap, tespike.cosim.cli\nmmap.mmap(-1, {START_MARGIN})\n"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))   # this process's tespike
    try:
        done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env,
                              stdin=subprocess.DEVNULL, timeout=PROBE_SECONDS)
    except OSError:                    # no process to try it in: the import itself will tell
        return None
    except subprocess.TimeoutExpired:  # OpenBLAS short of threads' room can hang its start
        return _starved()
    return _starved() if short_of_room(done) else None


def short_of_room(done) -> bool:
    """Whether a trial start or import in a child (a ``subprocess.CompletedProcess``) failed for
    want of address space: killed by a signal (a failed reservation met as SIGSEGV or SIGABRT), or
    saying so (:data:`NO_ROOM_WORDS`); another failure is left for the real start to tell."""
    return done.returncode != 0 and (done.returncode < 0 or any(word in done.stderr for word in NO_ROOM_WORDS))
