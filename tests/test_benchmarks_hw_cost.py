"""Cheap checks of benchmarks/hw_cost.py: the Yosys report parser and one real synthesis."""

import importlib.util
import json
import shutil
from pathlib import Path

import pytest

from golden.config import SensorConfig

spec = importlib.util.spec_from_file_location(
    "hw_cost", Path(__file__).resolve().parent.parent / "benchmarks" / "hw_cost.py")
hw_cost = importlib.util.module_from_spec(spec)
spec.loader.exec_module(hw_cost)

# Shape of Yosys 0.23's `stat -json -tech cmos` (values from a real run).
REPORT = {
    "creator": "Yosys 0.23 (git sha1 7ce5011c24b)",
    "invocation": "stat -json -tech cmos ",
    "modules": {"\\te_pixel": {"num_cells": 254, "num_cells_by_type": {
        "$_AOI3_": 32, "$_DFF_P_": 23, "$_NAND_": 60, "$_NOR_": 66, "$_NOT_": 49, "$_OAI3_": 24},
        "estimated_num_transistors": "1306"}},
    "design": {"num_cells": 254, "num_cells_by_type": {
        "$_AOI3_": 32, "$_DFF_P_": 23, "$_NAND_": 60, "$_NOR_": 66, "$_NOT_": 49, "$_OAI3_": 24},
        "estimated_num_transistors": "1306"},
}


def test_parse_stat_reads_yosys_json():
    stat = hw_cost.parse_stat(json.dumps(REPORT))
    assert (stat["cells"], stat["flops"], stat["transistors"]) == (254, 23, 1306)


def test_parse_stat_counts_all_flip_flop_kinds_and_refuses_incomplete_estimate():
    report = json.loads(json.dumps(REPORT))
    report["design"]["num_cells_by_type"] = {"$_SDFF_PP0_": 18, "$_SDFFE_PP0P_": 5, "$_XOR_": 37}
    report["design"]["estimated_num_transistors"] = "1574+"
    with pytest.raises(ValueError, match="incomplete"):
        hw_cost.parse_stat(json.dumps(report))
    del report["design"]["estimated_num_transistors"]
    assert hw_cost.parse_stat(json.dumps(report))["flops"] == 23


def test_dynamic_range_matches_spec_section_5():
    assert hw_cost.dynamic_range_db(SensorConfig()) == pytest.approx(47.604, abs=1e-3)     # 16 * 15
    assert hw_cost.dynamic_range_db(SensorConfig(mode="ml")) == pytest.approx(48.131, abs=1e-3)  # 255


@pytest.mark.skipif(shutil.which("yosys") is None, reason="Debian yosys not installed")
def test_synthesized_ml_pixel_has_exactly_its_state_bits():
    from rtl.verilog import pixel_verilog
    config = hw_cost.counting_only(SensorConfig(mode="ml", b1=2, b2=2, ml_bits=5))
    stat = hw_cost.synthesize(pixel_verilog(config), "ml_pixel")
    assert stat["flops"] == hw_cost.state_bits(config) == 1 + 5 + 5
    assert 16 * stat["flops"] < stat["transistors"] <= stat["transistors_max"]


def test_compare_calls_a_difference_only_when_ranges_do_not_overlap():
    def est(lo, hi):
        return {"transistors": lo, "transistors_max": hi}
    assert hw_cost.compare(est(100, 110), est(120, 130)) == "fewer"
    assert hw_cost.compare(est(140, 150), est(120, 130)) == "more"
    assert hw_cost.compare(est(100, 125), est(120, 130)).startswith("about")
