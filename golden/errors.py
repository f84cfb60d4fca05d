"""Errors that name what was wrong; the command line prints them as one line."""

import math
import re

import numpy as np


class TespikeError(Exception):
    """Base of every refusal the project makes on purpose (bad config, bad input)."""


class ConfigError(TespikeError, ValueError):
    """A configuration key, value or rule of SPEC section 2 was broken."""


class InputError(TespikeError, ValueError):
    """A stimulus, scene, stream or other input file breaks SPEC section 6."""


class IllegalWordError(InputError):
    """A readout word outside its configuration's word set (SPEC section 5). A caller that decodes
    a reshaped or cut array catches it to name the word's index in the array it was given."""


def is_count(value, least: int = 0) -> bool:
    """Whether ``value`` is an integer (Python's or numpy's, never a bool) of at least ``least``: the
    test behind the refusals of counts, sizes and seeds."""
    return not isinstance(value, bool) and isinstance(value, (int, np.integer)) and value >= least


def check_flag(value, what: str, error: type = None) -> bool:
    """``value`` where it is True or False (never a string: ``"False"`` had been taken as True), else
    one line naming ``what`` (as ``error``, :class:`InputError` by default)."""
    if not isinstance(value, (bool, np.bool_)):
        raise (error or InputError)(f"{what} = {value!r}: must be True or False")
    return bool(value)


def check_counts(**counts) -> None:
    """Refuse any of ``counts`` (name -> value) that is not an integer >= 1 (:func:`is_count`), naming it."""
    for name, value in counts.items():
        if not is_count(value, 1):
            raise InputError(f"{name} = {value!r}: must be an integer >= 1")


def is_positive_number(value) -> bool:
    """Whether ``value`` is a finite real number > 0 (Python's or numpy's, never a bool): the test
    behind the refusals of lights, peaks, constants and durations."""
    return (not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating))
            and math.isfinite(value) and value > 0)


#: A terminal's escape sequence (colour, bold) in a library's message: never part of a quoted cause.
_ESCAPE = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def one_line(exc: BaseException | str, limit: int = 200) -> str:
    """An exception's message (or a message) as one short line, for refusals that quote a cause:
    terminal escape sequences dropped, whitespace collapsed, the exception's type name when it says
    nothing; past ``limit`` characters its middle is cut (``...``), so that both what it names, at
    its start, and the cause, at its end, stay (a quoted 400-digit value had cut the cause off)."""
    text = " ".join(_ESCAPE.sub("", str(exc)).split()) or type(exc).__name__
    if len(text) <= limit:
        return text
    tail = max(1, limit // 3)
    return text[:limit - tail] + "..." + text[-tail:]
