"""tespike.golden.activity: every register and output port of both generated tops, per block,
equals a count of an Icarus VCD of the very Verilog ``tespike verilog`` writes."""

import re
import shutil

import numpy as np
import pytest

from tespike.cosim.activity import flip_flops, register_bits, vcd_activity, edges_after_reset
from tespike.cosim.icarus import DUT_SCOPE, run_icarus, run_icarus_stream
from tespike.cosim.tops import Top
from tespike.golden.activity import BLOCKS, top_activity
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError

def model_counts(activity) -> dict[tuple[str, str], int]:
    """The model's :class:`tespike.golden.activity.Activity` as :func:`vcd_activity` reports it: totals
    per (block, name), registers of zero width left out."""
    return {key: int(value.sum()) for key, value in activity.toggles.items() if activity.bits[key] > 0}


needs_tools = pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("yosys")),
                                 reason="Icarus Verilog and Yosys are needed")

TE = SensorConfig(mode="te", b1=2, b2=2, threshold=5, acc_bits=4, input_bits=3)
ML = SensorConfig(mode="ml", b1=2, b2=2, ml_bits=3, threshold=4, acc_bits=4, input_bits=3)
MSB = SensorConfig(mode="ml", b1=2, b2=2, ml_bits=3, ml_readout="msb", threshold=3, acc_bits=3, input_bits=3)
TE_NO_CCC = SensorConfig(mode="te", b1=2, b2=1, clocks_per_tick=3, threshold=2, acc_bits=3, input_bits=2)
ML_NO_DIVIDER = SensorConfig(mode="ml", b1=1, b2=2, clocks_per_tick=1, ml_bits=2, threshold=2,
                             acc_bits=3, input_bits=2)

#: (config, (H, W), lanes or None for the parallel top)
CASES = [(TE, (2, 3), None), (TE, (2, 3), 1), (TE, (2, 3), 2), (TE, (2, 3), 8), (TE, (3, 4), 5),
         (ML, (3, 4), None), (ML, (3, 4), 3), (ML, (2, 3), 4),
         (MSB, (3, 4), None), (MSB, (3, 4), 2), (MSB, (2, 3), 6),
         (TE_NO_CCC, (2, 3), None), (TE_NO_CCC, (2, 3), 3),
         (ML_NO_DIVIDER, (2, 3), None), (ML_NO_DIVIDER, (2, 3), 2)]


def _stimulus(config, shape, readouts, seed):
    """Dark to saturating pixels: counters that stay low, overflow, saturate."""
    rng = np.random.default_rng(seed)
    n = shape[0] * shape[1]
    rate = np.linspace(0, config.input_max, n)
    e = rng.poisson(rate, (readouts * config.clocks_per_readout, n))
    return np.minimum(e, config.input_max).reshape(-1, *shape)


def _case_id(case):
    config, (h, w), lanes = case
    return f"{config}-{h}x{w}-{'parallel' if lanes is None else f'{lanes}lanes'}"


@needs_tools
@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_every_block_equals_a_vcd_count_of_the_generated_verilog(case, tmp_path):
    config, shape, lanes = case
    e = _stimulus(config, shape, 4, sum(shape) + (lanes or 0))
    top = Top(config, *shape, lanes)
    text = top.verilog()
    vcd = tmp_path / "run.vcd"
    if lanes is None:
        run_icarus(config, e, verilog=text, vcd_path=vcd)
    else:
        run_icarus_stream(config, e, lanes, verilog=text, vcd_path=vcd)
    edges = edges_after_reset(vcd, DUT_SCOPE)
    activity = top_activity(config, e, lanes, edges=edges)
    found = vcd_activity(vcd, config, text, top.module, lanes is not None, DUT_SCOPE)
    assert model_counts(activity) == found
    blocks = {block: sum(n for (b, _), n in found.items() if b == block) for block in BLOCKS}
    assert activity.per_block() == blocks
    assert blocks["pixel"] > 0 and blocks["timing"] > 0 and blocks["output"] > 0
    assert (blocks["readout"] > 0) == (lanes is not None)
    # every flip-flop of the text is a register of the model, with the model's width
    widths = {key: bits * activity.toggles[key].size for key, bits in activity.bits.items() if key[0] != "output"}
    assert register_bits(text, top.module, config, lanes is not None) == widths
    assert activity.register_bits() == {b: sum(n for (k, _), n in widths.items() if k == b) for b in BLOCKS}


@needs_tools
@pytest.mark.parametrize("lanes, anchor", [(2, "  always @(posedge clk) rst_sample <= rst;\n"),
                                           (None, "  assign frame = words;\n")])
def test_a_register_the_model_does_not_know_is_refused(lanes, anchor, tmp_path):
    top = Top(TE, 2, 3, lanes)
    text = top.verilog()
    assert anchor in text
    text = text.replace(anchor, anchor + "  reg spare = 1'b0;\n  always @(posedge clk) spare <= ~spare;\n", 1)
    names = {reg.name for reg in flip_flops(text, top.module)[0]}
    assert "spare" in names
    e = _stimulus(TE, (2, 3), 1, 0)
    vcd = tmp_path / "run.vcd"
    if lanes is None:
        run_icarus(TE, e, verilog=text, vcd_path=vcd)
    else:
        run_icarus_stream(TE, e, lanes, verilog=text, vcd_path=vcd)
    with pytest.raises(InputError, match="spare"):
        vcd_activity(vcd, TE, text, top.module, lanes is not None, DUT_SCOPE)


@pytest.mark.parametrize("lanes", [None, 2])
@pytest.mark.parametrize("config", [TE, MSB], ids=str)
def test_a_window_counts_exactly_its_edges(config, lanes):
    e = _stimulus(config, (2, 3), 5, 3)
    whole = top_activity(config, e, lanes)
    split = config.clocks_per_readout + 3
    head = top_activity(config, e, lanes, edges=split)
    tail = top_activity(config, e, lanes, start=split)
    for key, counts in whole.toggles.items():
        assert np.array_equal(counts, head.toggles[key] + tail.toggles[key]), key
    assert tail.edges == whole.edges - split and head.readouts + tail.readouts == whole.readouts == 5


def test_no_light_toggles_only_the_clocks_structure():
    """Dark, the pixels and the words never change: only timing, beat counter and reset sample do."""
    config = TE
    e = np.zeros((3 * config.clocks_per_readout, 2, 3), np.int64)
    activity = top_activity(config, e, 2)
    blocks = activity.per_block()
    assert blocks["pixel"] == blocks["readout"] == 0
    assert activity.toggles[("output", "out_words")].sum() == 0
    F, L = config.clocks_per_tick, config.clocks_per_readout
    edges = activity.edges
    # the S_h divider counts 3, 0, 1, 2, 3, 0, ... (F = 4, 2 bits): 2 + 1 + 2 + 1 toggles per 4 edges
    assert F == 4 and edges % 4 == 0
    assert activity.toggles[("timing", "divider")][0] == 6 * edges // 4
    assert activity.toggles[("control", "rst_sample")][0] == 2 and activity.readouts == e.shape[0] // L


def test_no_light_parallel_toggles_only_the_timing_and_frame_valid():
    """Dark, the parallel top's pixels, word registers and frame never change, it has no
    control register, and its reset state is its power-up state: only the timing counts."""
    config = TE
    L = config.clocks_per_readout
    e = np.zeros((3 * L, 2, 3), np.int64)
    activity = top_activity(config, e)
    blocks = activity.per_block()
    assert blocks["pixel"] == blocks["readout"] == blocks["control"] == 0
    assert activity.register_bits()["control"] == 0
    assert activity.toggles[("output", "frame")].sum() == 0
    # frame_valid_reg (and the port) rises and falls once per readout (edges = T + 1: the
    # last edge clears the third strobe)
    assert activity.toggles[("timing", "frame_valid_reg")][0] == 2 * 3 == activity.toggles[("output", "frame_valid")][0]
    assert activity.readouts == 3 and activity.edges == 3 * L + 1


def test_the_switching_counts_refuse_what_they_cannot_run_on_in_one_line():
    """(A preset's name had been an AttributeError or 'too many values to unpack', float electrons
    were truncated, negative ones counted, a NaN light drawn from, 0 lanes a ZeroDivisionError.)"""
    from tespike.golden.errors import ConfigError
    from tespike.golden.toggles import constant_light_toggles, count_toggles
    te, clocks = SensorConfig(), np.zeros((240, 2, 2), np.int64)
    for call, name in ((lambda: count_toggles("te", clocks[:, 0]), "count_toggles"),
                       (lambda: constant_light_toggles("te", np.ones(2), 1), "constant_light_toggles"),
                       (lambda: top_activity("te", clocks), "top_activity")):
        with pytest.raises(ConfigError, match=f"^{name}: configuration must be a SensorConfig"):
            call()
    for call, refusal in ((lambda: count_toggles(te, clocks[:, 0] + 0.5), "^electrons dtype float64 is not an integer"),
                          (lambda: count_toggles(te, clocks[:, 0] - 1), "^electrons value -1 is negative"),
                          (lambda: count_toggles(te, clocks), r"^electrons shape \(240, 2, 2\): must be \(T, n\)"),
                          (lambda: constant_light_toggles(te, np.array([np.nan]), 1), "^light: every value must be finite"),
                          (lambda: constant_light_toggles(te, np.ones(2), 0), "^readouts = 0: must be an integer >= 1$"),
                          (lambda: top_activity(te, clocks.astype(float)), "^electrons dtype float64 is not an integer"),
                          (lambda: top_activity(te, clocks, 0), "^lanes = 0: must be an integer >= 1")):
        with pytest.raises(InputError, match=refusal):
            call()


@pytest.mark.parametrize("options, words", [
    ({"edges": 2.5}, "edges = 2.5: must be an integer >= 0 or None (the whole run)"),
    ({"edges": "5"}, "edges = '5': must be an integer >= 0 or None (the whole run)"),
    ({"start": 2.5}, "start = 2.5: must be an integer >= 0"),
    ({"start": None}, "start = None: must be an integer >= 0"),
    ({"reset": "no"}, "reset = 'no': must be True or False"),
], ids=["fractional-edges", "text-edges", "fractional-start", "no-start", "text-reset"])
def test_top_activity_refuses_a_run_it_cannot_count_in_one_line(options, words):
    """``edges=2.5`` counted 2 edges and ``'5'`` five, ``start=2.5`` was a slice's TypeError, and
    ``reset='no'`` ran a reset."""
    from tespike.golden.activity import top_activity
    with pytest.raises(InputError, match="^" + re.escape(words) + "$"):
        top_activity(SensorConfig(), np.zeros((4, 1, 2), np.uint16), **options)


def test_timing_states_refuses_edges_that_are_no_count():
    """2.5 edges had made four states silently."""
    from tespike.golden.activity import timing_states
    with pytest.raises(InputError, match=r"^edges = 2.5: must be an integer >= 0$"):
        timing_states(SensorConfig(), 2.5)
