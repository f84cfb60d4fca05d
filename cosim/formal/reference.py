"""SPEC sections 1-6 written as Verilog for the proofs of the generated tops, independent of rtl/.

:func:`reference_verilog` writes a module ``spec_reference`` for one configuration and one
H x W array, from SPEC's text alone (no line of :mod:`rtl` is read or reused): per pixel
the rule of section 3 (``q = acc + e``, the spike, the subtractive saturating reset, the TE
counter with its overflow flag and latched CCC, the ML saturating counter and its msb
readout), the word of section 4, and the clocks of section 1 (a pixel-clock position
``ph`` inside the S_h cycle and ``jj`` inside the readout interval, CCC = jj + 1).

Time is counted as SPEC section 6 counts it: the rising edge that samples ``e[t]`` is
pixel clock t, and t = 0 is the first edge with ``rst`` low. A reset edge (``rst`` high)
drops the charge it sees and returns every register to its power-up value (zero
counters, position at the next interval's first clock), so the reference powers up as if
reset one edge before the first. ``done`` is high in the clock after the edge that
sampled an interval's last charge, with that interval's ``words`` (pixel p = r W + c at
``[p*Wd +: Wd]``).

Two outputs follow from ``done`` and ``words``, each at a fixed latency the design
documents (:data:`PARALLEL_DELAY`, :data:`STREAM_DELAY`, edges after the interval's last
edge): the parallel top's ``frame_valid``/``frame``, and the streaming top's beats, beat j
of an interval carrying pixels j N + i in lane i (0 past the last pixel), one per clock,
spelled out beat by beat (no run-time index). A reset clears both.
"""

from __future__ import annotations

from tespike.golden.beats import check_array_size
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count

#: Edges between the edge that samples an interval's last charge and the first clock its
#: words show on the parallel top (0: ``frame_valid`` in the very next clock, sampled one
#: clock after the last, docs/rtl.md "Latency and reset").
PARALLEL_DELAY = 0
#: The same for beat 0 of the streaming top (1: beat j is sampled 2 + j clocks after the
#: interval's last clock, docs/rtl.md "Streaming readout").
STREAM_DELAY = 1


def checked_request(config, what: str, height=None, width=None, lanes=None) -> SensorConfig:
    """The configuration re-validated, and the array's sizes and lane count (where given) integers
    >= 1, refused in one line naming ``what`` (a preset's name had been an AttributeError of
    ``check``, 0 lanes a ZeroDivisionError): every harness builder's first step."""
    config = SensorConfig.checked(config, what)
    if height is not None or width is not None:
        check_array_size(height, width)
    if lanes is not None and not is_count(lanes, 1):
        raise InputError(f"{what}: lanes {lanes!r} must be an integer >= 1 (or None: the parallel top)")
    return config


def _bits(value: int) -> int:
    return max(1, int(value).bit_length())


def _pixel(config: SensorConfig, p: int) -> tuple[str, str, str, str]:
    """(declarations, combinational next values, reset lines, clock lines) of pixel ``p``."""
    c = config
    A, E = c.acc_bits, c.input_bits
    QB = max(A, E) + 1
    wd = c.word_bits
    n = f"p{p}_"
    decl = (f"  reg [{A - 1}:0] {n}acc = 0;\n"
            f"  wire [{QB - 1}:0] {n}q = {{{QB - A}'d0, {n}acc}} + {{{QB - E}'d0, charge[{p * E} +: {E}]}};\n"
            f"  wire {n}s = {n}q >= {QB}'d{c.threshold};\n"
            f"  wire [{QB - 1}:0] {n}after = {n}s ? {n}q - {QB}'d{c.threshold} : {n}q;\n"
            f"  wire [{A - 1}:0] {n}acc1 = ({n}after > {QB}'d{c.acc_max}) ? {A}'d{c.acc_max} "
            f": {n}after[{A - 1}:0];\n"
            f"  wire [{wd - 1}:0] {n}word;\n")
    reset = f"      {n}acc <= 0;\n"
    clock = f"      {n}acc <= {n}acc1;\n"
    if c.is_te:
        b1, b2, d = c.b1, c.b2, c.d
        cap = 2 ** b1
        decl += (f"  reg [{b1}:0] {n}sfc = 0;   // reaches 2^b1 = {cap} at the overflow\n"
                 f"  reg {n}ovf = 0;\n"
                 f"  reg [{b2 - 1}:0] {n}m = 0;\n"
                 f"  wire {n}counting = ~{n}ovf & {n}s;\n"
                 f"  wire [{b1}:0] {n}sfc1 = {n}counting ? {n}sfc + 1'b1 : {n}sfc;\n"
                 f"  wire {n}hit = {n}counting & ({n}sfc1 == {b1 + 1}'d{cap});\n"
                 f"  wire {n}ovf1 = {n}ovf | {n}hit;\n"
                 f"  wire [{b2 - 1}:0] {n}m1 = {n}hit ? ccc : {n}m;\n"
                 f"  assign {n}word = {n}ovf1 ? ({wd}'d{1 << d} | {{{wd - b2}'d0, {n}m1}}) "
                 f": {{{wd - b1}'d0, {n}sfc1[{b1 - 1}:0]}};\n")
        reset += f"      {n}sfc <= 0; {n}ovf <= 0; {n}m <= 0;\n"
        clock += (f"      {n}sfc <= last ? 0 : {n}sfc1;\n"
                  f"      {n}ovf <= last ? 1'b0 : {n}ovf1;\n"
                  f"      {n}m <= last ? 0 : {n}m1;\n")
        return decl, "", reset, clock
    B = c.ml_bits
    decl += (f"  reg [{B - 1}:0] {n}cnt = 0;\n"
             f"  wire [{B - 1}:0] {n}cnt1 = ({n}s && {n}cnt != {B}'d{c.ml_max}) ? {n}cnt + 1'b1 : {n}cnt;\n")
    if c.is_msb:
        # bit_length(cnt1): how many of 1, 2, 4, ... 2^(B-1) are <= cnt1
        length = " + ".join(f"({wd}'d0 + ({n}cnt1 >= {B}'d{2 ** j}))" for j in range(B))
        power = "".join(f"({n}word == {wd}'d{j + 1}) ? {B}'d{2 ** j} : " for j in range(B))
        decl += (f"  assign {n}word = {length};\n"
                 f"  wire [{B - 1}:0] {n}taken = {power}{B}'d0;   // 2^(word - 1), 0 for word 0\n")
        after = f"{n}cnt1 - {n}taken"
    else:
        decl += f"  assign {n}word = {n}cnt1;\n"
        after = "0"
    reset += f"      {n}cnt <= 0;\n"
    clock += f"      {n}cnt <= last ? {after} : {n}cnt1;\n"
    return decl, "", reset, clock


def _delay(name: str, width: int, source: str, stages: int, what: str) -> tuple[str, str]:
    """A ``stages``-deep shift register from ``source`` (cleared by rst): (declarations, name of
    its output)."""
    if stages == 0:
        return "", source
    regs = "".join(f"  reg [{width - 1}:0] {name}{s} = 0;\n" for s in range(stages))
    shift = "".join(f"      {name}{s} <= {source if s == 0 else f'{name}{s - 1}'};\n" for s in range(stages))
    return (regs + "  always @(posedge clk)\n    if (rst) begin\n"
            + "".join(f"      {name}{s} <= 0;\n" for s in range(stages))
            + f"    end else begin  // {what}\n{shift}    end\n"), f"{name}{stages - 1}"


def reference_verilog(config: SensorConfig, height: int, width: int, lanes: int | None = None, *,
                      parallel_delay: int = PARALLEL_DELAY, stream_delay: int = STREAM_DELAY) -> str:
    """Module ``spec_reference`` (ports ``clk``, ``rst``, ``charge``; ``done``/``words``; the
    parallel ``frame_valid``/``frame``; with ``lanes``, ``out_valid``/``out_first``/``out_words``
    and ``beat_words`` (the words beat ``beat_index`` must carry, for the contract monitor)."""
    c = checked_request(config, "reference_verilog", height, width, lanes)
    for name, value in (("parallel_delay", parallel_delay), ("stream_delay", stream_delay)):
        if not is_count(value):                          # (-1 had been taken)
            raise InputError(f"reference_verilog {name} {value!r}: must be an integer >= 0")
    P, E, wd = height * width, c.input_bits, c.word_bits
    F, alpha = c.clocks_per_tick, c.alpha
    pixels = [_pixel(c, p) for p in range(P)]
    words = "{" + ", ".join(f"p{p}_word" for p in reversed(range(P))) + "}"
    fv_decl, fv = _delay("fv_d", 1, "done", parallel_delay, "the parallel top's latency")
    fr_decl, fr = _delay("frame_d", P * wd, "words", parallel_delay, "the parallel top's latency")
    ports = ["input wire clk", "input wire rst", f"input wire [{P * E - 1}:0] charge",
             "output reg done = 0", f"output reg [{P * wd - 1}:0] words = 0",
             "output wire frame_valid", f"output wire [{P * wd - 1}:0] frame"]
    stream = ""
    if lanes is not None:
        beats = -(-P // lanes)
        bb = _bits(beats)
        ports += ["output wire out_valid", "output wire out_first", f"output wire [{lanes * wd - 1}:0] out_words",
                  f"input wire [{bb - 1}:0] beat_index", f"input wire [{P * wd - 1}:0] beat_source",
                  f"output wire [{lanes * wd - 1}:0] beat_words"]
        go_decl, go = _delay("go_d", 1, "done", stream_delay - 1, "the streaming top's latency") \
            if stream_delay >= 1 else ("", None)
        src_decl, src = _delay("src_d", P * wd, "words", stream_delay - 1, "the streaming top's latency") \
            if stream_delay >= 1 else ("", None)
        if stream_delay < 1:
            raise ValueError("the streaming reference needs a latency of at least one edge")

        def lane_words(source: str, b: int) -> str:
            parts = [f"{source}[{(b * lanes + i) * wd} +: {wd}]" if b * lanes + i < P else f"{wd}'d0"
                     for i in reversed(range(lanes))]
            return "{" + ", ".join(parts) + "}"

        def select(index: str, source: str) -> str:
            return "".join(f"({index} == {bb}'d{b}) ? {lane_words(source, b)} : "
                           for b in range(beats)) + f"{lanes * wd}'d0"
        stream = (go_decl + src_decl +
                  f"  // The streaming readout: beat j of an interval is pixels j*{lanes} + i, one beat a clock.\n"
                  f"  reg sending = 0;\n  reg [{bb - 1}:0] beat = 0;\n"
                  f"  reg [{P * wd - 1}:0] buffer = 0;\n"
                  f"  always @(posedge clk)\n"
                  f"    if (rst) begin sending <= 0; beat <= 0; end\n"
                  f"    else if ({go}) begin buffer <= {src}; sending <= 1; beat <= 0; end\n"
                  f"    else if (sending) begin\n"
                  f"      beat <= beat + 1'b1;\n"
                  f"      if (beat == {bb}'d{beats - 1}) sending <= 0;\n"
                  f"    end\n"
                  f"  assign out_valid = sending;\n"
                  f"  assign out_first = sending & (beat == {bb}'d0);\n"
                  f"  assign out_words = sending ? ({select('beat', 'buffer')}) : {lanes * wd}'d0;\n"
                  f"  assign beat_words = {select('beat_index', 'beat_source')};\n")
    ccc = f"  wire [{c.b2 - 1}:0] ccc = jj + 1'b1;   // CCC = j + 1 during S_h cycle j\n" if c.is_te else ""
    return f"""\
// SPEC reference of a {height} x {width} {c.mode} array (cosim/formal/reference.py), written from SPEC only.
module spec_reference (
  {(',' + chr(10) + '  ').join(ports)}
);
  // SPEC section 1: pixel clock ph inside S_h (F = {F}), S_h cycle jj inside S_r (alpha = {alpha})
  reg [{_bits(F - 1) - 1}:0] ph = 0;
  reg [{_bits(alpha - 1) - 1}:0] jj = 0;
{ccc}  wire last = (ph == {F - 1}) && (jj == {alpha - 1});   // t mod L == L - 1
{''.join(d for d, _, _, _ in pixels)}  always @(posedge clk)
    if (rst) begin
      ph <= 0; jj <= 0; done <= 0;
{''.join(r for _, _, r, _ in pixels)}    end else begin
      ph <= (ph == {F - 1}) ? 0 : ph + 1'b1;
      if (ph == {F - 1}) jj <= (jj == {alpha - 1}) ? 0 : jj + 1'b1;
      done <= last;
      if (last) words <= {words};
{''.join(k for _, _, _, k in pixels)}    end
{fv_decl}{fr_decl}  assign frame_valid = {fv};
  assign frame = {fr};
{stream}endmodule
"""
