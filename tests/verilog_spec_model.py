"""A small hand-written Verilog-2005 model of the SPEC section 6 array ports, for tests.

It lets the outside-simulator harnesses (cosim/verilator.py, cosim/icarus.py) be
tested on their own, independently of the Amaranth-generated Verilog: the same
ports and bit layout, the SPEC section 3 pixel rule written directly, one
generate loop over pixels (the ML msb readout as SPEC section 3 states it: a
bit_length scan and a subtraction of that power of two). ``latency`` picks how the frame reaches the ports
(0: combinational in the interval's last clock, 1: registered, 2: one more
register). ``bug`` plants a known fault so tests can prove they notice it: a wrong
latched CCC value, a second ``frame_valid`` per interval, a syntax error, an X
on ``frame`` or on ``frame_valid``.
"""

from __future__ import annotations

from tespike.golden.config import SensorConfig

BUGS = (None, "m_plus_one", "double_valid", "syntax", "x_frame", "x_valid")


def _zext(expr: str, width: int, to: int) -> str:
    return expr if to == width else f"{{{{{to - width}{{1'b0}}}}, {expr}}}"


def _msb_scan(count: str, bits: int, word_bits: int, indent: str, target: str = "word_n") -> str:
    """Procedural bit_length of ``count``: one ``if`` per bit, the highest set bit assigned last."""
    return "".join(f"{indent}if ({count}[{j}]) {target} = {word_bits}'d{j + 1};\n" for j in range(bits))


def spec_model_verilog(config: SensorConfig, height: int, width: int, *,
                       latency: int = 1, bug: str | None = None, style: str = "generate") -> str:
    if style == "loop":
        if latency != 1 or bug is not None:
            raise ValueError("the loop style has latency 1 and no planted faults")
        return _loop_verilog(config, height, width)
    if latency not in (0, 1, 2) or bug not in BUGS or (bug and bug.startswith("x_") and latency != 1):
        raise ValueError((latency, bug))
    c = config
    N, E, A, WD = height * width, c.input_bits, c.acc_bits, c.word_bits
    QB = max(A, E) + 1                      # q = acc + e never wraps
    top = "te_pixel_array" if c.is_te else "ml_pixel_array"
    F, ALPHA = c.clocks_per_tick, c.alpha
    if c.is_te:
        SB = c.b1 + 1                       # the SFC counts up to 2^b1 (its carry is ovf)
        m_value = "(ccc + 1'b1)" if bug == "m_plus_one" else "ccc"
        # build the word without width tricks: flag bit d, payload m or sfc
        pixel_count = f"""
    wire counting = s & ~ovf;
    wire [{SB - 1}:0] sfc_inc = sfc + {{{{{SB - 1}{{1'b0}}}}, counting}};
    wire overflow = counting & (sfc_inc == {SB}'d{c.p_max});
    wire ovf_n = ovf | overflow;
    wire [{c.b2 - 1}:0] m_n = overflow ? {m_value} : m;
    wire [{c.d - 1}:0] m_wide = {_zext("m_n", c.b2, c.d)};
    wire [{c.d - 1}:0] sfc_wide = {_zext(f"sfc_inc[{c.b1 - 1}:0]", c.b1, c.d)};
    wire [{WD - 1}:0] word_n = ovf_n ? {{1'b1, m_wide}} : {{1'b0, sfc_wide}};
    always @(posedge clk)
      if (rst | last) begin sfc <= {SB}'d0; ovf <= 1'b0; m <= {c.b2}'d0; end
      else begin sfc <= sfc_inc; ovf <= ovf_n; m <= m_n; end
"""
        pixel_regs = f"reg [{SB - 1}:0] sfc; reg ovf; reg [{c.b2 - 1}:0] m;"
    elif c.is_msb:
        SB = c.ml_bits
        pixel_count = f"""
    wire [{SB - 1}:0] cnt_n = (s && sfc != {SB}'d{c.ml_max}) ? sfc + {SB}'d1 : sfc;
    reg [{WD - 1}:0] word_n;   // bit_length(cnt_n): the last set bit wins
    always @* begin
      word_n = {WD}'d0;
{_msb_scan("cnt_n", SB, WD, "      ")}    end
    wire [{SB - 1}:0] top_bit = (word_n == {WD}'d0) ? {SB}'d0 : ({SB}'d1 << (word_n - {WD}'d1));
    always @(posedge clk)
      if (rst) sfc <= {SB}'d0;
      else if (last) sfc <= cnt_n - top_bit;   // the rest of the count stays
      else sfc <= cnt_n;
"""
        pixel_regs = f"reg [{SB - 1}:0] sfc;"
    else:
        SB = c.ml_bits
        pixel_count = f"""
    wire [{SB - 1}:0] word_n = (s && sfc != {SB}'d{c.ml_max}) ? sfc + {SB}'d1 : sfc;
    always @(posedge clk)
      if (rst | last) sfc <= {SB}'d0;
      else sfc <= word_n;
"""
        pixel_regs = f"reg [{SB - 1}:0] sfc;"
    valid_now = f"last | (tick == 32'd0 && j == 32'd0 && 1'b{1 if F * ALPHA > 1 else 0})" if bug == "double_valid" else "last"
    if latency == 0:
        out = f"""
  assign frame_valid = ~rst & ({valid_now});
  assign frame = word_all;
"""
    else:
        out = f"""
  reg valid_r; reg [{N * WD - 1}:0] frame_r;
  always @(posedge clk)
    if (rst) begin valid_r <= 1'b0; frame_r <= {N * WD}'d0; end
    else begin valid_r <= {valid_now}; if (last) frame_r <= word_all; end
"""
        if latency == 1 and bug == "x_frame":
            out += f"  assign frame_valid = valid_r;\n  assign frame = {{frame_r[{N * WD - 1}:1], 1'bx}};\n" \
                if N * WD > 1 else "  assign frame_valid = valid_r;\n  assign frame = 1'bx;\n"
        elif latency == 1 and bug == "x_valid":
            out += "  assign frame_valid = valid_r ? 1'bx : 1'b0;\n  assign frame = frame_r;\n"
        elif latency == 1:
            out += "  assign frame_valid = valid_r;\n  assign frame = frame_r;\n"
        else:
            out += f"""
  reg valid_d; reg [{N * WD - 1}:0] frame_d;
  always @(posedge clk)
    if (rst) begin valid_d <= 1'b0; frame_d <= {N * WD}'d0; end
    else begin valid_d <= valid_r; frame_d <= frame_r; end
  assign frame_valid = valid_d;
  assign frame = frame_d;
"""
    syntax = "  this is not verilog;\n" if bug == "syntax" else ""
    return f"""// Hand-written SPEC section 6 model (tests only): {c}, {height} x {width}
module {top}(clk, rst, charge, frame_valid, frame);
  input clk;
  input rst;
  input [{N * E - 1}:0] charge;
  output frame_valid;
  output [{N * WD - 1}:0] frame;
{syntax}
  reg [31:0] tick;   // pixel clock inside the S_h cycle, 0..F-1
  reg [31:0] j;      // S_h cycle inside the readout interval, 0..alpha-1
  wire last = (tick == 32'd{F - 1}) && (j == 32'd{ALPHA - 1});
  wire [{c.b2 - 1}:0] ccc = j[{c.b2 - 1}:0] + {c.b2}'d1;
  always @(posedge clk)
    if (rst) begin tick <= 32'd0; j <= 32'd0; end
    else if (tick == 32'd{F - 1}) begin
      tick <= 32'd0;
      j <= (j == 32'd{ALPHA - 1}) ? 32'd0 : j + 32'd1;
    end else tick <= tick + 32'd1;

  wire [{N * WD - 1}:0] word_all;
  genvar i;
  generate for (i = 0; i < {N}; i = i + 1) begin : px
    reg [{A - 1}:0] acc;
    {pixel_regs}
    wire [{QB - 1}:0] q = {{{{{QB - A}{{1'b0}}}}, acc}} + {{{{{QB - E}{{1'b0}}}}, charge[i * {E} +: {E}]}};
    wire s = q >= {QB}'d{c.threshold};
    wire [{QB - 1}:0] rest = s ? q - {QB}'d{c.threshold} : q;
    wire [{A - 1}:0] acc_n = (rest > {QB}'d{c.acc_max}) ? {A}'d{c.acc_max} : rest[{A - 1}:0];
    always @(posedge clk) acc <= rst ? {A}'d0 : acc_n;
{pixel_count}
    assign word_all[i * {WD} +: {WD}] = word_n;
  end endgenerate
{out}
endmodule
"""


def _loop_verilog(config: SensorConfig, height: int, width: int) -> str:
    """The same array as one clocked block with a procedural ``for`` loop over register arrays.

    Verilator keeps such a loop a C++ loop (one copy of the pixel code), where a
    ``generate`` loop of instances becomes one copy per pixel. It is here to
    measure what that costs (benchmarks/bench_verilator.py), latency 1.
    """
    c = config
    N, E, A, WD = height * width, c.input_bits, c.acc_bits, c.word_bits
    QB = max(A, E) + 1
    top = "te_pixel_array" if c.is_te else "ml_pixel_array"
    F, ALPHA = c.clocks_per_tick, c.alpha
    if c.is_te:
        SB = c.b1 + 1
        regs = f"""  reg [{SB - 1}:0] sfc [0:{N - 1}];
  reg ovf [0:{N - 1}];
  reg [{c.b2 - 1}:0] m [0:{N - 1}];
  reg counting, overflow, ovf_n;
  reg [{SB - 1}:0] sfc_inc;
  reg [{c.b2 - 1}:0] m_n;
  reg [{c.d - 1}:0] m_wide, sfc_wide;"""
        count = f"""      counting = s & ~ovf[i];
      sfc_inc = sfc[i] + {{{{{SB - 1}{{1'b0}}}}, counting}};
      overflow = counting & (sfc_inc == {SB}'d{c.p_max});
      ovf_n = ovf[i] | overflow;
      m_n = overflow ? ccc : m[i];
      m_wide = {_zext("m_n", c.b2, c.d)};
      sfc_wide = {_zext(f"sfc_inc[{c.b1 - 1}:0]", c.b1, c.d)};
      if (rst | last) begin sfc[i] = {SB}'d0; ovf[i] = 1'b0; m[i] = {c.b2}'d0; end
      else begin sfc[i] = sfc_inc; ovf[i] = ovf_n; m[i] = m_n; end
      if (~rst & last) frame_r[i * {WD} +: {WD}] = ovf_n ? {{1'b1, m_wide}} : {{1'b0, sfc_wide}};"""
    elif c.is_msb:
        SB = c.ml_bits
        regs = f"""  reg [{SB - 1}:0] sfc [0:{N - 1}];
  reg [{SB - 1}:0] sfc_n;
  reg [{WD - 1}:0] w_n;"""
        count = f"""      sfc_n = (s && sfc[i] != {SB}'d{c.ml_max}) ? sfc[i] + {SB}'d1 : sfc[i];
      w_n = {WD}'d0;
{_msb_scan("sfc_n", SB, WD, "      ", "w_n")}      if (rst) sfc[i] = {SB}'d0;
      else if (last) sfc[i] = sfc_n - ((w_n == {WD}'d0) ? {SB}'d0 : ({SB}'d1 << (w_n - {WD}'d1)));
      else sfc[i] = sfc_n;
      if (~rst & last) frame_r[i * {WD} +: {WD}] = w_n;"""
    else:
        SB = c.ml_bits
        regs = f"""  reg [{SB - 1}:0] sfc [0:{N - 1}];
  reg [{SB - 1}:0] sfc_n;"""
        count = f"""      sfc_n = (s && sfc[i] != {SB}'d{c.ml_max}) ? sfc[i] + {SB}'d1 : sfc[i];
      sfc[i] = (rst | last) ? {SB}'d0 : sfc_n;
      if (~rst & last) frame_r[i * {WD} +: {WD}] = sfc_n;"""
    return f"""// Hand-written SPEC section 6 model, procedural-loop style (tests only): {c}, {height} x {width}
module {top}(clk, rst, charge, frame_valid, frame);
  input clk;
  input rst;
  input [{N * E - 1}:0] charge;
  output frame_valid;
  output [{N * WD - 1}:0] frame;
  reg [31:0] tick;
  reg [31:0] j;
  wire last = (tick == 32'd{F - 1}) && (j == 32'd{ALPHA - 1});
  wire [{c.b2 - 1}:0] ccc = j[{c.b2 - 1}:0] + {c.b2}'d1;
  always @(posedge clk)
    if (rst) begin tick <= 32'd0; j <= 32'd0; end
    else if (tick == 32'd{F - 1}) begin
      tick <= 32'd0;
      j <= (j == 32'd{ALPHA - 1}) ? 32'd0 : j + 32'd1;
    end else tick <= tick + 32'd1;

  reg [{A - 1}:0] acc [0:{N - 1}];
{regs}
  reg [{N * WD - 1}:0] frame_r;
  reg valid_r;
  reg [{QB - 1}:0] q, rest;
  reg s;
  integer i;
  // State is read and written only here, so blocking assignments inside the loop are safe.
  always @(posedge clk) begin
    valid_r <= ~rst & last;
    for (i = 0; i < {N}; i = i + 1) begin
      q = {{{{{QB - A}{{1'b0}}}}, acc[i]}} + {{{{{QB - E}{{1'b0}}}}, charge[i * {E} +: {E}]}};
      s = q >= {QB}'d{c.threshold};
      rest = s ? q - {QB}'d{c.threshold} : q;
      acc[i] = rst ? {A}'d0 : (rest > {QB}'d{c.acc_max}) ? {A}'d{c.acc_max} : rest[{A - 1}:0];
{count}
    end
  end
  assign frame_valid = valid_r;
  assign frame = frame_r;
endmodule
"""
