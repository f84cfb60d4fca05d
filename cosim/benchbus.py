"""The co-simulation testbench's conventions, shared by the testbench and its waveform reader.

:mod:`tespike.cosim.rtlsim` drives the RTL with them and :mod:`tespike.cosim.vcd` reads its VCD
back with them (the clock period, where the array sits in the scope tree, how
the ``charge`` and ``frame`` buses are packed); both import them from here, so
neither imports the other's internals.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from tespike.golden.errors import InputError, is_count

from .outside import pack_rows, unpack_rows, words_per_row

#: Clock period given to the simulator (1 MHz); only the waveform's time axis sees it.
CLOCK_PERIOD_S = 1e-6

#: Clock period in VCD time units (Amaranth writes a 1 fs timescale).
CLOCK_PERIOD_FS = round(CLOCK_PERIOD_S * 1e15)

#: Submodule name of the pixel array under the wrapper.
ARRAY_SCOPE = "array"

#: VCD scope of the testbench wrapper.
BENCH_SCOPE = "bench.top"

#: Bytes of packed bits materialised at once while packing the stimulus.
_PACK_CHUNK_BYTES = 1 << 22


def iter_packed_charge(stimulus: np.ndarray, input_bits: int) -> Iterator[int]:
    """Yield, per pixel clock, the ``charge`` bus as one integer.

    Pixel (r, c) of clock t sits at bits ``[(r W + c) E +: E]``: the bus layout
    of :func:`tespike.cosim.outside.pack_rows` (one implementation for every backend),
    packed in chunks of clocks; only the final ``int.from_bytes`` is per clock.
    """
    T = stimulus.shape[0]
    flat = stimulus.reshape(T, -1)
    rows = max(1, _PACK_CHUNK_BYTES // max(1, flat.shape[1] * input_bits // 8 + 1))
    for start in range(0, T, rows):
        for row in pack_rows(flat[start:start + rows], input_bits):
            yield int.from_bytes(row.tobytes(), "little")


def frame_rows(frames: list[int], n_values: int, bits: int) -> np.ndarray:
    """Port values as integers -> ``(K, words_per_row)`` uint32 rows, as the outside harnesses capture them."""
    nbytes = 4 * words_per_row(n_values, bits)
    if not is_count(n_values, 1):                       # (0 had been an OverflowError)
        raise InputError(f"frame_rows: {n_values!r} values a frame: must be an integer >= 1")
    frames = list(frames)
    bad = next((f for f in frames if not (is_count(f) and f < 1 << (n_values * bits))), None)
    if bad is not None:                                  # (numpy's 5, 5.0, -1 or 2^40: AttributeError, OverflowError)
        raise InputError(f"frame_rows: port value {bad!r} is no integer of 0 .. 2^{n_values * bits} - 1")
    frames = [int(f) for f in frames]
    raw = b"".join(f.to_bytes(nbytes, "little") for f in frames)
    return np.frombuffer(raw, "<u4").reshape(len(frames), nbytes // 4)


def unpack_frames(frames: list[int], n_pixels: int, word_bits: int) -> np.ndarray:
    """Frame bus integers -> ``(K, n_pixels)`` int64 words (:func:`tespike.cosim.outside.unpack_rows`)."""
    return unpack_rows(frame_rows(frames, n_pixels, word_bits), n_pixels, word_bits)
