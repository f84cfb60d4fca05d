"""What a command prints on success and whether it draws progress bars.

Command modules import these from here (not from :mod:`tespike.cosim.cli`, which imports
the command modules), so the dependency runs one way: cli -> commands -> console.
"""

from __future__ import annotations

import sys


def progress_wanted(args) -> bool:
    """Draw progress bars? ``--progress on``/``off``, else only when stderr is a terminal."""
    choice = getattr(args, "progress", "auto")
    if choice is True:                  # a command's own --progress switch
        return True
    if choice in ("on", "off"):
        return choice == "on"
    return sys.stderr.isatty()


def report(args, message: str) -> None:
    """The one line a command prints on stdout on success (silenced by ``--quiet``)."""
    if not getattr(args, "quiet", False):
        print(message, flush=True)
