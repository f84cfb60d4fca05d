"""The generated array Verilog run by Icarus (cosim/icarus.py) equals the literal SPEC rule.

The first test is the outside check of issue 3: ``tespike.rtl.verilog.array_verilog``
for every edge configuration (the paper's TE and ML settings among them),
random and extreme stimuli, compared bit for bit with
``tespike.golden.reference.step_reference``. The others test the testbench itself on a
hand-written model of the same ports (tests/verilog_spec_model.py): latencies,
planted faults, X detection, refusals.
"""

import shutil
import subprocess

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.sensor import simulate
from tespike.cosim.icarus import run_icarus, verilog_testbench
from tespike.cosim.outside import SimulatorBuildError, SimulatorMissingError, SimulatorRunError
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.outside_helpers import KINDS, SHAPE, generated_verilog, make_stimulus, reference_words
from tests.verilog_spec_model import spec_model_verilog

pytestmark = pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("vvp")),
                                reason="Icarus Verilog (iverilog, vvp) is not installed")

PAPER_TE, PAPER_ML = SensorConfig(), SensorConfig(mode="ml")


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_generated_verilog_equals_reference(config, kind, rng):
    stim = make_stimulus(kind, config, rng)
    words = run_icarus(config, stim, verilog=generated_verilog(config, *SHAPE))
    assert words.shape == (3,) + SHAPE and words.dtype == np.int64
    assert np.array_equal(words, reference_words(config, stim))


def test_default_verilog_is_the_generated_array(rng):
    """Without ``verilog=``, run_icarus generates the array itself (1 x 1, 32-bit input)."""
    config = EDGE_CONFIGS[7]
    assert config.input_bits == 32
    stim = make_stimulus("random", config, rng, shape=(1, 1), readouts=4)
    assert np.array_equal(run_icarus(config, stim), simulate(config, stim))


@pytest.mark.parametrize("latency", [0, 1, 2])
@pytest.mark.parametrize("config", [PAPER_TE, PAPER_ML, EDGE_CONFIGS[7], EDGE_CONFIGS[11], MSB_CONFIGS[0],
                                    MSB_CONFIGS[3]], ids=str)
def test_testbench_follows_any_fixed_latency(config, latency, rng):
    stim = make_stimulus("random", config, rng, readouts=4)
    model = spec_model_verilog(config, *SHAPE, latency=latency)
    if latency > config.clocks_per_readout:
        with pytest.raises(SimulatorRunError, match="latency 2 clocks is outside"):
            run_icarus(config, stim, verilog=model)
    else:
        assert np.array_equal(run_icarus(config, stim, verilog=model), reference_words(config, stim))


@pytest.mark.parametrize("config", [PAPER_TE, PAPER_ML, EDGE_CONFIGS[4], EDGE_CONFIGS[5], EDGE_CONFIGS[11]]
                         + MSB_CONFIGS, ids=str)
def test_loop_style_model_equals_reference(config, rng):
    """The procedural-loop model the benchmark compares against is itself exact."""
    stim = make_stimulus("random", config, rng, readouts=4)
    words = run_icarus(config, stim, verilog=spec_model_verilog(config, *SHAPE, style="loop"))
    assert np.array_equal(words, reference_words(config, stim))


def test_a_wrong_word_is_noticed(rng):
    """The comparison can fail: a model latching m one too high differs from the reference."""
    stim = make_stimulus("random", PAPER_TE, rng, readouts=4)
    words = run_icarus(PAPER_TE, stim, verilog=spec_model_verilog(PAPER_TE, *SHAPE, bug="m_plus_one"))
    assert not np.array_equal(words, reference_words(PAPER_TE, stim))


@pytest.mark.parametrize("bug, words", [
    ("double_valid", r"frame_valid was high \d+ times in the run, expected 3"),
    ("x_frame", "frame holds X or Z"),
    ("x_valid", "frame_valid holds X or Z"),
])
def test_broken_ports_are_refused(bug, words, rng):
    stim = make_stimulus("random", PAPER_TE, rng)
    with pytest.raises(SimulatorRunError, match=words):
        run_icarus(PAPER_TE, stim, verilog=spec_model_verilog(PAPER_TE, *SHAPE, bug=bug))


def test_compile_error_names_the_line(rng):
    stim = make_stimulus("zero", PAPER_TE, rng, readouts=1)
    with pytest.raises(SimulatorBuildError, match=r"array\.v:\d+: syntax error"):
        run_icarus(PAPER_TE, stim, verilog=spec_model_verilog(PAPER_TE, *SHAPE, bug="syntax"))


def test_work_dir_keeps_the_files(tmp_path, rng):
    stim = make_stimulus("random", PAPER_ML, rng, readouts=1)
    run_icarus(PAPER_ML, stim, work_dir=tmp_path, verilog=spec_model_verilog(PAPER_ML, *SHAPE))
    assert {"array.v", "tb.v", "stimulus.hex", "captures.txt", "sim.vvp"} <= {p.name for p in tmp_path.iterdir()}
    assert len((tmp_path / "stimulus.hex").read_text().split()) == PAPER_ML.clocks_per_readout
    with pytest.raises(InputError, match="not an existing directory"):        # (a bad argument, before any run)
        run_icarus(PAPER_ML, stim, work_dir=tmp_path / "nope", verilog="")


def test_missing_icarus_is_a_clear_error(monkeypatch, rng):
    monkeypatch.setenv("PATH", "")
    with pytest.raises(SimulatorMissingError, match="'iverilog' is not on PATH"):
        run_icarus(PAPER_TE, make_stimulus("zero", PAPER_TE, rng, readouts=1), verilog="")


@pytest.mark.parametrize("stim, words", [
    (np.zeros((240, 2, 3), np.float64), "not an integer type"),
    (np.zeros((239, 2, 3), np.int64), "not a multiple of L"),
    (np.full((240, 2, 3), 1 << 16, np.int64), r"exceeds 2\^input_bits - 1"),
    (np.full((240, 2, 3), -1, np.int64), "negative"),
])
def test_bad_stimulus_is_refused_before_simulating(stim, words):
    with pytest.raises(InputError, match=words):
        run_icarus(PAPER_TE, stim, verilog="this would not compile")


def test_no_whole_readout_gives_no_words():
    words = run_icarus(PAPER_TE, np.zeros((0, 2, 3), np.uint16), verilog="not compiled")
    assert words.shape == (0, 2, 3)


def test_testbench_drives_only_the_spec_ports():
    text = verilog_testbench("te_pixel_array", 96, 30, "frame", "ports")
    assert "te_pixel_array dut(.clk(clk), .rst(rst), .charge(charge), .frame_valid(frame_valid), .frame(frame));" in text
    assert "reg [95:0] charge;" in text and "wire [29:0] frame;" in text


@pytest.mark.parametrize("generation", ["-g2005", "-g2012"])
def test_frame_is_defined_from_the_first_readout_in_verilog_and_systemverilog_mode(tmp_path, generation):
    """In the dark no word ever changes: the parallel top's frame must still read the words (0),
    not X. A SystemVerilog simulator sets the registers' initial values before any process starts,
    so the frame's always @* loop alone left frame X for the whole run (iverilog -g2012)."""
    from tespike.rtl.verilog import array_verilog
    (tmp_path / "array.v").write_text(array_verilog(SensorConfig(), 1, 2))
    (tmp_path / "tb.v").write_text(
        "module tb; reg clk = 0, rst = 1; reg [31:0] charge = 0; wire valid; wire [9:0] frame;\n"
        "  te_pixel_array dut(.clk(clk), .rst(rst), .charge(charge), .frame_valid(valid), .frame(frame));\n"
        "  integer t; initial begin #1 clk = 1; #1 clk = 0; rst = 0;\n"
        "    for (t = 0; t < 480; t = t + 1) begin #1 clk = 1; #1 if (valid) $display(\"frame=%b\", frame);\n"
        "      clk = 0; end $finish; end\n"
        "endmodule\n")
    subprocess.run(["iverilog", generation, "-o", "t.vvp", "tb.v", "array.v"], cwd=tmp_path, check=True)
    shown = subprocess.run(["vvp", "-n", "t.vvp"], cwd=tmp_path, capture_output=True, text=True, check=True).stdout
    frames = [line for line in shown.splitlines() if line.startswith("frame=")]
    assert frames == ["frame=0000000000"] * 2


def test_the_testbench_writer_refuses_an_unknown_kind_of_outputs():
    """It had been a KeyError."""
    with pytest.raises(InputError, match="^outputs 'fram': must be one of frame, beats$"):
        verilog_testbench("array", 4, 4, "fram", "ports")
