"""Argument types the benchmarks share: a file that must be there before the run starts."""

import argparse
from pathlib import Path


def existing_file(text: str) -> Path:
    """``argparse`` type of an input file: refused by the parser in one line (the script's usage and
    the file named) where it is missing or not a file, instead of a traceback once the run has started
    (benchmarks run from the repository's root: a relative path is taken from there)."""
    path = Path(text)
    if not path.is_file():
        where = "" if path.is_absolute() else f" (from {Path.cwd()})"
        raise argparse.ArgumentTypeError(f"{text!r} is not a file{where}")
    return path
