"""``tespike evaluate`` as a user runs it."""

import csv
import os
import shutil

import numpy as np

from tespike.cosim.cli import main
from tespike.recon.scenes import make_scene


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
    rows = list(csv.DictReader((tmp_path / "ev" / "results.csv").read_text().splitlines()))
    assert sorted({r["sequence"] for r in rows}) == ["default", "mine"] and len(rows) == 6
    assert sorted({r["sensor"] for r in rows}) == ["ml", "ml-msb", "te"]
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
    refused(capsys, "evaluate", "--sensor-seed", 3, "--out", out, "--sensor-seed")     # no noise sensor: ignored
    np.save(tmp_path / "a.npy", np.full((4, 8, 8), 0.3, np.float32))
    (tmp_path / "b.npy").symlink_to(tmp_path / "a.npy")                                  # (scored twice, in the means)
    refused(capsys, "evaluate", "--set", "none", "--scene", tmp_path / "a.npy", "--scene", tmp_path / "b.npy",
            "--out", out, "is the same file as --scene")
    assert not out.exists()


def test_a_run_into_a_new_folder_keeps_another_runs_results_written_meanwhile(tmp_path, capsys, monkeypatch):
    """Two evaluations into one new --out, neither with --force: both passed the check at their start,
    and the later one replaced the other's finished results without a word."""
    import tespike.recon.report as report
    np.save(tmp_path / "a.npy", np.full((4, 16, 16), 0.3, np.float32))
    out, real = tmp_path / "ev", report.write_outputs

    def another_run_finishes_meanwhile(evaluation, folder, **kwargs):
        out.mkdir()
        (out / "table.md").write_text("the other run's")
        return real(evaluation, folder, **kwargs)
    monkeypatch.setattr(report, "write_outputs", another_run_finishes_meanwhile)
    args = ("evaluate", "--set", "none", "--scene", tmp_path / "a.npy", "--methods", "tfp", "--repeats", 1, "--progress",
            "off", "--out", out)
    refused(capsys, *args, "was filled by another run while this one ran")
    assert (out / "table.md").read_text() == "the other run's" and os.listdir(out) == ["table.md"]
    assert not [name for name in os.listdir(tmp_path) if name.endswith(".part")]
    shutil.rmtree(out)                                   # with --force, the run replaces it
    code, _, err = run_here(capsys, *args, "--force")
    assert code == 0, err
    assert (out / "table.md").read_text() != "the other run's"


def test_evaluate_without_the_count_camera(tmp_path, capsys):
    (tmp_path / "msb.json").write_text('{"mode": "ml", "ml_readout": "msb", "ml_bits": 6}')
    code, stdout, stderr = run_here(capsys, "evaluate", "--set", "default", "--frames", 10, "--height", 16,
                                    "--width", 16, "--methods", "tfi", "--ml-count-config", "none",
                                    "--ml-config", tmp_path / "msb.json", "--out", tmp_path / "ev")
    assert code == 0, stderr
    assert "| TFI_ML |" in stdout and "ML-count" not in stdout
    rows = list(csv.DictReader((tmp_path / "ev" / "results.csv").read_text().splitlines()))
    assert sorted(r["sensor"] for r in rows) == ["ml-msb", "te"]


def test_evaluate_table(tmp_path, capsys, empty_weights_dir):
    """--table: the paper's rows and every metric column, ML (msb) left and TE right, no ML-count rows,
    complexity with Table 10 beside; a method without weights says so instead of failing the table."""
    import torch

    import tespike.recon.learned
    from tespike import recon
    from tespike.golden.config import SensorConfig
    from tespike.recon.learning.weights import save_weights
    folder = empty_weights_dir
    torch.manual_seed(0)
    module, sizes = recon.learned.method_classes("bsf")
    save_weights(folder / "bsf-te.pt", module(sizes.preset("cpu")).eval(), SensorConfig.preset("te"), {}, "bsf")
    code, stdout, stderr = run_here(capsys, "evaluate", "--table", "--set", "default", "--frames", 10, "--height", 24,
                                    "--width", 24, "--methods", "tfp,bsf", "--vdp-frames", 1, "--out", tmp_path / "ev")
    assert code == 0, stderr
    lines = stdout.splitlines()
    assert lines[0].startswith("| ML reconstruction | PSNR-μ ↑ | SSIM-μ ↑ | PU21-PSNR (dB) ↑ | HDR-VQM ↓ | "
                               "FovVideoVDP (JOD) ↑ | ms / frame ↓ (median of 1, ")
    assert "| TE reconstruction |" in lines[0] and "| paper: parameters |" in lines[0]
    assert lines[3].startswith("| BSF_ML | no weights |") and "| BSF_TE | " in lines[3]
    assert lines[3].endswith("| 2.071 M | 0.887 T | 0.231 |") and "ML-count" not in stdout
    assert "bsf-ml-msb.pt' is missing" in stdout and "FovVideoVDP (JOD, HDR display" in stdout
    for name in ("table.md", "table.csv", "results.csv", "quality_vs_time.png"):
        assert (tmp_path / "ev" / name).is_file()
    rows = list(csv.DictReader((tmp_path / "ev" / "results.csv").read_text().splitlines()))
    assert {(r["method"], r["sensor"]) for r in rows} == {("tfp", "ml-msb"), ("tfp", "te"), ("bsf", "te")}
    assert all(float(r["hdr_vqm"]) >= 0 and r["frames_vdp"] == "1" for r in rows)


def test_evaluate_noise_tables(tmp_path, capsys):
    code, stdout, stderr = run_here(capsys, "evaluate", "--noise", "--set", "default", "--frames", 10,
                                    "--height", 24, "--width", 24, "--methods", "tfp", "--out", tmp_path / "ev")
    assert code == 0, stderr
    assert "| TE reconstruction | PSNR-μ ↑ (shot noise only) |" in stdout and "(dark current eq. 13)" in stdout
    rows = list(csv.DictReader((tmp_path / "ev" / "results.csv").read_text().splitlines()))
    assert sorted(r["sensor"] for r in rows) == ["ml", "ml-msb", "te", "te+eq12", "te+eq13"]


def test_evaluate_sensor_noise_and_calibrate(tmp_path, capsys):
    """--sensor-noise adds a noise sensor named by the file, --calibrate its +cal rows; one line each refusal."""
    (tmp_path / "hot.json").write_text('{"dark_current": "eq12", "dark_level": 2.0, "dsnu": 0.3}')
    code, stdout, stderr = run_here(capsys, "evaluate", "--sensor-noise", tmp_path / "hot.json", "--calibrate",
                                    "--sensor-seed", 4, "--set", "default", "--frames", 10, "--height", 24,
                                    "--width", 24, "--methods", "tfp", "--ml-count-config", "none",
                                    "--out", tmp_path / "ev")
    assert code == 0, stderr
    assert "(dark_current eq12, dark_level 2, dsnu 0.3)" in stdout and "| TFP_TE (calibrated) | - | - |" in stdout
    rows = list(csv.DictReader((tmp_path / "ev" / "results.csv").read_text().splitlines()))
    assert [r["sensor"] for r in rows] == ["ml-msb", "te", "te+hot", "te+hot+cal"]
    out = tmp_path / "refused"
    refused(capsys, "evaluate", "--calibrate", "--out", out, "--calibrate needs a noise sensor")
    refused(capsys, "evaluate", "--sensor-seed", -1, "--out", out, "--sensor-seed -1")
    # the paper's dark currents have no per-pixel maps: seeds 0 and 5 gave the same table
    refused(capsys, "evaluate", "--noise", "--sensor-seed", 5, "--out", out, "none has any")
    (tmp_path / "eq12.json").write_text("{}")
    refused(capsys, "evaluate", "--sensor-noise", tmp_path / "eq12.json", "--out", out, "'te+eq12' is reserved for --noise's built-in sensors")
    (tmp_path / "none.json").write_text("{}")             # (a column labelled '()', the TE camera's again)
    refused(capsys, "evaluate", "--sensor-noise", tmp_path / "none.json", "--out", out, "no non-ideality")
    (tmp_path / "again.json").write_text((tmp_path / "hot.json").read_text())
    refused(capsys, "evaluate", "--sensor-noise", tmp_path / "hot.json", "--sensor-noise", tmp_path / "again.json",
            "--out", out, "the same sensor noise as 'te+hot'")
    refused(capsys, "evaluate", "--sensor-noise", tmp_path / "hot.json", "--store", tmp_path, "--out", out,
            "--sensor-noise does not apply with --store")
    # two scene files of one stem ("sequence labels must be unique, got ['I', 'I']" named neither)
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        np.save(tmp_path / folder / "I.npy", make_scene("lights", 4, 16, 16, seed=1))
    refused(capsys, "evaluate", "--set", "none", "--scene", tmp_path / "a" / "I.npy", "--scene",
            tmp_path / "b" / "I.npy", "--methods", "tfp", "--out", out, "/b/I.npy' and --scene")
    # a dark current beyond the sensor's range: no calibration; the refusal names the sensor (it named
    # calibrate's --dark and --flat, flags this command does not have)
    (tmp_path / "sat.json").write_text('{"dark_current": "eq12", "dark_level": 1e6}')
    refused(capsys, "evaluate", "--sensor-noise", tmp_path / "sat.json", "--calibrate", "--set", "default",
            "--frames", 4, "--height", 16, "--width", 16, "--methods", "tfp", "--ml-count-config", "none",
            "--progress", "off", "--out", out, "calibrating noise sensor te+sat: the dark stream is saturated")
    assert not out.exists()


def test_evaluate_table_refuses(tmp_path, capsys, empty_weights_dir):   # no weights, whatever the checkout holds
    out = tmp_path / "ev"
    refused(capsys, "evaluate", "--table", "--vdp-frames", 0, "--out", out, "--vdp-frames 0")
    refused(capsys, "evaluate", "--metrics", "vdp3", "--out", out, "--metrics 'vdp3'")
    refused(capsys, "evaluate", "--table", "--frames", 0, "--out", out, "--frames 0")
    refused(capsys, "evaluate", "--table", "--threads", 0, "--out", out, "--threads 0")
    # options of a part the run lacks were dropped without a word (exit 0, the same results)
    refused(capsys, "evaluate", "--vdp-frames", 2, "--out", out, "add fovvideovdp to --metrics")
    for flag in ("--frames", "--height", "--width"):
        refused(capsys, "evaluate", "--set", "none", "--scene", "i.npy", flag, 5, "--out", out,
                f"{flag} sizes the built-in sequences of --set; with --set none")
    refused(capsys, "evaluate", "--table", "--store", tmp_path / "s.zarr", "--out", out, "--table does not apply")
    # every option --store does not take, the simulation's included, refused away from its default (one list)
    # (typed at its default value too: --set heldout was accepted where --ml-count-config ml was not)
    for flag, value in (("--seed", 3), ("--te-config", "ml"), ("--frames", 5), ("--set", "default"),
                        ("--ml-count-config", "none"), ("--scene", "i.npy"), ("--set", "heldout"),
                        ("--te-config", "te")):
        refused(capsys, "evaluate", flag, value, "--store", tmp_path / "s.zarr", "--out", out,
                f"{flag} does not apply with --store")
    refused(capsys, "evaluate", "--methods", "tfp,bsf", "--set", "default", "--frames", 4, "--height", 24, "--width", 24,
            "--out", out, "bsf-ml-msb.pt' is missing")
    assert not out.exists()


def test_table_frames_leave_ten_scored_frames_for_the_learned_methods():
    """--table's 70 frames are the learned methods' span plus nine: ten frames scored. A change of
    a network's span (its sizes) fails here rather than shrinking Table 1 without a word."""
    from tespike.cosim.commands.evaluate_cmd import TABLE_DEFAULTS
    from tespike.recon.evaluate import learned_span, scored_frames
    from tespike.recon.learned import LEARNED
    from tespike.recon.settings import DEFAULT_WINDOW
    scored = scored_frames(TABLE_DEFAULTS[0], DEFAULT_WINDOW, learned_span(list(LEARNED)))
    assert scored.stop - scored.start == 10, scored
