"""Verilog of the streaming array (SPEC section 6, ``tespike verilog --lanes N``).

The Verilog form of :class:`tespike.rtl.stream.StreamingPixelArray` (same ports,
timing and words at every clock, checked bit for bit against the golden model in
Icarus, Verilator and cocotb), drawn as a chip is: every block a module, one
instance per site, hierarchy kept, so that a synthesis tool sees H x W copies
of one small pixel and one small readout cell and nothing that grows faster
than the pixel count (``tespike synthesize``, docs/hardware-cost.md).
The top ``<mode>_pixel_array_stream`` (ports ``clk``, ``rst``, ``charge``,
``out_valid``, ``out_first``, ``out_words``) holds:

* the readout timing block, ``<mode>_readout_timing``, generated from Amaranth
  (:class:`tespike.rtl.timing.ReadoutTiming`, one instance);
* ``rst_sample`` (``rst`` one edge later: it clears the pixels, as in
  :mod:`tespike.rtl.array`) and the beat counter (``sending``, ``beat``);
* B beat groups (``<mode>_beat_group``, B - 1 instances of N sites, and
  ``<mode>_beat_group_end``, the S = H W - (B - 1) N last sites): group j holds
  the sites of pixels p = j N + i (raster order, p = r W + c), site i on lane i,
  each site one pixel ``<mode>_stream_pixel`` (its input register
  ``charge_sample``, its state registers, and the pixel rule
  ``<mode>[_msb]_stream_pixel_rule``, a combinational module: the rule of
  :mod:`tespike.rtl.pixel`, proved equivalent to it by ``tespike prove``, property
  ``stream-pixel-rule``) and one readout cell ``<mode>_readout_cell`` (a Wd-bit
  register), in a generate loop. Grouping by beat keeps the top's own netlist
  at B instances (Yosys's passes over the top cost time per wire: with all
  2 H W site instances in the top, ``synth`` grew to about 13 CPU-minutes at
  400 x 250).

The readout is a shift register per lane (the second buffer of a
double-buffered readout). At the edge where the timing shows ``frame_valid``
every cell loads its pixel's word of the interval's last clock and the pixels
integrate on; on every clock that carries a beat, cell p takes the word of cell
p + N (group j's cell i takes group j + 1's; 0 past the last pixel). Lane i is
chain i, i + N, i + 2N, ... and its output is cell i's register (group 0), so beat j carries pixels j N + i exactly as SPEC
section 6 orders, and after the last beat every cell holds 0 (``out_words`` is
0 whenever ``out_valid`` is low). The logic is one 3-way multiplexer per cell
bit: linear in H x W, where a run-time index ``held[beat*N + i]`` per lane made a
multiplexer over all H x W words per lane (N x H x W).

``rst`` clears the timing, the beat counter and every readout cell at its edge;
the pixels are cleared one edge later by ``rst_sample`` (the edge that would
otherwise process the clock the reset edge sampled, :mod:`tespike.rtl.array`).

For Verilator at sensor size, :func:`stream_loop_verilog` writes the same top
as a simulation view: the pixels and cells as memories and one clocked ``for``
loop (Verilator 5.006 copies every instance's logic into its own scope, about
90 KB per pixel; docs/outside-simulators.md, "Sensor size"). It holds the very
same rule text and the same shift-register readout, and the tests run both
views against the golden model.
"""

from __future__ import annotations

import json

from tespike.golden.config import SensorConfig
from tespike.golden.beats import beat_count, check_lanes
from tespike.golden.errors import ConfigError

from .array import check_array_size
from .timing import ReadoutTiming
from .names import stream_module_names
from .verilog import genvar_names, generate_loop, checked_config, convert_modules

#: A one-bit one, zero-extended by :func:`_zext` for the msb readout's power of two.
ONE_BIT = "1'b1"


def _zero_fill(pad: str) -> str:
    """The end group's assignment to the last beat: its cells, then ``pad`` (the zeros of the lanes
    past the last pixel, SPEC section 6) where it has fewer cells than lanes. That replication
    grows with the lanes (up to MAX_LANES x Wd bits), past the 8 Kibit Verilator takes for a
    mistake: waived for this one line."""
    if not pad:
        return "  assign beat_bus[B - 1] = end_held;\n"
    return ("  /* verilator lint_off WIDTHCONCAT */\n"
            f"  assign beat_bus[B - 1] = {pad};\n"
            "  /* verilator lint_on WIDTHCONCAT */\n")


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
    """One pixel's rule as a combinational module: the design's per-site rule, and what
    ``tespike prove`` proves.

    The module ``<mode>[_msb]_stream_pixel_rule`` is instantiated once per site by
    :func:`stream_pixel_verilog` (the design) and holds the very text of :func:`_pixel_rule`
    that the simulation view's loop holds (same declarations, same body, same indent), with
    one pixel (``P = 1``) and the loop's clocked block made combinational: the state memories are loaded from the
    ``<reg>_q`` inputs (the registers' current values), the body runs once, and the
    ``<reg>_d`` outputs show what the body left in them (the values the top's registers take
    at the edge). ``charge`` is the input register's value (``charge_sample[p]``), ``held_q``
    / ``held_d`` the second buffer's entry, ``word_now`` the body's ``word``.
    :func:`tespike.cosim.formal.stream_rule_equivalence` proves it equivalent to :mod:`tespike.rtl.pixel`.
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
module {stream_module_names(c)['rule']} (
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


def _state_registers(config: SensorConfig) -> dict[str, int]:
    """A pixel's state registers and their widths, as the rule module names them."""
    c = config
    return {"acc": c.acc_bits, **({"sfc": c.b1, "ovf": 1, "m": c.b2} if c.is_te else {"count": c.ml_bits})}


def stream_pixel_verilog(config: SensorConfig) -> str:
    """One site's pixel ``<mode>_stream_pixel``: the input register, the state registers and
    one instance of the rule module (:func:`stream_pixel_rule_verilog`); ``word`` is the word
    of the clock in the input register (combinational from registers only).

    The rule's second-buffer entry is not used here (the readout cell holds the word), so its
    ``held`` ports are tied off; the rule is proved with them all the same.
    """
    c = checked_config(config)
    names = stream_module_names(c)
    regs = _state_registers(c)
    te = c.is_te
    state = "".join(f"  reg [{w - 1}:0] {r}_q = {w}'d0;\n  wire [{w - 1}:0] {r}_d;\n" for r, w in regs.items())
    pins = ("".join(f" .{r}_q({r}_q)," for r in regs) + "\n   "
            + "".join(f" .{r}_d({r}_d)," for r in regs))
    update = "".join(f"    {r}_q <= {r}_d;\n" for r in regs)
    return f"""\
// {names['pixel']}: one pixel site of {names['top']} (input register, state, rule).
module {names['pixel']} (
  input  wire clk,
  input  wire [{c.input_bits - 1}:0] charge,   // this pixel's bits of the top's charge port
{f"  input  wire [{c.b2 - 1}:0] ccc," + chr(10) if te else ""}\
  input  wire last,                // S_r of the clock in the input register
  input  wire clear,               // rst sampled: clears the state at this edge
  output wire [{c.word_bits - 1}:0] word       // the word of the clock in the input register
);
  reg [{c.input_bits - 1}:0] charge_sample = {c.input_bits}'d0;  // the input register
{state}  // The rule's second-buffer entry: unused here, the readout cell holds the word.
  /* verilator lint_off UNUSEDSIGNAL */
  wire [{c.word_bits - 1}:0] held_unused;
  /* verilator lint_on UNUSEDSIGNAL */
  {names['rule']} rule (.charge(charge_sample), {'.ccc(ccc), ' if te else ''}.last(last), \
.frame_valid(1'b0), .clear(clear),
   {pins} .held_q({c.word_bits}'d0), .held_d(held_unused), .word_now(word));
  always @(posedge clk) begin
    charge_sample <= charge;
{update}  end
endmodule
"""


def readout_cell_verilog(config: SensorConfig) -> str:
    """One readout cell ``<mode>_readout_cell``: a Wd-bit register that loads its pixel's word
    (``load``), else takes the next cell's word while a beat leaves (``shift``); ``rst`` clears it."""
    c = checked_config(config)
    wd = c.word_bits
    return f"""\
// {stream_module_names(c)['cell']}: one cell of the per-lane readout shift registers.
module {stream_module_names(c)['cell']} (
  input  wire clk,
  input  wire rst,
  input  wire load,                // frame_valid: take this site's pixel word
  input  wire shift,               // a beat leaves: take the word of the cell N sites on
  input  wire [{wd - 1}:0] word,
  input  wire [{wd - 1}:0] shift_in,
  output reg  [{wd - 1}:0] held
);
  initial held = {wd}'d0;
  always @(posedge clk)
    if (rst) held <= {wd}'d0;
    else if (load) held <= word;
    else if (shift) held <= shift_in;
endmodule
"""


def _geometry(config: SensorConfig, height: int, width: int, lanes: int) -> tuple[int, int, int]:
    """(pixels, beats, beat counter bits) after refusing a bad size or lane count."""
    height, width = check_array_size(height, width)
    check_lanes(config, height, width, lanes)
    beats = beat_count(height * width, lanes)
    return height * width, beats, max(1, beats.bit_length())


def _header(config: SensorConfig, height: int, width: int, lanes: int, view: str, grid: bool) -> str:
    """The top's comment, ports and local parameters (``H`` and ``W`` only where ``grid`` loops use them)."""
    names = stream_module_names(config)
    beats = beat_count(height * width, lanes)
    wd = config.word_bits
    return f"""\
// The user names the output file (tespike verilog --out A.v): waive Verilator's file-name style check.
/* verilator lint_off DECLFILENAME */
// {names['top']}: {height} x {width} {'time-encoding' if config.is_te else 'multi-level counter'} pixels, one
// readout timing block and a double-buffered readout of {lanes} lanes (tespike, SPEC section 6):
// readout interval k leaves as B = {beats} beats; beat j carries pixels p = j*{lanes} + i (raster
// order, p = r*{width} + c) at out_words[i*{wd} +: {wd}], 0 past the last pixel. Beat j is sampled
// 2 + j clocks after the interval's last clock (the last at most 2L after it).
// {view}
// config: {json.dumps(config.to_dict())}
module {names['top']} (
  input  wire clk,                           // pixel clock, rising edge
  input  wire rst,                           // synchronous, active high
  input  wire [{height * width * config.input_bits - 1}:0] charge,  // pixel (r, c) at [(r*W + c)*{config.input_bits} +: {config.input_bits}]
  output wire out_valid,                     // high on each clock that carries a beat
  output wire out_first,                     // high with beat 0 of each readout interval
  output wire [{lanes * wd - 1}:0] out_words     // lane i at [i*{wd} +: {wd}]
);
{f"  localparam integer H = {height};{chr(10)}  localparam integer W = {width};{chr(10)}" if grid else ""}  localparam integer P = {height * width};   // pixels, p = r*W + c
  localparam integer E = {config.input_bits};
  localparam integer WD = {wd};
  localparam integer N = {lanes};        // lanes
"""


def _timing_and_beats(config: SensorConfig, beats: int, beat_bits: int) -> str:
    """``rst_sample``, the timing block and the beat counter (shared by both views)."""
    names = stream_module_names(config)
    te = config.is_te
    return f"""\
{f"  wire [{config.b2 - 1}:0] ccc;  // shared clock cycle counter, 1..alpha" + chr(10) if te else ""}\
  wire last;         // S_r: the clock in the input registers is an interval's last
  wire frame_valid;  // ... and not the empty clock after reset: the words go to the readout
  reg rst_sample = 1'b0;  // rst sampled: clears the pixels at the edge after a reset edge

  always @(posedge clk) rst_sample <= rst;
  wire clear = rst_sample;

  {names['timing']} timing (.clk(clk), .rst(rst), {'.ccc(ccc), ' if te else ''}.last(last), .frame_valid(frame_valid));

  // The beat counter: beats 0..B-1 on the clocks after the words went to the readout.
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
  assign out_valid = sending;
  assign out_first = sending & (beat == {beat_bits}'d0);
"""


def group_verilog(config: SensorConfig, sites: int, *, chained: bool) -> str:
    """One beat group: ``sites`` consecutive sites (pixel + readout cell each, a generate loop),
    the sites whose words leave in one beat. ``chained``: each cell shifts in the word of the
    next group's cell of the same lane (``shift_in``); the end group (the last beat's sites)
    shifts in 0. Named ``<mode>_beat_group`` / ``<mode>_beat_group_end``."""
    c = checked_config(config)
    names = stream_module_names(c)
    name = names["group"] if chained else names["group_end"]
    te = c.is_te
    shift = "shift_in[i*WD +: WD]" if chained else "{WD{1'b0}}"

    def site(i, indent):
        return (f"{indent}wire [WD-1:0] word;  // this site's pixel word\n"
                f"{indent}{names['pixel']} pixel (.clk(clk), .charge(charge[{i}*E +: E]), "
                f"{'.ccc(ccc), ' if te else ''}.last(last), .clear(clear), .word(word));\n"
                f"{indent}{names['cell']} readout (.clk(clk), .rst(rst), .load(frame_valid), .shift(sending),\n"
                f"{indent}  .word(word), .shift_in({shift.replace('i*', f'{i}*')}), .held(held[{i}*WD +: WD]));\n")

    loop = generate_loop("i", sites, "SITES", "site", site, "    ")
    return f"""\
// {name}: {sites} sites of {names['top']} whose words leave in one beat (site i on lane i).
module {name} (
  input  wire clk,
  input  wire rst,                 // clears the readout cells
  input  wire clear,               // rst sampled: clears the pixels
{f"  input  wire [{c.b2 - 1}:0] ccc," + chr(10) if te else ""}\
  input  wire last,
  input  wire frame_valid,         // the cells load their pixels' words
  input  wire sending,             // a beat leaves: every cell shifts by one group
  input  wire [{sites * c.input_bits - 1}:0] charge,   // site i at [i*{c.input_bits} +: {c.input_bits}]
{f"  input  wire [{sites * c.word_bits - 1}:0] shift_in,  // the next group's cells" + chr(10) if chained else ""}\
  output wire [{sites * c.word_bits - 1}:0] held       // this group's cells, site i at [i*{c.word_bits} +: {c.word_bits}]
);
  localparam integer SITES = {sites};
  localparam integer E = {c.input_bits};
  localparam integer WD = {c.word_bits};
  genvar {", ".join(genvar_names("i", sites))};
  generate
{loop}  endgenerate
endmodule
"""


def stream_top_verilog(config: SensorConfig, height: int, width: int, lanes: int) -> str:
    """The top ``<mode>_pixel_array_stream`` (SPEC section 6 streaming ports) and its hand-written
    blocks: the beat groups, the site pixel, its rule and the readout cell (the timing block is
    Amaranth's, :func:`stream_array_verilog`).

    Sites are grouped by beat: group j holds pixels j N .. j N + N - 1 (the end group the
    S = P - (B - 1) N last ones), so lane i is cell i of every group, group j's cells shift
    into group j - 1's, and ``out_words`` is group 0's cells. The top holds B group instances
    and the synthesis tool sees one full group and one end group, whatever H x W is.
    """
    config = checked_config(config)
    pixels, beats, beat_bits = _geometry(config, height, width, lanes)
    names = stream_module_names(config)
    n = lanes
    end_sites = pixels - (beats - 1) * n
    te = config.is_te
    pins = f".clk(clk), .rst(rst), .clear(clear), {'.ccc(ccc), ' if te else ''}.last(last), " \
           f".frame_valid(frame_valid), .sending(sending),"

    def group(j, indent):
        return (f"{indent}{names['group']} group ({pins}\n"
                f"{indent}  .charge(charge[{j}*N*E +: N*E]), .shift_in(beat_bus[{j} + 1]), "
                f".held(beat_bus[{j}]));\n")

    full = generate_loop("j", beats - 1, "B - 1", "groups", group, "    ") if beats > 1 else ""
    pad = "" if end_sites == n else "{{(N - S)*WD{1'b0}}, end_held}"
    top = (_header(config, height, width, lanes,
                   "Structure: B beat groups of N sites (one pixel and one readout cell each), "
                   "one timing block.", False)
           + _timing_and_beats(config, beats, beat_bits) + f"""
  // Beat group j's readout cells (pixel j*N + i at [i*WD +: WD]); lane i is cell i of
  // every group, group j + 1's cells shift into group j's, group 0's cells are the lanes.
  localparam integer B = {beats};
  localparam integer S = P - (B - 1)*N;   // sites of the end group: {end_sites}
  wire [N*WD-1:0] beat_bus [0:B-1];
  wire [S*WD-1:0] end_held;
{f"  genvar {', '.join(genvar_names('j', beats - 1))};{chr(10)}  generate{chr(10)}{full}  endgenerate{chr(10)}" if full else ""}\
  {names['group_end']} group_end ({pins}
    .charge(charge[(B - 1)*N*E +: S*E]), .held(end_held));
{_zero_fill(pad)}  assign out_words = beat_bus[0];
endmodule
""")
    parts = [top]
    if beats > 1:
        parts.append(group_verilog(config, n, chained=True))
    parts += [group_verilog(config, end_sites, chained=False), stream_pixel_verilog(config),
              stream_pixel_rule_verilog(config), readout_cell_verilog(config)]
    return "\n".join(parts)


def _clear_lines(config: SensorConfig, indent: str) -> str:
    """Zero the counter state of pixel ``p`` (the power-up values)."""
    if config.is_te:
        return (f"{indent}sfc[p] = {config.b1}'d0;\n{indent}ovf[p] = 1'b0;\n"
                f"{indent}m[p] = {config.b2}'d0;\n")
    return f"{indent}count[p] = {config.ml_bits}'d0;\n"


def stream_loop_verilog(config: SensorConfig, height: int, width: int, lanes: int) -> str:
    """The same top as a simulation view for Verilator at sensor size: the pixels, input
    registers and readout cells as memories, one clocked ``for`` loop applying the same rule
    text (:func:`_pixel_rule`) and the same shift-register readout to every site (module
    docstring). Not for synthesis: :func:`stream_top_verilog` is the design."""
    config = checked_config(config)
    pixels, beats, beat_bits = _geometry(config, height, width, lanes)
    decls, body = _pixel_rule(config, RULE_INDENT)
    top = (_header(config, height, width, lanes,
                   "Simulation view (one clocked loop over memories); the design is the instance view.", False)
           + _timing_and_beats(config, beats, beat_bits) + f"""
  // The pixels: one entry per pixel in each memory, one loop over them per clock.
  reg [E-1:0] charge_sample [0:P-1];  // the input registers
  reg [{config.acc_bits - 1}:0] acc [0:P-1];    // charge residual, saturating
{decls}  reg [WD-1:0] held [0:P-1];     // the readout cells: lane i is held[i], held[i + N], ...
  integer p;
  initial  // power-up state as the Amaranth array's: all zero, as after a reset
    for (p = 0; p < P; p = p + 1) begin
      charge_sample[p] = {{E{{1'b0}}}};
      acc[p] = {{{config.acc_bits}{{1'b0}}}};
{_clear_lines(config, "      ")}      held[p] = {{WD{{1'b0}}}};
    end
  // State is read and written only in this block, so blocking assignments are safe;
  // p rises, so held[p + N] is still the cell's value before this edge.
  /* verilator lint_off BLKSEQ */
  always @(posedge clk)
    for (p = 0; p < P; p = p + 1) begin
      if (sending) held[p] = (p + N < P) ? held[p + N] : {{WD{{1'b0}}}};
{body}      if (rst) held[p] = {{WD{{1'b0}}}};
      charge_sample[p] = charge[p*E +: E];
    end
  /* verilator lint_on BLKSEQ */

  reg [N*WD-1:0] lanes;
  integer i;
  always @* begin
    lanes = {{N*WD{{1'b0}}}};
    for (i = 0; i < N; i = i + 1)
      if (i < P) lanes[i*WD +: WD] = held[i];
  end
  assign out_words = lanes;
endmodule
""")
    return top


#: The two forms of the streaming top: the design (instances) and the Verilator simulation view.
VIEWS = ("instances", "loop")


def stream_array_verilog(config: SensorConfig, height: int, width: int, lanes: int, *,
                         view: str = "instances") -> str:
    """Verilog text of the streaming H x W array with N lanes: the top, its blocks and the timing.

    ``view="loop"``: the simulation view of :func:`stream_loop_verilog` instead of the
    design. Refuses (:class:`tespike.golden.errors.ConfigError`, one line naming the smallest N) a
    lane count whose B = ceil(H W / N) beats do not fit in the L clocks of a readout interval.
    """
    config = checked_config(config)
    if view not in VIEWS:
        raise ConfigError(f"view = {view!r}: one of {', '.join(VIEWS)}")
    make = stream_top_verilog if view == "instances" else stream_loop_verilog
    top = make(config, height, width, lanes)   # refuses before any conversion
    timing, = convert_modules((ReadoutTiming(config), stream_module_names(config)["timing"]))
    return "\n".join([top, timing])
