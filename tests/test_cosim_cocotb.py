"""The cocotb testbench (cosim/cocotb_bench.py) on the generated Verilog: TE, ML count, ML msb.

Each camera's 2 x 3 array under Icarus and Verilator, scoreboarded by the golden
model; the testbench notices a planted wrong word and an X on ``frame``
(hand-written models of the ports, tests/verilog_spec_model.py); ``tespike
cocotb`` runs both simulators from one command; bad input is refused in one line.
Builds are cached (``<cache>/cocotb``), so only the first run pays for them.
"""

import shutil

import numpy as np
import pytest

from tespike.cosim.cocotb_bench import Settings, default_stimulus
from tespike.cosim.compare import first_difference
from tespike.cosim.cocotb_run import run_cocotb
from tespike.golden.config import SensorConfig
from tespike.golden.reference import step_reference
from tests.cli import assert_refused, run_tespike
from tests.verilog_spec_model import spec_model_verilog

cocotb = pytest.importorskip("cocotb")

HAVE = {"icarus": bool(shutil.which("iverilog") and shutil.which("vvp")),
        "verilator": bool(shutil.which("verilator"))}

#: One camera of each kind, with short readout intervals where the preset's L = 240 is not needed.
CAMERAS = [
    SensorConfig.preset("te"),                                                         # L = 240
    SensorConfig(mode="ml", ml_bits=3, b1=2, b2=2, clocks_per_tick=3, threshold=20),   # L = 9
    SensorConfig.preset("ml-msb"),                                                     # L = 240
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=5, b1=2, b2=2, threshold=9),    # L = 12
]


def needs(simulator):
    return pytest.mark.skipif(not HAVE[simulator], reason=f"{simulator} is not installed")


@pytest.mark.parametrize("simulator", [pytest.param("icarus", marks=needs("icarus")),
                                       pytest.param("verilator", marks=needs("verilator"))])
@pytest.mark.parametrize("config", CAMERAS, ids=str)
def test_generated_verilog_passes_the_cocotb_bench(config, simulator, tmp_path):
    settings = Settings(config, 2, 3, readouts=3, seed=7)
    result = run_cocotb(settings, simulator, work_dir=tmp_path)
    assert result.passed, result.message + "\n" + result.log.read_text()[-3000:]
    assert "RTL == golden model" in result.message and '"readouts": 3' in result.message
    assert result.log == tmp_path / f"{simulator}.log"


def test_default_stimulus_reaches_many_codes(rng):
    """Else the bench would prove little: dark, mid and saturated pixels, and several words."""
    for config in CAMERAS:
        stim = default_stimulus(config, np.random.default_rng(7), 3, 2, 3)
        words = step_reference(config, stim)[0]
        assert stim.max() == config.input_max and len(np.unique(words)) >= 3, config


@needs("icarus")
def test_cocotb_bench_notices_a_wrong_word(tmp_path):
    """A model latching the CCC one too high fails, naming the first differing word."""
    config = SensorConfig(b1=2, b2=2, clocks_per_tick=3, threshold=30)
    (tmp_path / "bad.v").write_text(spec_model_verilog(config, 2, 3, bug="m_plus_one"))
    result = run_cocotb(Settings(config, 2, 3, readouts=4), "icarus", verilog_path=tmp_path / "bad.v",
                        work_dir=tmp_path)
    assert not result.passed
    assert "RTL != golden model" in result.message and "first at readout" in result.message


@needs("icarus")
def test_cocotb_bench_refuses_x_on_frame(tmp_path):
    config = SensorConfig(b1=2, b2=2, clocks_per_tick=3, threshold=30)
    (tmp_path / "x.v").write_text(spec_model_verilog(config, 2, 3, bug="x_frame"))
    result = run_cocotb(Settings(config, 2, 3), "icarus", verilog_path=tmp_path / "x.v", work_dir=tmp_path)
    assert not result.passed and "X or Z" in result.message and "frame" in result.message


@needs("icarus")
def test_cocotb_bench_accepts_any_fixed_latency(tmp_path):
    """Latency 2 (two output registers) is legal for L >= 2: the bench follows it."""
    config = SensorConfig(mode="ml", ml_readout="msb", ml_bits=5, b1=2, b2=2, threshold=9)
    (tmp_path / "late.v").write_text(spec_model_verilog(config, 2, 3, latency=2))
    result = run_cocotb(Settings(config, 2, 3), "icarus", verilog_path=tmp_path / "late.v",
                        work_dir=tmp_path)
    assert result.passed and '"latency": 2' in result.message, result.message


@needs("icarus")
def test_cocotb_work_dir_may_be_relative(tmp_path, monkeypatch):
    """A relative work folder (``--work-dir logs``) holds the run: the results file was looked
    for under the folder twice over (the simulator runs inside it), and every run failed."""
    monkeypatch.chdir(tmp_path)
    config = SensorConfig(b1=2, b2=2, clocks_per_tick=3, threshold=30)
    (tmp_path / "ok.v").write_text(spec_model_verilog(config, 2, 3))
    result = run_cocotb(Settings(config, 2, 3), "icarus", verilog_path="ok.v", work_dir="logs")
    assert result.passed, result.message
    assert (tmp_path / "logs" / "icarus-results.xml").is_file()


def test_first_difference_names_readout_and_pixel():
    expected = np.zeros((2, 2, 3), np.int64)
    got = expected.copy()
    got[1, 0, 2] = 5
    assert first_difference(got, expected).text() == ("1 of 12 words differ; first at readout 1, "
                                                      "pixel (0, 2): RTL word 5, golden word 0")
    assert first_difference(expected, expected) is None


@pytest.mark.skipif(not (HAVE["icarus"] and HAVE["verilator"]), reason="needs Icarus and Verilator")
def test_cocotb_command_runs_both_simulators(tmp_path):
    """One command, both simulators (the builds of the test above are reused)."""
    result = run_tespike("cocotb", "--config", "ml-msb", "--height", 2, "--width", 3, "--readouts", 2,
                         "--seed", 3, "--work-dir", tmp_path / "logs")
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.splitlines()
    assert [line.split(":")[1].strip() for line in lines] == ["icarus", "verilator"], lines
    assert all(": pass: RTL == golden model" in line for line in lines)
    assert sorted(p.name for p in (tmp_path / "logs").glob("*.log")) == ["icarus.log", "verilator.log"]
    for kept in (tmp_path / "logs").iterdir():          # (they named the staging folder, gone once in place)
        assert ".part" not in kept.read_text(errors="replace"), kept


@needs("icarus")
def test_cocotb_command_takes_a_stimulus_file(tmp_path):
    config = SensorConfig.preset("ml-msb")
    np.save(tmp_path / "e.npy", default_stimulus(config, np.random.default_rng(3), 2, 2, 3).astype(np.uint16))
    result = run_tespike("cocotb", "--config", "ml-msb", "--height", 2, "--width", 3,
                         "--stimulus", tmp_path / "e.npy", "--simulator", "icarus")
    assert result.returncode == 0, result.stdout + result.stderr
    assert '"readouts": 2' in result.stdout


@pytest.mark.parametrize("argv, words", [
    (["--config", "te", "--height", 0, "--width", 2], ["height", "0"]),
    (["--config", "te", "--height", 2, "--width", 2, "--verilog", "/nonexistent/a.v",
      "--simulator", "icarus"], ["/nonexistent/a.v", "does not exist"]),
    # a folder or a device was said not to exist
    (["--config", "te", "--height", 2, "--width", 2, "--verilog", "/dev/null", "--simulator", "icarus"],
     ["--verilog file '/dev/null' is a character device"]),
    (["--config", "te", "--height", 2, "--width", 2, "--verilog", "/", "--simulator", "icarus"],
     ["--verilog file '/' is a directory"]),
    (["--config", "te", "--height", 2, "--width", 2, "--simulator", "no-such-sim"], ["no-such-sim"]),
    # every name checked before the first run (icarus ran to a pass, then bogus was refused); a
    # name given twice ran twice without a word
    (["--config", "te", "--height", 2, "--width", 2, "--simulator", "icarus", "bogus"], ["'bogus'"]),
    (["--config", "te", "--height", 2, "--width", 2, "--simulator", "icarus", "icarus"], ["icarus is given twice"]),
    (["--config", "te", "--height", 2, "--width", 2, "--readouts", 0], ["--readouts", "0"]),
    (["--config", "te", "--height", 2, "--width", 2, "--seed", -1], ["--seed -1"]),      # (a traceback)
    (["--config", "te", "--height", 2, "--width", 2, "--work-dir", "/dev/null"], ["--work-dir", "not a directory"]),
    # the default stimulus's options with a stimulus file were dropped without a word
    (["--config", "te", "--height", 2, "--width", 2, "--stimulus", "e.npy", "--readouts", 7], ["--readouts", "ignored"]),
    (["--config", "te", "--height", 2, "--width", 2, "--stimulus", "e.npy", "--seed", 1], ["--seed", "ignored"]),
])
def test_cocotb_command_refuses_bad_input(argv, words, tmp_path):
    assert_refused(run_tespike("cocotb", *argv), *words)


@needs("icarus")
def test_a_run_that_compares_nothing_is_no_pass(tmp_path):
    """A reset every readout interval leaves no whole interval to compare: it said "pass"."""
    np.save(tmp_path / "e.npy", np.ones((240, 2, 2), np.uint16))
    np.save(tmp_path / "r.npy", (np.arange(240) == 100).astype(np.uint8))
    result = run_tespike("cocotb", "--config", "te", "--height", 2, "--width", 2, "--simulator", "icarus",
                         "--stimulus", tmp_path / "e.npy", "--resets", tmp_path / "r.npy")
    assert_refused(result, "icarus: nothing was compared")


@needs("icarus")
def test_cocotb_command_refuses_a_stimulus_of_another_size(tmp_path):
    np.save(tmp_path / "e.npy", np.zeros((240, 3, 3), np.int64))
    result = run_tespike("cocotb", "--config", "te", "--height", 2, "--width", 2, "--simulator", "icarus",
                         "--stimulus", tmp_path / "e.npy")
    assert_refused(result, "3, 3", "2 x 2")


@needs("icarus")
def test_a_verilog_file_that_does_not_build_is_named_as_given(tmp_path):
    """The compiler's error line named the cache's copy of the file (``<cache>/cocotb/<key>/array.v``)."""
    text = spec_model_verilog(SensorConfig.preset("te"), 2, 2).replace("endmodule", "endmodule oops", 1)
    (tmp_path / "mine.v").write_text(text)
    result = run_tespike("cocotb", "--config", "te", "--height", 2, "--width", 2, "--simulator", "icarus",
                         "--verilog", tmp_path / "mine.v", env={"TESPIKE_CACHE": str(tmp_path / "cache")})
    assert_refused(result, str(tmp_path / "mine.v"), "build")
    assert "array.v" not in result.stderr.split("(full log")[0]


@pytest.mark.parametrize("edit", ["frame_valid renamed", "charge an output"])
def test_a_top_without_specs_ports_is_refused_before_the_run(tmp_path, edit):
    """The testbench reaches ports by name: an internal net named frame_valid passed for the port
    (the top's own frame_valid renamed and tied to 0: 'pass', exit 0)."""
    from tespike.rtl.verilog import array_verilog
    text = array_verilog(SensorConfig.preset("te"), 2, 3)
    if edit == "frame_valid renamed":
        text = text.replace("output wire frame_valid,", "output wire fv,", 1).replace(
            "  assign frame = words;", "  wire frame_valid;\n  assign fv = 1'b0;\n  assign frame = words;", 1)
        words = ("port frame_valid: no such port",)
    else:
        text = text.replace("input  wire [95:0] charge,", "output wire [95:0] charge,", 1)
        words = ("port charge: an output of 96 bit(s)", "wants an input")
    assert text != array_verilog(SensorConfig.preset("te"), 2, 3)
    (tmp_path / "mine.v").write_text(text)
    result = run_tespike("cocotb", "--config", "te", "--height", 2, "--width", 3, "--simulator", "icarus",
                         "--readouts", 2, "--verilog", tmp_path / "mine.v",
                         env={"TESPIKE_CACHE": str(tmp_path / "cache")})
    assert_refused(result, str(tmp_path / "mine.v"), *words)


def test_the_work_folder_is_one_runs_whole(tmp_path):
    """--work-dir mixed runs: the commands file was appended to, another simulator's files of an
    earlier run stayed, and a stopped run left its partial log under the final name. The folder is
    now replaced whole when the run ends; one holding files no run writes is refused."""
    work = tmp_path / "cw"
    work.mkdir()
    (work / "verilator.log").write_text("an earlier run's\n")
    (work / "icarus-commands.txt").write_text("an earlier run's\n")
    env = {"TESPIKE_CACHE": str(tmp_path / "cache")}
    result = run_tespike("cocotb", "--config", "te", "--height", 2, "--width", 2, "--readouts", 2,
                         "--simulator", "icarus", "--work-dir", work, env=env)
    assert result.returncode == 0, result.stderr
    assert f"(log: {work / 'icarus.log'})" in result.stdout
    assert sorted(p.name for p in work.iterdir()) == ["icarus-commands.txt", "icarus-results.xml", "icarus.log"]
    assert "an earlier run's" not in (work / "icarus-commands.txt").read_text()
    (work / "notes.txt").write_text("mine")
    result = run_tespike("cocotb", "--config", "te", "--height", 2, "--width", 2, "--simulator", "icarus",
                         "--work-dir", work, env=env)
    assert_refused(result, "--work-dir", "'notes.txt'", "no cocotb run writes")
    assert (work / "notes.txt").read_text() == "mine"


@needs("icarus")
def test_a_build_stopped_midway_leaves_no_entry_in_the_cache(tmp_path, monkeypatch):
    """The build ran in the cache entry itself: Ctrl-C, SIGTERM or SIGHUP mid-build (and a kill)
    left a visible half-built entry (sources, objects, no "done"). It is built in a hidden folder
    renamed into place once done, and a stop removes that folder."""
    import types

    import tespike.cosim.cocotb_run as cocotb_run
    verilog = tmp_path / "a.v"
    verilog.write_text("module top(input clk); endmodule\n")

    def stopped(simulator):
        def build(*, build_dir, **kwargs):
            (build_dir / "sim.vvp").write_text("half")
            raise KeyboardInterrupt
        return types.SimpleNamespace(build=build)
    monkeypatch.setattr(cocotb_run, "_runner", stopped)
    with pytest.raises(KeyboardInterrupt):
        cocotb_run.build(verilog, "top", "icarus", cache_root=tmp_path / "cache")
    assert [p.name for p in (tmp_path / "cache" / "cocotb").iterdir() if not p.name.endswith(".lock")] == []

    def built(simulator):
        def build(*, build_dir, **kwargs):
            (build_dir / "sim.vvp").write_text("whole")
        return types.SimpleNamespace(build=build)
    monkeypatch.setattr(cocotb_run, "_runner", built)
    final = cocotb_run.build(verilog, "top", "icarus", cache_root=tmp_path / "cache")
    assert (final / "done").is_file() and (final / "sim.vvp").read_text() == "whole"
    assert not final.name.startswith(".")
