"""``tespike rtl-sim`` (SPEC section 6): the stream file, the waveform, and refusals of bad input."""

import json
import sys
import types

import numpy as np
import pytest

from tespike.cosim.cli import main
from tespike.cosim.vcd import waveform_words
from tespike.golden.config import SensorConfig
from tests.cli import assert_refused, run_tespike
from tests.cosim_helpers import golden_words, threshold_stimulus

CONFIG = {"b1": 2, "b2": 2, "threshold": 20}


def _inputs(tmp_path, rng, readouts=3, shape=(2, 3), dtype=np.int32):
    config = SensorConfig(**CONFIG)
    (tmp_path / "c.json").write_text(json.dumps(CONFIG))
    stim = threshold_stimulus(config, rng, readouts, *shape).astype(dtype)
    np.save(tmp_path / "e.npy", stim)
    return config, stim


def _leftovers(tmp_path, *names):
    return [p.name for p in tmp_path.iterdir() if any(p.name.lstrip(".").startswith(n) for n in names)]


def test_rtl_sim_writes_the_spec_stream(tmp_path, rng):
    config, stim = _inputs(tmp_path, rng, dtype=np.uint16)
    result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz")
    assert result.returncode == 0, result.stderr
    with np.load(tmp_path / "s.npz") as npz:
        assert set(npz.files) == {"words", "config"}
        assert np.array_equal(npz["words"], golden_words(config, stim))
        assert json.loads(str(npz["config"])) == config.to_dict()
    assert not _leftovers(tmp_path, "s.npz.")


def test_rtl_sim_preset_config(tmp_path, rng):
    config = SensorConfig(mode="ml")
    stim = threshold_stimulus(config, rng, 2, 1, 2)
    np.save(tmp_path / "e.npy", stim)
    result = run_tespike("rtl-sim", "--config", "ml", "--stimulus", tmp_path / "e.npy", "--out", tmp_path / "s.npz")
    assert result.returncode == 0, result.stderr
    with np.load(tmp_path / "s.npz") as npz:
        assert np.array_equal(npz["words"], golden_words(config, stim))


def test_rtl_sim_ml_msb_preset_with_vcd(tmp_path, rng):
    """``--config ml-msb``: the msb readout's stream, and the same words read back from the VCD."""
    config = SensorConfig.preset("ml-msb")
    stim = threshold_stimulus(config, rng, 3, 1, 2)
    np.save(tmp_path / "e.npy", stim)
    result = run_tespike("rtl-sim", "--config", "ml-msb", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--vcd", tmp_path / "w.vcd")
    assert result.returncode == 0, result.stderr
    with np.load(tmp_path / "s.npz") as npz:
        words = npz["words"]
        assert json.loads(str(npz["config"]))["ml_readout"] == "msb"
    assert np.array_equal(words, golden_words(config, stim)) and words.max() <= config.ml_bits
    assert np.array_equal(waveform_words(tmp_path / "w.vcd", config, (1, 2)).words, words)


def test_rtl_sim_vcd_and_gtkw(tmp_path, rng):
    config, stim = _inputs(tmp_path, rng, readouts=2, shape=(1, 2))
    result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--vcd", tmp_path / "w.vcd")
    assert result.returncode == 0, result.stderr
    with np.load(tmp_path / "s.npz") as npz:
        words = npz["words"]
    assert np.array_equal(waveform_words(tmp_path / "w.vcd", config, (1, 2)).words, words)
    assert "bench.top.array.px_0_0.acc" in (tmp_path / "w.gtkw").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.json", "e.npy", "s.npz", "w.gtkw", "w.vcd"]


@pytest.mark.parametrize("stimulus, words", [
    (np.zeros((24, 2, 2), np.float32), ["float"]),
    (np.zeros((24, 2, 2), bool), ["bool"]),
    (np.zeros((23, 2, 2), np.int32), ["23", "multiple"]),
    (np.full((24, 2, 2), -3, np.int32), ["-3"]),
    (np.full((24, 2, 2), 65536, np.int64), ["65536"]),
    (np.zeros((24, 4), np.int32), ["shape"]),
    (np.zeros((24, 0, 2), np.int32), ["shape"]),
])
def test_rtl_sim_refuses_bad_stimulus_without_output(tmp_path, stimulus, words):
    (tmp_path / "c.json").write_text(json.dumps(CONFIG))
    np.save(tmp_path / "e.npy", stimulus)
    result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--vcd", tmp_path / "w.vcd")
    assert_refused(result, *words)
    assert not _leftovers(tmp_path, "s.npz", "w.vcd", "w.gtkw")


@pytest.mark.parametrize("text, words", [
    ('{"b1": 4, "gain": 2}', ["'gain'"]),
    ('{"b1": 0}', ["'b1'", "0"]),
    ('{"b1": 4.0}', ["'b1'"]),
    ('[1, 2]', ["JSON object"]),
    ('{"b1": ', ["JSON"]),
])
def test_rtl_sim_refuses_bad_config(tmp_path, text, words):
    (tmp_path / "c.json").write_text(text)
    np.save(tmp_path / "e.npy", np.zeros((240, 1, 1), np.int32))
    result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz")
    assert_refused(result, *words)
    assert not _leftovers(tmp_path, "s.npz")


def test_rtl_sim_refuses_missing_files_and_directories(tmp_path, rng):
    _inputs(tmp_path, rng)
    base = ["rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy"]
    assert_refused(run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "no.npy",
                               "--out", tmp_path / "s.npz"), "no.npy", "does not exist")
    assert_refused(run_tespike(*base, "--out", tmp_path / "nodir" / "s.npz"), "--out", "nodir")
    assert_refused(run_tespike(*base, "--out", tmp_path / "s.npz", "--vcd", tmp_path / "nodir" / "w.vcd"),
                   "--vcd", "nodir")
    assert_refused(run_tespike(*base, "--out", tmp_path / "s.npz", "--gtkw", tmp_path / "w.gtkw"), "--gtkw")
    for nameless in (".", "/"):                          # (the save file's name made from it: a ValueError traceback)
        assert_refused(run_tespike(*base, "--out", tmp_path / "s.npz", "--vcd", nameless),
                       f"cannot write --vcd '{nameless}': it is a directory")
    assert_refused(run_tespike(*base, "--out", tmp_path / "s.npz", "--vcd", tmp_path / "w.vcd",
                               "--backend", "icarus"), "--vcd", "icarus")
    # the two progress options disagreeing: --no-progress won without a word
    assert_refused(run_tespike(*base, "--out", tmp_path / "s.npz", "--no-progress", "--progress", "on"),
                   "--no-progress and --progress on")
    assert not _leftovers(tmp_path, "s.npz", "w.vcd", "w.gtkw")


# -- in-process: refusals that need a patched RTL or backend ----------------

def _main(capsys, tmp_path, *extra):
    code = main(["rtl-sim", "--config", str(tmp_path / "c.json"), "--stimulus", str(tmp_path / "e.npy"),
                 "--out", str(tmp_path / "s.npz"), *map(str, extra)])
    return code, capsys.readouterr().err


def test_rtl_sim_refuses_a_config_the_rtl_cannot_build(monkeypatch, capsys, tmp_path, rng):
    import tespike.rtl.array
    from tespike import rtl
    _inputs(tmp_path, rng)

    def refusing(config, height, width, **kwargs):
        raise ValueError(f"{height} x {width} is too large for this process")

    monkeypatch.setattr(rtl.array, "PixelArray", refusing)
    code, err = _main(capsys, tmp_path, "--vcd", tmp_path / "w.vcd")
    assert code != 0 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "RTL cannot build" in err and "too large" in err
    assert not _leftovers(tmp_path, "s.npz", "w.vcd", "w.gtkw")


def test_rtl_sim_reports_a_broken_rtl_protocol_in_one_line(monkeypatch, capsys, tmp_path, rng):
    import tespike.rtl.array
    from tespike import rtl
    from tests.test_cosim_rtlsim import _delayed_array
    _inputs(tmp_path, rng)
    monkeypatch.setattr(rtl.array, "PixelArray", _delayed_array(12))       # latency 13 > L = 12
    code, err = _main(capsys, tmp_path, "--vcd", tmp_path / "w.vcd")
    assert code == 1 and len(err.strip().splitlines()) == 1 and "latency" in err
    assert not _leftovers(tmp_path, "s.npz", "w.vcd", "w.gtkw")


@pytest.mark.parametrize("backend, function", [("verilator", "run_verilator"), ("icarus", "run_icarus")])
def test_rtl_sim_hands_other_backends_the_stimulus(monkeypatch, capsys, tmp_path, rng, backend, function):
    config, stim = _inputs(tmp_path, rng)
    seen = {}

    def fake(cfg, stimulus, **kwargs):
        seen["args"] = (cfg, stimulus)
        return golden_words(cfg, stimulus)

    monkeypatch.setitem(sys.modules, f"tespike.cosim.{backend}", types.SimpleNamespace(**{function: fake}))
    code, err = _main(capsys, tmp_path, "--backend", backend)
    assert code == 0, err
    assert seen["args"][0] == config and np.array_equal(seen["args"][1], stim)
    with np.load(tmp_path / "s.npz") as npz:
        assert np.array_equal(npz["words"], golden_words(config, stim))


def test_rtl_sim_refuses_a_backend_result_of_the_wrong_shape(monkeypatch, capsys, tmp_path, rng):
    _inputs(tmp_path, rng)
    fake = types.SimpleNamespace(run_icarus=lambda cfg, stim, **kw: np.zeros((1, 1, 1), np.int64))
    monkeypatch.setitem(sys.modules, "tespike.cosim.icarus", fake)
    code, err = _main(capsys, tmp_path, "--backend", "icarus")
    assert code != 0 and "shape (1, 1, 1)" in err and len(err.strip().splitlines()) == 1
    assert not _leftovers(tmp_path, "s.npz")


def test_rtl_sim_names_a_missing_backend_module(monkeypatch, capsys, tmp_path, rng):
    from tespike.cosim import backends
    _inputs(tmp_path, rng)
    monkeypatch.setitem(backends.VERILOG_BACKENDS, "verilator", ("cosim._no_such_backend", "run_verilator"))
    code, err = _main(capsys, tmp_path, "--backend", "verilator")
    assert code != 0 and len(err.strip().splitlines()) == 1
    assert "'verilator' is not available" in err and "cosim._no_such_backend" in err


def test_rtl_sim_check_agrees_with_golden(tmp_path, rng):
    _inputs(tmp_path, rng)
    result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--check")
    assert result.returncode == 0, result.stderr
    assert "RTL == golden model for 3 readouts of 2 x 3 pixels" in result.stderr


def test_rtl_sim_check_names_the_first_difference(monkeypatch, capsys, tmp_path, rng):
    config, stim = _inputs(tmp_path, rng)
    wrong = golden_words(config, stim)
    wrong[1, 1, 2] = 1 if wrong[1, 1, 2] == 0 else 0     # still a legal word, not the golden one
    monkeypatch.setitem(sys.modules, "tespike.cosim.icarus", types.SimpleNamespace(run_icarus=lambda c, s, **k: wrong))
    code, err = _main(capsys, tmp_path, "--backend", "icarus", "--check")
    assert code == 1 and "1 of 18 words differ; first at readout 1, pixel (1, 2)" in err
    with np.load(tmp_path / "s.npz") as npz:
        assert np.array_equal(npz["words"], wrong)


def test_rtl_sim_icarus_backend_end_to_end(tmp_path, rng):
    """Runs once the verilator helper's cosim.icarus is merged (skipped before)."""
    pytest.importorskip("tespike.cosim.icarus")
    import shutil
    if shutil.which("iverilog") is None:
        pytest.skip("iverilog is not installed")
    config, stim = _inputs(tmp_path, rng, readouts=2, shape=(1, 2))
    result = run_tespike("rtl-sim", "--config", tmp_path / "c.json", "--stimulus", tmp_path / "e.npy",
                         "--out", tmp_path / "s.npz", "--backend", "icarus", "--check")
    assert result.returncode == 0, result.stderr
    with np.load(tmp_path / "s.npz") as npz:
        assert np.array_equal(npz["words"], golden_words(config, stim))


def test_a_run_stopped_between_its_outputs_leaves_the_previous_set_whole(tmp_path, rng, monkeypatch, capsys):
    """The VCD and save file were renamed into place when the simulation ended and the stream after:
    a stop between left the new waveform beside the previous run's stream."""
    from tespike.cosim.cli import main
    from tespike.golden import io

    _inputs(tmp_path, rng)
    args = ["rtl-sim", "--config", str(tmp_path / "c.json"), "--stimulus", str(tmp_path / "e.npy"),
            "--out", str(tmp_path / "s.npz"), "--vcd", str(tmp_path / "w.vcd"), "-q"]
    assert main(args) == 0
    before = {name: (tmp_path / name).read_bytes() for name in ("s.npz", "w.vcd", "w.gtkw")}
    np.save(tmp_path / "e.npy", np.load(tmp_path / "e.npy")[:12])    # another run: another waveform

    def stopped(*_, **__):
        raise KeyboardInterrupt
    monkeypatch.setattr(io, "save_stream", stopped)
    assert main(args) == 130
    capsys.readouterr()
    assert {name: (tmp_path / name).read_bytes() for name in before} == before
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")]


def test_first_difference_refuses_words_it_cannot_compare_in_one_line():
    """Arrays of two shapes were numpy's broadcast error, a list or None an unpacking error."""
    from tespike.cosim.compare import first_difference
    from tespike.golden.errors import InputError
    with pytest.raises(InputError, match=r"^RTL words \(1, 2, 2\) and golden words \(1, 2, 3\) differ in shape$"):
        first_difference(np.zeros((1, 2, 2), np.int64), np.zeros((1, 2, 3), np.int64))
    for rtl in (None, [1, 2], np.zeros((1, 2, 2))):
        with pytest.raises(InputError, match="^RTL words: must be an integer"):
            first_difference(rtl, np.zeros((1, 2, 2), np.int64))
    assert first_difference(np.zeros((1, 2, 2), np.int64), np.zeros((1, 2, 2), np.uint8)) is None
