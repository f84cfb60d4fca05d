"""Run the generated Verilog of either top in Icarus Verilog: an independent, outside check.

:func:`run_icarus` (the parallel top, ``tespike.rtl.verilog.array_verilog``) and
:func:`run_icarus_stream` (the streaming top, ``--lanes N``) write the top's
Verilog and one Verilog-2005 testbench (:func:`verilog_testbench`, its output ports
taken from :class:`tespike.cosim.tops.Top`) that drives only the SPEC section 6 ports:
it reads the stimulus rows with ``$readmemh`` (and the reset vector with
``$readmemb``), holds ``rst`` for :data:`~tespike.cosim.outside.RESET_CLOCKS` clocks,
then per pixel clock puts the row on ``charge`` (and its ``rst``), waits for the
logic to settle, samples the outputs (``frame_valid`` / ``frame``, or
``out_valid`` / ``out_first`` / ``out_words``) and gives the rising edge. Every capture is written with
``$fwrite("%h")``; an X or Z on an output is reported, never read as a number. Compiled with ``iverilog -g2005`` (``-g2012`` would give
Amaranth's initialisers SystemVerilog semantics), run with ``vvp``.

Icarus is slow (tens of cycles per second at 1024 pixels): use it on small
arrays; use :mod:`tespike.cosim.verilator` for scale.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from tespike.golden.atomic import work_folder
from tespike.golden.config import SensorConfig
from tespike.golden.io import atomic_output
from tespike.golden.errors import InputError
from tespike.golden.paths import check_output_file, path_text

from . import children
from .outside import (RESET_CLOCKS, SimulatorBuildError, SimulatorRunError, first_error_line, hex_to_rows,
                      pack_rows, require_tool, rows_to_hex, run_process)
from .tops import RunPlan, check_stream_lanes, prepare

TESTBENCH_TOP = "tespike_tb"
_STIMULUS = "stimulus.hex"
_CAPTURES = "captures.txt"
_RESETS = "resets.txt"
#: The VCD a run with ``vcd_path`` dumps (all signals under the top, scope ``tespike_tb.dut``).
DUMP = "waves.vcd"
DUT_SCOPE = f"{TESTBENCH_TOP}.dut"

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


def verilog_testbench(top: str, charge_bits: int, output_bits: int, outputs: str, what: str, dump: bool = False) -> str:
    """The one Verilog-2005 testbench; ``outputs`` picks the top's output ports (:data:`_OUTPUTS`);
    ``dump``: every signal of the top and below goes to :data:`DUMP` (a VCD)."""
    if not isinstance(outputs, str) or outputs not in _OUTPUTS:
        raise InputError(f"outputs {outputs!r}: must be one of {', '.join(_OUTPUTS)}")
    declare, connect, capture = _OUTPUTS[outputs]
    dumping = f'    $dumpfile("{DUMP}");\n    $dumpvars(0, dut);\n' if dump else ""
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
{dumping}    clk = 1'b0;
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


def _simulate(run: RunPlan, verilog: str, what: str, work_dir, vcd_path=None) -> tuple[np.ndarray, list[str]]:
    """Compile ``verilog`` with the top's testbench, run it on the stimulus (and ``rst`` = the
    reset vector, :mod:`tespike.cosim.resets`); return the parsed captures. ``vcd_path``: the
    run's VCD of every signal is moved there."""
    top, stimulus = run.top, run.stimulus
    T = stimulus.shape[0]
    iverilog = require_tool("iverilog", "iverilog")
    vvp = require_tool("vvp", "iverilog")
    bench = verilog_testbench(top.module, top.charge_bits, top.output_bits, top.outputs,
                              "streaming ports" if top.streaming else "ports", vcd_path is not None)
    with work_folder("tespike-icarus-") as scratch:
        work = Path(path_text(work_dir, "work_dir")) if work_dir is not None else Path(scratch)
        if not work.is_dir():
            raise SimulatorRunError(f"work_dir {str(work)!r} is not an existing directory")
        children.write_work_file(work / "array.v", verilog)
        children.write_work_file(work / "tb.v", bench)
        E = top.config.input_bits
        with atomic_output(work / _STIMULUS) as tmp:
            rows = rows_to_hex(pack_rows(stimulus.reshape(T, -1), E), top.charge_bits)
            Path(tmp).write_text("\n".join(rows) + "\n")
        rst = np.zeros(T, np.uint8) if run.resets is None else run.resets.astype(np.uint8)
        children.write_work_file(work / _RESETS, "\n".join("01"[v] for v in rst) + "\n")
        (work / _CAPTURES).unlink(missing_ok=True)
        compiled = run_process([iverilog, "-g2005", "-o", "sim.vvp", "-s", TESTBENCH_TOP,
                                f"-P{TESTBENCH_TOP}.CLOCKS={T}", f"-P{TESTBENCH_TOP}.READOUTS={run.expected}",
                                f"-P{TESTBENCH_TOP}.FLUSH={top.flush}", "tb.v", "array.v"], cwd=work)
        if compiled.returncode != 0:
            raise SimulatorBuildError(
                f"iverilog -g2005 could not compile {what} (exit {compiled.returncode}): "
                f"{first_error_line(compiled.stderr + compiled.stdout)}{children.room_note(work)}")
        ran = run_process([vvp, "-n", "sim.vvp"], cwd=work)
        if ran.returncode != 0:                 # (iverilog cut short by a full disk exits 0: vvp then fails)
            raise SimulatorRunError(f"{what}: vvp failed (exit {ran.returncode}): "
                                    f"{first_error_line(ran.stderr + ran.stdout)}{children.room_note(work)}")
        try:
            captures = _parse_captures(work / _CAPTURES, what, top.word_port)
        except SimulatorRunError as exc:
            raise SimulatorRunError(f"{exc}{children.room_note(work)}") from None
        if vcd_path is not None:
            shutil.move(work / DUMP, vcd_path)
        return captures


def _run(run: RunPlan, verilog: str | None, work_dir, vcd_path=None):
    """Simulate ``run`` in Icarus (either top); its words, beats, or each segment's. The arguments
    are checked before anything runs: Verilog text that is none (a TypeError), a work folder that does
    not exist, a waveform path that cannot be written (found only after the simulation, as
    shutil's error or a file moved into a folder)."""
    if verilog is not None and not isinstance(verilog, str):
        raise InputError(f"verilog: must be the Verilog text to simulate, not {type(verilog).__name__}")
    if work_dir is not None and not Path(path_text(work_dir, "work_dir")).is_dir():
        raise InputError(f"work_dir {str(work_dir)!r} is not an existing directory")
    if vcd_path is not None:
        check_output_file(vcd_path, "vcd_path")
    top = run.top
    if run.idle:
        return top.empty()
    what = top.describe("Icarus")
    clocks, lines = _simulate(run, top.verilog() if verilog is None else verilog, what, work_dir, vcd_path)
    firsts = [line[0] == "1" for line in lines] if top.streaming else []
    rows = hex_to_rows([line[1:] for line in lines] if top.streaming else lines, top.output_bits)
    return top.result(run, clocks, firsts, rows, what)


def run_icarus(config: SensorConfig, stimulus: np.ndarray, *, work_dir: str | Path | None = None,
               verilog: str | None = None, resets=None, vcd_path: str | Path | None = None):
    """Simulate the generated Verilog of a (T, H, W) stimulus in Icarus; return words (K, H, W).

    ``work_dir`` keeps the Verilog, testbench, stimulus and captures there (an
    existing directory); by default a temporary directory is used and removed.
    ``verilog`` replaces ``tespike.rtl.verilog.array_verilog(config, H, W)`` (tests use
    a hand-written model of the same ports). ``resets`` (T booleans): ``rst`` of
    every stimulus clock; the run is then checked segment by segment
    (:func:`tespike.cosim.resets.frame_segments`) and the result is a list of each
    segment's words ``(n, H, W)``. ``vcd_path``: write a VCD of every signal of the top there
    (scope :data:`DUT_SCOPE`; :mod:`tespike.cosim.activity` counts its toggles).
    """
    config = SensorConfig.required(config, "run_icarus")
    return _run(prepare(config, stimulus, None, resets), verilog, work_dir, vcd_path)


def run_icarus_stream(config: SensorConfig, stimulus: np.ndarray, lanes: int, *,
                      work_dir: str | Path | None = None, verilog: str | None = None, resets=None,
                      vcd_path: str | Path | None = None):
    """Simulate the streaming top (``--lanes N``) on a (T, H, W) stimulus; return beats (K, B, N).

    Equal to ``tespike.golden.beats.beats(golden words, N)`` for a correct array; the beat
    timing is held to SPEC section 6 (:func:`tespike.cosim.stream_ports.check_beats`).
    ``verilog`` replaces ``tespike.rtl.verilog_stream.stream_array_verilog(config, H, W, N)``.
    ``resets``: as :func:`run_icarus`; the result is then each segment's beats ``(n, N)``
    (:func:`tespike.cosim.resets.beat_segments`). ``vcd_path``: as :func:`run_icarus`.
    """
    config = SensorConfig.required(config, "run_icarus_stream")
    check_stream_lanes(lanes, "run_icarus_stream")
    return _run(prepare(config, stimulus, lanes, resets), verilog, work_dir, vcd_path)
