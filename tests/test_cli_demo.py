"""``tespike demo``: the README's main job, with its defaults, end to end."""

import numpy as np

from cosim.cli import main
from golden.io import load_scene, load_stream
from tests.cli import run_tespike


def run_here(capsys, *args):
    """The command in this process (no interpreter start-up): (exit code, stdout, stderr)."""
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_demo_with_defaults(tmp_path):
    result = run_tespike("demo", "--out", tmp_path / "demo")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    out = tmp_path / "demo"
    for name in ("TFP_ML", "TFI_ML", "TFP_TE", "TFI_TE", "TFP_ML-count", "TFI_ML-count"):
        assert f"| {name} |" in result.stdout
    light = load_scene(out / "I.npy")
    assert light.shape == (32, 96, 128) and light.max() == 1.0
    for mode in ("te", "ml", "ml-msb"):
        words, config = load_stream(out / f"S_{mode}.npz")
        assert config.mode == mode.split("-")[0] and config.is_msb == (mode == "ml-msb")
        assert words.shape == light.shape
        for method in ("tfp", "tfi"):
            images = np.load(out / f"R_{method}_{mode}.npy")
            assert images.shape == light.shape and images.dtype == np.float32
    assert (out / "table.md").read_text(encoding="utf-8").count("\n") == 6
    assert (out / "strips" / "default.png").read_bytes()[:4] == b"\x89PNG"
    assert not list(out.rglob("*.part"))


def test_demo_is_deterministic_and_sized(tmp_path, capsys):
    args = ("demo", "--frames", 10, "--height", 24, "--width", 40, "--seed", 2)
    assert run_here(capsys, *args, "--out", tmp_path / "a")[0] == 0
    assert run_here(capsys, *args, "--out", tmp_path / "b")[0] == 0
    for name in ("I.npy", "R_tfi_te.npy"):
        a, b = np.load(tmp_path / "a" / name), np.load(tmp_path / "b" / name)
        assert a.shape[0] == 10 and np.array_equal(a, b)
    assert (tmp_path / "a" / "table.csv").read_text().splitlines()[1:] != []


def test_demo_refuses_bad_sizes(tmp_path, capsys):
    code, _, err = run_here(capsys, "demo", "--frames", 0, "--out", tmp_path / "d")
    assert code == 2 and "frames" in err and len(err.strip().splitlines()) == 1
