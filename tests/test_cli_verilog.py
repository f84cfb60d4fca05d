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
