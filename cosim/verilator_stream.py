"""Run the streaming top (SPEC section 6, ``--lanes N``) in Verilator, up to sensor size.

The build is :func:`cosim.verilator.build` (same cache, runtime objects and
precompiled header) with this module's harness, which drives only ``clk``,
``rst`` and ``charge`` and records every clock with ``out_valid`` high: a
uint64 sample clock, a uint32 ``out_first`` and ``ceil(N*Wd/32)`` uint32 words
of ``out_words``. Verilator's module inlining stays on: the generated Verilog
itself says what to inline (the pixel into its row) and what not (the row), see
:mod:`rtl.verilog_stream`; ``-fno-inline`` would keep every pixel instance apart
and bring back the build that grows faster than the pixel count.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from golden.config import SensorConfig
from golden.io import check_stimulus
from golden.beats import beat_count, check_lanes

from .outside import RESET_CLOCKS, SimulatorRunError, first_error_line, words_per_row
from .stream_ports import check_beats, flush_clocks, stream_top_module
from .verilator import CXX_OPT, READ_ROWS, build, c_type, check_cxx_opt, write_stimulus_file


def stream_harness_cpp(top: str, charge_bits: int, lane_bits: int) -> str:
    """C++ ``main`` driving ``clk``, ``rst``, ``charge`` and recording the beats (module docstring)."""
    in_words = (charge_bits + 31) // 32
    out_words = (lane_bits + 31) // 32
    if charge_bits > 64:
        set_charge = f"std::memcpy(top->charge.data(), w, sizeof(uint32_t) * {in_words});"
    elif charge_bits > 32:
        set_charge = "top->charge = (uint64_t)w[0] | ((uint64_t)w[1] << 32);"
    else:
        set_charge = f"top->charge = ({c_type(charge_bits)})w[0];"
    if lane_bits > 64:
        get_lanes = f"std::memcpy(w, top->out_words.data(), sizeof(uint32_t) * {out_words});"
    elif lane_bits > 32:
        get_lanes = "uint64_t v = top->out_words; w[0] = (uint32_t)v; w[1] = (uint32_t)(v >> 32);"
    else:
        get_lanes = "w[0] = (uint32_t)top->out_words;"
    return f"""// tespike Verilator harness for {top}: SPEC section 6 streaming ports only (generated).
#include "Varray.h"
#include "verilated.h"
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

static const size_t IN_WORDS = {in_words};
static const size_t OUT_WORDS = {out_words};
static const size_t READ_ROWS = {READ_ROWS};
static const int RESET_CLOCKS = {RESET_CLOCKS};

static inline void set_charge(Varray* top, const uint32_t* w) {{ {set_charge} }}
static inline void get_lanes(const Varray* top, uint32_t* w) {{ {get_lanes} }}

static int fail(const char* what, const char* path) {{
    std::fprintf(stderr, "tespike_sim: %s %s\\n", what, path);
    return 3;
}}

int main(int argc, char** argv) {{
    if (argc != 7) {{
        std::fprintf(stderr, "usage: %s STIMULUS CLOCKS BEATS FLUSH CAPTURES PROGRESS_EVERY\\n", argv[0]);
        return 2;
    }}
    const char* stim_path = argv[1];
    const uint64_t clocks = std::strtoull(argv[2], nullptr, 10);
    const uint64_t beats = std::strtoull(argv[3], nullptr, 10);
    const uint64_t flush = std::strtoull(argv[4], nullptr, 10);
    const char* out_path = argv[5];
    const uint64_t progress = std::strtoull(argv[6], nullptr, 10);

    std::FILE* in = std::fopen(stim_path, "rb");
    if (!in) return fail("cannot open stimulus", stim_path);
    std::FILE* out = std::fopen(out_path, "wb");
    if (!out) return fail("cannot open captures", out_path);

    const std::unique_ptr<VerilatedContext> context{{new VerilatedContext}};
    const std::unique_ptr<Varray> top{{new Varray{{context.get()}}}};
    const size_t read_rows = READ_ROWS * IN_WORDS > (1u << 24) ? 16 : READ_ROWS;   // at most ~64 MB
    std::vector<uint32_t> rows(read_rows * IN_WORDS), zero(IN_WORDS, 0), lanes(OUT_WORDS, 0);

    top->clk = 0;
    top->rst = 1;
    set_charge(top.get(), zero.data());
    top->eval();
    for (int i = 0; i < RESET_CLOCKS; ++i) {{
        top->clk = 1; top->eval();
        top->clk = 0; top->eval();
    }}
    top->rst = 0;

    uint64_t captured = 0;
    size_t have = 0, next = 0;
    for (uint64_t t = 0; t < clocks + flush; ++t) {{
        if (t >= clocks && captured >= beats) break;
        const uint32_t* row = zero.data();
        if (t < clocks) {{
            if (next == have) {{
                const uint64_t left = clocks - t;
                const size_t want = left < read_rows ? (size_t)left : read_rows;
                if (std::fread(rows.data(), sizeof(uint32_t) * IN_WORDS, want, in) != want)
                    return fail("stimulus file too short:", stim_path);
                have = want;
                next = 0;
            }}
            row = &rows[next++ * IN_WORDS];
        }}
        set_charge(top.get(), row);
        top->clk = 0;
        top->eval();                      // inputs of clock t settle; sample before the edge
        if (top->out_valid) {{
            const uint32_t first = top->out_first;
            get_lanes(top.get(), lanes.data());
            if (std::fwrite(&t, sizeof t, 1, out) != 1 || std::fwrite(&first, sizeof first, 1, out) != 1 ||
                std::fwrite(lanes.data(), sizeof(uint32_t), OUT_WORDS, out) != OUT_WORDS)
                return fail("cannot write captures", out_path);
            ++captured;
        }}
        top->clk = 1;
        top->eval();                      // rising edge t
        if (progress && (t + 1) % progress == 0) {{
            std::printf("%llu\\n", (unsigned long long)(t + 1));
            std::fflush(stdout);
        }}
    }}
    top->final();
    std::fclose(in);
    if (std::fclose(out) != 0) return fail("cannot write captures", out_path);
    return 0;
}}
"""


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


def run_executable(executable: Path, stim_path: Path, cap_path: Path, clocks: int, beats: int, flush: int,
                   progress: bool = False) -> None:
    """Run a built streaming model on a stimulus file; captures go to ``cap_path``."""
    every = max(1, min(1 << 16, clocks // 100)) if progress else 0
    argv = [str(executable), str(stim_path), str(clocks), str(beats), str(flush), str(cap_path), str(every)]
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            if progress:
                from tqdm import tqdm
                with tqdm(total=clocks, unit="clk", desc="verilator", file=sys.stderr) as bar:
                    done = 0
                    for line in process.stdout:
                        clock = min(int(line), clocks)
                        bar.update(clock - done)
                        done = clock
            _, err = process.communicate()
        except BaseException:          # interrupted: no simulator left running
            process.kill()
            raise
    if process.returncode != 0:
        raise SimulatorRunError(f"Verilator simulation of {executable} failed (exit {process.returncode}): "
                                f"{first_error_line(err)}")


def run_verilator_stream(config: SensorConfig, stimulus: np.ndarray, lanes: int, *,
                         build_dir=None, progress: bool = False, verilog: str | None = None,
                         cxx_opt: str = CXX_OPT) -> np.ndarray:
    """Simulate the streaming top on a (T, H, W) stimulus in Verilator; return beats (K, B, N).

    Equal to ``golden.beats.beats(golden words, N)`` for a correct array; the beat
    timing is held to SPEC section 6 (:func:`cosim.stream_ports.check_beats`).
    ``verilog`` replaces ``rtl.verilog_stream.stream_array_verilog(config, H, W, N)``.
    """
    check_stimulus(stimulus, config)
    check_cxx_opt(cxx_opt)
    T, H, W = stimulus.shape
    check_lanes(config, H, W, lanes)
    K, B = T // config.clocks_per_readout, beat_count(H * W, lanes)
    if K == 0:
        return np.zeros((0, B, lanes), np.int64)
    if verilog is None:
        from rtl.verilog_stream import stream_array_verilog
        verilog = stream_array_verilog(config, H, W, lanes)
    executable = build_stream(config, verilog, H, W, lanes, build_dir=build_dir, progress=progress,
                              cxx_opt=cxx_opt)
    with tempfile.TemporaryDirectory(prefix="tespike-verilator-") as scratch:
        stim_path, cap_path = Path(scratch) / "stimulus.bin", Path(scratch) / "captures.bin"
        write_stimulus_file(stim_path, stimulus, config.input_bits)
        run_executable(executable, stim_path, cap_path, T, K * B, flush_clocks(config), progress)
        clocks, firsts, rows = read_beat_captures(cap_path, words_per_row(lanes, config.word_bits))
    what = f"Verilator run of {stream_top_module(config)} ({H} x {W}, {lanes} lanes)"
    return check_beats(clocks, firsts, rows, config, H, W, lanes, K, what)[0]
