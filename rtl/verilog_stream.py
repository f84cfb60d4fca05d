"""Verilog of the streaming array (SPEC section 6, ``tespike verilog --lanes N``).

The Verilog form of :class:`rtl.stream.StreamingPixelArray`, written to build in
Verilator at sensor size (400 x 250 pixels). Three hand-written structural
levels around the Amaranth-generated pixel and timing modules:

* ``<mode>_pixel_array_stream`` (top, SPEC ports ``clk``, ``rst``, ``charge``,
  ``out_valid``, ``out_first``, ``out_words``): the timing block, H row
  modules in a generate loop, and the beat counter, which after the edge where
  the pixels show the words of interval k (``frame_valid``) puts beat
  j = 0..B-1 on ``out_words``, one per clock, lane i showing the held word of
  pixel p = j*N + i (row p / W, column p % W; 0 past the last pixel);
* ``<mode>_pixel_row``: one row of W pixels, each behind its own E-bit input
  register, and the row's second buffer ``held`` (W words), loaded by one loop
  at the ``frame_valid`` edge and read by the beats while the pixels integrate
  the next interval (a column-parallel readout's row buffer); kept a module of
  its own in Verilator (``verilator no_inline_module``);
* ``<mode>_pixel`` (Amaranth), inlined into the row
  (``verilator inline_module``), and ``<mode>_readout_timing`` (Amaranth).

Why rows (docs/outside-simulators.md, "Sensor size"): with one non-inlined
module instance per pixel Verilator 5.006 writes per-instance set-up code and a
symbol table that every C++ file includes, both growing with H x W, so the
build grows faster than the pixel count (128 x 128 did not build in 25
minutes); with every pixel inlined into one module the code itself grows with
H x W. With rows, the symbol table has H entries and the one row module's code
W pixels: the build grows with H + W. The row's ``charge`` input is marked
``verilator public_flat_rd`` so that it stays a variable of each row instance;
otherwise Verilator 5.006 replaces it by its connection (``charge[r*W*E +: W*E]``)
and writes one copy of the row's code per row (15 MB of C++ at 64 x 64 instead
of 1.5 MB), as :func:`cosim.verilator.shared_pixel_view` explains for the pixel.

The ``verilator`` comments are comments to every other tool; Icarus, Yosys and
a synthesis flow see the same structure: H x W pixel instances.
"""

from __future__ import annotations

import json
import re

from golden.config import SensorConfig
from golden.stream import beat_count, check_lanes

from .array import check_array_size
from .pixel import pixel_class
from .timing import ReadoutTiming
from .verilog import _check, _convert, _genvars, _loop, module_names


def stream_module_names(config: SensorConfig) -> dict[str, str]:
    """``top`` (``<mode>_pixel_array_stream``), ``row``, ``pixel`` and ``timing``."""
    names = module_names(config)
    return {**names, "top": names["top"] + "_stream", "row": f"{config.mode}_pixel_row"}


def _mark_module(verilog: str, module: str, comment: str) -> str:
    """Insert ``comment`` as the first line of ``module``'s body (after its port list)."""
    pattern = re.compile(rf"^(module {re.escape(module)}\(.*?\);\n)", re.M | re.S)
    text, count = pattern.subn(lambda mo: mo.group(1) + f"  {comment}\n", verilog, count=1)
    if count != 1:
        raise ValueError(f"module {module} not found in the Verilog")
    return text


def row_verilog(config: SensorConfig, width: int) -> str:
    """One row of W pixels: input registers, pixel instances, words gathered into ``words``."""
    names = stream_module_names(config)
    e, wd, b2 = config.input_bits, config.word_bits, config.b2
    te = config.is_te
    ccc_port = f"  input  wire [{b2 - 1}:0] ccc,                 // shared clock cycle counter\n" if te else ""
    ccc_pin = ".ccc(ccc), " if te else ""

    def pixel(c, indent):
        return (f"{indent}reg [E-1:0] charge_sample = {e}'d0;  // this pixel's input register\n"
                f"{indent}always @(posedge clk) charge_sample <= charge[{c}*E +: E];\n"
                f"{indent}{names['pixel']} pixel (.clk(clk), .rst(rst), .charge(charge_sample), "
                f"{ccc_pin}.last(last),\n{indent}  .clear(clear), .word(word[{c}]));\n")

    loop = _loop("c", width, "W", "col", pixel, "    ")
    return f"""\
// {names['row']}: one row of {width} pixels of {names['top']}, each behind its own
// input register, and the row's second buffer: at the edge with load high it takes the
// pixels' words (pixel c at [c*{wd} +: {wd}]) and holds them while the pixels integrate on.
module {names['row']} (
  input  wire clk,
  input  wire rst,
  input  wire [{width * e - 1}:0] charge /* verilator public_flat_rd */,  // this row's slice of charge
{ccc_port}  input  wire last,                      // S_r: last pixel clock of the readout interval
  input  wire clear,                     // rst sampled one edge earlier: clears the pixels
  input  wire load,                      // the pixels show an interval's words: hold them
  output wire [{width * wd - 1}:0] held      // the held word of pixel c at [c*{wd} +: {wd}]
);
  /* verilator no_inline_module */
  localparam integer W = {width};
  localparam integer E = {e};
  localparam integer WD = {wd};
  wire [WD-1:0] word [0:W-1];
  reg [{width * wd - 1}:0] words;  // the second buffer of this row
  integer i;
  always @(posedge clk)
    if (load)
      for (i = 0; i < W; i = i + 1) words[i*WD +: WD] <= word[i];
  assign held = words;

  genvar {", ".join(_genvars("c", width))};
  generate
{loop}  endgenerate
endmodule
"""


def stream_top_verilog(config: SensorConfig, height: int, width: int, lanes: int) -> str:
    """The top ``<mode>_pixel_array_stream`` with exactly the SPEC section 6 streaming ports."""
    config = _check(config)
    height, width = check_array_size(height, width)
    check_lanes(config, height, width, lanes)
    names = stream_module_names(config)
    e, wd, b2 = config.input_bits, config.word_bits, config.b2
    pixels, n = height * width, lanes
    beats = beat_count(pixels, n)
    beat_bits = max(1, beats.bit_length())
    te = config.is_te
    ccc_wire = f"  wire [{b2 - 1}:0] ccc;  // shared clock cycle counter, 1..alpha\n" if te else ""
    ccc_pin = ".ccc(ccc), " if te else ""

    def row(r, indent):
        return (f"{indent}{names['row']} pixels (.clk(clk), .rst(rst), .charge(charge[{r}*W*E +: W*E]), "
                f"{ccc_pin}.last(last),\n{indent}  .clear(rst_sample), .load(frame_valid), .held(row_held[{r}]));\n")

    loop = _loop("r", height, "H", "row", row, "    ")
    return f"""\
// The user names the output file (tespike verilog --out A.v): waive Verilator's file-name style check.
/* verilator lint_off DECLFILENAME */
// {names['top']}: {height} x {width} {'time-encoding' if te else 'multi-level counter'} pixels, one
// readout timing block and a double-buffered readout of {n} lanes (tespike, SPEC section 6):
// readout interval k leaves as B = {beats} beats; beat j carries pixels p = j*{n} + i (raster
// order, p = r*{width} + c) at out_words[i*{wd} +: {wd}], 0 past the last pixel. Beat j is sampled
// 2 + j clocks after the interval's last clock (the last at most 2L after it).
// config: {json.dumps(config.to_dict())}
module {names['top']} (
  input  wire clk,                           // pixel clock, rising edge
  input  wire rst,                           // synchronous, active high
  input  wire [{pixels * e - 1}:0] charge,  // pixel (r, c) at [(r*W + c)*{e} +: {e}]
  output wire out_valid,                     // high on each clock that carries a beat
  output wire out_first,                     // high with beat 0 of each readout interval
  output wire [{n * wd - 1}:0] out_words     // lane i at [i*{wd} +: {wd}]
);
  localparam integer H = {height};
  localparam integer W = {width};
  localparam integer E = {e};
  localparam integer WD = {wd};
  localparam integer N = {n};        // lanes
  localparam integer P = H*W;       // pixels
{ccc_wire}  wire last;         // S_r: last pixel clock of the readout interval
  wire frame_valid;  // the pixels show the words of an interval (one clock per interval): load them
  reg rst_sample = 1'b0;  // clears the pixels at the edge after a reset edge

  always @(posedge clk) rst_sample <= rst;

  {names['timing']} timing (.clk(clk), .rst(rst), {ccc_pin}.last(last), .frame_valid(frame_valid));

  // The pixels, one row module per row; each row holds its words of the last interval.
  wire [W*WD-1:0] row_held [0:H-1];
  genvar {", ".join(_genvars("r", height))};
  generate
{loop}  endgenerate

  // The beat counter: beats 0..B-1 on the clocks after the load.
  reg sending = 1'b0;
  reg [{beat_bits - 1}:0] beat = {beat_bits}'d0;
  always @(posedge clk)
    if (rst) begin
      sending <= 1'b0;
      beat <= {beat_bits}'d0;
    end else if (frame_valid) begin
      sending <= 1'b1;
      beat <= {beat_bits}'d0;
    end else if (sending) begin
      if (beat == {beat_bits}'d{beats - 1}) sending <= 1'b0;  // beat B - 1
      beat <= beat + {beat_bits}'d1;
    end

  // The beat's lanes, read from the rows' buffers: lane i shows pixel p = beat*N + i.
  reg [N*WD-1:0] lanes;
  integer i, p;
  always @* begin
    lanes = {{N*WD{{1'b0}}}};
    p = 0;
    if (sending)
      for (i = 0; i < N; i = i + 1) begin
        p = beat*N + i;
        if (p < P) lanes[i*WD +: WD] = row_held[p / W][(p % W)*WD +: WD];
      end
  end
  assign out_valid = sending;
  assign out_first = sending & (beat == {beat_bits}'d0);
  assign out_words = lanes;
endmodule
"""


def stream_array_verilog(config: SensorConfig, height: int, width: int, lanes: int) -> str:
    """Verilog text of the streaming H x W array with N lanes: top, row, pixel and timing modules.

    Refuses (:class:`golden.errors.ConfigError`, one line naming the smallest N) a lane
    count whose B = ceil(H W / N) beats do not fit in the L clocks of a readout interval.
    """
    config = _check(config)
    top = stream_top_verilog(config, height, width, lanes)   # refuses before any conversion
    names = stream_module_names(config)
    pixel, timing = _convert((pixel_class(config)(config, word_register=False), names["pixel"]),
                             (ReadoutTiming(config), names["timing"]))
    pixel = _mark_module(pixel, names["pixel"], "/* verilator inline_module */")
    return "\n".join([top, row_verilog(config, width), pixel, timing])
