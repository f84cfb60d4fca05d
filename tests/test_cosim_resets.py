"""Reset asserted in the middle of a run, with charge in every pixel (cosim/resets.py), in every simulator.

A reset vector from :func:`tespike.cosim.resets.reset_sweep` cuts segments at every phase
(mid-interval, on the interval's last clock, before, during and on the last
beat, held 1-3 clocks) while the stimulus keeps charge flowing into every pixel,
reset clocks included. Each top (parallel and streaming) in Amaranth, Icarus,
Verilator (the parallel top for TE only) and cocotb (ML msb) must show SPEC section 6's reset state and, segment by
segment, the golden model's words from zero state. Planted reset faults of the
generated Verilog (the readout's beat counter not cleared by ``rst``; the pixels
cleared by ``rst`` instead of the sampled reset; the timing block's registers
not cleared) are caught, though each passes the runs without a mid-run reset.
"""

import re
import shutil

import numpy as np
import pytest

from tespike.cosim.outside import SimulatorRunError
from tespike.cosim.resets import (Segment, beat_segments, check_resets, first_segment_difference, frame_segments,
                          golden_segments, reset_sweep, segments)
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.beats import beat_count, beats
from tests.outside_helpers import reference_words

needs_icarus = pytest.mark.skipif(not shutil.which("iverilog"), reason="Icarus Verilog is not installed")
needs_verilator = pytest.mark.skipif(not shutil.which("verilator"), reason="Verilator is not installed")

SHAPE, LANES = (2, 3), 2                   # 6 pixels, B = 3 beats
#: One camera of each kind, L = 12 (b1 = b2 = 2): a sweep is about 400 clocks.
CAMERAS = [SensorConfig(b1=2, b2=2),
           SensorConfig(mode="ml", ml_bits=3, b1=2, b2=2, threshold=20),
           SensorConfig(mode="ml", ml_readout="msb", ml_bits=5, b1=2, b2=2, threshold=9)]


def sweep(config, seed=11):
    """A reset sweep and a stimulus that leaves charge in every pixel on every clock, resets included."""
    rng = np.random.default_rng(seed)
    resets = reset_sweep(config, rng, beats=beat_count(SHAPE[0] * SHAPE[1], LANES))
    level = rng.uniform(0.05, 0.7, size=SHAPE)            # spikes per clock: counts and overflows mixed
    stim = rng.integers(1, np.maximum(2, 2 * level * config.threshold + 1), size=(len(resets), *SHAPE))
    return np.minimum(stim, config.input_max), resets


def assert_segments_golden(config, stim, resets, got, lanes=None):
    expected = golden_segments(config, stim, resets, lanes)
    assert first_segment_difference(got, expected) is None, first_segment_difference(got, expected)
    shown = [len(g) for g in got]
    assert len(got) > 20 and sum(shown) > 10 and 0 in shown          # cut before and after outputs
    assert len(np.unique(np.concatenate([np.asarray(g).ravel() for g in got]))) >= 4   # several codes


# -- the rules, on captures written by hand -------------------------------------------------

def test_segments_split_at_each_reset_edge():
    resets = np.array([0, 0, 1, 1, 0, 0, 0, 1, 0, 0], bool)
    assert segments(resets) == [Segment(0, 2), Segment(4, 7), Segment(8, None)]
    assert segments(None) == [Segment(0, None)]
    assert segments(np.array([0, 1], bool)) == [Segment(0, 1), Segment(2, None)]   # ends in reset
    assert Segment(4, 7).readouts(10, 2) == 2 and Segment(8, None).readouts(10, 2) == 1


@pytest.mark.parametrize("bad, match", [(np.zeros(3, bool), "one value per stimulus clock"),
                                        (np.array([0, 2, 0, 0]), "0 or 1"),
                                        (np.array([0.0, 1, 0, 0]), "0 or 1")])
def test_bad_reset_vectors_are_refused(bad, match):
    with pytest.raises(InputError, match=match):
        check_resets(bad, 4)


def test_a_reset_vector_file_is_read_as_every_npy_input_and_named(tmp_path):
    """--resets went to np.load directly: an empty file was an EOFError traceback, an archive was "of
    shape (1,)" and no refusal named the file."""
    from tespike.cosim.cocotb_bench import Settings
    from tespike.golden.config import SensorConfig
    (tmp_path / "empty.npy").write_bytes(b"")
    with open(tmp_path / "archive.npy", "wb") as handle:
        np.savez(handle, a=np.zeros(3))
    np.save(tmp_path / "float.npy", np.zeros(2 * SensorConfig().clocks_per_readout))
    for name, words in (("empty.npy", "is empty"), ("archive.npy", "holds an archive"),
                        ("float.npy", "holds float64 values")):
        settings = Settings(SensorConfig(), 1, 1, 2, 0, None, None, str(tmp_path / name))
        with pytest.raises(InputError, match=f"{name}'.*{words}|{words}.*{name}"):
            settings.inputs()


def test_a_sweep_over_a_stimulus_file_runs_to_its_end_without_resets(tmp_path):
    """A stimulus file beside --resets sweep was refused as a 'reset vector' of another length, a
    vector the user never gave, with the length of a sweep they could not choose."""
    from tespike.cosim.cocotb_bench import Settings
    from tespike.cosim.resets import reset_sweep
    config = SensorConfig(mode="ml", ml_readout="msb", b1=2, b2=2)         # L = 12
    L = config.clocks_per_readout
    sweep = reset_sweep(config, np.random.default_rng(1), tail_readouts=2)   # (Settings' own: seed + 1)
    np.save(tmp_path / "short.npy", np.ones((len(sweep) - L, 1, 1), np.int64))
    np.save(tmp_path / "long.npy", np.ones((len(sweep) + 2 * L, 1, 1), np.int64))
    settings = Settings(config, 1, 1, 2, 0, str(tmp_path / "long.npy"), None, "sweep")
    stimulus, resets = settings.inputs()
    assert len(stimulus) == len(resets) == len(sweep) + 2 * L
    assert np.array_equal(resets[:len(sweep)], sweep) and not resets[len(sweep):].any()
    short = Settings(config, 1, 1, 2, 0, str(tmp_path / "short.npy"), None, "sweep")
    with pytest.raises(InputError, match=f"^--resets sweep resets the array at every phase over {len(sweep)} pixel "
                                         f"clocks .*: stimulus '.*short.npy' has {len(sweep) - L}; give one of"):
        short.inputs()


def _frames(clocks, n=1):
    return np.zeros((len(clocks), n), np.uint32)


def test_frame_rules_follow_the_reset():
    """L = 2, latency 1: interval k of a segment at kL + L - 1 + 1, due by the reset edge, none after."""
    config = SensorConfig(b1=1, b2=1)                 # F = 2, alpha = 1, L = 2, 2-bit words
    resets = np.zeros(10, bool)
    resets[5] = True                                  # segment 0: clocks 0..5, segment 1 from 6
    good = [2, 4, 8, 10]                              # k = 0, 1 of each (clock 6 + 2, 6 + 4)
    words = frame_segments(good, _frames(good), config, 1, 1, resets, 10, "t")
    assert [len(w) for w in words] == [2, 2]
    for wrong, why in [([2, 4, 6, 8, 10], "frame_valid at its clocks"),       # one after the reset edge
                       ([2, 8, 10], "frame_valid at its clocks"),             # interval 1 lost before it
                       ([2, 4, 8], "frame_valid at its clocks")]:             # last segment short
        with pytest.raises(SimulatorRunError, match=why):
            frame_segments(wrong, _frames(wrong), config, 1, 1, resets, 10, "t")
    resets[6] = True                                  # held two clocks: clock 6 samples the reset state
    with pytest.raises(SimulatorRunError, match="while rst is held"):
        frame_segments([2, 4, 6], _frames([2, 4, 6]), config, 1, 1, resets, 10, "t")


def test_beat_rules_cut_the_interval_at_the_reset_edge():
    """B = 2 beats at 2 and 3 clocks after the interval (the generated top's schedule)."""
    config = SensorConfig(b1=1, b2=2)                 # L = 6
    resets = np.zeros(30, bool)
    resets[12] = True                                 # segment 0: 0..12, interval 0 ends at 5, 1 at 11
    first = [7, 8, 13, 19, 20, 25, 26]                # seg 0: 0's beats, 1's beat 0 at 13 > 12: none
    seg1 = [19, 20, 25, 26]                           # segment 1 from 13: its intervals end at 18, 24

    def run(clocks):
        firsts = [c in (7, 13, 19, 25) for c in clocks]
        return beat_segments(clocks, firsts, _frames(clocks), config, 1, 2, 1, resets, 30, "t")

    assert [len(b) for b in run([7, 8, *seg1])] == [2, 4]
    with pytest.raises(SimulatorRunError, match="expected"):
        run(first)                                    # a beat of segment 0 after its reset edge
    resets[12], resets[8] = False, True               # reset edge 8: both beats of interval 0 due by it
    seg1 = [16, 17, 22, 23, 28, 29]                   # segment 1 from 9: intervals end at 14, 20, 26
    clocks = [7, *seg1]                               # beat 1 at 8 lost: a prefix, but not the schedule's
    with pytest.raises(SimulatorRunError, match="none after it"):
        beat_segments(clocks, [True, True, False, True, False, True, False], _frames(clocks), config,
                      1, 2, 1, resets, 30, "t")
    clocks = [7, 8, *seg1]
    assert [len(b) for b in beat_segments(clocks, [True, False] * 4, _frames(clocks), config, 1, 2, 1,
                                          resets, 30, "t")] == [2, 6]


# -- the generated tops ----------------------------------------------------------------------

@needs_icarus
@pytest.mark.parametrize("config", CAMERAS, ids=str)
def test_icarus_resets_mid_run_equal_golden(config):
    from tespike.cosim.icarus import run_icarus, run_icarus_stream
    stim, resets = sweep(config)
    assert_segments_golden(config, stim, resets, run_icarus(config, stim, resets=resets))
    assert_segments_golden(config, stim, resets, run_icarus_stream(config, stim, LANES, resets=resets), LANES)


@pytest.mark.parametrize("config", CAMERAS, ids=str)
def test_amaranth_resets_mid_run_equal_golden(config):
    from tespike.cosim.rtlsim import rtl_words
    from tespike.cosim.rtlsim import rtl_stream_beats
    stim, resets = sweep(config)
    assert_segments_golden(config, stim, resets, rtl_words(config, stim, resets=resets))
    assert_segments_golden(config, stim, resets, rtl_stream_beats(config, stim, LANES, resets=resets), LANES)


@needs_verilator
@pytest.mark.parametrize("config", CAMERAS, ids=str)
def test_verilator_resets_mid_run_equal_golden(config):
    """Both tops for TE (the parallel top's build is the slow one), the streaming top for every camera."""
    from tespike.cosim.verilator import run_verilator, run_verilator_stream
    stim, resets = sweep(config)
    if config.is_te:
        assert_segments_golden(config, stim, resets, run_verilator(config, stim, resets=resets))
    assert_segments_golden(config, stim, resets, run_verilator_stream(config, stim, LANES, resets=resets),
                           LANES)


@pytest.mark.parametrize("simulator, lanes", [
    pytest.param("icarus", None, marks=needs_icarus), pytest.param("icarus", LANES, marks=needs_icarus),
    pytest.param("verilator", 4, marks=needs_verilator)])
def test_cocotb_resets_mid_run_equal_golden(simulator, lanes, tmp_path):
    """The ML msb camera of tests/test_cosim_stream.py's cocotb run (the same Verilog: one build)."""
    pytest.importorskip("cocotb")
    from tespike.cosim.cocotb_bench import Settings
    from tespike.cosim.cocotb_run import run_cocotb
    config = SensorConfig(mode="ml", ml_readout="msb", b1=2, b2=2)     # L = 12
    result = run_cocotb(Settings(config, *SHAPE, readouts=2, seed=3, lanes=lanes, resets="sweep"), simulator,
                        work_dir=tmp_path)
    assert result.passed, result.message
    assert '"segments": ' in result.message and '"resets": 0' not in result.message


def test_reset_without_a_reset_mid_run_is_the_plain_run(rng):
    """An all-low vector is one segment: the same words as the run without one."""
    from tespike.cosim.rtlsim import rtl_words
    config = CAMERAS[1]
    stim = rng.integers(0, 60, size=(2 * config.clocks_per_readout, 1, 2))
    got = rtl_words(config, stim, resets=np.zeros(len(stim), bool))
    assert len(got) == 1 and np.array_equal(got[0], reference_words(config, stim))


# -- planted reset faults ----------------------------------------------------------------------

def _timing_reset_removed(verilog: str, which: int) -> str:
    """The timing module's ``which``-th ``if (rst)`` (divider, CCC, then ``primed`` in the streaming
    top's ``_readout_timing``, the ``frame_valid`` register in the parallel top's ``_array_timing``)
    never taken."""
    start = re.search(r"_(readout|array)_timing\(", verilog).start()
    spots = [m.start() for m in re.finditer(r"if \(rst\) begin", verilog[start:])]
    at = start + spots[which]
    return verilog[:at] + "if (1'b0) begin" + verilog[at + len("if (rst) begin"):]


#: name -> (top, edit of the generated Verilog). Each edit passes the runs without a mid-run reset.
FAULTS = {
    "beat counter not cleared by rst": ("stream", lambda v: re.sub(
        r"if \(rst\) begin\n\s*sending <= 1'b0;\n\s*beat <= \d+'d0;\n\s*end else ", "", v)),
    "stream pixels cleared by rst, not the sampled reset": (
        "stream", lambda v: v.replace("wire clear = rst_sample;", "wire clear = rst;")),
    "pixels cleared one edge after rst": ("parallel", lambda v: v.replace("  wire last;", (
        "  wire last;\n  reg rst_late = 1'b0;\n  always @(posedge clk) rst_late <= rst;"), 1)
        .replace(".clear(rst)", ".clear(rst_late)")),
    "CCC not cleared by rst": ("stream", lambda v: _timing_reset_removed(v, 1)),
    "CCC not cleared by rst (parallel)": ("parallel", lambda v: _timing_reset_removed(v, 1)),
    "frame_valid not cleared by rst": ("parallel", lambda v: _timing_reset_removed(v, 2)),
}


@needs_icarus
@pytest.mark.parametrize("fault", FAULTS)
def test_planted_reset_faults_are_caught(fault):
    from tespike.cosim.icarus import run_icarus, run_icarus_stream
    from tespike.rtl.verilog import array_verilog
    from tespike.rtl.verilog_stream import stream_array_verilog
    config = CAMERAS[0]
    top, edit = FAULTS[fault]
    good = (stream_array_verilog(config, *SHAPE, LANES) if top == "stream" else array_verilog(config, *SHAPE))
    bad = edit(good)
    assert bad != good, f"the edit {fault!r} no longer applies to the generated Verilog: update FAULTS"
    stim, resets = sweep(config)
    try:
        if top == "stream":
            got = run_icarus_stream(config, stim, LANES, verilog=bad, resets=resets)
        else:
            got = run_icarus(config, stim, verilog=bad, resets=resets)
    except SimulatorRunError:
        return                                             # caught by the reset-state / timing rules
    assert first_segment_difference(got, golden_segments(config, stim, resets, LANES if top == "stream"
                                                         else None)) is not None, fault


@needs_icarus
def test_the_two_reviewed_faults_pass_a_run_without_reset():
    """Why the reset runs exist: both edits of the issue pass today's reset-once check."""
    from tespike.cosim.icarus import run_icarus_stream
    from tespike.rtl.verilog_stream import stream_array_verilog
    config = CAMERAS[0]
    stim = sweep(config)[0][:3 * config.clocks_per_readout]
    words = reference_words(config, stim)
    for fault in ("beat counter not cleared by rst", "stream pixels cleared by rst, not the sampled reset"):
        bad = FAULTS[fault][1](stream_array_verilog(config, *SHAPE, LANES))
        assert np.array_equal(run_icarus_stream(config, stim, LANES, verilog=bad), beats(words, LANES))


@needs_icarus
def test_cocotb_command_resets_mid_run(tmp_path):
    """``tespike cocotb --resets sweep``, and one-line refusals of a reset file that does not fit."""
    pytest.importorskip("cocotb")
    from tests.cli import assert_refused, run_tespike
    (tmp_path / "c.json").write_text('{"mode": "ml", "ml_readout": "msb", "b1": 2, "b2": 2}')
    common = ["cocotb", "--config", tmp_path / "c.json", "--height", 2, "--width", 3, "--simulator", "icarus",
              "--readouts", 2]
    result = run_tespike(*common, "--lanes", 4, "--resets", "sweep")
    assert result.returncode == 0, result.stdout + result.stderr
    assert '"segments": 26' in result.stdout and '"resets": 25' in result.stdout
    np.save(tmp_path / "r.npy", np.zeros(5, bool))
    assert_refused(run_tespike(*common, "--resets", tmp_path / "r.npy"), "reset vector", "(24,)")
    assert_refused(run_tespike(*common, "--resets", tmp_path / "none.npy"), "none.npy")


def test_the_reset_helpers_and_the_save_file_writer_refuse_in_one_line(tmp_path):
    """(A preset's name had been an AttributeError; a missing waveform a FileNotFoundError traceback,
    and nothing is written.)"""
    from tespike.cosim.vcd import write_gtkw
    from tespike.golden.errors import ConfigError
    for call, name in ((lambda: golden_segments("te", np.zeros((240, 1, 1), np.int64), None), "golden_segments"),
                       (lambda: reset_sweep("te", np.random.default_rng(1)), "reset_sweep"),
                       (lambda: write_gtkw(tmp_path / "W.gtkw", tmp_path / "W.vcd", "te"), "write_gtkw")):
        with pytest.raises(ConfigError, match=f"^{name}: configuration must be a SensorConfig"):
            call()
    with pytest.raises(InputError, match="^waveform file .*W.vcd' does not exist$"):
        write_gtkw(tmp_path / "W.gtkw", tmp_path / "W.vcd", SensorConfig())
    assert not list(tmp_path.iterdir())


def test_reset_sweep_and_rtl_run_refuse_arguments_that_are_none_in_one_line():
    """``reset_sweep(config, 0)`` was an AttributeError of ``permutation`` and ``tail_readouts=-1`` a
    vector of no whole interval; rtl_run's ``reset_charge=2.5`` was Amaranth's TypeError, ``progress='no'``
    showed a bar and a save file without a waveform was a plain ValueError."""
    from tespike.cosim.rtlsim import rtl_run
    config = SensorConfig()
    for rng in (0, None):
        with pytest.raises(InputError, match="^reset_sweep rng: must be a numpy Generator"):
            reset_sweep(config, rng)
    for options in ({"tail_readouts": -1}, {"tail_readouts": 2.5}, {"beats": 0}):
        (name, value), = options.items()
        with pytest.raises(InputError, match=f"^reset_sweep {name} = {value!r}: must be an integer >= "):
            reset_sweep(config, np.random.default_rng(0), **options)
    stimulus = np.zeros((config.clocks_per_readout, 1, 2), np.uint16)
    for charge in (2.5, "x", -1, 1 << 32):
        with pytest.raises(InputError, match=rf"^reset_charge {charge!r}: must be an integer in 0 \.\. 2\^32 - 1"):
            rtl_run(config, stimulus, reset_charge=charge)
    with pytest.raises(InputError, match="^progress = 'no': must be None"):
        rtl_run(config, stimulus, progress="no")
    with pytest.raises(InputError, match=r"^a GTKWave save file \(gtkw_path\) needs a waveform \(vcd_path\)$"):
        rtl_run(config, stimulus, gtkw_path="w.gtkw")
