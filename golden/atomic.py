"""Atomic output files: write a hidden temporary, move it into place only when complete.

Every writer of the project goes through :func:`atomic_output` (re-exported by
:mod:`golden.io`), so a failed or interrupted run never leaves a half-written
file. Standard library only, below :mod:`golden.config` and :mod:`golden.io`,
which both use it.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import InputError
from .paths import check_output_file


#: Hidden temporaries are named ``.<name>.<pid>.<random>.part`` beside the output;
#: the pid lets the next run at that path remove one a killed run left behind.
_PART_NAME = 100          # characters of the output's name kept in the temporary's name


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _remove_stale_parts(directory: Path, stem: str) -> None:
    """Remove ``.<stem>.<pid>.<random>.part`` files whose process is gone (killed runs)."""
    pattern = re.compile(r"\." + re.escape(stem) + r"\.(\d+)\.[A-Za-z0-9_]{8}\.part")
    try:
        entries = [e for e in os.scandir(directory) if e.name.startswith("." + stem + ".")]
    except OSError:
        return
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if not match or not entry.is_file(follow_symlinks=False):
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
        with contextlib.suppress(OSError):
            os.unlink(entry.path)


def _write_error(path: str, exc: OSError) -> InputError:
    """An OSError of writing, as one line naming the user's path (never the temporary)."""
    if exc.errno is None and "requested" in str(exc):          # numpy's short write: a full disk
        reason = f"short write ({exc}); is the disk full?"
    else:
        reason = exc.strerror or str(exc) or type(exc).__name__
    return InputError(f"cannot write {path!r}: {reason}")


@contextlib.contextmanager
def atomic_output(path: str | Path, what: str | None = None) -> Iterator[str]:
    """Yield a temporary path to write; on success move it to ``path``, else remove it.

    ``path`` is checked with :func:`golden.paths.check_output_file` first. A
    symlink's target is replaced (the link stays); a character device or FIFO
    (``/dev/null``, a pipe) is written through once the temporary is complete,
    never replaced. The file gets the mode the user's umask gives (an existing
    file keeps its mode). Temporaries are ``.<name>.<pid>.<random>.part`` beside
    the target; one left by a killed run is removed by the next run at that path.
    Any OSError while writing becomes an :class:`InputError` naming ``path``.
    """
    shown = os.fspath(path)
    target = check_output_file(path, what)
    try:
        info = os.stat(target)
    except OSError:
        info = None
    through = info is not None and (stat.S_ISCHR(info.st_mode) or stat.S_ISFIFO(info.st_mode))
    if through:
        directory = Path(tempfile.gettempdir())
        prefix = f".tespike.{os.getpid()}."
    else:
        directory = target.parent
        stem = target.name[:_PART_NAME]
        _remove_stale_parts(directory, stem)
        prefix = f".{stem}.{os.getpid()}."
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=".part", dir=directory)
        os.close(fd)
    except OSError as exc:
        raise _write_error(shown, exc) from None
    try:
        try:
            yield tmp
            if through:
                _write_through(tmp, target, shown)
            else:
                mode = (info.st_mode & 0o777) if info is not None else (0o666 & ~_umask())
                os.chmod(tmp, mode)
                os.replace(tmp, target)
        except OSError as exc:
            if exc.filename not in (None, tmp, str(target)):
                raise                              # about another file: the caller names it
            raise _write_error(shown, exc) from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


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
