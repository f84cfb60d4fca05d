"""tespike.cosim.energy: the CV^2 model's figures by hand, and energies that grow with what they count."""

import shutil

import numpy as np
import pytest

from tespike.cosim.energy import SKY130_HD, EnergyModel, block_cells, block_energy, run_energy
from tespike.golden.activity import BLOCKS, top_activity
from tespike.golden.config import SensorConfig

TE = SensorConfig(mode="te", b1=2, b2=2, threshold=5, acc_bits=4, input_bits=3)


def test_per_event_energies_by_hand():
    # 1.8 V, 2.3 fF unit input: a logic node 3 x 2.3 = 6.9 fF, half C V^2 = 0.5 * 6.9e-15 * 3.24
    assert SKY130_HD.gate_toggle == pytest.approx(11.178e-15, rel=1e-12)
    # a flip-flop toggle: (3 + 4) x 2.3 fF = 16.1 fF at half C V^2
    assert SKY130_HD.flop_toggle == pytest.approx(26.082e-15, rel=1e-12)
    # its clock every cycle: 4 x 2.3 fF = 9.2 fF charged and discharged, C V^2
    assert SKY130_HD.clock_per_flop == pytest.approx(29.808e-15, rel=1e-12)


def test_block_energy_by_hand():
    """10 toggles of 2 register bits, 2 flip-flops and 6 gates, over 5 clocks."""
    parts = block_energy(10, register_bits=2, flops=2, gates=6, clocks=5)
    assert float(parts["data"]) == pytest.approx(10 * 26.082e-15)
    assert float(parts["logic"]) == pytest.approx(6 * 10 / 2 * 11.178e-15)   # 30 gate toggles
    assert float(parts["clock"]) == pytest.approx(2 * 5 * 29.808e-15)
    assert all(np.asarray(value).dtype == np.float64 for value in parts.values())


def test_energy_grows_with_toggles_clocks_and_supply():
    base = dict(register_bits=8, flops=8, gates=40, clocks=100)
    totals = [sum(block_energy(t, **base).values()) for t in (0, 5, 50, 500)]
    assert all(a < b for a, b in zip(totals, totals[1:]))
    assert sum(block_energy(5, **{**base, "clocks": 200}).values()) > totals[1]
    assert sum(block_energy(5, **{**base, "gates": 80}).values()) > totals[1]
    low = EnergyModel("1.2 V", 1.2, 2.3e-15, 3.0, 4.0, 4.0)
    ratio = sum(block_energy(5, model=low, **base).values()) / totals[1]
    assert ratio == pytest.approx((1.2 / 1.8) ** 2)          # every part is C V^2


def test_a_run_costs_more_with_more_light():
    L = TE.clocks_per_readout
    cells = {block: {"flops": 10, "gates": 50} for block in BLOCKS}
    rng = np.random.default_rng(0)
    totals = []
    for rate in (0.0, 0.2, 1.0, 3.0):
        e = np.minimum(rng.poisson(rate, (4 * L, 2, 3)), TE.input_max)
        energy = run_energy(top_activity(TE, e, 2), cells)
        totals.append(sum(part["total"] for part in energy.values()))
        assert energy["pixel"]["clock"] == pytest.approx(10 * (4 * L + 4) * SKY130_HD.clock_per_flop)
    assert all(a < b for a, b in zip(totals, totals[1:])), totals


@pytest.mark.skipif(not shutil.which("yosys"), reason="Yosys is not installed")
@pytest.mark.parametrize("lanes", [None, 2])
def test_block_cells_count_every_synthesised_flip_flop(lanes):
    from tespike.cosim.synthesis import hierarchy_total, synthesize_hierarchy
    from tespike.cosim.tops import Top

    top = Top(TE, 2, 3, lanes)
    result = synthesize_hierarchy(top.verilog(), top.module, gate_sets=("cmos2",))
    probe = top_activity(TE, np.zeros((TE.clocks_per_readout, 2, 3), np.int64), lanes)
    cells = block_cells(result["modules"], result["top"], TE, lanes is not None)
    total = hierarchy_total(result["modules"], result["top"])
    assert sum(c["flops"] for c in cells.values()) == total["flops"]
    assert sum(c["flops"] + c["gates"] for c in cells.values()) == total["cells"]
    bits = probe.register_bits()
    for block in ("pixel", "timing", "control", "readout"):   # synthesis keeps every modelled bit here
        assert cells[block]["flops"] == bits[block], block


@pytest.mark.skipif(not (shutil.which("yosys") and shutil.which("iverilog")), reason="Yosys and Icarus are needed")
def test_gate_level_check_runs_the_synthesised_netlist():
    """The netlist gives the golden beats (logic_check refuses otherwise); its gates toggle
    more in light than in the dark, and the estimate is of the same order."""
    from tespike.cosim.gate_activity import logic_check

    L = TE.clocks_per_readout
    dark = np.zeros((3 * L, 2, 3), np.int64)
    bright = np.minimum(np.random.default_rng(2).poisson(3.0, (3 * L, 2, 3)), TE.input_max)
    low, high = logic_check(TE, dark, 2), logic_check(TE, bright, 2)
    assert set(high) == {"pixel", "readout", "timing", "control"}
    assert high["pixel"]["measured"] > low["pixel"]["measured"] and high["pixel"]["gates"] > 0
    assert low["timing"]["measured"] == high["timing"]["measured"] > 0       # the timing ignores the light
    assert 0.2 < high["pixel"]["ratio"] < 5


def test_the_energy_figures_refuse_counts_and_models_that_are_none_in_one_line():
    """block_energy(-5, 4, 1, 1, -1) gave negative joules, NaN toggles and 2.5 flops went through, a
    model's name was an AttributeError, a negative supply made a model, and run_energy of cells
    without a block was a KeyError."""
    from tespike.golden.errors import InputError
    for args, words in (((5, 4, 1, 1, -1), "block_energy clocks = -1"), ((5, -4, 1, 1, 1), "block_energy register_bits = -4"),
                        ((5, 4, 2.5, 1, 1), "block_energy flops = 2.5")):
        with pytest.raises(InputError, match=f"^{words}: must be an integer >= 0$"):
            block_energy(*args)
    for toggles in (-5, float("nan"), "x"):
        with pytest.raises(InputError, match="^block_energy toggles: must be finite counts >= 0$"):
            block_energy(toggles, 4, 1, 1, 1)
    with pytest.raises(InputError, match="^energy model 'sky130': must be an EnergyModel"):
        block_energy(5, 4, 1, 1, 1, model="sky130")
    for vdd in (-1.8, float("nan"), "1.8"):
        with pytest.raises(InputError, match=f"^energy model vdd = {vdd!r}: must be a finite number > 0$"):
            EnergyModel("x", vdd, 2e-15, 3, 4, 4)
    with pytest.raises(InputError, match="^run_energy activity: must be an Activity"):
        run_energy(None, {})
    activity = top_activity(SensorConfig(), np.zeros((SensorConfig().clocks_per_readout, 1, 2), np.uint16))
    with pytest.raises(InputError, match="^run_energy cells: no flops and gates of block "):
        run_energy(activity, {}, SKY130_HD)
    with pytest.raises(InputError, match="^block_cells: the synthesised modules hold no top 'top'"):
        block_cells({}, "top", SensorConfig(), False)
