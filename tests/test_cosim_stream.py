"""The streaming top's Verilog (rtl/verilog_stream.py) in Icarus, Verilator and cocotb equals the golden beats.

Every simulator drives only ``clk``, ``rst`` and ``charge`` and reads only
``out_valid``, ``out_first`` and ``out_words``; the beats are held to SPEC
section 6 (count, ``out_first``, the 2L latency bound:
:func:`tespike.cosim.stream_ports.check_beats`) and compared bit for bit with
:func:`tespike.golden.beats.beats` of the literal SPEC rule's words.
"""

import shutil

import numpy as np
import pytest

from tespike.cosim.icarus import run_icarus_stream
from tespike.cosim.outside import SimulatorRunError
from tespike.golden.config import SensorConfig
from tespike.golden.beats import beats
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.outside_helpers import KINDS, make_stimulus, reference_words
from tests.stream_helpers import STREAM_SHAPE, lane_counts

needs_icarus = pytest.mark.skipif(not shutil.which("iverilog"), reason="Icarus Verilog is not installed")
needs_verilator = pytest.mark.skipif(not shutil.which("verilator"), reason="Verilator is not installed")


#: Lanes 0 and 1 swapped at the streaming top's output (a wiring fault the checks must notice).
LANE_SWAP = ("assign out_words = beat_bus[0];",
             "assign out_words = {beat_bus[0][N*WD-1:2*WD], beat_bus[0][WD-1:0], beat_bus[0][2*WD-1:WD]};")


def _verilog(config, shape, lanes):
    from tespike.rtl.verilog_stream import stream_array_verilog
    return stream_array_verilog(config, *shape, lanes)


@needs_icarus
@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_icarus_stream_equals_golden(config, rng):
    """Every edge configuration, every kind of lane count, all four stimulus kinds."""
    stimuli = [make_stimulus(kind, config, rng, shape=STREAM_SHAPE) for kind in KINDS]
    for lanes in lane_counts(config):
        verilog = _verilog(config, STREAM_SHAPE, lanes)
        for kind, stim in zip(KINDS, stimuli):
            got = run_icarus_stream(config, stim, lanes, verilog=verilog)
            assert np.array_equal(got, beats(reference_words(config, stim), lanes)), (lanes, kind)


@needs_icarus
@pytest.mark.parametrize("config", [EDGE_CONFIGS[0], EDGE_CONFIGS[4], EDGE_CONFIGS[9], MSB_CONFIGS[0]], ids=str)
def test_icarus_loop_view_equals_golden(config, rng):
    """The simulation view (rtl.verilog_stream.stream_loop_verilog: the same rule text and
    shift-register readout as one clocked loop) gives the golden beats for every kind of lane count."""
    from tespike.rtl.verilog_stream import stream_array_verilog
    stim = make_stimulus("random", config, rng, shape=STREAM_SHAPE)
    for lanes in lane_counts(config):
        verilog = stream_array_verilog(config, *STREAM_SHAPE, lanes, view="loop")
        got = run_icarus_stream(config, stim, lanes, verilog=verilog)
        assert np.array_equal(got, beats(reference_words(config, stim), lanes)), lanes


@needs_icarus
def test_icarus_stream_notices_a_wrong_beat(rng):
    """A lane swapped in the Verilog is caught (the comparison can fail)."""
    config = SensorConfig(b1=2, b2=2)
    stim = make_stimulus("random", config, rng, shape=STREAM_SHAPE)
    verilog = _verilog(config, STREAM_SHAPE, 4).replace(*LANE_SWAP)
    got = run_icarus_stream(config, stim, 4, verilog=verilog)
    assert not np.array_equal(got, beats(reference_words(config, stim), 4))


@needs_icarus
def test_icarus_stream_refuses_a_late_beat(rng):
    """Beats held back past the 2L bound (a counter that starts late) break SPEC section 6."""
    config = SensorConfig(b1=1, b2=2)                          # L = 6
    stim = make_stimulus("random", config, rng, shape=STREAM_SHAPE)
    late = _verilog(config, STREAM_SHAPE, 1)
    late = late.replace("assign out_valid = sending;", "assign out_valid = 1'b0;")
    with pytest.raises(SimulatorRunError, match="out_valid was high 0 times"):
        run_icarus_stream(config, stim, 1, verilog=late)


@needs_verilator
@pytest.mark.parametrize("config, lanes", [
    (EDGE_CONFIGS[0], 4),        # paper TE, B = 2, N does not divide H*W
    (EDGE_CONFIGS[1], 1),        # paper ML count, one lane
    (EDGE_CONFIGS[4], 6),        # L = 1: N = H*W, one beat every clock
    (EDGE_CONFIGS[7], 7),        # 32-bit input, N > H*W
    (MSB_CONFIGS[0], 5),         # ML msb
    (MSB_CONFIGS[3], 6),         # ML msb, L = 1
], ids=str)
def test_verilator_stream_equals_golden(config, lanes, rng):
    from tespike.cosim.verilator import run_verilator_stream
    verilog = _verilog(config, STREAM_SHAPE, lanes)
    for kind in KINDS:
        stim = make_stimulus(kind, config, rng, shape=STREAM_SHAPE)
        got = run_verilator_stream(config, stim, lanes, verilog=verilog)
        assert np.array_equal(got, beats(reference_words(config, stim), lanes)), kind


@needs_verilator
def test_verilator_stream_larger_array(rng):
    """A 24 x 40 paper-TE array over 4 readouts, in the simulation view Verilator runs at sensor size
    (the design's 960 pixel instances took 323 s to build and run here under a load of 12; the design
    itself is checked in Verilator at 2 x 3 above, and at every size in Icarus and Amaranth)."""
    from tespike.cosim.verilator import run_verilator_stream
    from tespike.golden.sensor import simulate
    from tespike.rtl.verilog_stream import stream_array_verilog
    config = SensorConfig()
    L = config.clocks_per_readout
    light = 10.0 ** rng.uniform(-3.0, np.log10(1.5), size=(24, 40))
    stim = rng.poisson(42000.0 * light / L, size=(4 * L, 24, 40)).astype(np.int64)
    got = run_verilator_stream(config, stim, 7, verilog=stream_array_verilog(config, 24, 40, 7, view="loop"))
    assert np.array_equal(got, beats(simulate(config, stim), 7))


@pytest.mark.parametrize("simulator", [
    pytest.param("icarus", marks=needs_icarus), pytest.param("verilator", marks=needs_verilator)])
def test_cocotb_stream_bench(simulator, tmp_path):
    pytest.importorskip("cocotb")
    from tespike.cosim.cocotb_bench import Settings
    from tespike.cosim.cocotb_run import run_cocotb
    config = SensorConfig(mode="ml", ml_readout="msb", b1=2, b2=2)     # L = 12
    result = run_cocotb(Settings(config, 2, 3, readouts=3, seed=3, lanes=4), simulator, work_dir=tmp_path)
    assert result.passed, result.message
    assert '"beats": 2' in result.message and '"lanes": 4' in result.message


@needs_icarus
def test_cocotb_stream_bench_notices_a_wrong_beat(tmp_path):
    pytest.importorskip("cocotb")
    from tespike.cosim.cocotb_bench import Settings
    from tespike.cosim.cocotb_run import run_cocotb
    config = SensorConfig(b1=2, b2=2)
    bad = _verilog(config, (2, 3), 4).replace(*LANE_SWAP)
    (tmp_path / "bad.v").write_text(bad)
    result = run_cocotb(Settings(config, 2, 3, readouts=3, lanes=4), "icarus",
                        verilog_path=tmp_path / "bad.v", work_dir=tmp_path)
    assert not result.passed and "differ" in result.message
