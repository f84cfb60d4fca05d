"""What a command prints on success and whether it draws progress bars.

Command modules import these from here (not from :mod:`tespike.cosim.cli`, which imports
the command modules), so the dependency runs one way: cli -> commands -> console.
"""

from __future__ import annotations

import errno
import os
import stat
import sys


def progress_wanted(args) -> bool:
    """Draw progress bars? ``--progress on``/``off``, else only when stderr is a terminal."""
    choice = getattr(args, "progress", "auto")
    if choice in ("on", "off"):
        return choice == "on"
    return sys.stderr.isatty()


def bar(desc: str, unit: str = "readout", total: int | None = None):
    """A progress hook for the libraries (``golden`` draws nothing itself: it depends on numpy
    alone): wraps an iterable in a tqdm bar on stderr, shown after two seconds, gone when done."""
    def wrap(items):
        from tqdm import tqdm
        return tqdm(items, total=total, desc=desc, unit=unit, delay=2.0, leave=False)
    return wrap


def report(args, message: str) -> None:
    """The one line a command prints on stdout on success (silenced by ``--quiet``); on stderr where
    an output of the command is standard output itself (``--out /dev/stdout``: the line would follow
    the file's bytes into the pipe)."""
    if not getattr(args, "quiet", False):
        stream = sys.stderr if _writes_standard_output(args) else sys.stdout
        print(printable(message, stream), file=stream, flush=True)


def _writes_standard_output(args) -> bool:
    """Whether a path among the command's arguments is the file standard output writes to."""
    try:
        out = os.fstat(sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        return False
    if stat.S_ISCHR(out.st_mode):       # (a terminal, /dev/null: the line mixes with nothing)
        return False
    for value in vars(args).values():
        if isinstance(value, str) and value:
            try:
                info = os.stat(value)
            except (OSError, ValueError):
                continue
            if (info.st_dev, info.st_ino) == (out.st_dev, out.st_ino):
                return True
    return False


def printable(text: str, stream) -> str:
    """``text`` as ``stream`` can encode it: a path the terminal's encoding lacks (``é`` under ASCII, a
    non-UTF-8 byte under a strict UTF-8 locale) escaped, never a UnicodeEncodeError after the output
    is written."""
    encoding = getattr(stream, "encoding", None) or "utf-8"
    try:
        text.encode(encoding, errors=getattr(stream, "errors", None) or "strict")
        return text
    except (UnicodeEncodeError, LookupError):
        return text.encode(encoding, errors="backslashreplace").decode(encoding, errors="replace")


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun`` in the plural unless n is 1: "1 readout", "4 readouts" (nouns taking an -s)."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


class StandardOutputError(OSError):
    """A write to standard output failed (a full disk under ``> log``, a closed pipe): the
    command's line names standard output, which such an error alone does not."""


class _NamedStandardOutput:
    """``sys.stdout`` whose failed writes raise :class:`StandardOutputError`, and which writes text its
    encoding lacks escaped (:func:`printable`: evaluate's table holds a "μ", and under an ASCII locale
    its print had ended a finished run in a UnicodeEncodeError traceback); all else is the stream's."""

    def __init__(self, stream):
        self._stream = stream
        #: The first failure, kept: argparse's help drops the error its write raised.
        self.failure: StandardOutputError | None = None

    def _failed(self, exc: OSError) -> StandardOutputError:
        failure = StandardOutputError(exc.errno, exc.strerror)
        self.failure = self.failure or failure
        return failure

    def write(self, text):
        try:
            try:
                return self._stream.write(text)
            except UnicodeEncodeError:                  # (raised before any of it is written)
                return self._stream.write(printable(text, self._stream))
        except OSError as exc:
            raise self._failed(exc) from None

    def flush(self):
        if self.failure is not None:               # (what was lost is not written later)
            raise self.failure
        try:
            self._stream.flush()
        except OSError as exc:
            raise self._failed(exc) from None

    def __getattr__(self, name):
        return getattr(self._stream, name)


class _ClosedStandardOutput:
    """What ``print`` writes to when the process started with stdout closed (``sys.stdout`` is
    None, where ``print`` drops what it is given): each write fails, named."""

    encoding = "utf-8"

    def write(self, text):
        raise StandardOutputError(errno.EBADF, "closed (the command started without one)")

    def flush(self):
        pass

    def isatty(self):
        return False


def closed_at_start() -> bool:
    """Whether this process started with its standard output closed (``tespike ... >&-``), as
    :func:`name_standard_output` found it."""
    stream = sys.stdout
    return isinstance(stream, _NamedStandardOutput) and isinstance(stream._stream, _ClosedStandardOutput)


def name_standard_output() -> None:
    """Make this process's ``sys.stdout`` say so when a write to it fails, or when it was closed
    at the start (the ``tespike`` process only: a library caller's stdout is its own)."""
    if sys.stdout is None:
        sys.stdout = _NamedStandardOutput(_ClosedStandardOutput())
    elif not isinstance(sys.stdout, _NamedStandardOutput):
        sys.stdout = _NamedStandardOutput(sys.stdout)


def drop_standard_output() -> None:
    """After standard output failed: what is still buffered goes to the null device, so that the
    interpreter's exit does not print Python's two-line "Exception ignored" about it."""
    if isinstance(sys.stdout, _NamedStandardOutput):   # (its failure is said: not raised again at exit)
        sys.stdout = sys.stdout._stream
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:
        return
    try:
        os.dup2(null, sys.__stdout__.fileno() if sys.__stdout__ is not None else 1)
    except (OSError, ValueError):
        pass
    finally:
        os.close(null)


def closed_pipe(exc: OSError) -> bool:
    """Whether standard output failed because its reader went away (``tespike ... | head -1``):
    ended quietly, as a shell tool killed by SIGPIPE ends."""
    return isinstance(exc, StandardOutputError) and exc.errno == errno.EPIPE
