"""What a command prints on success and whether it draws progress bars.

Command modules import these from here (not from :mod:`tespike.cosim.cli`, which imports
the command modules), so the dependency runs one way: cli -> commands -> console.
"""

from __future__ import annotations

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
    """The one line a command prints on stdout on success (silenced by ``--quiet``)."""
    if not getattr(args, "quiet", False):
        print(printable(message, sys.stdout), flush=True)


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
