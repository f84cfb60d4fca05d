"""``tespike evaluate`` as a user runs it."""

import csv

import numpy as np

from cosim.cli import main
from recon.scenes import make_scene


def run_here(capsys, *args):
    """The command in this process (no interpreter start-up): (exit code, stdout, stderr)."""
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def refused(capsys, *args_and_words):
    *args, word = args_and_words
    code, _, err = run_here(capsys, *args)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and word in lines[0], err


def test_evaluate_user_scene_and_builtin_set(tmp_path, capsys):
    np.save(tmp_path / "mine.npy", make_scene("lights", 10, 24, 32, seed=9))
    code, stdout, stderr = run_here(capsys, "evaluate", "--set", "default", "--frames", 10, "--height", 24, "--width", 32,
                         "--scene", tmp_path / "mine.npy", "--methods", "tfp", "--out", tmp_path / "ev")
    assert code == 0, stderr
    assert "| TFP_ML |" in stdout and "| TFP_TE |" in stdout and "| TFP_ML-count |" in stdout
    rows = list(csv.DictReader(open(tmp_path / "ev" / "results.csv")))
    assert sorted({r["sequence"] for r in rows}) == ["default", "mine"] and len(rows) == 6
    assert sorted({r["mode"] for r in rows}) == ["ml", "ml-msb", "te"]
    assert (tmp_path / "ev" / "strips" / "mine.png").is_file()
    assert not list((tmp_path / "ev").rglob("*.part"))


def test_evaluate_refuses(tmp_path, capsys):
    out = tmp_path / "ev"
    refused(capsys, "evaluate", "--set", "training", "--out", out, "training")
    refused(capsys, "evaluate", "--set", "none", "--out", out, "nothing to evaluate")
    refused(capsys, "evaluate", "--set", "default", "--methods", "magic", "--out", out, "magic")
    refused(capsys, "evaluate", "--te-config", "ml", "--out", out, "te-config")
    refused(capsys, "evaluate", "--ml-config", "ml", "--out", out, "ml_readout 'count'")
    refused(capsys, "evaluate", "--ml-count-config", "ml-msb", "--out", out, "--ml-count-config")
    refused(capsys, "evaluate", "--set", "none", "--scene", tmp_path / "no.npy", "--out", out, "no.npy")
    assert not out.exists()


def test_evaluate_without_the_count_camera(tmp_path, capsys):
    (tmp_path / "msb.json").write_text('{"mode": "ml", "ml_readout": "msb", "ml_bits": 6}')
    code, stdout, stderr = run_here(capsys, "evaluate", "--set", "default", "--frames", 10, "--height", 16,
                                    "--width", 16, "--methods", "tfi", "--ml-count-config", "none",
                                    "--ml-config", tmp_path / "msb.json", "--out", tmp_path / "ev")
    assert code == 0, stderr
    assert "| TFI_ML |" in stdout and "ML-count" not in stdout
    rows = list(csv.DictReader(open(tmp_path / "ev" / "results.csv")))
    assert sorted(r["mode"] for r in rows) == ["ml-msb", "te"]
