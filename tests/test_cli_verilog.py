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
