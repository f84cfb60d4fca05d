"""Proofs of the generated Verilog tops (cosim.formal.tops): they pass on the text ``tespike verilog``
writes, and fail on hand edits of the kinds a designer could slip (issue 26's list)."""

import re
import shutil

import pytest

from tespike.cosim.formal.abc import prove_harness
from tespike.cosim.formal.tops import (design_text, verilog_parallel_harness, small_clocks, verilog_stream_harness,
                               timing_harness)
from tespike.golden.config import load_config

pytestmark = pytest.mark.skipif(
    not all(shutil.which(tool) for tool in ("yosys", "yosys-abc")),
    reason="yosys and yosys-abc are needed (install.sh installs them)")

TE = small_clocks(load_config("te"))     # b1 = b2 = 2: F = 4, alpha = 3, L = 12


def _timing_module(text: str) -> tuple[int, int]:
    """The timing module of a generated text: ``te_array_timing`` (parallel) or ``te_readout_timing``."""
    found = re.search(r"module te_(array|readout)_timing\(", text)
    assert found, "no timing module in the text"
    return found.start(), text.index("endmodule", found.start())


def _in_timing(text: str, pattern: str, new: str, occurrence: int = 0) -> str:
    """``text`` with the ``occurrence``-th match of ``pattern`` inside the timing module replaced."""
    start, end = _timing_module(text)
    matches = list(re.finditer(pattern, text[start:end]))
    assert len(matches) > occurrence, (pattern, text[start:end])
    found = matches[occurrence]
    return text[:start + found.start()] + found.expand(new) + text[start + found.end():]


def _replace(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new)


RESET_TO = r"(if \(rst\) begin\n\s+\\\$\d+\s+= )"
#: name -> (design: "parallel" or "stream", edit of the generated text)
MUTANTS = {
    "S_h divider reset value": ("parallel", lambda t: _in_timing(t, RESET_TO + r"2'h0;", r"\g<1>2'h1;", 0)),
    "S_h divider power-up value": ("parallel", lambda t: _in_timing(t, r"reg \[1:0\] divider = 2'h0;",
                                                                   "reg [1:0] divider = 2'h3;")),
    "CCC start after reset (parallel)": ("parallel", lambda t: _in_timing(t, RESET_TO + r"2'h1;", r"\g<1>2'h2;", 0)),
    "frame_valid not cleared by rst (parallel)": ("parallel", lambda t: _in_timing(
        t, RESET_TO + r"1'h0;", r"\g<1>1'h1;")),
    "frame_valid combinational from last (parallel)": ("parallel", lambda t: _replace(
        t, ".frame_valid(frame_valid));", ".frame_valid());\n  assign frame_valid = last;")),
    "CCC start after reset": ("stream", lambda t: _in_timing(t, RESET_TO + r"2'h3;", r"\g<1>2'h1;", 1)),
    "primed not cleared by rst": ("stream", lambda t: _in_timing(t, RESET_TO + r"1'h0;", r"\g<1>1'h1;")),
    "CCC bus registered, last not": ("parallel", lambda t: _replace(_replace(
        t, "  wire last;", "  wire last;\n  reg [1:0] ccc_late = 2'd3;\n  always @(posedge clk) ccc_late <= ccc;"),
        ".ccc(ccc), .last(last),\n", ".ccc(ccc_late), .last(last),\n")),
    "lane index off by one": ("stream", lambda t: _replace(
        t, ".shift_in(shift_in[i*WD +: WD])", ".shift_in(shift_in[((i + 1) % SITES)*WD +: WD])")),
    "beat order reversed": ("stream", lambda t: _replace(
        t, ".charge(charge[j*N*E +: N*E])", ".charge(charge[(B - 2 - j)*N*E +: N*E])")),
    "out_first on beat 1": ("stream", lambda t: _replace(t, "sending & (beat == 2'd0)", "sending & (beat == 2'd1)")),
    "beat counter one bit narrow": ("stream", lambda t: _replace(t, "reg [1:0] beat = 2'd0;", "reg [0:0] beat = 2'd0;")),
    "beat/sending not cleared by rst": ("stream", lambda t: _replace(t, "if (rst) begin\n      sending <= 1'b0;",
                                                                     "if (1'b0) begin\n      sending <= 1'b0;")),
    "pixels cleared by rst, not the sampled reset (stream)": ("stream", lambda t: _replace(
        t, "wire clear = rst_sample;", "wire clear = rst;")),
    "pixels cleared one edge after rst (parallel)": ("parallel", lambda t: _replace(_replace(
        t, "  wire last;", "  wire last;\n  reg rst_late = 1'b0;\n  always @(posedge clk) rst_late <= rst;"),
        ".clear(rst)", ".clear(rst_late)")),
    "two pixels' charge swapped (parallel)": ("parallel", lambda t: _replace(
        t, "charge[(r*W + c)*E +: E]", "charge[((r*W + c) ^ 1)*E +: E]")),
    "two pixels' charge swapped (stream)": ("stream", lambda t: _replace(
        t, "te_stream_pixel pixel (.clk(clk), .charge(charge[i*E +: E])",
        "te_stream_pixel pixel (.clk(clk), .charge(charge[(i ^ 1)*E +: E])")),
}


def _harness(design: str, text: str | None = None):
    """2 x 3 pixels; the stream with 2 lanes (3 beats, none padded) ."""
    if design == "parallel":
        return verilog_parallel_harness(TE, 2, 3, text)
    return verilog_stream_harness(TE, 2, 3, 2, text)


@pytest.mark.parametrize("design", ["parallel", "stream"])
def test_generated_tops_are_proved(design):
    result = prove_harness(design, _harness(design))
    assert result.proved and result.method.startswith("unbounded"), result


def test_timing_blocks_are_proved_and_their_reset_values_matter():
    assert prove_harness("timing", timing_harness(TE)).proved
    late = _in_timing(design_text(TE, 1, 1, 1), RESET_TO + r"2'h3;", r"\g<1>2'h1;", 1)   # CCC after reset
    result = prove_harness("timing", timing_harness(TE, late))
    assert not result.proved and "CCC" in result.detail, result
    assert prove_harness("array-timing", timing_harness(TE, sampled_input=False)).proved
    late = _in_timing(design_text(TE, 1, 1, None), RESET_TO + r"2'h1;", r"\g<1>2'h3;", 0)   # CCC after reset
    result = prove_harness("array-timing", timing_harness(TE, late, sampled_input=False))
    assert not result.proved and "CCC" in result.detail, result


@pytest.mark.parametrize("mutant", list(MUTANTS))
def test_a_hand_edit_fails_the_proof(mutant):
    design, edit = MUTANTS[mutant]
    text = design_text(TE, 2, 3, None if design == "parallel" else 2)
    result = prove_harness(mutant, _harness(design, edit(text)))
    assert not result.proved and result.detail.startswith("clock "), result


#: ML hand edits: name -> (preset, design, edit of the generated text at small clocks, ml_bits = 3)
ML_MUTANTS = {
    "count saturates one early (parallel)": ("ml", "parallel", lambda t: _replace(
        t, "count == 3'h7", "count == 3'h6")),
    "count saturates one early (stream)": ("ml", "stream", lambda t: _replace(
        t, "count[p] != 3'd7", "count[p] != 3'd6")),
    "count not cleared at readout (stream)": ("ml", "stream", lambda t: _replace(
        t, "count[p] = last ? 3'd0 : count_next;", "count[p] = count_next;")),
    "msb remainder keeps the wrong bits (parallel)": ("ml-msb", "parallel", lambda t: _replace(
        t, "| count_next[2:1]", "| count_next[2:2]")),
    "msb index off by one (parallel)": ("ml-msb", "parallel", lambda t: _replace(
        t, "count_next[2] ? 2'h3", "count_next[2] ? 2'h2")),
    "msb remainder dropped (parallel)": ("ml-msb", "parallel", lambda t: re.sub(
        r"(else if \(last\) begin\n\s+\\\$\d+\s+= )\{ 1'h0, [^}]*\};", r"\g<1>3'h0;", t, count=1)),
    "msb takes 2^word, not 2^(word - 1) (stream)": ("ml-msb", "stream", lambda t: _replace(
        t, "<< (word - 2'd1)", "<< word")),
    "count saturates one early (msb stream)": ("ml-msb", "stream", lambda t: _replace(
        t, "count[p] != 3'd7", "count[p] != 3'd6")),
}


def _ml_harness(preset: str, design: str, text: str | None = None):
    config = small_clocks(load_config(preset))
    if design == "parallel":
        return verilog_parallel_harness(config, 2, 3, text)
    return verilog_stream_harness(config, 2, 3, 2, text)


@pytest.mark.parametrize("preset", ["ml", "ml-msb"])
@pytest.mark.parametrize("design", ["parallel", "stream"])
def test_ml_tops_are_proved(preset, design):
    result = prove_harness(preset, _ml_harness(preset, design))
    assert result.proved and result.method.startswith("unbounded"), result


@pytest.mark.parametrize("mutant", list(ML_MUTANTS))
def test_an_ml_hand_edit_fails_the_proof(mutant):
    preset, design, edit = ML_MUTANTS[mutant]
    config = small_clocks(load_config(preset))
    text = design_text(config, 2, 3, None if design == "parallel" else 2)
    edited = edit(text)
    assert edited != text, mutant
    result = prove_harness(mutant, _ml_harness(preset, design, edited))
    assert not result.proved and result.detail.startswith("clock "), result
