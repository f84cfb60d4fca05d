"""Run the streaming top (SPEC section 6, ``--lanes N``) in Verilator, up to sensor size.

The build is :func:`cosim.verilator.build` (same cache, runtime objects and
precompiled header) with the streaming form of the one harness
(:func:`cosim.verilator.harness_cpp`, ``outputs="beats"``), which drives only
``clk``, ``rst`` and ``charge`` and records every clock with ``out_valid`` high:
a uint64 sample clock, a uint32 ``out_first`` and ``ceil(N*Wd/32)`` uint32
words of ``out_words``. Verilator's module inlining stays on: the streaming
top's Verilog holds one copy of the pixel rule whatever the size
(:mod:`rtl.verilog_stream`), and ``-fno-inline`` would only keep the timing
module apart.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from golden.config import SensorConfig
from golden.io import check_stimulus
from golden.stream import beat_count, check_lanes

from .outside import words_per_row
from .resets import beat_segments, check_resets, segments
from .stream_ports import check_beats, flush_clocks, stream_top_module
from .verilator import (CXX_OPT, build, check_cxx_opt, harness_cpp, run_captures,  # noqa: F401
                        run_executable, write_stimulus_file)


def stream_harness_cpp(top: str, charge_bits: int, lane_bits: int) -> str:
    """C++ ``main`` driving ``clk``, ``rst``, ``charge`` and recording the beats (module docstring)."""
    return harness_cpp(top, charge_bits, lane_bits, outputs="beats")


def build_stream(config: SensorConfig, verilog: str, height: int, width: int, lanes: int, *,
                 build_dir=None, progress: bool = False, cxx_opt: str = CXX_OPT,
                 extra_flags: tuple[str, ...] = ()) -> Path:
    """Build (or find in the cache) the Verilator model of a streaming top; return the executable."""
    top = stream_top_module(config)
    charge_bits, lane_bits = height * width * config.input_bits, lanes * config.word_bits
    return build(verilog, top, charge_bits, lane_bits, build_dir=build_dir, progress=progress,
                 inline=True, cxx_opt=cxx_opt, extra_flags=tuple(extra_flags),
                 harness=stream_harness_cpp(top, charge_bits, lane_bits))


def read_beat_captures(path, lane_words: int):
    """The harness's capture records -> (clocks, firsts, lane rows)."""
    record = np.dtype([("clock", "<u8"), ("first", "<u4"), ("lanes", "<u4", (lane_words,))])
    data = np.fromfile(path, dtype=record)
    return (data["clock"].astype(np.int64), data["first"].astype(bool),
            data["lanes"].reshape(len(data), lane_words))


def run_verilator_stream(config: SensorConfig, stimulus: np.ndarray, lanes: int, *,
                         build_dir=None, progress: bool = False, verilog: str | None = None,
                         cxx_opt: str = CXX_OPT, resets=None):
    """Simulate the streaming top on a (T, H, W) stimulus in Verilator; return beats (K, B, N).

    Equal to ``golden.stream.beats(golden words, N)`` for a correct array; the beat
    timing is held to SPEC section 6 (:func:`cosim.stream_ports.check_beats`).
    ``verilog`` replaces ``rtl.verilog_stream.stream_array_verilog(config, H, W, N)``.
    ``resets`` (T booleans): ``rst`` of every stimulus clock (:mod:`cosim.resets`); the
    result is then a list of each segment's beats ``(n, N)``.
    """
    check_stimulus(stimulus, config)
    check_cxx_opt(cxx_opt)
    T, H, W = stimulus.shape
    check_lanes(config, H, W, lanes)
    L, B = config.clocks_per_readout, beat_count(H * W, lanes)
    resets = check_resets(resets, T)
    K = T // L if resets is None else segments(resets, T)[-1].readouts(T, L)
    if K == 0 and resets is None:
        return np.zeros((0, B, lanes), np.int64)
    if verilog is None:
        from rtl.verilog_stream import stream_array_verilog
        verilog = stream_array_verilog(config, H, W, lanes)
    executable = build_stream(config, verilog, H, W, lanes, build_dir=build_dir, progress=progress,
                              cxx_opt=cxx_opt)
    clocks, firsts, rows = run_captures(executable, stimulus, config.input_bits, K * B, flush_clocks(config),
                                        words_per_row(lanes, config.word_bits), progress, resets, firsts=True)
    what = f"Verilator run of {stream_top_module(config)} ({H} x {W}, {lanes} lanes)"
    if resets is not None:
        return beat_segments(clocks, firsts, rows, config, H, W, lanes, resets, T, what)
    return check_beats(clocks, firsts, rows, config, H, W, lanes, K, what)[0]
