"""Proofs of the generated Verilog tops, read from the very text ``tespike verilog`` writes.

Each property is a Verilog harness beside the generated text (:func:`design_text`, the
same generator calls as ``tespike verilog``), proved by ABC (:mod:`tespike.cosim.formal.abc`). Only the tops' ports and the timing block's ports are used,
never an internal name, so the proofs hold whatever structure produces those ports.

* ``parallel-equiv`` (``<mode>_pixel_array``): ``frame_valid`` equals the SPEC reference's
  (:mod:`tespike.cosim.formal.reference`) on every clock, and ``frame`` equals its words while
  ``frame_valid`` is high. ``rst`` and ``charge`` are free inputs on every clock.
* ``stream-equiv`` (``<mode>_pixel_array_stream``, N lanes): ``out_valid`` equals the
  reference's on every clock, ``out_first`` and ``out_words`` while it is high; and the
  streaming contract of SPEC section 6 checked by a monitor that sees only the top's ports
  and the reference's words of each interval: a beat only while an interval's words are
  outstanding (so ``out_valid`` stays low after a reset until the first beat is due, and no
  word leaves twice), each beat the next ``N`` words in raster order (0 past the last
  pixel), ``out_first`` with beat 0 only, no beat of interval k + 1 before the last of k,
  the last beat sampled within 2L clocks of the interval's last clock.
* ``timing`` (``<mode>_readout_timing``, the streaming top's block, behind its input
  register): its reset state and phase: in the clock after the edge that samples ``e[t]``
  (t = 0 the first edge with ``rst`` low), CCC = j + 1 (j = (t mod L) div F), ``last`` iff
  t mod L = L - 1, ``frame_valid`` = ``last`` except in the clock after a reset (t = -1:
  CCC alpha, ``last`` high, ``frame_valid`` low).
* ``array-timing`` (``<mode>_array_timing``, the parallel top's block, counting the clock
  on the port): while the port carries ``e[t]``, CCC = j + 1 and ``last`` iff
  t mod L = L - 1; ``frame_valid`` is ``last`` of the clock before, low in the clock after
  a reset (which puts t = 0 on the port).
  Both by k-induction (depth L + 2: L clocks of outputs pin the phase), so they hold for
  every input sequence of any length.

Every harness starts from power-up (the design's initial values; the reference powers up
in its reset state) and is proved for every input sequence of any length where ABC's
unbounded engines finish (all default tops do), else for every sequence of ``bound`` clocks:
at least three readout intervals and the last interval's beats (:func:`bmc_bound`). The
harnesses name no internal register of the design; the unbounded engines find the match
between the design's registers and the reference's themselves (signal correspondence).
"""

from __future__ import annotations

from dataclasses import dataclass

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, check_flag, is_count
from tespike.rtl.names import module_names, stream_module_names

from .reference import PARALLEL_DELAY, STREAM_DELAY, checked_request, reference_verilog


def _check_clocks(value, name: str) -> None:
    """A proof's clocks given (None: the default): an integer >= 1 (0 had fallen back to the default
    without a word, -5 and 2.5 been taken)."""
    if value is not None and not is_count(value, 1):
        raise InputError(f"{name} {value!r}: must be an integer >= 1 clocks (or None: the default)")


def design_text(config: SensorConfig, height: int, width: int, lanes: int | None) -> str:
    """The Verilog text ``tespike verilog`` writes for this array (parallel without ``lanes``)."""
    if lanes is None:
        from tespike.rtl.verilog import array_verilog
        return array_verilog(config, height, width)
    from tespike.rtl.verilog_stream import stream_array_verilog
    return stream_array_verilog(config, height, width, lanes)


def bmc_bound(config: SensorConfig, height: int, width: int, lanes: int | None, intervals: int = 3) -> int:
    """Clocks of the bounded proofs: ``intervals`` readout intervals after the first edge,
    then the latency and the last interval's beats, and one more clock."""
    config = checked_request(config, "bmc_bound", height, width, lanes)
    if not is_count(intervals, 1):
        raise InputError(f"bmc_bound intervals {intervals!r}: must be an integer >= 1")
    L = config.clocks_per_readout
    drain = PARALLEL_DELAY if lanes is None else STREAM_DELAY + -(-height * width // lanes)
    return intervals * L + drain + 2


@dataclass
class Harness:
    """Verilog text of a proof: the design, the reference and the harness module ``proof_top``;
    ``messages`` maps the harness's assertion lines to what each says."""
    text: str
    messages: dict[int, str]
    method: str          # "bmc" or "induction"
    steps: int           # BMC bound, or induction depth


class _Asserts:
    """Assertion lines of a harness, each remembered by its line number for the failure report."""

    def __init__(self):
        self.lines: list[tuple[str, str]] = []

    def add(self, condition: str, message: str) -> None:
        self.lines.append((condition, message))

    def render(self, first_line: int) -> tuple[str, dict[int, str]]:
        text, messages = "", {}
        for k, (condition, message) in enumerate(self.lines):
            text += f"  always @* assert ({condition});  // {message}\n"
            messages[first_line + k] = message
        return text, messages


def _proof_top(charge_bits: int) -> str:
    """The header of an equivalence harness: ``proof_top`` with the free inputs every clock."""
    return f"module proof_top (input wire clk, input wire rst, input wire [{charge_bits - 1}:0] charge);\n"


def _on_inputs(module: str, name: str, **outputs: str) -> str:
    """An instance of ``module`` (the top under proof or the SPEC reference) on the harness's free
    ``clk``, ``rst`` and ``charge``, each of its ``outputs`` (port=net) on a net of the harness."""
    pins = "".join(f", .{port}({net})" for port, net in outputs.items())
    return f"  {module} {name} (.clk(clk), .rst(rst), .charge(charge){pins});\n"


def _assemble(parts: list[str], body_head: str, asserts: _Asserts, body_tail: str = "") -> tuple[str, dict]:
    prefix = "\n".join(parts) + "\n" + body_head
    text, messages = asserts.render(prefix.count("\n") + 1)
    return prefix + text + body_tail + "endmodule\n", messages


def verilog_parallel_harness(config: SensorConfig, height: int, width: int, design: str | None = None,
                     bound: int | None = None) -> Harness:
    """``parallel-equiv``: the parallel top against the SPEC reference (see the module docstring)."""
    c = checked_request(config, "verilog_parallel_harness", height, width)
    _check_clocks(bound, "bound")
    P, E, wd = height * width, c.input_bits, c.word_bits
    design = design_text(c, height, width, None) if design is None else design
    head = (_proof_top(P * E) + f"  wire dut_valid;\n  wire [{P * wd - 1}:0] dut_frame;\n"
            + _on_inputs(module_names(c)["top"], "dut", frame_valid="dut_valid", frame="dut_frame")
            + f"  wire done, ref_valid;\n  wire [{P * wd - 1}:0] words, ref_frame;\n"
            + _on_inputs("spec_reference", "ref", done="done", words="words", frame_valid="ref_valid",
                         frame="ref_frame"))
    a = _Asserts()
    a.add("dut_valid == ref_valid", "frame_valid on the reference's clocks (latency, reset, one per interval)")
    a.add("!ref_valid || dut_frame == ref_frame", "frame equals the reference's words while frame_valid")
    text, messages = _assemble([design, reference_verilog(c, height, width)], head, a)
    return Harness(text, messages, "bmc", bound or bmc_bound(c, height, width, None))


def verilog_stream_harness(config: SensorConfig, height: int, width: int, lanes: int, design: str | None = None,
                   bound: int | None = None) -> Harness:
    """``stream-equiv``: the streaming top against the SPEC reference and the streaming contract
    (see the module docstring)."""
    c = checked_request(config, "verilog_stream_harness", height, width, lanes)
    _check_clocks(bound, "bound")
    P, E, wd, n = height * width, c.input_bits, c.word_bits, lanes
    L = c.clocks_per_readout
    B = -(-P // n)
    bb = max(1, B.bit_length())
    ab = (2 * L + 2).bit_length()
    design = design_text(c, height, width, n) if design is None else design
    head = (_proof_top(P * E) + f"  wire out_valid, out_first;\n  wire [{n * wd - 1}:0] out_words;\n"
            + _on_inputs(stream_module_names(c)["top"], "dut", out_valid="out_valid", out_first="out_first", out_words="out_words")
            + f"  wire done, ref_valid, ref_first, ref_fv;\n"
            f"  wire [{P * wd - 1}:0] words, ref_frame;\n  wire [{n * wd - 1}:0] ref_words, beat_words;\n"
            # the contract monitor: a queue of the intervals whose words are outstanding
            f"  reg q0v = 0, q1v = 0;\n  reg [{P * wd - 1}:0] q0w = 0, q1w = 0;\n"
            f"  reg [{ab - 1}:0] age0 = 0, age1 = 0;  // clocks since the interval's last edge\n"
            f"  reg [{bb - 1}:0] sent = 0;            // beats of the head interval seen\n"
            + _on_inputs("spec_reference", "ref", done="done", words="words", frame_valid="ref_fv",
                         frame="ref_frame", out_valid="ref_valid", out_first="ref_first", out_words="ref_words",
                         beat_index="sent", beat_source="q0w", beat_words="beat_words")
            + f"  wire pop = out_valid && q0v && sent == {bb}'d{B - 1};\n"
            f"  wire hv = pop ? q1v : q0v;\n"
            f"  wire [{ab - 1}:0] top_age = {ab}'d{2 * L + 1};\n"
            f"  always @(posedge clk)\n"
            f"    if (rst) begin q0v <= 0; q1v <= 0; sent <= 0; end\n"
            f"    else begin\n"
            f"      if (out_valid && q0v) sent <= pop ? {bb}'d0 : sent + 1'b1;\n"
            f"      age0 <= (age0 < top_age) ? age0 + 1'b1 : age0;\n"
            f"      age1 <= (age1 < top_age) ? age1 + 1'b1 : age1;\n"
            f"      if (pop) begin q0v <= q1v; q0w <= q1w; age0 <= (age1 < top_age) ? age1 + 1'b1 : age1; "
            f"q1v <= 0; end\n"
            f"      if (done && !hv) begin q0v <= 1; q0w <= words; age0 <= 1; end\n"
            f"      else if (done) begin q1v <= 1; q1w <= words; age1 <= 1; end\n"
            f"    end\n")
    a = _Asserts()
    a.add("out_valid == ref_valid", "out_valid on the reference's clocks (latency, reset, B beats per interval)")
    a.add("!ref_valid || out_first == ref_first", "out_first equals the reference's")
    a.add("!ref_valid || out_words == ref_words", "out_words equal the reference's beat")
    a.add("!out_valid || q0v", "a beat only while an interval's words are outstanding "
                               "(none after a reset before the first is due, none twice)")
    a.add("!out_first || out_valid", "out_first only on a beat")
    a.add("!out_valid || out_first == (sent == 0)", "out_first with beat 0 only; no beat of k + 1 before the last of k")
    a.add("!out_valid || out_words == beat_words", "each beat carries the next N words in raster order")
    a.add(f"!q0v || age0 <= {2 * L - 1}", "last beat sampled within 2L clocks of the interval's end")
    a.add("!(done && q1v && !pop)", "at most two intervals outstanding")
    text, messages = _assemble([design, reference_verilog(c, height, width, n)], head, a)
    return Harness(text, messages, "bmc", bound or bmc_bound(c, height, width, n))


def timing_harness(config: SensorConfig, design: str | None = None, depth: int | None = None,
                   sampled_input: bool = True) -> Harness:
    """``timing``: a timing block's reset state and phase (see the module docstring), by
    k-induction. ``sampled_input``: the streaming top's block (read from its text), whose
    counters show the clock the input register holds; else the parallel top's
    (``array-timing``), whose counters show the clock on the port (clock 0 after a reset) and
    whose ``frame_valid`` is ``last`` one edge later, never in the clock after a reset."""
    c = checked_request(config, "timing_harness")
    _check_clocks(depth, "depth")
    check_flag(sampled_input, "sampled_input")
    F, alpha, L = c.clocks_per_tick, c.alpha, c.clocks_per_readout
    if design is None:
        design = design_text(c, 1, 1, 1 if sampled_input else None)
    fb, jb = max(1, (F - 1).bit_length()), max(1, (alpha - 1).bit_length())
    ccc = f"  wire [{c.b2 - 1}:0] ccc;\n" if c.is_te else ""
    pin = ".ccc(ccc), " if c.is_te else ""
    ph0, jj0 = (F - 1, alpha - 1) if sampled_input else (0, 0)
    head = (f"module proof_top (input wire clk, input wire rst);\n{ccc}  wire last, frame_valid;\n"
            f"  {module_names(c)['timing' if sampled_input else 'array_timing']} dut (.clk(clk), .rst(rst), {pin}.last(last), "
            f".frame_valid(frame_valid));\n"
            f"  // the pixel clock t the counters describe: ph inside S_h, jj inside S_r; after a reset\n"
            f"  // t = -1 (sampled input: the interval's last clock, no frame) or t = 0 (at the port)\n"
            f"  reg [{fb - 1}:0] ph = {ph0};\n  reg [{jb - 1}:0] jj = {jj0};\n  reg primed = 0;\n"
            f"  reg shown = 0;  // the reference's frame_valid at the port: last one edge later\n"
            f"  wire ref_last = (ph == {F - 1}) && (jj == {alpha - 1});\n"
            f"  always @(posedge clk)\n"
            f"    if (rst) begin ph <= {ph0}; jj <= {jj0}; primed <= 0; shown <= 0; end\n"
            f"    else begin\n"
            f"      ph <= (ph == {F - 1}) ? 0 : ph + 1'b1;\n"
            f"      if (ph == {F - 1}) jj <= (jj == {alpha - 1}) ? 0 : jj + 1'b1;\n"
            f"      primed <= 1;\n"
            f"      shown <= ref_last;\n"
            f"    end\n")
    a = _Asserts()
    if c.is_te:
        a.add(f"ccc == jj + {c.b2}'d1", "CCC = j + 1 during S_h cycle j (after a reset: alpha, or 1 at the port)")
    a.add("last == ref_last", "last on clock L - 1 of each interval")
    if sampled_input:
        a.add("frame_valid == (ref_last && primed)", "frame_valid with last, never in the clock after a reset")
    else:
        a.add("frame_valid == shown", "frame_valid one clock after last, never in the clock after a reset")
    text, messages = _assemble([design], head, a)
    return Harness(text, messages, "induction", depth or L + 2)


# -- what ``tespike prove`` runs on the tops ---------------------------------------------------
#: Array sizes of the default run (rows, columns).
SIZES = ((1, 1), (2, 3), (3, 4))
#: Most pixels of an array ``tespike prove`` takes: its proofs' state grows with the array (every
#: site's registers and the reference's copy of them), and a top is the same module per site in a
#: generate loop, so a few small arrays (every lane count, padded beats) prove the structure that
#: larger ones repeat.
MAX_PROOF_PIXELS = 64
#: Lane counts tried on each size of :data:`SIZES` (one beat per pixel, padded last beats, a
#: single beat); the others get 2 and 5. A lane count whose beats do not fit in L clocks is skipped.
LANES = {(1, 1): (1, 2), (2, 3): (2, 5), (3, 4): (5, 12)}


def small_clocks(config: SensorConfig) -> SensorConfig:
    """``config`` with the smallest clocks that still have every phase (b1 = b2 = 2: F = 4,
    alpha = 3, L = 12) and small widths (theta 3, A 3, E 2, ml_bits 3), so that three readout
    intervals of a 3 x 4 array are a few seconds of proof."""
    values = dict(SensorConfig.required(config, "small_clocks").to_dict(), b1=2, b2=2, alpha=3, clocks_per_tick=4, threshold=3, acc_bits=3,
                  input_bits=2, ml_bits=3)
    return SensorConfig(**values).check()


def lane_counts(config: SensorConfig, height: int, width: int) -> list[int]:
    """The lane counts of :data:`LANES` that fit (B <= L), or the smallest that does."""
    pixels, L = height * width, config.clocks_per_readout
    fit = [n for n in LANES.get((height, width), (2, 5)) if -(-pixels // n) <= L]
    return fit or [-(-pixels // L)]


def top_properties(config: SensorConfig, sizes) -> dict[str, object]:
    """``{label: harness builder}`` of every generated top of ``config`` at ``sizes``: the two timing
    blocks once, the parallel top and the streaming top at each lane count of each size."""
    props = {"timing": lambda: timing_harness(config),
             "array-timing": lambda: timing_harness(config, sampled_input=False)}
    for h, w in sizes:
        props[f"parallel {h}x{w}"] = lambda h=h, w=w: verilog_parallel_harness(config, h, w)
        for n in lane_counts(config, h, w):
            props[f"stream {h}x{w} N={n}"] = lambda h=h, w=w, n=n: verilog_stream_harness(config, h, w, n)
    return props
