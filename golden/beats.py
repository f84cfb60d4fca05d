"""The streaming readout of SPEC section 6: the words of each readout interval as beats of N lanes.

A chip cannot bring all H x W words out in one clock; with ``--lanes N`` the
array sends readout interval k as B = ceil(H W / N) beats, beat j carrying the
words of pixels p = j N + i (raster order, p = r W + c) in lane i, lanes past
the last pixel carrying 0. The beats of one interval must fit in one readout
interval (B <= L), so the smallest lane count is ceil(H W / L).

:func:`beats` is the reference every simulator check of the streaming top uses;
:func:`check_lanes` is the one refusal of an impossible lane count.
"""

from __future__ import annotations

import numpy as np

from .config import SensorConfig
from .decode import check_word_dtype
from .errors import ConfigError, InputError, is_count, is_positive_number


#: Most lanes accepted: 262144 (2^18, the largest streaming array's pixel count). N above H W
#: only adds lanes that carry 0; beyond this the out_words port (N Wd bits) and the Verilog
#: integers that index it (32-bit) stop being something a simulator or a chip can hold.
MAX_LANES = 1 << 18


def beat_count(pixels: int, lanes: int) -> int:
    """B = ceil(pixels / lanes): beats per readout interval."""
    if not (is_count(pixels) and is_count(lanes, 1)):
        raise InputError(f"beat count of {pixels!r} pixels on {lanes!r} lanes: the pixels must be an integer "
                         ">= 0, the lanes an integer >= 1")
    return -(-pixels // lanes)


def min_lanes(config: SensorConfig, height: int, width: int) -> int:
    """The smallest N whose B = ceil(H W / N) beats fit in one readout interval of L clocks."""
    config = SensorConfig.required(config, "min_lanes")
    height, width = check_array_size(height, width)
    return beat_count(height * width, config.clocks_per_readout)


def check_array_size(height, width) -> tuple[int, int]:
    """An array's rows and columns, each an integer >= 1, refused in one line otherwise (two negative
    sizes had passed as a positive pixel count, and 0 rows needed 0 lanes)."""
    if not (is_count(height, 1) and is_count(width, 1)):
        raise ConfigError(f"array of {height!r} x {width!r} pixels: the rows and columns must be integers >= 1")
    return int(height), int(width)


def check_lanes(config: SensorConfig, height: int, width: int, lanes) -> int:
    """Refuse a lane count that is not an integer in 1..MAX_LANES or whose beats do not fit in L clocks.

    The message names the smallest N that works (one line, :class:`ConfigError`). N above
    H W is legal (SPEC section 6): one beat, its lanes past the last pixel carrying 0.
    """
    config = SensorConfig.required(config, "check_lanes")
    height, width = check_array_size(height, width)
    pixels, L = height * width, config.clocks_per_readout
    if type(lanes) is not int or lanes < 1:
        raise ConfigError(f"lanes = {lanes!r}: must be an integer >= 1")
    if lanes > MAX_LANES:
        raise ConfigError(f"lanes = {lanes}: at most {MAX_LANES} lanes are supported (out_words would be "
                          f"{lanes} x {config.word_bits} bits; {pixels} pixels need at most {pixels})")
    beats = beat_count(pixels, lanes)
    if beats > L:
        raise ConfigError(f"lanes = {lanes}: {height} x {width} pixels need B = ceil({pixels} / {lanes}) = "
                          f"{beats} beats, more than the L = {L} clocks of a readout interval; "
                          f"the smallest N is {min_lanes(config, height, width)}")
    return lanes


def beats(words: np.ndarray, lanes: int) -> np.ndarray:
    """Words ``(K, H, W)`` -> beats ``(K, B, N)``: beat j, lane i holds pixel j N + i in raster order, or 0."""
    words = np.asarray(words)
    if words.ndim != 3:
        raise InputError(f"beats wants words (K, H, W), got shape {words.shape}")
    check_word_dtype(words.dtype)
    if type(lanes) is not int or lanes < 1:
        raise InputError(f"lanes = {lanes!r}: must be an integer >= 1")
    K, H, W = words.shape
    B = beat_count(H * W, lanes)
    out = np.zeros((K, B * lanes), words.dtype)
    out[:, :H * W] = words.reshape(K, H * W)
    return out.reshape(K, B, lanes)


def unbeat(beats_: np.ndarray, height: int, width: int) -> np.ndarray:
    """Inverse of :func:`beats`: ``(K, B, N)`` -> words ``(K, H, W)`` (the padding lanes are dropped)."""
    beats_ = np.asarray(beats_)
    if not (is_count(height, 1) and is_count(width, 1)):
        raise InputError(f"unbeat: height {height!r} and width {width!r} must be integers >= 1")
    if beats_.ndim != 3 or beats_.shape[2] < 1 or beats_.shape[1] != beat_count(height * width, beats_.shape[2]):
        raise InputError(f"unbeat: beats of shape {beats_.shape} are not those of {height} x {width} pixels "
                         "(they must be (K, B, N) with B = ceil(H W / N): more beats would be dropped, "
                         "fewer cannot hold the pixels)")
    K = beats_.shape[0]
    return beats_.reshape(K, -1)[:, :height * width].reshape(K, height, width)


def output_bandwidth(config: SensorConfig, height: int, width: int, pixel_clock_hz: float) -> dict:
    """What the streaming readout of an H x W array costs at a pixel clock of ``pixel_clock_hz``.

    Returns ``readout_hz`` (readout intervals per second, f / L), ``bits_per_s`` (the words that
    must leave: H W Wd f / L, whatever the lane count), ``min_lanes`` (N = ceil(H W / L)),
    ``pins`` (N Wd output bits at that N) and ``port_bits_per_s`` (N Wd f, what those pins carry
    when every clock holds a beat; at least ``bits_per_s``).
    """
    config = SensorConfig.required(config, "output_bandwidth")
    if not is_positive_number(pixel_clock_hz):           # (a negative clock had given negative bits/s)
        raise InputError(f"pixel clock {pixel_clock_hz!r} Hz: must be a finite number > 0")
    L, wd = config.clocks_per_readout, config.word_bits
    lanes = min_lanes(config, height, width)
    return {"readout_hz": pixel_clock_hz / L, "word_bits": wd,
            "bits_per_s": height * width * wd * pixel_clock_hz / L,
            "min_lanes": lanes, "pins": lanes * wd, "port_bits_per_s": lanes * wd * pixel_clock_hz}
