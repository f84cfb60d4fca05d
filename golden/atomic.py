"""Atomic output files: write a hidden temporary, move it into place only when complete.

Every writer of the project goes through :func:`atomic_output` (re-exported by
:mod:`tespike.golden.io`), so a failed or interrupted run never leaves a half-written
file. A run killed outright (SIGKILL: no handler, no ``finally``) leaves none either:
each temporary is registered with a small janitor process (:class:`_Janitor`) that
removes what is still registered once the run is gone. Standard library only, below
:mod:`tespike.golden.config` and :mod:`tespike.golden.io`, which both use it.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import functools
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Callable, Iterator

from .errors import InputError
from .paths import check_folder_path, check_output_file, passes_through, path_text


#: Hidden temporaries are named ``.<name>.<pid>.<random>.part`` beside the output;
#: the pid lets the next run at that path remove one a killed run left behind.
_PART_NAME = 100          # characters of the output's name kept in the temporary's name


#: Errors of a write that ran out of room: a full disk, a file-size limit (EFBIG), a quota. A
#: buffered write raises them at a later flush or close, often as an OSError naming no file,
#: which the writer then names (:func:`tespike.recon.train.appending`, the dataset build).
NO_ROOM = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)


#: Every output this process has moved into place whole, as the user named it, in order: an
#: interrupted command says which of its outputs were already complete (:func:`finished_outputs`).
_FINISHED: list[str] = []


def start_janitor(report_faults: bool = False, name: str = "tespike") -> None:
    """Start the process that removes this process's temporaries should it be killed outright
    (:class:`_Janitor`; best effort, started anyway with the first temporary). ``report_faults``
    (a command's whole process): a fatal signal, e.g. the bus error of reading a memory-mapped
    input another program cut short, ends in the janitor's one line naming the file
    (:func:`held_mapping`) instead of the shell's bare "Bus error"; the fault handler's own
    dump goes to the janitor, never to the terminal. ``name`` starts that line, as the
    command's own refusals start (``tespike simulate``)."""
    _Janitor.start()
    process = _Janitor._process
    if report_faults and process is not None:
        _Janitor._line(b"n" + os.fsencode(name).hex().encode())
        import faulthandler
        faulthandler.enable(file=process.stdin, all_threads=False)


def held_mapping(path: str | os.PathLike, size: int, opened: int | None = None) -> None:
    """``path`` (``size`` bytes) is read through a memory map: should a fatal signal end the run
    once it is shorter (another program cut it short), the janitor names it; and while a command
    watches its inputs (:func:`watching_inputs`), its outputs are not written should the file be
    written over in place meanwhile (:func:`check_inputs_unchanged`). ``opened``: a descriptor of the
    file, open since before its bytes were first read (e.g. for a CRC), that this takes over."""
    if _Janitor._process is not None and _Janitor._owner == os.getpid():
        try:
            changed = os.stat(path).st_mtime_ns      # (a file cut short, then written whole again, changed)
        except OSError:
            changed = -1
        _Janitor._send(b"m", path, b" %d %d" % (size, changed))
    key = os.fspath(path)
    if _watched is None or key in _watched:
        return                         # (an ``opened`` not taken is the caller's to close)
    try:
        fd = os.open(key, os.O_RDONLY) if opened is None else opened
    except OSError:                    # (no descriptor to spare: unwatched, as a library caller's)
        return
    try:
        _watched[key] = (fd, _signature(os.fstat(fd)))
    except OSError:
        os.close(fd)


#: While a command runs (:func:`watching_inputs`): each file it reads through a memory map -> a
#: descriptor of it and its (size, modification time) when first read; None outside a command.
_watched: dict[str, tuple[int, tuple]] | None = None


def watch_descriptor(path: str | os.PathLike) -> int | None:
    """A descriptor of ``path`` to hand to :func:`held_mapping` once the file is mapped, opened now,
    before its bytes are first read; None where nothing is watched (or no descriptor is to spare)."""
    if _watched is None or os.fspath(path) in _watched:
        return None
    try:
        return os.open(path, os.O_RDONLY)
    except OSError:
        return None


def taken_descriptors() -> set[int]:
    """The descriptors the watch holds (a caller closes an ``opened`` it did not take)."""
    return {fd for fd, _ in (_watched or {}).values()}


def _signature(info: os.stat_result) -> tuple:
    """What a write changes (not the change time: a link removed, the file replaced at its path,
    changes that too)."""
    return info.st_size, info.st_mtime_ns


@contextlib.contextmanager
def watching_inputs() -> Iterator[None]:
    """Watch, for the ``with`` (a command's run), the files read through memory maps
    (:func:`held_mapping`); the outputs it moves into place check them first
    (:func:`check_inputs_unchanged`). A library caller's reads are never watched."""
    global _watched
    outer, _watched = _watched, {}
    try:
        yield
    finally:
        for fd, _ in _watched.values():
            with contextlib.suppress(OSError):
                os.close(fd)
        _watched = outer


def check_inputs_unchanged() -> None:
    """Refuse (:class:`InputError`) to finish an output once a watched input was written over in
    place while the command read it (``dd conv=notrunc``, an editor saving in place): the output
    would mix the old bytes with the new ones (a reconstruction had blended two streams, exit 0).
    The file read is the one opened (a descriptor held): one replaced by a new file at its path, or
    removed, left what was read whole, and is no fault."""
    for path, (fd, seen) in (_watched or {}).items():
        try:
            now = _signature(os.fstat(fd))
        except OSError:
            continue
        if now != seen:
            raise InputError(f"input file {path!r} was written over while the command read it (its size or "
                             "modification time changed): no output written (run again on a file left alone)")


#: Folders this process holds (:func:`folder_held`), by real path -> [how many ``with`` blocks hold
#: each, the descriptor the outermost holds it open with].
_HELD_FOLDERS: dict[str, list[int]] = {}


@contextlib.contextmanager
def folder_held(path: str | os.PathLike, refusal: str) -> Iterator[Callable[[], bool]]:
    """Hold the existing folder ``path`` for this process alone for the ``with`` (an exclusive ``flock``
    on it; a link to a folder holds the folder): another process holding it is refused with
    ``InputError(f"{refusal} is held by another process ...")``. Held again inside (a command and
    the library function it calls), it is the same hold. The lock goes with the process however it ends.
    Yields a function that tells whether ``path`` still names the folder held (:func:`_still_named`:
    one removed during the run and made again at ``path`` by a writer is another)."""
    import fcntl
    key = os.path.realpath(path)
    if key in _HELD_FOLDERS:
        hold = _HELD_FOLDERS[key]
        hold[0] += 1
        try:
            yield functools.partial(_still_named, path, hold[1])
        finally:
            hold[0] -= 1
        return
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{refusal} is held by another process (another run writing it): wait for it "
                             "to end, or choose another") from None
        _HELD_FOLDERS[key] = [1, fd]
        try:
            yield functools.partial(_still_named, path, fd)
        finally:
            del _HELD_FOLDERS[key]
    finally:
        os.close(fd)


def process_group_holder():
    """A function for a child to call between fork and exec (``preexec_fn``, after it has made
    its own process group): it has the janitor kill that group should this process end before
    :func:`release_process_group`. Registered by the child itself, the group is held before
    the tool can start anything; registered by the parent after the start, a kill in between
    would leave what the tool started (make's compilers) running. The child writes one line
    to the janitor's pipe with ``os.write`` (atomic, and no lock a fork may have left held)."""
    _Janitor.start()
    process = _Janitor._process
    fd = process.stdin.fileno() if process is not None else None

    def hold() -> None:
        if fd is not None:
            try:
                os.write(fd, b"g%d\n" % os.getpid())
            except OSError:
                pass
    return hold


def release_process_group(group: int) -> None:
    """The process group ``group`` has ended (its tool returned and was cleaned up)."""
    _Janitor._line(b"e%d" % group)


#: The work folders (:func:`work_folder`) open in this process: files written inside them are
#: intermediates, never reported as outputs.
_WORK_FOLDERS: set[Path] = set()


@contextlib.contextmanager
def work_folder(prefix: str, dir: str | os.PathLike | None = None) -> Iterator[Path]:
    """A new folder for a run's intermediate files (the inputs and outputs of the tools it
    drives): removed when the block ends, and by the janitor should this process be killed
    outright (``tempfile.TemporaryDirectory`` left it behind); renamed away inside the block
    (a finished build moved into its cache), nothing is removed. Files written in it with
    :func:`atomic_output` are not reported among the run's outputs (:func:`finished_outputs`)."""
    path = real = None
    try:
        with stops_held():              # (made and held as one step: a stop in between left it behind)
            path = Path(tempfile.mkdtemp(prefix=prefix, dir=dir))
            _Janitor.hold(path)
        real = Path(os.path.realpath(path))
        _WORK_FOLDERS.add(real)
        yield path
    finally:
        _WORK_FOLDERS.discard(real)
        if path is not None:
            _remove_held(path)


def run_temporaries(prefix: str = "tespike-run-") -> Path | None:
    """Give this process, and every process it starts, a temporary folder of its own: made in the
    temporary directory (``$TMPDIR``, else ``/tmp``), held by the janitor and made ``tempfile``'s
    folder and ``$TMPDIR`` for the rest of the process. What the outside tools write there (Yosys's
    ABC folders, Icarus's and the compiler's temporaries, Dask's scratch space, torch's) goes with it
    when the process ends, killed outright or interrupted too (they had been left in ``$TMPDIR``).
    None, nothing changed, where the folder cannot be made (the temporaries then fail as before,
    naming the directory), or where no janitor runs (out of file handles, ``ulimit -n``): the folder
    would outlive a kill. This process removes it itself at its exit (:mod:`atexit`, before the
    janitor ends); the janitor, once this process is gone however it ended."""
    _Janitor.start()
    if _Janitor._process is None or _Janitor._owner != os.getpid():
        return None
    _remove_stale_run_folders(prefix)
    try:
        with stops_held():              # (made, locked and held as one step)
            for _ in range(8):          # (another run's sweep may take a folder not yet locked)
                path = Path(tempfile.mkdtemp(prefix=prefix))
                try:
                    if _lock_run_folder(path):
                        break
                except OSError:         # (out of file handles, no flock there: no folder rather than one unheld)
                    with contextlib.suppress(OSError):
                        os.rmdir(path)
                    return None
            else:
                return None
            _Janitor.hold(path)
    except OSError:
        return None
    owner = os.getpid()

    def remove() -> None:               # (a forked child that runs the exit handlers leaves it alone)
        if os.getpid() == owner:
            _remove_held(path)
    atexit.register(remove)
    tempfile.tempdir = str(path)
    os.environ["TMPDIR"] = str(path)
    return path


#: Descriptors of this process's run folders, each under its ``flock`` for the process's life.
_RUN_FOLDER_LOCKS: list[int] = []


def _lock_run_folder(path: Path) -> bool:
    """Lock this process's new run folder (a shared ``flock`` on it, kept open until the process
    ends, however it ends): the mark by which a later run tells a folder in use from one a killed
    run left (:func:`_remove_stale_run_folders`), across process namespaces, where a pid would not.
    False where another run's sweep removed it before the lock was taken (made again)."""
    import fcntl
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)    # (OSError, here or from flock: the caller's)
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)  # (waits out a sweep holding it)
    except BaseException:
        os.close(fd)
        raise
    if not _still_named(path, fd):
        os.close(fd)
        return False
    _RUN_FOLDER_LOCKS.append(fd)
    return True


def _remove_stale_run_folders(prefix: str) -> None:
    """Remove the run folders (``prefix`` + 8 characters, in the temporary directory) that no live
    process holds: those of runs killed outright together with their janitor (a container's or the
    out-of-memory killer's SIGKILL of every process), which nothing else would remove. A folder is
    stale when its exclusive ``flock`` can be taken: every process of its run is gone. Only this
    user's folders, never a link."""
    import fcntl
    pattern = re.compile(re.escape(prefix) + r"[A-Za-z0-9_]{8}")
    try:
        entries = [e for e in os.scandir(tempfile.gettempdir()) if e.name.startswith(prefix)]
    except OSError:
        return
    for entry in entries:
        try:
            if (not pattern.fullmatch(entry.name) or not entry.is_dir(follow_symlinks=False)
                    or entry.stat(follow_symlinks=False).st_uid != os.getuid()):
                continue
            fd = os.open(entry.path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:                     # (held: its run is alive)
            os.close(fd)
            continue
        try:
            shutil.rmtree(entry.path, ignore_errors=True)
        finally:
            os.close(fd)


def _remove_held(path: str | Path) -> None:
    """Remove a temporary (file or folder) the janitor holds, and release it; where it cannot be
    removed whole (out of file handles: ``rmtree`` opens each folder it walks), the janitor keeps it
    and removes it once this process ends. A temporary already renamed into place is only released."""
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            os.unlink(path)
    if not os.path.lexists(path):
        _Janitor.release(path)


def _names_inside(filename, folder: Path, target: Path) -> bool:
    """Whether an error's ``filename`` is the results folder being built (``folder``), a file in it,
    or its target: a file the run writes, not one it reads."""
    try:
        name = Path(os.path.abspath(os.fspath(filename)))
    except (TypeError, ValueError):
        return True
    return any(name == place or name.is_relative_to(place) for place in (Path(folder), target))


def _finished(target: Path, shown: str) -> None:
    """``shown`` (the user's name of ``target``) was moved into place whole: an output of the
    run, unless written inside a work folder."""
    real = Path(os.path.realpath(target))
    if not any(real.is_relative_to(folder) for folder in _WORK_FOLDERS):
        _FINISHED.append(shown)


def finished_outputs(since: int = 0) -> list[str]:
    """The outputs moved into place whole since the ``since``-th (``len(finished_outputs())`` marks a start)."""
    return _FINISHED[since:]


#: The janitor: reads ``+HEX`` (a temporary made) and ``-HEX`` (settled) lines, the paths'
#: bytes in hex, and ``gPGID`` / ``ePGID`` lines (an outside tool's process group started,
#: ended: :func:`process_group_holder`), and once its input ends (the run is over, however it
#: ended) kills every process group and removes every path still registered. In a session
#: of its own, so a signal to the run's process group (Ctrl-C, a kill of the group) leaves
#: it to clean up.
_JANITOR_CODE = r"""
import os, shutil, signal, sys
held, groups, mapped, fault, name = set(), set(), {}, None, "tespike"
for line in sys.stdin.buffer:
    line = line.strip()
    try:                                              # (the fault handler's dump shares the pipe)
        if line.startswith(b"Fatal Python error: "):  # its first line (report_faults)
            fault = fault or line[20:].decode(errors="replace").strip(": ")
        elif line[:1] == b"n":                        # (the command, as its refusals name it)
            name = os.fsdecode(bytes.fromhex(line[1:].decode()))
        elif line[:1] == b"m":
            path, _, rest = line[1:].partition(b" ")
            size, _, changed = rest.partition(b" ")
            mapped[bytes.fromhex(path.decode())] = (int(size), int(changed or -1))
        elif line[:1] == b"+":
            held.add(bytes.fromhex(line[1:].decode()))
        elif line[:1] == b"-":
            held.discard(bytes.fromhex(line[1:].decode()))
        elif line[:1] == b"g":
            groups.add(int(line[1:]))
        elif line[:1] == b"e":
            groups.discard(int(line[1:]))
    except ValueError:
        pass
for group in groups:
    try:
        os.killpg(group, signal.SIGKILL)
    except OSError:
        pass
for path in held:
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            os.unlink(path)
        except OSError:
            pass
if fault:
    def now(path):
        try:
            info = os.stat(path)
            return info.st_size, info.st_mtime_ns
        except OSError:
            return -1, -1
    cut = [path for path, (was, _) in mapped.items() if now(path)[0] < was]
    changed = [path for path, (_, was) in mapped.items() if was != -1 and now(path)[1] not in (-1, was)]
    if cut:
        text = (f"{name}: error: input file {os.fsdecode(cut[0])!r} was cut short while it was read "
                f"({fault}: it changed under the command; run again on a file left alone)")
    elif changed:               # (cut short, then written whole again before this looked)
        text = (f"{name}: error: input file {os.fsdecode(changed[0])!r} changed while it was read "
                f"({fault}: another program wrote it; run again on a file left alone)")
    else:
        text = f"{name}: error: the process ended on a fatal signal ({fault})"
        try:                    # (the command's own limits, inherited: a library may die of one in C)
            import resource
            limit = resource.getrlimit(resource.RLIMIT_AS)[0]
            limit = 0 if limit == resource.RLIM_INFINITY else limit
        except (ImportError, OSError, ValueError):
            limit = 0
        if limit > 0:
            text += (f", under an address-space limit (ulimit -v) of {limit >> 20} MB: most likely out of "
                     "memory (raise the limit, or take less: a smaller --batch or --crop)")
    sys.stderr.write(text + "\n")
    sys.stderr.flush()
os._exit(0)                     # (its interpreter's teardown took 3 ms the command waited for)
"""


class _Janitor:
    """This process's janitor (started with its first temporary; a forked child starts its own).
    Best effort: where it cannot start, temporaries are still removed by ``finally`` and, after
    a kill, by the next run at that path (:func:`_remove_stale_parts`)."""

    _process: subprocess.Popen | None = None
    _owner: int | None = None

    @classmethod
    def start(cls) -> None:
        """Start this process's janitor now (a command does, before its work): started with
        the first temporary instead, it could still be starting when a kill comes."""
        if cls._owner != os.getpid():
            cls._owner, cls._process = os.getpid(), None
            try:
                cls._process = subprocess.Popen([sys.executable, "-I", "-S", "-c", _JANITOR_CODE],
                                                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                                start_new_session=True)   # (stderr: its one fault line)
            except OSError:
                return
            atexit.register(cls._close)

    @classmethod
    def hold(cls, path: str | Path) -> None:
        """Remove ``path`` if this process ends before :meth:`release`."""
        cls._send(b"+", path)

    @classmethod
    def release(cls, path: str | Path) -> None:
        cls._send(b"-", path)

    @classmethod
    def _send(cls, mark: bytes, path: str | Path, tail: bytes = b"") -> None:
        cls._line(mark + os.fsencode(os.fspath(path)).hex().encode() + tail)

    @classmethod
    def _line(cls, line: bytes) -> None:
        cls.start()
        if cls._process is not None:
            try:
                cls._process.stdin.write(line + b"\n")
                cls._process.stdin.flush()
            except (OSError, ValueError):
                cls._process = None

    @classmethod
    def _close(cls) -> None:
        """At a normal exit: end the janitor (nothing is registered any more) and reap it."""
        process, cls._process = cls._process, None
        if process is not None and cls._owner == os.getpid():
            import faulthandler
            if faulthandler.is_enabled():            # (its file, the pipe, is about to close)
                faulthandler.disable()
            with contextlib.suppress(OSError, ValueError, subprocess.TimeoutExpired):
                process.stdin.close()
                process.wait(5)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _remove_stale_parts(directory: Path, stem: str, folders: bool = False) -> None:
    """Remove ``.<stem>.<pid>.<random>.part`` files (``folders``: folders) whose process is gone (killed runs)."""
    pattern = re.compile(r"\." + re.escape(stem) + r"\.(\d+)\.[A-Za-z0-9_]{8}\.part")
    try:
        entries = [e for e in os.scandir(directory) if e.name.startswith("." + stem + ".")]
    except OSError:
        return
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        kind = entry.is_dir(follow_symlinks=False) if folders else entry.is_file(follow_symlinks=False)
        if not match or not kind:
            continue
        pid = int(match.group(1))
        if pid == os.getpid():
            continue
        try:
            os.kill(pid, 0)
            continue                        # its writer is still running
        except ProcessLookupError:
            pass
        except (PermissionError, OverflowError):
            continue
        if folders:
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.unlink(entry.path)


def _write_error(path: str, exc: OSError) -> InputError:
    """An OSError of writing, as one line naming the user's path (never the temporary)."""
    from .resources import file_handles_fault, file_size_text
    if exc.errno is None and "requested" in str(exc):          # numpy's short write: a full disk
        reason = _file_size_limit(path) or f"short write ({exc}); is the disk full?"
    else:
        reason = file_handles_fault(exc) or exc.strerror or str(exc) or type(exc).__name__
        if exc.errno == errno.EFBIG:                    # (the system's words name no limit)
            reason += file_size_text()
    return InputError(f"cannot write {path!r}: {reason}")


def _file_size_limit(path: str) -> str | None:
    """Why a short write stopped where the disk still has room: the process's file size limit
    (``ulimit -f``; Python ignores its SIGXFSZ, so the write is cut at the limit), else None."""
    try:
        import resource
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if limit == resource.RLIM_INFINITY:
            return None
        folder = os.statvfs(os.path.dirname(os.path.abspath(path)))
    except (ImportError, OSError, ValueError):
        return None
    if folder.f_bavail * folder.f_frsize <= limit:              # (room for less than the limit: maybe full)
        return None
    from .resources import file_size_text
    return f"File too large{file_size_text()}"


@contextlib.contextmanager
def atomic_output(path: str | Path, what: str | None = None) -> Iterator[str]:
    """Yield a temporary path to write; on success move it to ``path``, else remove it.

    ``path`` is checked with :func:`tespike.golden.paths.check_output_file` first. A
    symlink's target is replaced (the link stays); a character device or FIFO
    (``/dev/null``, a pipe) is written through once the temporary is complete,
    never replaced. The file gets the mode the user's umask gives (an existing
    file keeps its mode). Temporaries are ``.<name>.<pid>.<random>.part`` beside
    the target; one left by a killed run is removed by the next run at that path.
    Any OSError while writing becomes an :class:`InputError` naming ``path``.
    """
    target = check_output_file(path, what)
    shown = os.fspath(path)
    try:
        info = os.stat(target)
    except OSError:
        info = None
    through = info is not None and passes_through(info.st_mode)
    if through:
        directory = Path(tempfile.gettempdir())
        prefix = f".tespike.{os.getpid()}."
    else:
        directory = target.parent
        stem = target.name[:_PART_NAME]
        _remove_stale_parts(directory, stem)
        prefix = f".{stem}.{os.getpid()}."
    tmp, deferred = None, False
    try:
        try:
            with stops_held():          # (made and held as one step: a stop in between left it behind)
                fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=".part", dir=directory)
                os.close(fd)
                _Janitor.hold(tmp)
        except OSError as exc:
            raise _write_error(shown, exc) from None
        try:
            yield tmp
            check_inputs_unchanged()
            if through:
                _write_through(tmp, target, shown)
                _finished(target, shown)
            else:
                mode = (info.st_mode & 0o777) if info is not None else (0o666 & ~_umask())
                os.chmod(tmp, mode)
                group = next((g for g in reversed(_together) if target in g[0]), None)
                if group is not None:              # renamed with the group's other outputs
                    group[1].append((tmp, target, shown))
                    deferred = True
                else:
                    with stops_held():
                        os.replace(tmp, target)
                        _finished(target, shown)
        except OSError as exc:
            if exc.filename not in (None, tmp, str(target)):
                raise                              # about another file: the caller names it
            raise _write_error(shown, exc) from None
    finally:
        if tmp is not None and not deferred:
            _remove_held(tmp)


#: The open groups of :func:`outputs_together`, innermost last: each (its targets, the finished
#: temporaries (temporary, target, name shown) waiting for the group's end).
_together: list[tuple[set, list]] = []


@contextlib.contextmanager
def outputs_together(*paths):
    """The outputs ``paths`` (None entries ignored) that :func:`atomic_output` finishes inside the
    block are renamed into place together when the block ends, in one :func:`stops_held` step; a
    block that fails or is stopped renames none of them (other files, e.g. a tool's work files,
    are renamed as usual). For a command whose outputs are one run's (``rtl-sim``'s stream,
    waveform and save file): written one after the other, a stop between them left the new
    waveform beside the previous run's stream. (A SIGKILL between two renames of the step can
    still split them.)"""
    pending: list = []
    group = ({check_output_file(path) for path in paths if path is not None}, pending)
    _together.append(group)
    try:
        try:
            yield
        finally:
            _together.remove(group)
        with stops_held():
            for tmp, target, shown in pending:
                try:
                    os.replace(tmp, target)
                except OSError as exc:
                    raise _write_error(shown, exc) from None
                _finished(target, shown)
    finally:                                   # (a renamed temporary is gone: its unlink does nothing)
        for tmp, _, _ in pending:
            _remove_held(tmp)


#: Signals that stop a command, held while an output is committed (:func:`stops_held`) or a
#: library whose start cannot be interrupted is loading (``cosim.library_room``).
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


#: Stops (signal numbers) the command's handlers turned into exceptions (:func:`note_stop`). Python
#: prints and drops an exception raised inside a finalizer (a ``__del__``, a weakref callback), and
#: the command would go on to rename its outputs into place and end as if never stopped.
_stops_raised: list[int] = []


def note_stop(signum: int) -> None:
    """Record that a handler is raising the stop ``signum`` (the command's handlers call it)."""
    _stops_raised.append(signum)


def forget_stops() -> None:
    """Forget the stops recorded (at a command's end: the next, in this process too, starts with none)."""
    _stops_raised.clear()


def raise_lost_stop() -> None:
    """Raise again, through its handler, a stop a handler raised that is not being handled now, so was
    dropped on the way (in a finalizer). A stop being handled (a checkpoint saved before it goes on)
    is not lost."""
    handling = sys.exception()
    if not _stops_raised or (handling is not None and not isinstance(handling, Exception)) \
            or threading.current_thread() is not threading.main_thread():
        return
    number = _stops_raised[-1]
    handler = signal.getsignal(number)
    if callable(handler):
        handler(number, None)


@contextlib.contextmanager
def stops_held(again: bool = True):
    """Ctrl-C, SIGTERM and SIGHUP held while an output is renamed into place and recorded as
    written, then raised again through the handlers they would have met: a command stopped there
    reports the output as written (:func:`finished_outputs`), never a replaced file it does not
    name. A stop dropped earlier (:func:`raise_lost_stop`) is raised first: nothing is renamed. Only the
    main thread can change the handlers (elsewhere nothing is held). ``again=False``: the stops held
    are dropped, for work a stop being handled does on its way out (the checkpoint an interrupted
    training saves: a second Ctrl-C, pressed while it was written, had lost the run)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raise_lost_stop()
    held, previous = [], {}
    for number in STOP_SIGNALS:
        if signal.getsignal(number) not in (signal.SIG_IGN, None):
            previous[number] = signal.signal(number, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        for number in held if again else ():
            signal.raise_signal(number)


def _write_through(tmp: str, target: Path, shown: str) -> None:
    """Copy a finished temporary into a character device or FIFO (never replacing it)."""
    try:
        fd = os.open(target, os.O_WRONLY | os.O_NONBLOCK)
    except OSError as exc:
        if exc.errno == errno.ENXIO:
            raise InputError(f"cannot write {shown!r}: the FIFO has no reader") from None
        raise
    os.set_blocking(fd, True)
    with os.fdopen(fd, "wb") as out, open(tmp, "rb") as source:
        shutil.copyfileobj(source, out, 1 << 20)


#: renameat2's flag that swaps two paths in one step (Linux >= 3.15).
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: str, b: str) -> bool:
    """Swap two existing paths in one atomic step; False where the system cannot."""
    import ctypes
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EPERM, errno.ENOTSUP):
        return False
    raise OSError(code, os.strerror(code), b)


def folder_holds_files(path: str | Path) -> bool:
    """Whether ``path`` is a folder with anything in it (a previous run's results)."""
    try:
        with os.scandir(path) as entries:
            return any(True for _ in entries)
    except (FileNotFoundError, NotADirectoryError):
        return False


def _still_named(path: str | Path, fd: int) -> bool:
    """Whether ``path`` still names the folder open as ``fd`` (held open, its inode is no other
    folder's meanwhile: one removed and made again at ``path`` is another)."""
    try:
        held, now = os.fstat(fd), os.stat(path)
    except OSError:
        return False
    return held.st_nlink > 0 and (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino)


def _check_same_folder(tmp: Path, made: int | None, shown: str) -> None:
    """Refuse to move ``tmp`` into place unless it is still the folder made for the run (``made``: a
    descriptor of it, open since; None: not checked): one removed during the run (with the folder
    holding it) and made again by a writer's ``mkdir(parents=True)`` held only the files written
    after, and had been moved into place, the command exiting 0."""
    if made is not None and not _still_named(tmp, made):
        raise InputError(f"cannot write {shown!r}: the folder it was being built in "
                         f"({str(tmp.parent)!r}) was removed during the run; nothing written")


@contextlib.contextmanager
def atomic_folder(path: str | Path, replace: bool = True) -> Iterator[Path]:
    """Yield a hidden temporary folder to fill; on success it becomes ``path`` whole, else it is removed.

    A results folder is one run's: the new folder is built beside the target
    (``.<name>.<pid>.<random>.part``, same file system) and swapped with it in one
    step (Linux ``renameat2``; elsewhere two renames), the previous contents then
    removed. Killed or failing at any moment, ``path`` holds the previous run whole
    or the new one whole; a temporary a killed run left is removed by the next run.
    A symlink ``path`` keeps pointing where it did (its target folder is replaced).
    Errors naming a file inside the temporary are re-worded to name it under ``path``.
    ``replace=False`` (a run that found ``path`` new or empty, not told to replace it): a ``path``
    that holds files when the new folder is ready, another run's finished meanwhile, is refused and
    kept (the later of two runs into one new folder had replaced the other's results).
    """
    shown = path_text(path, "folder")
    check_folder_path(shown, "folder")              # ('' or nosuch/..: the folder holding the inputs)
    target = Path(os.path.realpath(shown))
    stem = target.name[:_PART_NAME]
    _remove_stale_parts(target.parent, stem, folders=True)
    tmp, inside, made = None, None, None
    mark = len(_FINISHED)          # files written inside the temporary are not outputs yet

    def reworded(text: str) -> str:
        return text.replace(inside, shown.rstrip("/") or shown) if inside else text

    try:
        try:
            with stops_held():          # (made and held as one step: a stop in between left it behind)
                tmp = Path(tempfile.mkdtemp(prefix=f".{stem}.{os.getpid()}.", suffix=".part", dir=target.parent))
                _Janitor.hold(tmp)
            inside = str(tmp)
            os.chmod(tmp, 0o777 & ~_umask())
        except OSError as exc:
            raise _write_error(shown, exc) from None
        try:                            # (held open, its inode cannot be another folder's while the run lasts)
            made = os.open(tmp, os.O_RDONLY | os.O_DIRECTORY)
        except OSError:                 # (out of file handles: not checked)
            made = None
        try:
            yield tmp
            check_inputs_unchanged()
            _check_same_folder(tmp, made, shown)
            with stops_held():                    # (the two renames below are one step to a stop)
                if not replace and folder_holds_files(target):
                    raise InputError(f"folder {shown!r} was filled by another run while this one ran; it is kept: "
                                     "replace it with --force, or choose another folder")
                if not os.path.lexists(target):
                    os.rename(tmp, target)
                elif not folder_holds_files(target) and target.is_dir():
                    os.replace(tmp, target)        # an empty folder is replaced in one step
                elif _exchange(str(tmp), str(target)):
                    pass                           # tmp now holds the previous run: removed below
                else:
                    old = Path(tempfile.mkdtemp(prefix=f".{stem}.{os.getpid()}.", suffix=".part",
                                                dir=target.parent))
                    os.rename(target, old / "previous")
                    os.rename(tmp, target)
                    os.rename(old, tmp)
                del _FINISHED[mark:]
                _finished(target, shown)
        except InputError as exc:
            raise InputError(reworded(str(exc))) from None
        except OSError as exc:
            if exc.filename and not _names_inside(exc.filename, tmp, target):
                raise                              # a file the run read (a font out of handles): not written
            raise _write_error(reworded(os.fspath(exc.filename)) if exc.filename else shown, exc) from None
    finally:
        if _FINISHED[mark:] != [shown]:
            del _FINISHED[mark:]
        if made is not None:
            os.close(made)
        if tmp is not None:
            _remove_held(tmp)
