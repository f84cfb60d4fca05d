"""``tespike demo``: circuit to image on a small crop (the README's job, sized for a test)."""

import shutil

import numpy as np
import pytest

from tespike.cosim.cli import main
from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_words
from tespike.golden.errors import InputError
from tespike.golden.fastsim import simulate_scene
from tespike.golden.io import load_scene, load_stream
from tests.cli import run_tespike

#: A small demo: 10 readouts of 24 x 32, the RTL on 11 x 11 pixels for 3 readouts.
SMALL = ("--frames", 10, "--height", 24, "--width", 32, "--crop", 11, "--rtl-readouts", 3, "--repeats", 1)


def _golden_msb_ready() -> bool:
    """The fast simulator emits legal msb words (golden msb simulation, branch msb-golden)."""
    config = SensorConfig.preset("ml-msb")
    try:
        check_words(simulate_scene(config, np.full((2, 2, 2), 0.5), seed=0), config)
        return True
    except InputError:
        return False


def run_here(capsys, *args):
    """The command in this process (no interpreter start-up): (exit code, stdout, stderr)."""
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_small_demo_closes_the_loop(tmp_path):
    out = tmp_path / "demo"
    result = run_tespike("demo", *SMALL, "--sensors", "ml,te", "--no-hw-cost", "--out", out)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr and "[6/6]" in result.stderr      # progress shown
    assert "RTL: bit-identical" in result.stdout
    for name in ("TFP_ML-count", "TFI_ML-count", "TFP_TE", "TFI_TE"):
        assert f"| {name} |" in result.stdout
    light = load_scene(out / "I.npy")
    assert light.shape == (10, 24, 32) and light.max() == 1.0
    te, config = load_stream(out / "S_te.npz")
    rtl, rtl_config = load_stream(out / "S_rtl.npz")
    assert config == rtl_config == SensorConfig() and rtl.shape == (3, 11, 11)
    report = (out / "report.md").read_text(encoding="utf-8")
    y, x = (int(v) for v in report.split("crop: rows ")[1].split(",")[0].split("..")[0:1] +
            report.split("columns ")[1].split("..")[0:1])
    assert np.array_equal(rtl, te[:3, y:y + 11, x:x + 11])          # the RTL crop is the full frame's
    assert np.load(out / "E_crop.npy").shape == (3 * 240, 11, 11)
    assert (out / "verdict.txt").read_text().startswith("bit-identical")
    gtkw = (out / "W.gtkw").read_text()
    assert "[timestart]" in gtkw and '[dumpfile] "W.vcd"' in gtkw      # relative to the save file
    for section in ("## Configuration", "## RTL against the golden model", "## Dynamic range",
                    "## Hardware cost", "## Run time of every stage", "## Rerun each step"):
        assert section in report, section
    assert "tespike rtl-sim --config te --stimulus E_crop.npy" in report and "PSNR-μ" in report
    # the methods run are named as what they are (it said "every one of the registry" without the baselines)
    methods = report.split("Methods: ")[1].split("\n")[0]
    assert "with weights for every sensor here: tfp, tfi" in methods and "(not " in methods and "bsf" in methods
    for method in ("tfp", "tfi"):
        for mode in ("ml", "te", "rtl"):
            assert np.load(out / f"R_{method}_{mode}.npy").dtype == np.float32
    for png in ("frame.png", "rtl_crop.png", "quality_vs_time.png", "strips/default.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG", png
    assert not list(out.rglob("*.part")) and not list(out.rglob(".*"))


@pytest.mark.skipif(not _golden_msb_ready(), reason="golden msb simulation not in this checkout yet")
def test_demo_with_every_sensor_and_the_hardware_cost(tmp_path, capsys):
    code, out, err = run_here(capsys, "demo", *SMALL, "--quiet", "--out", tmp_path / "d")
    assert code == 0, err
    assert out == ""                                        # (--quiet printed the verdict and wrote-lines)
    report = (tmp_path / "d" / "report.md").read_text(encoding="utf-8")
    assert "| TFP_ML |" in report and "| TFP_ML-count |" in report and "| ml-msb |" in report
    assert "| te | " in report.split("## Hardware cost")[1]
    assert load_stream(tmp_path / "d" / "S_ml-msb.npz")[1].is_msb


def test_demo_reports_the_first_difference(tmp_path, capsys, monkeypatch):
    """A wrong word rebuilt from the waveform: exit 1, the verdict names readout, pixel and words."""
    import tespike.cosim.vcd
    from tespike import cosim
    real = cosim.vcd.waveform_words

    def broken(*args, **kwargs):
        wave = real(*args, **kwargs)
        wave.words[1, 2, 3] ^= 1
        return wave

    monkeypatch.setattr(cosim.vcd, "waveform_words", broken)
    code, out, err = run_here(capsys, "demo", *SMALL, "--sensors", "te", "--no-hw-cost", "--quiet",
                              "--out", tmp_path / "d")
    assert code == 1
    verdict = (tmp_path / "d" / "verdict.txt").read_text()
    assert verdict.startswith("DIFFERENT: 1 of 363 words differ; first at readout 1, crop pixel (2, 3)")
    assert "RTL word" in verdict and "golden word" in verdict and verdict.strip() in err and out == ""


@pytest.mark.skipif(shutil.which("iverilog") is None, reason="Icarus Verilog not installed")
def test_demo_on_the_generated_verilog(tmp_path, capsys):
    code, out, err = run_here(capsys, "demo", *SMALL, "--sensors", "te", "--no-hw-cost", "--quiet",
                              "--backend", "icarus", "--out", tmp_path / "d")
    assert code == 0, err
    assert "bit-identical: icarus RTL == golden model" in (tmp_path / "d" / "verdict.txt").read_text()
    assert not (tmp_path / "d" / "W.vcd").exists()
    assert "--backend icarus" in (tmp_path / "d" / "report.md").read_text(encoding="utf-8")


def test_demo_is_deterministic(tmp_path, capsys):
    args = ("demo", *SMALL, "--sensors", "te", "--no-hw-cost", "--quiet", "--seed", 2)
    assert run_here(capsys, *args, "--out", tmp_path / "a")[0] == 0
    assert run_here(capsys, *args, "--out", tmp_path / "b")[0] == 0
    for name in ("I.npy", "R_tfi_te.npy", "E_crop.npy", "R_tfp_rtl.npy"):
        assert np.array_equal(np.load(tmp_path / "a" / name), np.load(tmp_path / "b" / name)), name


@pytest.mark.parametrize("args, word", [(("--frames", 0), "--frames"), (("--crop", 40), "--crop"), (("--crop", 10), "--crop"),
                                        (("--rtl-readouts", 11), "--rtl-readouts"),
                                        (("--sensors", "ml"), "--sensors"), (("--sensors", "te,xx"), "--sensors")])
def test_demo_refuses_bad_options(tmp_path, capsys, args, word):
    given = dict(zip(SMALL[::2], SMALL[1::2]))
    given.update(zip(args[::2], args[1::2]))         # (an option given twice is refused on its own)
    code, _, err = run_here(capsys, "demo", *(item for pair in given.items() for item in pair),
                            "--out", tmp_path / "d")
    assert code == 2 and word in err and len(err.strip().splitlines()) == 1


def test_demo_refuses_weights_for_none_of_its_sensors(tmp_path, capsys):
    """--weights: a file trained for no sensor of the demo is refused before any work."""
    import torch

    from tespike.golden.config import SensorConfig
    from tespike.recon.learned import method_classes
    from tespike.recon.learning.weights import save_weights
    torch.manual_seed(0)
    module, sizes = method_classes("bsf")
    save_weights(tmp_path / "w.pt", module(sizes.preset("cpu")), SensorConfig(b1=3, b2=3), {}, "bsf")
    code, _, err = run_here(capsys, "demo", *SMALL, "--weights", tmp_path / "w.pt", "--out", tmp_path / "d")
    assert code == 2 and "none of the sensors" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()


def test_an_interrupted_demo_leaves_the_previous_demo_whole(tmp_path, capsys, monkeypatch):
    """The demo fills a temporary folder and swaps it in when done: stopped at its fifth stage it left the
    previous demo's folder holding the new run's scene and streams beside the old report (two runs mixed)."""
    import os

    import tespike.cosim.demo as demo
    from tests.test_cli_hardening import snapshot
    args = ("demo", *SMALL, "--sensors", "te", "--no-hw-cost", "--quiet", "--out", tmp_path / "d")
    assert run_here(capsys, *args)[0] == 0
    before = snapshot(tmp_path)

    def stopped(*_, **__):
        raise KeyboardInterrupt
    monkeypatch.setattr(demo, "dynamic_ranges", stopped)
    code, _, err = run_here(capsys, *args[:-4], "--seed", 5, "--quiet", "--out", tmp_path / "d")
    assert code == 130 and err.strip() == "tespike demo: interrupted", err
    assert snapshot(tmp_path) == before                                 # untouched, no temporary
    (tmp_path / "d" / "notes.txt").write_text("mine")                   # replacing would delete it: refused
    code, _, err = run_here(capsys, *args)
    assert code == 2 and "'notes.txt'" in err and "new or empty folder" in err
    assert sorted(os.listdir(tmp_path)) == ["d"]


def test_the_crop_and_hardware_helpers_refuse_what_they_cannot_use_in_one_line(rng):
    """A crop larger than the frame had a negative corner; a list of sensor names an AttributeError."""
    from tespike.cosim.demo import choose_crop, hardware_cost
    light = rng.random((3, 8, 10))
    light[:, 7, 9] = 5.0                                   # the brightest pixel, in a corner: the crop stays inside
    assert choose_crop(light, 4) == (4, 6) and choose_crop(light, 8) == (0, 2)
    for size in (9, 0, 2.5):
        with pytest.raises(InputError, match=f"^choose_crop: crop {size!r} must be an integer from 1 to the frame's 8$"):
            choose_crop(light, size)
    with pytest.raises(InputError, match=r"^choose_crop: the light must be a non-empty \(K, H, W\) sequence"):
        choose_crop(light[0], 2)
    for configs in (["te"], {"te": "te"}):
        with pytest.raises(InputError, match="^hardware_cost: the sensors must be a dict of name -> SensorConfig"):
            hardware_cost(configs)
