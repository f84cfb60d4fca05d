"""Cheap checks of benchmarks/hw_cost.py and cosim/synthesis.py: the Yosys report parser and one real synthesis."""

import importlib.util
import json
import shutil
from pathlib import Path

import pytest

from tespike.cosim.synthesis import parse_stat
from tespike.golden.config import SensorConfig

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
    stat = parse_stat(json.dumps(REPORT))
    assert (stat["cells"], stat["flops"], stat["transistors"]) == (254, 23, 1306)


def test_parse_stat_counts_all_flip_flop_kinds_and_refuses_incomplete_estimate():
    report = json.loads(json.dumps(REPORT))
    report["design"]["num_cells_by_type"] = {"$_SDFF_PP0_": 18, "$_SDFFE_PP0P_": 5, "$_XOR_": 37}
    report["design"]["estimated_num_transistors"] = "1574+"
    with pytest.raises(ValueError, match="incomplete"):
        parse_stat(json.dumps(report))
    del report["design"]["estimated_num_transistors"]
    assert parse_stat(json.dumps(report))["flops"] == 23


def test_dynamic_range_matches_spec_section_5():
    assert hw_cost.dynamic_range_db(SensorConfig()) == pytest.approx(47.604, abs=1e-3)     # 16 * 15
    assert hw_cost.dynamic_range_db(SensorConfig(mode="ml")) == pytest.approx(48.131, abs=1e-3)  # 255
    msb = SensorConfig(mode="ml", ml_readout="msb")
    assert hw_cost.dynamic_range_db(msb) == pytest.approx(42.144, abs=1e-3)                  # 2^7
    assert hw_cost.dynamic_range_db(msb, n_s=4) == pytest.approx(54.185, abs=1e-3)          # 2^7 * 4


def test_groups_hold_each_camera_with_the_te_clocks():
    for _, te, mls in hw_cost.GROUPS:
        assert te.is_te and [hw_cost.kind(te, ml) for ml in mls][:2] == ["count", "msb same counter"]
        for ml in mls:
            assert (ml.clocks_per_tick, ml.alpha) == (te.clocks_per_tick, te.alpha)
            if hw_cost.kind(te, ml) == "msb equal range":    # about TE's range: within 3 dB
                assert abs(hw_cost.dynamic_range_db(ml) - hw_cost.dynamic_range_db(te)) < 3


def _row(config, counting, nobuffer=None):
    est = {"cells": 1, "flops": hw_cost.state_bits(config), "transistors": counting, "transistors_max": counting}
    nob = dict(est, transistors=nobuffer or counting, transistors_max=nobuffer or counting,
               flops=hw_cost.state_bits(config, False))
    return {"config": config, "word_bits": config.word_bits, "dr_db": hw_cost.dynamic_range_db(config),
            "full": est, "counting": est, "nobuffer": nob, "timing": est}


def test_claims_follow_the_numbers():
    """The reading is computed: swap who is smaller and the verdict on pixel cost turns."""
    te, mls = hw_cost.GROUPS[0][1], hw_cost.GROUPS[0][2]
    small_te = [("g", _row(te, 100), [_row(ml, 200) for ml in mls])]
    big_te = [("g", _row(te, 300), [_row(ml, 200) for ml in mls])]
    text_small, text_big = "\n".join(hw_cost.verdict(small_te)), "\n".join(hw_cost.verdict(big_te))
    assert "smaller in 2, larger in 0" in text_small and "Supported by this digital model" in text_small
    assert "smaller in 0, larger in 2" in text_big and "Not supported as a general statement" in text_big
    # the paper's 8-bit msb camera: 42.1 dB and 4 bits against TE's 47.6 dB and 5 bits
    assert "47.6 dB against 42.1 dB" in text_small and "1 more bit(s) per pixel per readout" in text_small
    assert "fewer bits in 0 of 2 comparisons (5 vs 4, 5 vs 4 bits)" in text_small


@pytest.mark.skipif(shutil.which("yosys") is None, reason="Debian yosys not installed")
def test_synthesized_ml_pixel_has_exactly_its_state_bits():
    from tespike.rtl.verilog import pixel_verilog
    config = hw_cost.counting_only(SensorConfig(mode="ml", b1=2, b2=2, ml_bits=5))
    stat = hw_cost.synthesize_module(pixel_verilog(config), "ml_pixel")
    assert stat["flops"] == hw_cost.state_bits(config) == 1 + 5 + 5
    assert 16 * stat["flops"] < stat["transistors"] <= stat["transistors_max"]


@pytest.mark.skipif(shutil.which("yosys") is None, reason="Debian yosys not installed")
def test_synthesized_msb_pixel_has_exactly_its_state_bits():
    """The msb pixel: the count's flip-flops and a bit_length(B) word, no hidden state."""
    from tespike.rtl.verilog import pixel_verilog
    config = hw_cost.counting_only(SensorConfig(mode="ml", ml_readout="msb", b1=2, b2=2, ml_bits=5))
    stat = hw_cost.synthesize_module(pixel_verilog(config), "ml_pixel")
    assert stat["flops"] == hw_cost.state_bits(config) == 1 + 5 + 3


def test_compare_calls_a_difference_only_when_ranges_do_not_overlap():
    def est(lo, hi):
        return {"transistors": lo, "transistors_max": hi}
    assert hw_cost.compare(est(100, 110), est(120, 130)) == "fewer"
    assert hw_cost.compare(est(140, 150), est(120, 130)) == "more"
    assert hw_cost.compare(est(100, 125), est(120, 130)).startswith("about")


def test_activity_column_counts_the_counters_switching():
    """At I = 1 TE's counters freeze after 2^b1 spikes while the 8-bit ML counter counts ~255."""
    te, ml = hw_cost.activity(SensorConfig()), hw_cost.activity(SensorConfig(mode="ml"))
    assert len(te) == len(ml) == len(hw_cost.ACTIVITY_LIGHT)
    assert te[1][1] < 40 < 200 < ml[1][1]
    assert te[1][0] > te[1][1] and ml[1][0] > ml[1][1]          # the accumulator adds to both
    assert hw_cost.activity_text(te[1]).count(" / ") == 2
