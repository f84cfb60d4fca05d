"""``tespike synthesize`` (cosim/commands/synthesize_cmd.py) and the hierarchy flow of cosim/synthesis.py."""

import re
import shutil

import pytest

from tespike.cosim.synthesis import hierarchy_total, parse_stat_modules, top_module
from tests.cli import assert_refused, run_tespike

needs_yosys = pytest.mark.skipif(not shutil.which("yosys"), reason="Yosys is not installed")

#: Yosys 0.23's ``stat -json`` of a design without a top attribute: note the stray comma.
STAT = """{
   "creator": "Yosys 0.23",
   "modules": {
      "\\\\cell": {"num_cells": 3, "num_cells_by_type": {"$_DFF_P_": 2, "$_MUX_": 1},
                   "estimated_num_transistors": "40"},
      "\\\\group": {"num_cells": 3, "num_cells_by_type": {"cell": 2, "$_AND_": 1},
                    "estimated_num_transistors": "6+"},
      "\\\\top": {"num_cells": 4, "num_cells_by_type": {"group": 3, "$_DFF_P_": 1},
                  "estimated_num_transistors": "24+"}
   },

}
"""


def test_hierarchy_is_multiplied_out_by_instance_counts():
    modules = parse_stat_modules(STAT)
    assert modules["group"]["instances"] == {"cell": 2} and modules["group"]["cells"] == 1
    assert modules["top"]["transistors"] == 24 and top_module(modules) == "top"
    for stat in modules.values():
        stat["transistors_max"] = stat["transistors"]
    total = hierarchy_total(modules, "top")
    assert total["cells"] == 1 + 3 * (1 + 2 * 3) and total["flops"] == 1 + 3 * 2 * 2
    assert total["transistors"] == 24 + 3 * (6 + 2 * 40)
    assert total["by_type"] == {"$_DFF_P_": 13, "$_AND_": 3, "$_MUX_": 6}


def test_an_incomplete_estimate_of_a_leaf_is_refused():
    with pytest.raises(ValueError, match="incomplete"):
        parse_stat_modules(STAT.replace('"40"', '"38+"'))


@needs_yosys
def test_synthesize_streaming_top_counts_every_state_bit():
    """Paper TE, 2 x 3, N = 4 (B = 2): per pixel 16 input + 9 acc + 4 SFC + 1 flag + 4 CCC latch + 5 readout
    = 39 flip-flops; the top 1 rst_sample + 1 sending + 2 beat; the timing 4 divider + 4 CCC + 1 primed."""
    result = run_tespike("synthesize", "--config", "te", "--height", 2, "--width", 3, "--lanes", 4)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert re.search(r"^te_stream_pixel\s+6\s+\d+\s+34\s", out, re.M), out
    assert re.search(r"^te_readout_cell\s+6\s+\d+\s+5\s", out, re.M), out
    assert re.search(r"^te_readout_timing\s+1\s+\d+\s+9\s", out, re.M), out
    assert re.search(r"^te_beat_group\s+1\s", out, re.M) and re.search(r"^te_beat_group_end\s+1\s", out, re.M)
    assert f"{6 * 39 + 4 + 9} flip-flops" in out, out
    assert re.search(r"yosys: [\d.]+ s wall, [\d.]+ s CPU, peak \d+ MB", out), out


@needs_yosys
def test_synthesize_a_verilog_file_finds_its_top(tmp_path):
    (tmp_path / "A.v").write_text("module leaf(input clk, input d, output reg q); always @(posedge clk) q <= d; endmodule\n"
                                  "module pair(input clk, input d, output q); wire m;\n"
                                  "  leaf a (.clk(clk), .d(d), .q(m)); leaf b (.clk(clk), .d(m), .q(q)); endmodule\n")
    result = run_tespike("synthesize", "--verilog", tmp_path / "A.v")
    assert result.returncode == 0, result.stderr
    assert "total pair: 2 cells, 2 flip-flops" in result.stdout, result.stdout


@needs_yosys
def test_synthesize_refuses_a_file_of_two_tops_unless_one_is_named(tmp_path):
    """Yosys's synth -auto-top picked one of two tops and the report dropped the other (exit 0)."""
    (tmp_path / "two.v").write_text("module m1(input a, output b); assign b = a; endmodule\n"
                                    "module m2(input a, output b); assign b = ~a; endmodule\n")
    assert_refused(run_tespike("synthesize", "--verilog", tmp_path / "two.v"), "2 top modules (m1, m2)", "name one")
    (tmp_path / "none.v").write_text("// no module here\n")      # "name one" could not help: there is none
    none = run_tespike("synthesize", "--verilog", tmp_path / "none.v")
    assert_refused(none, "defines no module")
    assert "name one" not in none.stderr
    named = run_tespike("synthesize", "--verilog", tmp_path / "two.v", "--top", "m2")
    assert named.returncode == 0 and "total m2: 1 cells" in named.stdout, named.stderr
    for top in ("m1; shell touch x", "1m"):
        assert_refused(run_tespike("synthesize", "--verilog", tmp_path / "two.v", "--top", top),
                       f"--top {top!r}", "not a Verilog module name")
    assert_refused(run_tespike("synthesize", "--verilog", tmp_path / "two.v", "--top", ""),   # (read as none
                   "--top '': an empty value")                                                # given)


@pytest.mark.parametrize("args, words", [
    (("--verilog", "missing.v"), ("missing.v", "does not exist")),
    (("--verilog", "A.v", "--config", "te"), ("--verilog", "not both")),
    (("--config", "te", "--height", 4), ("missing --width",)),
    (("--config", "te", "--height", 4, "--width", 4, "--lanes", 0), ("--lanes",)),
    (("--config", "te", "--height", 0, "--width", 4), ("height",)),
    (("--config", "te", "--height", 2, "--width", 2, "--top", "x"), ("--top",)),
])
def test_synthesize_refuses_bad_input_in_one_line(tmp_path, args, words):
    assert_refused(run_tespike("synthesize", *args), *words)


@needs_yosys
def test_synthesize_refuses_verilog_yosys_cannot_read(tmp_path):
    (tmp_path / "bad.v").write_text("module x(input a, output b); assign b = a &; endmodule\n")
    result = run_tespike("synthesize", "--verilog", tmp_path / "bad.v")
    assert_refused(result, f"--verilog '{tmp_path / 'bad.v'}'", "yosys failed", f"{tmp_path / 'bad.v'}:1:",
                   "syntax error")
    assert "design.v" not in result.stderr           # Yosys's copy of the file is never named
    (tmp_path / "empty.v").write_bytes(b"")
    assert_refused(run_tespike("synthesize", "--verilog", tmp_path / "empty.v"), "empty.v", "empty (0 bytes)")


def _stimulus_file(tmp_path, shape, clocks=240, name="E.npy"):
    import numpy as np

    rng = np.random.default_rng(0)
    path = tmp_path / name
    np.save(path, rng.poisson(50, (clocks, *shape)).astype(np.int64))
    return path


@needs_yosys
@pytest.mark.skipif(not shutil.which("iverilog"), reason="Icarus Verilog is not installed")
def test_synthesize_prices_the_toggles_of_a_run_checked_in_icarus(tmp_path):
    path = _stimulus_file(tmp_path, (2, 3))
    result = run_tespike("synthesize", "--config", "te", "--height", 2, "--width", 3, "--lanes", 2,
                         "--stimulus", path, "--icarus")
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "toggles equal to the Icarus VCD's in every block" in out, out
    for block in ("pixel", "readout", "timing", "control", "output"):
        row = re.search(rf"^{block}\s+(\d+)\s+(\d+)\s", out, re.M)
        assert row and row.group(1) == row.group(2), (block, out)
    assert re.search(r"^pixel\s+\d+\s+\d+\s+204\s+204\s", out, re.M), out      # 6 x 34 bits, all kept
    assert re.search(r"pJ per readout, [\d.]+ pJ per pixel-readout", out), out


@pytest.mark.parametrize("args, words", [
    (("--config", "te", "--height", 2, "--width", 3, "--icarus"), ("--icarus", "--stimulus")),
    (("--verilog", "A.v", "--stimulus", "E.npy"), ("--stimulus", "not --verilog")),
    (("--config", "te", "--height", 3, "--width", 3, "--stimulus", "E.npy"), ("2 x 3", "--height 3")),
    (("--config", "te", "--height", 33, "--width", 32, "--lanes", 8, "--stimulus", "big.npy", "--icarus"),
     ("--icarus", "1056 pixels")),
    (("--config", "te", "--height", 2, "--width", 3, "--stimulus", "short.npy"), ("T = 100", "multiple of L")),
])
def test_synthesize_refuses_a_bad_stimulus_in_one_line(tmp_path, args, words):
    _stimulus_file(tmp_path, (2, 3))
    _stimulus_file(tmp_path, (33, 32), name="big.npy")
    _stimulus_file(tmp_path, (2, 3), clocks=100, name="short.npy")      # not a whole readout (L = 240)
    args = tuple(tmp_path / a if str(a).endswith(".npy") else a for a in args)
    assert_refused(run_tespike("synthesize", *args), *words)


@needs_yosys
def test_quiet_synthesize_prints_nothing_and_still_refuses(tmp_path):
    """--quiet: "print nothing on stdout on success" holds here too (the report was printed whatever
    --quiet said); a refusal is still its one line on stderr."""
    quiet = run_tespike("synthesize", "--config", "te", "--height", 1, "--width", 2, "--quiet")
    assert quiet.returncode == 0 and quiet.stdout == "" and quiet.stderr == "", quiet.stderr
    loud = run_tespike("synthesize", "--config", "te", "--height", 1, "--width", 2)
    assert loud.returncode == 0 and "flops" in loud.stdout, loud.stderr
    refused = run_tespike("synthesize", "--config", "te", "--height", 0, "--width", 2, "--quiet")
    assert_refused(refused, "--height 0", ">= 1")


def test_the_synthesis_library_refuses_text_top_and_gate_sets_it_cannot_run_in_one_line():
    """``synthesize_hierarchy(None)`` was pathlib's TypeError from the folder Yosys runs in; a top with
    a space or an unknown gate set reached Yosys, which failed on its script."""
    from tespike.cosim.synthesis import synthesize_hierarchy, synthesize_module
    from tespike.golden.errors import InputError
    for text, kind in ((None, "NoneType"), ("", "an empty one"), (b"module a; endmodule", "bytes")):
        with pytest.raises(InputError, match=f"^Verilog text: must be a non-empty string of Verilog source, not {kind}$"):
            synthesize_hierarchy(text)
    for top in ("my top", 3, None):
        with pytest.raises(InputError, match=f"^top module {re.escape(repr(top))}: must be a Verilog module name$"):
            synthesize_module("module a; endmodule", top)
    for sets in (("cmos9",), "cmos2", ()):
        with pytest.raises(InputError, match="^gate sets .*: must be a sequence of cmos2, cmos3, cmos4, gates$"):
            synthesize_hierarchy("module a; endmodule", gate_sets=sets)
