"""What a user types, read as typed: an output's suffix names its format, a frame number is
decimal digits, a value that starts with '-' gets a hint, a window no frame can have is refused."""

import json

import numpy as np
import pytest

from tests.cli import assert_refused, run_tespike

TINY_JSON = json.dumps({"b1": 1, "b2": 1, "threshold": 3, "acc_bits": 3})       # L = 2


@pytest.fixture
def files(tmp_path):
    (tmp_path / "c.json").write_text(TINY_JSON)
    rng = np.random.default_rng(5)
    np.save(tmp_path / "e.npy", rng.integers(0, 6, size=(2 * 4, 3, 4)).astype(np.uint8))
    np.save(tmp_path / "i.npy", rng.uniform(0, 1, size=(4, 16, 16)).astype(np.float32))
    assert run_tespike("simulate", "--config", "te", "--scene", tmp_path / "i.npy", "--out", tmp_path / "s.npz",
                       "--seed", 1, "-q").returncode == 0
    return tmp_path


def output_cases(f):
    """(command line with OUT where the output goes, the suffix it must have)."""
    return [
        (("scene", "--name", "city", "--frames", 2, "--height", 8, "--width", 8, "--out", "OUT"), ".npy"),
        (("stimulus", "--config", "te", "--scene", f / "i.npy", "--out", "OUT"), ".npy"),
        (("simulate", "--config", "te", "--scene", f / "i.npy", "--out", "OUT"), ".npz"),
        (("golden", "--config", f / "c.json", "--stimulus", f / "e.npy", "--out", "OUT"), ".npz"),
        (("rtl-sim", "--config", f / "c.json", "--stimulus", f / "e.npy", "--out", "OUT"), ".npz"),
        (("reconstruct", "--stream", f / "s.npz", "--method", "tfp", "--out", "OUT"), ".npy"),
        (("calibrate", "--dark", f / "s.npz", "--flat", f / "s.npz", "--flat-light", 0.5, "--out", "OUT"), ".npz"),
        (("verilog", "--config", f / "c.json", "--height", 2, "--width", 2, "--out", "OUT"), ".v"),
        (("train", "--config", "te", "--steps", 1, "--out", "OUT"), ".pt"),
    ]


def test_an_output_named_for_another_format_is_refused_before_any_work(files):
    """``simulate --out S.png`` wrote a stream under a picture's name (and ``view`` reads by suffix)."""
    for args, suffix in output_cases(files):
        wrong = files / "out.png"
        result = run_tespike(*(wrong if a == "OUT" else a for a in args))
        assert_refused(result, "--out", "out.png", f"ending in {suffix}")
        assert not wrong.exists()


def test_the_format_suffix_is_read_in_any_case_and_devices_take_any_name(files):
    result = run_tespike("simulate", "--config", "te", "--scene", files / "i.npy", "--out", files / "S.NPZ", "-q")
    assert result.returncode == 0 and (files / "S.NPZ").is_file(), result.stderr
    result = run_tespike("simulate", "--config", "te", "--scene", files / "i.npy", "--out", "/dev/null", "-q")
    assert result.returncode == 0, result.stderr


def test_rtl_sim_waveform_files_are_named_for_their_format(files):
    base = ("rtl-sim", "--config", files / "c.json", "--stimulus", files / "e.npy", "--out", files / "w.npz")
    assert_refused(run_tespike(*base, "--vcd", files / "w.txt"), "--vcd", "ending in .vcd")
    assert_refused(run_tespike(*base, "--vcd", files / "w.vcd", "--gtkw", files / "w.sav"), "--gtkw", "ending in .gtkw")
    assert not (files / "w.npz").exists()


@pytest.mark.parametrize("spec", ["1_0:3", "\u0661:3", "0:\u0663"])
def test_a_frame_number_is_decimal_digits(files, spec):
    """Python's int reads ``1_0`` as 10 and Arabic-Indic digits as theirs: a frame range refuses both."""
    assert_refused(run_tespike("score", "--estimate", files / "i.npy", "--reference", files / "i.npy",
                               "--frames", spec), "--frames", "integers")
    assert_refused(run_tespike("view", "--input", files / "i.npy", "--frames", spec.replace(":", ","),
                               "--out", files / "v.png"), "--frames", "integers")


@pytest.mark.parametrize("value", ["1_0", "\u0664", "\u00b2"])          # 10, an Arabic-Indic 4, a superscript 2
def test_crops_and_sizes_are_decimal_digits(files, value):
    """``--crop`` and ``--sizes`` read their numbers themselves: as strictly as integer options
    (a superscript passed ``str.isdigit`` and then failed ``int`` in a traceback)."""
    assert_refused(run_tespike("stimulus", "--config", "te", "--scene", files / "i.npy", "--crop", f"0,0,{value},4",
                               "--out", files / "o.npy"), "--crop", "integers")
    assert_refused(run_tespike("scene", "--folder", files, "--crop", f"{value}x4", "--out", files / "o.npy"),
                   "--crop", "HxW")
    assert_refused(run_tespike("prove", "--sizes", f"{value}x1"), "--sizes", "HxW")
    assert not (files / "o.npy").exists()


def test_a_value_read_as_an_option_is_named_with_the_form_that_passes_it(files):
    result = run_tespike("score", "--estimate", files / "i.npy", "--reference", files / "i.npy", "--frames", "-1:")
    assert_refused(result, "--frames", "'-1:' was read as an option", "--frames=-1:")
    result = run_tespike("score", "--estimate", files / "i.npy", "--reference", files / "i.npy", "--frames=-1:")
    assert_refused(result, "--frames", "0 <= a < b")
    assert_refused(run_tespike("simulate", "--config", "te", "--scene", files / "i.npy", "--out"),
                   "--out", "expected one argument")


def test_evaluate_refuses_a_window_no_frame_of_its_shortest_sequence_can_have(files):
    """Reconstruct refused ``--window`` wider than ``2 K - 1``; evaluate took 99999 as the whole sequence."""
    base = ("evaluate", "--set", "none", "--scene", files / "i.npy", "--methods", "tfp")
    assert_refused(run_tespike(*base, "--window", 99999, "--out", files / "ev"), "--window 99999", "'i'", "7 readouts")
    assert not (files / "ev").exists()
    result = run_tespike(*base, "--window", 7, "--out", files / "ev", "-q")
    assert result.returncode == 0 and (files / "ev" / "table.md").is_file(), result.stderr
