"""Verilog of the streaming array (SPEC section 6, ``tespike verilog --lanes N``).

The Verilog form of :class:`rtl.stream.StreamingPixelArray` (same ports,
timing and words, checked bit for bit against the golden model in Icarus,
Verilator and cocotb), written so that Verilator builds it at sensor size
(400 x 250 pixels) in time and memory that hardly grow with the pixel count.
The top ``<mode>_pixel_array_stream`` (ports ``clk``, ``rst``, ``charge``,
``out_valid``, ``out_first``, ``out_words``) holds:

* the readout timing block, ``<mode>_readout_timing``, generated from Amaranth
  (:class:`rtl.timing.ReadoutTiming`, one instance);
* the pixels as memories indexed by pixel p = r W + c (``acc``, ``sfc``,
  ``ovf``, ``m`` or ``count``, and ``charge_sample``, the input register) and
  one clocked ``for`` loop over p that applies the pixel rule of
  :mod:`rtl.pixel` (same names: ``q``, ``spike``, ``rest``, ``total``,
  ``ovf_next``, ``m_next``, ``count_next``) to every pixel each clock, exactly
  as the Amaranth pixel does behind the array's input register
  (:mod:`rtl.array`): computed from ``charge_sample``, cleared by
  ``rst_sample``;
* the second buffer ``held`` (H x W words): at the edge where the timing shows
  ``frame_valid`` the loop stores each pixel's word of the interval's last
  clock there, and the pixels integrate on;
* the beat counter, which then puts beat j = 0..B-1 on ``out_words``, one per
  clock, lane i showing ``held[j*N + i]`` (0 past the last pixel).

Why a loop and not one pixel module instance per pixel, as the parallel top
(:mod:`rtl.verilog`) has: Verilator 5.006 copies every instance's logic into
its own scope before it optimises, whatever the hierarchy, so an instance
netlist costs it about 90 KB of memory per pixel (1.5 GB at 128 x 128 with the
pixels grouped in row modules; more than 6 GB, still growing, one minute into
400 x 250) and a build time that grows faster than the pixel count
(docs/outside-simulators.md, "Sensor size"). The loop holds one copy of the
pixel rule whatever H x W is. For a synthesis tool the loop unrolls into the
same H x W pixels.

The pixel rule here is its own Verilog text (:func:`_pixel_rule`), not generated from
:mod:`rtl.pixel`; ``tespike prove`` proves it equivalent to that pixel (property
``stream-pixel-rule``) through :func:`stream_pixel_rule_verilog`, one pixel of the same text.

The state is read and written only inside the loop's block, so its blocking
assignments are safe (``verilator lint_off BLKSEQ`` with that reason); nothing
outside the block reads a state memory in the same clock.
"""

from __future__ import annotations

import json

from golden.config import SensorConfig
from golden.beats import beat_count, check_lanes

from .array import check_array_size
from .timing import ReadoutTiming
from .verilog import checked_config, convert_modules, module_names

#: A one-bit one, zero-extended by :func:`_zext` for the msb readout's power of two.
ONE_BIT = "1'b1"


def stream_module_names(config: SensorConfig) -> dict[str, str]:
    """``top`` (``<mode>_pixel_array_stream``) and ``timing`` (``<mode>_readout_timing``)."""
    names = module_names(config)
    return {"top": names["top"] + "_stream", "timing": names["timing"]}


def _zext(expr: str, width: int, to: int) -> str:
    """``expr`` of ``width`` bits zero-extended to ``to`` bits (no zero-width replication)."""
    return expr if to == width else f"{{{{{to - width}{{1'b0}}}}, {expr}}}"


def _pixel_rule(config: SensorConfig, indent: str) -> tuple[str, str]:
    """(declarations, loop body) of one pixel's clock, pixel ``p``: the rule of rtl/pixel.py."""
    c = config
    A, E, WD = c.acc_bits, c.input_bits, c.word_bits
    QB = max(A, E) + 1                                      # q = acc + charge never wraps
    i = indent
    common = (f"  reg [{QB - 1}:0] q, rest;      // acc + charge; what stays after the spike\n"
              f"  reg spike;\n"
              f"  reg [{WD - 1}:0] word;          // the word this clock would read out\n")
    integrate = (f"{i}q = {_zext('acc[p]', A, QB)} + {_zext('charge_sample[p]', E, QB)};\n"
                 f"{i}spike = q >= {QB}'d{c.threshold};\n"
                 f"{i}rest = spike ? q - {QB}'d{c.threshold} : q;\n")
    acc_next = f"(rest > {QB}'d{c.acc_max}) ? {A}'d{c.acc_max} : rest[{A - 1}:0]"
    if c.is_te:
        b1, b2, d = c.b1, c.b2, c.d
        decls = (f"  reg [{b1 - 1}:0] sfc [0:P-1];   // spike-firing counter\n"
                 f"  reg ovf [0:P-1];               // overflow flag\n"
                 f"  reg [{b2 - 1}:0] m [0:P-1];    // CCC latched on overflow\n"
                 + common +
                 f"  reg [{b1}:0] total;            // sfc + spike; bit {b1} is the carry\n"
                 f"  reg ovf_next;\n"
                 f"  reg [{b2 - 1}:0] m_next;\n")
        body = (integrate +
                f"{i}total = {_zext('sfc[p]', b1, b1 + 1)} + {_zext('(spike & ~ovf[p])', 1, b1 + 1)};\n"
                f"{i}ovf_next = ovf[p] | total[{b1}];\n"
                f"{i}m_next = total[{b1}] ? ccc : m[p];\n"
                f"{i}word = ovf_next ? {{1'b1, {_zext('m_next', b2, d)}}} : "
                f"{{1'b0, {_zext(f'total[{b1 - 1}:0]', b1, d)}}};\n"
                f"{i}if (frame_valid) held[p] = word;\n"
                f"{i}if (clear) begin\n"
                f"{i}  acc[p] = {A}'d0; sfc[p] = {b1}'d0; ovf[p] = 1'b0; m[p] = {b2}'d0;\n"
                f"{i}end else begin\n"
                f"{i}  acc[p] = {acc_next};\n"
                f"{i}  sfc[p] = last ? {b1}'d0 : total[{b1 - 1}:0];\n"
                f"{i}  ovf[p] = last ? 1'b0 : ovf_next;\n"
                f"{i}  m[p] = m_next;   // shown only while the flag is set, so never cleared at readout\n"
                f"{i}end\n")
        return decls, body
    B = c.ml_bits
    decls = (f"  reg [{B - 1}:0] count [0:P-1]; // saturating spike counter\n" + common +
             f"  reg [{B - 1}:0] count_next;\n")
    body = integrate + (f"{i}count_next = (spike && count[p] != {B}'d{c.ml_max}) ? "
                        f"count[p] + {B}'d1 : count[p];\n")
    if c.is_msb:
        decls += f"  reg [{B - 1}:0] kept;           // the count after an msb readout\n"
        scan = "".join(f"{i}if (count_next[{j}]) word = {WD}'d{j + 1};\n" for j in range(B))
        body += (f"{i}word = {WD}'d0;                 // bit_length(count_next): the highest set bit wins\n"
                 + scan +
                 f"{i}kept = (word == {WD}'d0) ? count_next : "
                 f"count_next - ({_zext(ONE_BIT, 1, B)} << (word - {WD}'d1));\n")
        after = "kept"
    else:
        body += f"{i}word = count_next;\n"
        after = f"{B}'d0"
    body += (f"{i}if (frame_valid) held[p] = word;\n"
             f"{i}if (clear) begin\n"
             f"{i}  acc[p] = {A}'d0; count[p] = {B}'d0;\n"
             f"{i}end else begin\n"
             f"{i}  acc[p] = {acc_next};\n"
             f"{i}  count[p] = last ? {after} : count_next;\n"
             f"{i}end\n")
    return decls, body


#: Indent of the pixel rule inside the top's loop (and inside :func:`stream_pixel_rule_verilog`).
RULE_INDENT = "      "


def stream_pixel_rule_verilog(config: SensorConfig) -> str:
    """One pixel of the streaming top as a combinational module, for ``tespike prove``.

    The module ``<mode>_stream_pixel_rule`` holds the very text of :func:`_pixel_rule` that the
    top's loop holds (same declarations, same body, same indent), with one pixel (``P = 1``)
    and the loop's clocked block made combinational: the state memories are loaded from the
    ``<reg>_q`` inputs (the registers' current values), the body runs once, and the
    ``<reg>_d`` outputs show what the body left in them (the values the top's registers take
    at the edge). ``charge`` is the input register's value (``charge_sample[p]``), ``held_q``
    / ``held_d`` the second buffer's entry, ``word_now`` the body's ``word``.
    :func:`cosim.formal.stream_rule_equivalence` proves it equivalent to :mod:`rtl.pixel`.
    """
    c = checked_config(config)
    decls, body = _pixel_rule(c, RULE_INDENT)
    regs = {"acc": c.acc_bits, **({"sfc": c.b1, "ovf": 1, "m": c.b2} if c.is_te else
                                  {"count": c.ml_bits})}
    ports = ([f"  input  wire [{c.input_bits - 1}:0] charge,"]
             + ([f"  input  wire [{c.b2 - 1}:0] ccc,"] if c.is_te else [])
             + ["  input  wire last,", "  input  wire frame_valid,", "  input  wire clear,"]
             + [f"  input  wire [{w - 1}:0] {r}_q," for r, w in regs.items()]
             + [f"  input  wire [{c.word_bits - 1}:0] held_q,"]
             + [f"  output reg  [{w - 1}:0] {r}_d," for r, w in regs.items()]
             + [f"  output reg  [{c.word_bits - 1}:0] held_d,",
                f"  output reg  [{c.word_bits - 1}:0] word_now"])
    load = "".join(f"{RULE_INDENT}{r}[p] = {r}_q;\n" for r in regs)
    store = "".join(f"{RULE_INDENT}{r}_d = {r}[p];\n" for r in regs)
    return f"""\
// One pixel of {stream_module_names(c)['top']}: the rule text of its loop, combinational.
// config: {json.dumps(c.to_dict())}
module {c.mode}{'_msb' if c.is_msb else ''}_stream_pixel_rule (
{chr(10).join(ports)}
);
  localparam integer P = 1;
  localparam integer WD = {c.word_bits};
  reg [{c.input_bits - 1}:0] charge_sample [0:P-1];
  reg [{c.acc_bits - 1}:0] acc [0:P-1];
{decls}  reg [WD-1:0] held [0:P-1];
  integer p;
  always @* begin
    for (p = 0; p < P; p = p + 1) begin
      charge_sample[p] = charge;
{load}{RULE_INDENT}held[p] = held_q;
{body}{store}{RULE_INDENT}held_d = held[p];
{RULE_INDENT}word_now = word;
    end
  end
endmodule
"""


def _clear_lines(config: SensorConfig, indent: str) -> str:
    """Zero the counter state of pixel ``p`` (the power-up values)."""
    if config.is_te:
        return (f"{indent}sfc[p] = {config.b1}'d0;\n{indent}ovf[p] = 1'b0;\n"
                f"{indent}m[p] = {config.b2}'d0;\n")
    return f"{indent}count[p] = {config.ml_bits}'d0;\n"


def stream_top_verilog(config: SensorConfig, height: int, width: int, lanes: int) -> str:
    """The top ``<mode>_pixel_array_stream`` with exactly the SPEC section 6 streaming ports."""
    config = checked_config(config)
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
    decls, body = _pixel_rule(config, RULE_INDENT)
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
  localparam integer P = {pixels};   // pixels, p = r*{width} + c
  localparam integer E = {e};
  localparam integer WD = {wd};
  localparam integer N = {n};        // lanes
{ccc_wire}  wire last;         // S_r: the clock in the input register is an interval's last
  wire frame_valid;  // ... and not the empty clock after reset: the words go to held
  reg rst_sample = 1'b0;  // rst sampled: clears the pixels at the edge after a reset edge

  always @(posedge clk) rst_sample <= rst;
  wire clear = rst_sample;

  {names['timing']} timing (.clk(clk), .rst(rst), {ccc_pin}.last(last), .frame_valid(frame_valid));

  // The pixels: one entry per pixel in each memory, one loop over them per clock.
  reg [E-1:0] charge_sample [0:P-1];  // the input registers
  reg [{config.acc_bits - 1}:0] acc [0:P-1];    // charge residual, saturating
{decls}  reg [WD-1:0] held [0:P-1];     // the second buffer: the words of the last interval
  integer p;
  initial  // power-up state as the Amaranth array's: all zero, as after a reset
    for (p = 0; p < P; p = p + 1) begin
      charge_sample[p] = {{E{{1'b0}}}};
      acc[p] = {{{config.acc_bits}{{1'b0}}}};
{_clear_lines(config, "      ")}      held[p] = {{WD{{1'b0}}}};
    end
  // State is read and written only in this block, so blocking assignments are safe.
  /* verilator lint_off BLKSEQ */
  always @(posedge clk)
    for (p = 0; p < P; p = p + 1) begin
{body}      charge_sample[p] = charge[p*E +: E];
    end
  /* verilator lint_on BLKSEQ */

  // The beat counter: beats 0..B-1 on the clocks after the words went to held.
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

  // The beat's lanes: lane i shows held[beat*N + i], 0 past the last pixel.
  reg [N*WD-1:0] lanes;
  integer i;
  always @* begin
    lanes = {{N*WD{{1'b0}}}};
    if (sending)
      for (i = 0; i < N; i = i + 1)
        if (beat*N + i < P) lanes[i*WD +: WD] = held[beat*N + i];
  end
  assign out_valid = sending;
  assign out_first = sending & (beat == {beat_bits}'d0);
  assign out_words = lanes;
endmodule
"""


def stream_array_verilog(config: SensorConfig, height: int, width: int, lanes: int) -> str:
    """Verilog text of the streaming H x W array with N lanes: the top and the timing module.

    Refuses (:class:`golden.errors.ConfigError`, one line naming the smallest N) a lane
    count whose B = ceil(H W / N) beats do not fit in the L clocks of a readout interval.
    """
    config = checked_config(config)
    top = stream_top_verilog(config, height, width, lanes)   # refuses before any conversion
    timing, = convert_modules((ReadoutTiming(config), stream_module_names(config)["timing"]))
    return "\n".join([top, timing])
