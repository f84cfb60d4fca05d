"""Run the generated array Verilog in Icarus Verilog: an independent, outside check.

:func:`run_icarus` writes the array Verilog (``rtl.verilog.array_verilog``) and
a Verilog-2005 testbench that drives only the SPEC section 6 ports: it reads
the stimulus rows with ``$readmemh``, holds ``rst`` for
:data:`~cosim.outside.RESET_CLOCKS` clocks, then per pixel clock puts the row
on ``charge``, waits for the logic to settle, samples ``frame_valid`` /
``frame`` and gives the rising edge. Every capture is written with
``$fwrite("%h")``; an X or Z on ``frame_valid`` or ``frame`` is reported, never
read as a number. Compiled with ``iverilog -g2005`` (``-g2012`` would give
Amaranth's initialisers SystemVerilog semantics), run with ``vvp``.

Icarus is slow (tens of cycles per second at 1024 pixels): use it on small
arrays; use :mod:`cosim.verilator` for scale.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from golden.config import SensorConfig
from golden.io import atomic_output, check_stimulus

from .outside import (RESET_CLOCKS, SimulatorBuildError, SimulatorRunError, check_captures,
                      first_error_line, hex_to_rows, pack_rows, require_tool, rows_to_hex,
                      run_process, top_module, unpack_rows)
from .resets import beat_segments, check_resets, frame_segments, segments

TESTBENCH_TOP = "tespike_tb"
_STIMULUS = "stimulus.hex"
_CAPTURES = "captures.txt"
_RESETS = "resets.txt"

#: Half a pixel clock in ns (the testbench samples 1 ns after the inputs change).
_HALF_PERIOD = 5


#: What the testbench knows of each top's outputs: declarations, port connections, and the
#: Verilog that writes one capture line (``<clock> <hex>``; a non-0/1 flag writes ``<port>=<bits>``).
_OUTPUTS = {
    "frame": ("  wire frame_valid;\n  wire [{bits}:0] frame;",
              ".frame_valid(frame_valid), .frame(frame)",
              """      if (frame_valid === 1'b1) begin
        $fwrite(out, "%0d %h\\n", t, frame);
        captured = captured + 1;
      end else if (frame_valid !== 1'b0)
        $fwrite(out, "%0d frame_valid=%b\\n", t, frame_valid);"""),
    "beats": ("  wire out_valid, out_first;\n  wire [{bits}:0] out_words;",
              ".out_valid(out_valid), .out_first(out_first),\n    .out_words(out_words)",
              """      if (out_valid === 1'b1) begin
        if (out_first === 1'b1 || out_first === 1'b0) $fwrite(out, "%0d %b%h\\n", t, out_first, out_words);
        else $fwrite(out, "%0d out_first=%b\\n", t, out_first);
        captured = captured + 1;
      end else if (out_valid !== 1'b0)
        $fwrite(out, "%0d out_valid=%b\\n", t, out_valid);"""),
}


def _testbench(top: str, charge_bits: int, output_bits: int, outputs: str, what: str) -> str:
    """The one Verilog-2005 testbench; ``outputs`` picks the top's output ports (:data:`_OUTPUTS`)."""
    declare, connect, capture = _OUTPUTS[outputs]
    return f"""// tespike Icarus testbench for {top}: SPEC section 6 {what} only (generated).
`timescale 1ns / 1ns
module {TESTBENCH_TOP};
  parameter CLOCKS = 1;     // stimulus rows (pixel clocks)
  parameter READOUTS = 1;   // captures expected after the last reset
  parameter FLUSH = 1;      // clocks of zero charge allowed after the stimulus
  reg clk;
  reg rst;
  reg [{charge_bits - 1}:0] charge;
{declare.format(bits=output_bits - 1)}
  reg [{charge_bits - 1}:0] stimulus [0:CLOCKS - 1];
  reg resets [0:CLOCKS - 1];  // rst of each stimulus clock (cosim.resets)
  integer t, captured, out, i;

  {top} dut(.clk(clk), .rst(rst), .charge(charge), {connect});

  initial begin
    $readmemh("{_STIMULUS}", stimulus);
    $readmemb("{_RESETS}", resets);
    out = $fopen("{_CAPTURES}", "w");
    clk = 1'b0;
    rst = 1'b1;
    charge = {charge_bits}'d0;
    for (i = 0; i < {RESET_CLOCKS}; i = i + 1) begin
      #{_HALF_PERIOD} clk = 1'b1;
      #{_HALF_PERIOD} clk = 1'b0;
    end
    rst = 1'b0;
    captured = 0;
    t = 0;
    while (t < CLOCKS + FLUSH && !(t >= CLOCKS && captured >= READOUTS)) begin
      if (t < CLOCKS) begin
        charge = stimulus[t];
        rst = resets[t];
      end else begin
        charge = {charge_bits}'d0;
        rst = 1'b0;
      end
      #1;                                   // inputs of clock t settle; sample before the edge
{capture}
      if (rst) captured = 0;                // a reset edge: count the captures after it
      #{_HALF_PERIOD - 1} clk = 1'b1;       // rising edge t
      #{_HALF_PERIOD} clk = 1'b0;
      t = t + 1;
    end
    $fwrite(out, "end %0d\\n", t);
    $fclose(out);
    $finish;
  end
endmodule
"""


def icarus_testbench(top: str, charge_bits: int, frame_bits: int) -> str:
    """Verilog-2005 testbench of the SPEC section 6 ports; CLOCKS, READOUTS, FLUSH are parameters."""
    return _testbench(top, charge_bits, frame_bits, "frame", "ports")


def _parse_captures(path: Path, what: str, word_port: str = "frame") -> tuple[np.ndarray, list[str]]:
    try:
        lines = path.read_text().splitlines()
    except FileNotFoundError:
        raise SimulatorRunError(f"{what}: the testbench wrote no captures file") from None
    if not lines or not lines[-1].startswith("end "):
        raise SimulatorRunError(f"{what}: the testbench stopped before the end of the run")
    clocks, frames = [], []
    for line in lines[:-1]:
        clock, value = line.split(" ", 1)
        if not all(ch in "0123456789abcdefABCDEF" for ch in value):
            raise SimulatorRunError(
                f"{what}: at pixel clock {clock} "
                f"{value.split('=')[0] if '=' in value else word_port} "
                f"holds X or Z bits ({value[:40]}); SPEC section 6 outputs must be defined")
        clocks.append(int(clock))
        frames.append(value)
    return np.asarray(clocks, np.int64), frames


def _simulate(config: SensorConfig, stimulus: np.ndarray, verilog: str, testbench: str, flush: int,
              expected: int, what: str, work_dir, word_port: str = "frame",
              resets: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
    """Compile ``verilog`` with ``testbench``, run it on ``stimulus`` (and ``rst`` = ``resets``,
    :mod:`cosim.resets`); return the parsed captures. ``expected``: captures after the last reset."""
    T, H, W = stimulus.shape
    iverilog = require_tool("iverilog", "iverilog")
    vvp = require_tool("vvp", "iverilog")
    N, E = H * W, config.input_bits
    with tempfile.TemporaryDirectory(prefix="tespike-icarus-") as scratch:
        work = Path(work_dir) if work_dir is not None else Path(scratch)
        if not work.is_dir():
            raise SimulatorRunError(f"work_dir {str(work)!r} is not an existing directory")
        (work / "array.v").write_text(verilog)
        (work / "tb.v").write_text(testbench)
        with atomic_output(work / _STIMULUS) as tmp:
            Path(tmp).write_text("\n".join(rows_to_hex(pack_rows(stimulus.reshape(T, N), E), N * E)) + "\n")
        rst = np.zeros(T, np.uint8) if resets is None else resets.astype(np.uint8)
        (work / _RESETS).write_text("\n".join("01"[v] for v in rst) + "\n")
        (work / _CAPTURES).unlink(missing_ok=True)
        compiled = run_process([iverilog, "-g2005", "-o", "sim.vvp", "-s", TESTBENCH_TOP,
                                f"-P{TESTBENCH_TOP}.CLOCKS={T}", f"-P{TESTBENCH_TOP}.READOUTS={expected}",
                                f"-P{TESTBENCH_TOP}.FLUSH={flush}", "tb.v", "array.v"], cwd=work)
        if compiled.returncode != 0:
            raise SimulatorBuildError(
                f"iverilog -g2005 could not compile {what} (exit {compiled.returncode}): "
                f"{first_error_line(compiled.stderr + compiled.stdout)}")
        ran = run_process([vvp, "-n", "sim.vvp"], cwd=work)
        if ran.returncode != 0:
            raise SimulatorRunError(f"{what}: vvp failed (exit {ran.returncode}): "
                                    f"{first_error_line(ran.stderr + ran.stdout)}")
        return _parse_captures(work / _CAPTURES, what, word_port)


def run_icarus(config: SensorConfig, stimulus: np.ndarray, *, work_dir: str | Path | None = None,
               verilog: str | None = None, resets=None):
    """Simulate the generated Verilog of a (T, H, W) stimulus in Icarus; return words (K, H, W).

    ``work_dir`` keeps the Verilog, testbench, stimulus and captures there (an
    existing directory); by default a temporary directory is used and removed.
    ``verilog`` replaces ``rtl.verilog.array_verilog(config, H, W)`` (tests use
    a hand-written model of the same ports). ``resets`` (T booleans): ``rst`` of
    every stimulus clock; the run is then checked segment by segment
    (:func:`cosim.resets.frame_segments`) and the result is a list of each
    segment's words ``(n, H, W)``.
    """
    check_stimulus(stimulus, config)
    T, H, W = stimulus.shape
    L = config.clocks_per_readout
    resets = check_resets(resets, T)
    K = T // L if resets is None else segments(resets, T)[-1].readouts(T, L)
    if K == 0 and resets is None:
        return np.zeros((0, H, W), np.int64)
    N, E, Wd = H * W, config.input_bits, config.word_bits
    top = top_module(config)
    if verilog is None:
        from rtl.verilog import array_verilog
        verilog = array_verilog(config, H, W)
    what = f"Icarus run of {top} ({H} x {W})"
    clocks, frames = _simulate(config, stimulus, verilog, icarus_testbench(top, N * E, N * Wd), L + 1,
                               K, what, work_dir, resets=resets)
    if resets is not None:
        return frame_segments(clocks, hex_to_rows(frames, N * Wd), config, H, W, resets, T, what)
    check_captures(clocks, config, K, what)
    return unpack_rows(hex_to_rows(frames, N * Wd), N, Wd).reshape(K, H, W)


def icarus_stream_testbench(top: str, charge_bits: int, lane_bits: int) -> str:
    """Testbench of the streaming ports (``--lanes N``): each clock with ``out_valid`` high writes
    ``<clock> <out_first> <out_words in hex>``; READOUTS is the number of beats expected."""
    return _testbench(top, charge_bits, lane_bits, "beats", "streaming ports")


def run_icarus_stream(config: SensorConfig, stimulus: np.ndarray, lanes: int, *,
                      work_dir: str | Path | None = None, verilog: str | None = None, resets=None):
    """Simulate the streaming top (``--lanes N``) on a (T, H, W) stimulus; return beats (K, B, N).

    Equal to ``golden.stream.beats(golden words, N)`` for a correct array; the beat
    timing is held to SPEC section 6 (:func:`cosim.stream_ports.check_beats`).
    ``verilog`` replaces ``rtl.verilog_stream.stream_array_verilog(config, H, W, N)``.
    ``resets``: as :func:`run_icarus`; the result is then each segment's beats ``(n, N)``
    (:func:`cosim.resets.beat_segments`).
    """
    from golden.stream import beat_count, check_lanes

    from .stream_ports import check_beats, flush_clocks, stream_top_module

    check_stimulus(stimulus, config)
    T, H, W = stimulus.shape
    check_lanes(config, H, W, lanes)
    L, B = config.clocks_per_readout, beat_count(H * W, lanes)
    resets = check_resets(resets, T)
    K = T // L if resets is None else segments(resets, T)[-1].readouts(T, L)
    if K == 0 and resets is None:
        return np.zeros((0, B, lanes), np.int64)
    E, Wd = config.input_bits, config.word_bits
    top = stream_top_module(config)
    if verilog is None:
        from rtl.verilog_stream import stream_array_verilog
        verilog = stream_array_verilog(config, H, W, lanes)
    what = f"Icarus run of {top} ({H} x {W}, {lanes} lanes)"
    clocks, lines = _simulate(config, stimulus, verilog, icarus_stream_testbench(top, H * W * E, lanes * Wd),
                              flush_clocks(config), K * B, what, work_dir, "out_words", resets)
    firsts = [line[0] == "1" for line in lines]
    rows = hex_to_rows([line[1:] for line in lines], lanes * Wd)
    if resets is not None:
        return beat_segments(clocks, firsts, rows, config, H, W, lanes, resets, T, what)
    return check_beats(clocks, firsts, rows, config, H, W, lanes, K, what)[0]
