"""Outside tools and worker processes end with the command that started them.

A command killed outright (SIGKILL, the kernel's out-of-memory killer) runs no
handler, so what it started would run on for nobody: Yosys, a solver, a
simulator or a proof worker, for minutes. On Linux each such child asks the
kernel for SIGKILL when its parent goes (``prctl(PR_SET_PDEATHSIG)``), and one
whose parent is already gone when it asks leaves at once. Elsewhere nothing
changes. Every outside tool of :mod:`tespike.cosim` is started through
:func:`run` or :func:`popen`; the proof workers call :func:`end_with_parent`.
A tool that starts tools of its own (a build through make, whose compilers the
signal does not reach) runs in a process group of its own through
:func:`run_group`: the group is killed when the tool returns or is interrupted,
and by the command's janitor (:func:`tespike.golden.atomic.process_group_holder`,
which the tool's process registers itself before its exec)
when the command is killed outright.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import subprocess
import sys

#: ``PR_SET_PDEATHSIG`` of ``<linux/prctl.h>``.
PR_SET_PDEATHSIG = 1


def _prctl():
    """libc's ``prctl`` (Linux), looked up once in the parent: a forked child calls it and nothing else."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    prctl.argtypes = (ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong)
    prctl.restype = ctypes.c_int
    return prctl


_PRCTL = _prctl()


def end_with_parent(parent: int) -> None:
    """In a child process of ``parent``: get SIGKILL when the parent goes, and leave now if it
    already has (it may have gone between the fork and this call)."""
    if _PRCTL is not None:
        _PRCTL(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:
        os._exit(1)


def _preexec(parent: int):
    return (lambda: end_with_parent(parent)) if _PRCTL is not None else None


def ended(returncode: int) -> str:
    """How an outside tool that printed nothing ended, for the line of its failure: its exit status,
    or the signal that killed it (SIGXFSZ: the file size limit a write went past; a tool gets the
    system's default action for it, where Python ignores it)."""
    if returncode >= 0:
        return f"exit status {returncode}"
    try:
        name = signal.Signals(-returncode).name
    except ValueError:
        return f"killed by signal {-returncode}"
    if name == "SIGXFSZ":
        from tespike.golden.resources import file_size_text
        return f"killed by SIGXFSZ{file_size_text()}"
    return f"killed by {name}"


#: Free bytes below which an outside tool's failure in its work folder is put down to a full disk.
FULL_BELOW = 1 << 20


def room_note(folder) -> str:
    """``" (...)"`` saying that the file system of ``folder`` (a tool's work folder, in ``$TMPDIR``) is
    full, where it has less than FULL_BELOW bytes free; else "". A tool that cannot write its files
    seldom says so: yosys-smtbmc had ended in "gave no verdict: ## 0:00:00 Solver: z3"."""
    try:
        info = os.statvfs(folder)
    except OSError:
        return ""
    free = info.f_bavail * info.f_frsize
    if free >= FULL_BELOW:
        return ""
    return f" (the file system of its work folder {os.fspath(folder)!r} is full: {free // 1024} KiB free)"


def write_work_file(path, data: str | bytes) -> None:
    """Write a tool's input file into its work folder (``Path.write_text`` or ``write_bytes``); a failed
    write names the file: on a full disk or past ``ulimit -f`` Python's write raises an OSError that
    names none, and the command's line had been a bare "No space left on device"."""
    from pathlib import Path
    path = Path(path)
    try:
        if isinstance(data, bytes):
            path.write_bytes(data)
        else:
            path.write_text(data)
    except OSError as exc:
        if exc.filename is None and exc.errno is not None:
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise


def run(argv, **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run`` of a child that ends with this process."""
    return subprocess.run(argv, preexec_fn=_preexec(os.getpid()), **kwargs)


def popen(argv, **kwargs) -> subprocess.Popen:
    """``subprocess.Popen`` of a child that ends with this process."""
    return subprocess.Popen(argv, preexec_fn=_preexec(os.getpid()), **kwargs)


def run_group(argv, **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run`` of a child in a process group of its own that ends with this process,
    everything it started included: the group is killed once the child has returned (a
    compiler make left behind) or this process is interrupted, and by the janitor should this
    process be killed outright. Ctrl-C reaches only this process, which ends the group."""
    from tespike.golden.atomic import process_group_holder, release_process_group
    options = {k: v for k, v in kwargs.items() if k not in ("input", "timeout", "check", "capture_output")}
    if kwargs.get("capture_output"):                   # (as subprocess.run reads its options)
        options["stdout"] = options["stderr"] = subprocess.PIPE
    if kwargs.get("input") is not None:
        options["stdin"] = subprocess.PIPE
    parent, hold = os.getpid(), process_group_holder()

    def start_in_group() -> None:
        if _PRCTL is not None:
            end_with_parent(parent)
        hold()

    process = subprocess.Popen(argv, preexec_fn=start_in_group, process_group=0, **options)
    try:
        out, err = process.communicate(kwargs.get("input"), timeout=kwargs.get("timeout"))
    finally:
        try:
            os.killpg(process.pid, signal.SIGKILL)
        except OSError:                      # (the group is gone: nothing was left in it)
            pass
        process.wait()
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream is not None:
                stream.close()
        release_process_group(process.pid)
    done = subprocess.CompletedProcess(argv, process.returncode, out, err)
    if kwargs.get("check"):
        done.check_returncode()
    return done

