import json
import shutil
import subprocess

import pytest

from tests.cli import assert_refused, run_tespike


def test_verilog_command_writes_array(tmp_path):
    result = run_tespike("verilog", "--config", "ml", "--height", 3, "--width", 2, "--out", tmp_path / "A.v")
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "A.v").read_text()
    assert "module ml_pixel_array (" in text and "input  wire [95:0] charge" in text   # 3*2*16
    assert "output wire [47:0] frame" in text                                        # 3*2*8
    if shutil.which("iverilog"):
        build = subprocess.run(["iverilog", "-g2005", "-o", str(tmp_path / "a.vvp"), str(tmp_path / "A.v")],
                               capture_output=True, text=True)
        assert build.returncode == 0, build.stderr


def test_verilog_command_ml_msb_preset(tmp_path):
    """The msb camera's array: ml_pixel_array with bit_length(ml_bits) = 4-bit words."""
    result = run_tespike("verilog", "--config", "ml-msb", "--height", 2, "--width", 3, "--out", tmp_path / "A.v")
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "A.v").read_text()
    assert "module ml_pixel_array (" in text and "output wire [23:0] frame" in text   # 2*3*4
    assert '"ml_readout": "msb"' in text
    if shutil.which("verilator"):
        lint = subprocess.run(["verilator", "--lint-only", "-Wall", str(tmp_path / "A.v")],
                              capture_output=True, text=True)
        assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr


@pytest.mark.parametrize("height, width, words", [(0, 2, ["height", "0"]), (2, -3, ["width", "-3"])])
def test_verilog_refuses_bad_size_without_output(tmp_path, height, width, words):
    result = run_tespike("verilog", "--config", "te", "--height", height, "--width", width, "--out", tmp_path / "A.v")
    assert_refused(result, *words)
    assert not list(tmp_path.iterdir())


def test_verilog_refuses_bad_config_without_output(tmp_path):
    (tmp_path / "c.json").write_text(json.dumps({"b1": 4, "alpha": 99}))
    result = run_tespike("verilog", "--config", tmp_path / "c.json", "--height", 2, "--width", 2,
                         "--out", tmp_path / "A.v")
    assert_refused(result, "'alpha'", "99")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.json"]


def test_verilog_lanes_writes_the_streaming_top(tmp_path):
    """--lanes N: te_pixel_array_stream with the SPEC section 6 streaming ports; lints clean."""
    result = run_tespike("verilog", "--config", "te", "--height", 2, "--width", 3, "--lanes", 4,
                         "--out", tmp_path / "S.v")
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "S.v").read_text()
    assert "module te_pixel_array_stream (" in text and "input  wire [95:0] charge" in text   # 2*3*16
    assert "output wire out_valid" in text and "output wire out_first" in text
    assert "output wire [19:0] out_words" in text                                      # 4 lanes * 5
    assert "frame" not in text.split("module te_pixel_array_stream (")[1].split(");")[0]
    if shutil.which("verilator"):
        lint = subprocess.run(["verilator", "--lint-only", "-Wall", str(tmp_path / "S.v")],
                              capture_output=True, text=True)
        assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr


@pytest.mark.skipif(shutil.which("verilator") is None, reason="verilator not installed")
def test_verilog_lanes_far_beyond_the_pixels_lint_clean(tmp_path):
    """N above H W is legal (SPEC section 6): the lanes past the last pixel carry 0. Their zero fill
    is a replication of (N - S) Wd bits, past the 8 Kibit Verilator takes for a mistake (WIDTHCONCAT,
    fatal: `tespike cocotb --lanes 100000 --simulator verilator` failed to build); waived on its line."""
    result = run_tespike("verilog", "--config", "te", "--height", 2, "--width", 2, "--lanes", 100000,
                         "--out", tmp_path / "S.v")
    assert result.returncode == 0, result.stderr
    lint = subprocess.run(["verilator", "--lint-only", "-Wall", str(tmp_path / "S.v")],
                          capture_output=True, text=True)
    assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr[:2000]


def test_verilog_lanes_sensor_size_has_no_wide_literal(tmp_path):
    """400 x 250 (the paper's sensor) with the fewest lanes: written in seconds, no literal over 64 bits."""
    import re
    result = run_tespike("verilog", "--config", "ml-msb", "--height", 400, "--width", 250, "--lanes", 417,
                         "--out", tmp_path / "S.v")
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "S.v").read_text()
    assert "module ml_pixel_array_stream (" in text and "output wire [1667:0] out_words" in text
    assert max(int(w) for w in re.findall(r"\b(\d+)'[bdh]", text)) <= 64


@pytest.mark.parametrize("config, height, width, lanes, smallest", [
    ("te", 400, 250, 416, 417),          # B = 241 > L = 240
    ("te", 2, 3, 0, None),
])
def test_verilog_refuses_too_few_lanes_naming_the_smallest(tmp_path, config, height, width, lanes, smallest):
    result = run_tespike("verilog", "--config", config, "--height", height, "--width", width,
                         "--lanes", lanes, "--out", tmp_path / "S.v")
    words = ["--lanes", str(lanes)] + ([f"smallest N is {smallest}"] if smallest else [])
    assert_refused(result, *words)
    assert not list(tmp_path.iterdir())


def test_verilog_refuses_lanes_for_l_equal_one_below_the_pixel_count(tmp_path):
    """L = 1: every interval's words must leave in one beat, so N >= H * W."""
    (tmp_path / "one.json").write_text(json.dumps({"alpha": 1, "clocks_per_tick": 1}))
    result = run_tespike("verilog", "--config", tmp_path / "one.json", "--height", 2, "--width", 3,
                         "--lanes", 5, "--out", tmp_path / "S.v")
    assert_refused(result, "--lanes", "smallest N is 6")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.json"]


@pytest.mark.parametrize("lanes", [1 << 18 | 1, 10 ** 20])
def test_verilog_refuses_absurd_lane_counts_without_a_file(tmp_path, lanes):
    """A lane count past 2^18 is refused in one line, no file (it used to write a port of
    N * Wd bits, e.g. [499999999999999999994:0] for N = 10^20, and a 32-bit localparam N that wraps)."""
    result = run_tespike("verilog", "--config", "te", "--height", 2, "--width", 2,
                         "--lanes", lanes, "--out", tmp_path / "S.v")
    assert_refused(result, "--lanes", "at most 262144 lanes")
    assert not list(tmp_path.iterdir())
