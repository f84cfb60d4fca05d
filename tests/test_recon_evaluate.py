"""Evaluation harness: frame selection, tone map, Table 1 writers, an end-to-end small run."""

import csv
import io

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.fastsim import simulate_scene
from tespike.recon.evaluate import Evaluation, Measurement, evaluate, metric_subset, paper_configs, scored_frames
from tespike.recon.names import label
from tespike.recon.report import results_csv, table_csv, table_markdown, write_outputs
from tespike.recon.mulaw import tone_map
from tespike.recon.metrics import psnr_mu, ssim_mu
from tespike.recon.scenes import make_scene


def simulate(config, light, rng):
    return simulate_scene(config, light, seed=rng)


def test_scored_frames_skip_incomplete_windows():
    assert scored_frames(24, 9) == slice(4, 20)
    assert scored_frames(70, 9, 61) == slice(30, 40)          # a learned method's span inside too
    assert scored_frames(61, 9, 61) == slice(30, 31)
    assert scored_frames(60, 9, 61) == slice(4, 56)           # shorter than the span: the window's rule
    assert scored_frames(9, 9) == slice(4, 5)
    assert scored_frames(8, 9) == slice(0, 8)
    assert scored_frames(5, 1) == slice(0, 5)
    for bad in ((-3, 9), (24, 0), (24, 9, 0), (24.0, 9), (24, 9, 2.5), (True, 9)):   # (-3 had given slice(0, -3))
        with pytest.raises(InputError, match=r"^scored_frames\(.*\): frames must be an integer >= 0"):
            scored_frames(*bad)
    assert metric_subset(10, 4) == slice(3, 7) and metric_subset(10, None) == slice(0, 10)
    for bad in ((10, 2.5), (10, 0), (-1, 3)):
        with pytest.raises(InputError, match=r"^metric_subset\(.*\): frames must be an integer >= 0"):
            metric_subset(*bad)


def test_tone_map_divides_by_the_peak_and_clips():
    out = tone_map(np.array([-1.0, 0.0, 2.0, 4.0, 8.0]), peak=4.0)
    assert out[0] == 0 and out[1] == 0 and out[3] == 1 and out[4] == 1
    assert np.isclose(out[2], np.log1p(2500) / np.log1p(5000))


def test_paper_configs():
    configs = paper_configs()
    assert list(configs) == ["ml-msb", "te", "ml", "te+eq12", "te+eq13"]     # the last two: Tables 6-9
    assert configs["te+eq12"] == configs["te+eq13"] == SensorConfig()
    assert configs["te"] == SensorConfig() and configs["ml"] == SensorConfig(mode="ml")
    assert configs["ml-msb"] == SensorConfig(mode="ml", ml_readout="msb")
    assert configs["te"].threshold == 175 and configs["ml"].threshold == configs["ml-msb"].threshold == 328


def _hand_made(sensors=("ml-msb", "te")):
    rows = [Measurement("a", "ml-msb", "tfp", 20.0, 0.5, 1.0, 3), Measurement("b", "ml-msb", "tfp", 30.0, 0.7, 3.0, 3),
            Measurement("a", "te", "tfp", 25.0, 0.6, 2.0, 3), Measurement("b", "te", "tfp", 35.0, 0.8, 4.0, 3),
            Measurement("a", "ml-msb", "tfi", 10.0, 0.1, 5.0, 3), Measurement("a", "te", "tfi", 12.5, 0.25, 7.0, 3),
            Measurement("a", "ml", "tfp", 22.0, 0.55, 1.5, 3), Measurement("a", "ml", "tfi", 11.0, 0.15, 4.5, 3)]
    return Evaluation([r for r in rows if r.sensor in sensors], ("tfp", "tfi"), sensors, 9)


def test_summary_is_mean_of_sequence_means():
    summary = _hand_made().summary()
    assert summary["tfp", "ml-msb"] == {"psnr_mu": 25.0, "ssim_mu": 0.6, "ms_per_frame": 2.0, "sequences": 2}
    assert summary["tfp", "te"]["psnr_mu"] == 30.0
    assert summary["tfi", "te"]["sequences"] == 1


def test_an_evaluation_made_by_hand_takes_tuples_of_names():
    # one name had been read letter by letter: summary() looked for methods "t", "f" and "p"
    assert _hand_made(["ml-msb", "te"]).sensors == ("ml-msb", "te")
    for field, value in (("methods", "tfp"), ("sensors", "te"), ("methods", None), ("sensors", ()),
                         ("methods", ("tfp", 3)), ("metrics", "psnr_mu")):
        with pytest.raises(InputError, match=f"^Evaluation {field} .*: must be a tuple of names$"):
            Evaluation([], **{"methods": ("tfp",), "sensors": ("te",), "window": 9, field: value})


def test_table_markdown_has_the_paper_layout():
    lines = table_markdown(_hand_made()).splitlines()
    timing = "ms / frame ↓ (median of 1, 1 thread)"
    assert lines[0] == (f"| ML reconstruction | PSNR-μ ↑ | SSIM-μ ↑ | {timing} | "
                        f"TE reconstruction | PSNR-μ ↑ | SSIM-μ ↑ | {timing} |")
    assert lines[2] == "| TFP_ML | 25.00 | 0.600 | 2.00 | TFP_TE | 30.00 | 0.700 | 3.00 |"
    assert lines[3] == "| TFI_ML | 10.00 | 0.100 | 5.00 | TFI_TE | 12.50 | 0.250 | 7.00 |"
    assert len(lines) == 4


def test_table_markdown_puts_the_full_count_camera_in_extra_rows():
    """The msb camera is the paper's ML column; the full-count camera gets rows beneath it."""
    lines = table_markdown(_hand_made(("ml-msb", "te", "ml"))).splitlines()
    assert lines[0].startswith("| ML reconstruction |") and lines[0].count("reconstruction") == 2
    assert lines[2] == "| TFP_ML | 25.00 | 0.600 | 2.00 | TFP_TE | 30.00 | 0.700 | 3.00 |"
    assert lines[4] == "| TFP_ML-count | 22.00 | 0.550 | 1.50 |  |  |  |  |"
    assert lines[5] == "| TFI_ML-count | 11.00 | 0.150 | 4.50 |  |  |  |  |"
    assert len(lines) == 6
    # without a column sensor, every sensor is a column
    only = table_markdown(_hand_made(("ml",))).splitlines()
    assert only[0].startswith("| ML-count reconstruction |") and only[2].startswith("| TFP_ML-count | 22.00 |")
    # without the msb camera (a store of te and ml), the full-count camera is a column, never under "TE"
    lines = table_markdown(_hand_made(("te", "ml"))).splitlines()
    assert lines[0].startswith("| TE reconstruction |") and "| ML-count reconstruction |" in lines[0]
    assert lines[2].startswith("| TFP_TE | 30.00 |") and "| TFP_ML-count | 22.00 |" in lines[2] and len(lines) == 4


def test_table_and_results_csv():
    rows = list(csv.DictReader(io.StringIO(table_csv(_hand_made(("ml-msb", "te", "ml"))))))
    assert [r["method"] for r in rows] == ["tfp", "tfi"]
    assert rows[0]["te_name"] == "TFP_TE" and float(rows[0]["te_psnr_mu"]) == 30.0
    assert rows[1]["ml-msb_name"] == "TFI_ML" and float(rows[1]["ml-msb_ms_per_frame"]) == 5.0
    assert rows[0]["ml_name"] == "TFP_ML-count" and float(rows[0]["ml_psnr_mu"]) == 22.0
    full = list(csv.DictReader(io.StringIO(results_csv(_hand_made()))))
    assert len(full) == 6 and full[1]["sequence"] == "b" and float(full[1]["psnr_mu"]) == 30.0


@pytest.fixture(scope="module")
def small_run():
    sequences = [("m", make_scene("moderate", 12, 32, 40, seed=5)),
                 ("s", make_scene("sun", 12, 32, 40, seed=5, peak=30.0))]
    return sequences, evaluate(sequences, simulate, methods=("tfp", "tfi"), seed=3, progress=False,
                               keep=True)


def test_end_to_end_scores_are_the_metrics_of_the_scored_frames(small_run):
    sequences, evaluation = small_run
    assert len(evaluation.results) == 2 * 3 * 2
    for name, light in sequences:
        for mode in ("ml-msb", "te", "ml"):
            for method in ("tfp", "tfi"):
                result = next(r for r in evaluation.results
                              if (r.sequence, r.sensor, r.method) == (name, mode, method))
                images = evaluation.images[name, mode, method]
                assert images.shape == light.shape and result.frames_scored == 4
                peak = float(light.max())
                assert result.psnr_mu == pytest.approx(psnr_mu(images[4:8], light[4:8], peak=peak).mean())
                assert result.ssim_mu == pytest.approx(ssim_mu(images[4:8], light[4:8], peak=peak).mean())
                assert result.ms_per_frame > 0


def test_end_to_end_is_reproducible(small_run):
    sequences, evaluation = small_run
    again = evaluate(sequences[:1], simulate, methods=("tfp",), seed=3, progress=False)
    first = [r for r in evaluation.results if r.sequence == "m" and r.method == "tfp"]
    assert [r.psnr_mu for r in again.results] == [r.psnr_mu for r in first]
    other = evaluate(sequences[:1], simulate, methods=("tfp",), seed=4, progress=False)
    assert [r.psnr_mu for r in other.results] != [r.psnr_mu for r in first]


def test_run_time_is_the_median_of_repeats(small_run, monkeypatch):
    """Each method runs ``repeats`` times; the table says how many and with how many threads."""
    import torch

    import tespike.recon.methods
    from tespike import recon
    sequences, _ = small_run
    calls = []
    real = recon.methods.reconstruct
    monkeypatch.setattr(recon.methods, "reconstruct", lambda *a, **k: calls.append(a[0].shape) or real(*a, **k))
    evaluation = evaluate(sequences[:1], simulate, methods=("tfp",), sensors=("te",), seed=3,
                          progress=False, repeats=5)
    assert calls.count(sequences[0][1].shape) == 5            # plus one small warm-up call
    assert evaluation.repeats == 5 and evaluation.threads == torch.get_num_threads()
    assert f"median of 5, {torch.get_num_threads()} thread" in table_markdown(evaluation)
    with pytest.raises(InputError, match="repeats"):
        evaluate(sequences[:1], simulate, methods=("tfp",), repeats=0, progress=False)


def test_write_outputs(small_run, tmp_path):
    _, evaluation = small_run
    paths = write_outputs(evaluation, tmp_path / "eval")
    names = sorted(p.relative_to(tmp_path / "eval").as_posix() for p in (tmp_path / "eval").rglob("*"))
    assert names == ["quality_vs_time.png", "results.csv", "strips", "strips/m.png", "strips/s.png",
                     "table.csv", "table.md"]
    for key in ("plot", "strip:m", "strip:s"):
        assert paths[key].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "eval" / "table.md").read_text(encoding="utf-8") == table_markdown(evaluation)


def test_evaluate_refuses():
    light = make_scene("moderate", 4, 24, 24)
    with pytest.raises(InputError, match="unknown reconstruction method"):
        evaluate([("a", light)], simulate, methods=("magic",), progress=False)
    with pytest.raises(InputError, match="'tfp' is given twice"):     # (two TFP rows, their timings averaged)
        evaluate([("a", light)], simulate, methods=("tfp", "tfi", "tfp"), progress=False)
    with pytest.raises(InputError, match="unique"):
        evaluate([("a", light), ("a", light)], simulate, progress=False)
    with pytest.raises(InputError, match="no sequences"):
        evaluate([], simulate, progress=False)
    with pytest.raises(InputError, match="all zero"):
        evaluate([("z", np.zeros((3, 12, 12)))], simulate, progress=False)
    with pytest.raises(InputError, match="negative"):
        evaluate([("n", -light)], simulate, progress=False)
    with pytest.raises(InputError, match="no sensor configuration"):
        evaluate([("a", light)], simulate, configs={"te": SensorConfig()}, progress=False)
    # a light array where pairs belong ('too many values to unpack'), a pair of another kind
    with pytest.raises(InputError, match=r"^sequences: give \(label, light\) pairs, e.g. \[\('scene', light\)\]"):
        evaluate(light, simulate, methods=("tfp",), progress=False)
    for item in (["a", light], ("a", light, 1), (3, light), ("a", light[0])):
        with pytest.raises(InputError, match=r"^sequences: each must be a \(label, light \(K, H, W\)\) pair"):
            evaluate([item], simulate, methods=("tfp",), progress=False)


def test_one_name_given_as_a_string_is_that_name():
    """methods='tfp' had been 'unknown reconstruction method 't'', sensors='te' 'no sensor configuration
    for sensor 't'', metrics='psnr_pu21' 'unknown metric 'p''."""
    light = make_scene("moderate", 4, 24, 24)
    one = evaluate([("a", light)], simulate, methods="tfp", sensors="te", metrics="psnr_pu21", progress=False)
    assert (one.methods, one.sensors, one.metrics) == (("tfp",), ("te",), ("psnr_mu", "ssim_mu", "psnr_pu21"))


def test_method_options_reach_the_method(small_run):
    sequences, evaluation = small_run
    windowed = evaluate(sequences[:1], simulate, methods=("tfi",), sensors=("ml-msb",), seed=3, progress=False,
                        options={"tfi": {"search": "window"}})
    default = [r.psnr_mu for r in evaluation.results if (r.sequence, r.sensor, r.method) == ("m", "ml-msb", "tfi")]
    assert [r.psnr_mu for r in windowed.results] != default
    with pytest.raises(InputError, match="not an option"):
        evaluate(sequences[:1], simulate, methods=("tfp",), progress=False, options={"tfp": {"search": "window"}})


def test_light_far_above_float32_is_scored_not_overflowed():
    light = make_scene("moderate", 4, 24, 24, seed=1).astype(np.float64) * 1e300
    evaluation = evaluate([("huge", light)], simulate, methods=("tfp",), sensors=("te",), progress=False)
    (result,) = evaluation.results
    assert np.isfinite(result.psnr_mu) and result.psnr_mu < 10     # saturated codes: far too dark


def test_msb_and_count_cameras_see_the_same_light_and_differ(small_run):
    """The three sensors are simulated on the same light; the msb words are
    msb indices (0..8) and its reconstruction is not the count camera's."""
    sequences, evaluation = small_run
    msb, count = evaluation.streams["m", "ml-msb"], evaluation.streams["m", "ml"]
    assert msb.shape == count.shape and int(msb.max()) <= 8 < int(count.max())
    assert not np.array_equal(evaluation.images["m", "ml-msb", "tfp"], evaluation.images["m", "ml", "tfp"])


# ----------------------------------------------------------- the paper's Tables 1, 2, 6 to 10
def test_labels_are_the_papers_names():
    assert label("spk2imgnet", "te") == "Spk2ImgNet_TE" and label("mambaspike", "ml-msb") == "MambaSpike_ML"
    assert label("bsf", "te+eq12") == "BSF_TE+dark12" and label("tfp", "ml") == "TFP_ML-count"


def test_missing_weights_are_noted_by_default_and_refused_when_named(empty_weights_dir):
    light = make_scene("moderate", 6, 16, 16, seed=2)
    with pytest.raises(InputError, match=r"bsf-te\.pt' is missing"):
        evaluate([("a", light)], simulate, methods=("tfp", "bsf"), sensors=("te",), progress=False)
    evaluation = evaluate([("a", light)], simulate, methods=("tfp", "bsf"), sensors=("te",), progress=False,
                          missing="note", repeats=1)
    assert [(r.method, r.sensor) for r in evaluation.results] == [("tfp", "te")]
    assert set(evaluation.missing) == {("bsf", "te")}
    text = table_markdown(evaluation)
    assert "| BSF_TE | no weights |" in text and "- BSF_TE: no bsf weights for the te camera" in text
    everything = evaluate([("a", light)], simulate, sensors=("te",), progress=False, repeats=1)   # methods=None
    assert {m for m, _ in everything.missing} == {"spk2imgnet", "bsf", "mambaspike1", "mambaspike", "net"}
    assert [r.method for r in everything.results] == ["tfp", "tfi"]


def test_further_metrics_are_the_scores_of_the_scored_frames():
    from tespike.recon.score import score
    light = make_scene("moderate", 14, 24, 24, seed=4)
    evaluation = evaluate([("a", light)], simulate, methods=("tfp",), sensors=("te",), progress=False, keep=True,
                          repeats=1, metrics=("fovvideovdp", "psnr_pu21", "hdr_vqm"), vdp_frames=2)
    assert evaluation.metrics == ("psnr_mu", "ssim_mu", "psnr_pu21", "hdr_vqm", "fovvideovdp")
    (result,) = evaluation.results
    pred, truth = evaluation.images["a", "te", "tfp"][4:10], light[4:10]
    every = score(pred, truth, metrics=("psnr_pu21", "hdr_vqm"))
    assert result.psnr_pu21 == pytest.approx(every.mean["psnr_pu21"])
    assert result.hdr_vqm == pytest.approx(every.sequence["hdr_vqm"])
    assert result.fovvideovdp == pytest.approx(score(pred[2:4], truth[2:4], metrics=("fovvideovdp",)).mean["fovvideovdp"])
    # one name as a string is that metric (its letters had each been refused as a metric)
    assert score(pred, truth, metrics="psnr_pu21").mean == score(pred, truth, metrics=("psnr_pu21",)).mean
    assert result.frames_vdp == 2 and result.frames_scored == 6
    text = table_markdown(evaluation)
    assert "HDR-VQM ↓" in text and "FovVideoVDP (JOD) ↑" in text and "middle 2 scored frames" in text
    with pytest.raises(InputError, match="unknown metric 'vdp'"):
        evaluate([("a", light)], simulate, methods=("tfp",), metrics=("vdp",), progress=False)
    with pytest.raises(InputError, match="vdp_frames"):
        evaluate([("a", light)], simulate, methods=("tfp",), vdp_frames=0, progress=False)


def test_noise_sensors_get_dark_current_and_their_own_table():
    seen = []

    def recording(config, light, rng, noise_sensor=None):
        seen.append(noise_sensor and noise_sensor.noise.dark_current)
        return simulate_scene(config, light, seed=rng, sensor=noise_sensor)

    light = make_scene("moderate", 12, 24, 24, seed=3)
    configs = paper_configs()
    evaluation = evaluate([("a", light)], recording, methods=("tfp",), sensors=("ml-msb", "te", "te+eq12", "te+eq13"),
                          configs=configs, progress=False, repeats=1)
    assert seen == [None, None, "eq12", "eq13"]
    by_mode = {r.sensor: r.psnr_mu for r in evaluation.results}
    assert by_mode["te+eq12"] < by_mode["te"] and by_mode["te+eq13"] < by_mode["te"]   # dark current costs
    lines = table_markdown(evaluation).splitlines()
    assert lines[0].count("reconstruction") == 2 and len([x for x in lines if x.startswith("| TFP_")]) == 2
    noise = lines.index(next(x for x in lines if x.startswith("| TE reconstruction | PSNR-μ ↑ (shot noise only)")))
    assert "(dark current eq. 12)" in lines[noise] and "(dark current eq. 13)" in lines[noise]
    assert lines[noise + 2].startswith(f"| TFP_TE | {by_mode['te']:.2f} |")


def test_calibrated_rows_win_back_the_dark_current():
    """A +cal sensor reconstructs the same noise sensor with its calibration: its own row in the
    noise table, under the uncalibrated row; a custom sensor gets a column named by its options."""
    from tespike.golden.noise import Sensor, SensorNoise

    def simulate(config, light, rng, noise_sensor=None):
        return simulate_scene(config, light, seed=rng, sensor=noise_sensor)

    light = make_scene("moderate", 12, 24, 24, seed=3)
    noise_sensors = {"te+hot": Sensor(SensorNoise(dark_current="eq12", dark_level=2.0, dsnu=0.3, prnu=0.05), 1)}
    evaluation = evaluate([("a", light)], simulate, methods=("tfp",), sensors=("te", "te+hot", "te+hot+cal"),
                          progress=False, repeats=1, noise_sensors=noise_sensors,
                          configs=paper_configs() | {"te+hot": SensorConfig()})
    assert evaluation.noise_sensors == {"te+hot": noise_sensors["te+hot"], "te+hot+cal": noise_sensors["te+hot"]}
    by_sensor = {r.sensor: r.psnr_mu for r in evaluation.results}
    lost, won = by_sensor["te"] - by_sensor["te+hot"], by_sensor["te+hot+cal"] - by_sensor["te+hot"]
    assert lost > 5 and 0.5 * lost < won <= lost + 0.5, by_sensor     # most of the dark current's cost won back
    lines = table_markdown(evaluation).splitlines()
    assert lines[0].count("reconstruction") == 1        # the noise sensors sit in the noise table only
    assert any("(dark_current eq12, dark_level 2, dsnu 0.3, prnu 0.05)" in x for x in lines)
    assert any(x.startswith(f"| TFP_TE (calibrated) | - | - | {by_sensor['te+hot+cal']:.2f} |") for x in lines)
    rows = list(csv.DictReader(results_csv(evaluation).splitlines()))
    assert [r["sensor"] for r in rows] == ["te", "te+hot", "te+hot+cal"]
    with pytest.raises(InputError, match="'te' is no noise sensor to calibrate"):
        evaluate([("a", light)], simulate, methods=("tfp",), sensors=("te+cal",), progress=False)


def test_complexity_columns_with_the_papers_table10():
    evaluation = _hand_made()
    evaluation.methods = ("tfp", "tfi", "bsf")
    evaluation.missing = {("bsf", "ml-msb"): "no bsf weights", ("bsf", "te"): "no bsf weights"}
    evaluation.complexity = {"bsf": {"parameters": 152236, "flops": 9.5e9}}
    lines = table_markdown(evaluation).splitlines()
    assert lines[0].endswith("| parameters | GFLOPs / 384 x 512 | paper: parameters | paper: FLOPs | "
                             "paper: s / frame (GPU) |")
    assert lines[2].endswith("| - | - | - | - | - |")                    # TFP: no network
    assert lines[4].endswith("| 152,236 | 9.5 | 2.071 M | 0.887 T | 0.231 |")
    assert "| BSF_ML | no weights |" in lines[4] and "- BSF_ML, BSF_TE: no bsf weights" in lines
    rows = list(csv.DictReader(io.StringIO(table_csv(evaluation))))
    assert rows[2]["parameters"] == "152236" and float(rows[2]["paper_flops"]) == 0.887e12
    assert rows[2]["te_psnr_mu"] == ""                                   # CSV cells stay numeric or empty


def test_with_a_learned_method_frames_are_scored_where_its_span_fits(empty_weights_dir):
    import torch

    from tespike.recon.learned import method_classes
    from tespike.recon.learning.weights import save_weights
    torch.manual_seed(0)
    module, sizes = method_classes("spk2imgnet")
    save_weights(empty_weights_dir / "spk2imgnet-te.pt", module(sizes.preset("cpu")).eval(), SensorConfig(), {},
                 "spk2imgnet")
    light = make_scene("moderate", 63, 24, 24, seed=2)
    evaluation = evaluate([("a", light)], simulate, methods=("tfp", "spk2imgnet"), sensors=("te",), progress=False,
                          repeats=1)
    assert evaluation.span == 61 and [r.frames_scored for r in evaluation.results] == [3, 3]
    assert "- frames scored per sequence: 3, those whose 9-readout window" in table_markdown(evaluation)


def test_weights_given_replace_the_shipped_ones(empty_weights_dir, tmp_path):
    """``weights`` (``--weights``): a learned method runs with the user's file on the sensor it was trained for."""
    import torch

    from tespike.recon.learned import method_classes, weights_by_sensor
    from tespike.recon.learning.weights import save_weights
    from tespike.recon.methods import reconstruct
    torch.manual_seed(0)
    module, sizes = method_classes("bsf")
    save_weights(tmp_path / "mine.pt", module(sizes.preset("cpu")).eval(), SensorConfig(), {}, "bsf")
    light = make_scene("moderate", 63, 16, 16, seed=2)
    with pytest.raises(InputError, match="bsf-te.pt' is missing"):
        evaluate([("a", light)], simulate, methods=("bsf",), sensors=("te",), progress=False, repeats=1)
    chosen = weights_by_sensor([tmp_path / "mine.pt"], {"te": SensorConfig()})
    evaluation = evaluate([("a", light)], simulate, methods=("bsf",), sensors=("te",), progress=False, repeats=1,
                          weights=chosen, keep=True)
    words = evaluation.streams["a", "te"]
    assert np.array_equal(evaluation.images["a", "te", "bsf"],
                          reconstruct(words, SensorConfig(), "bsf", weights=tmp_path / "mine.pt"))


def test_evaluate_refuses_switches_sensors_options_and_weights_it_would_misread_in_one_line():
    """``progress='False'`` showed a bar and ``keep='no'`` kept the streams; a sensor named twice
    counted its sequences twice; options and weights for a method or sensor not in the run were
    dropped without a word, a window among a method's options was Python's "multiple values"; no
    sensor was ``max()`` of an empty sequence and a preset's name as a configuration an
    AttributeError."""
    from tespike.golden.errors import ConfigError
    light = np.full((9, 12, 12), 0.5, np.float32)
    sequences = [("a", light)]
    cases = [({"progress": "False"}, r"^progress = 'False': must be True, False \(or None\) or 'lines'$"),
             ({"keep": "no"}, r"^keep = 'no': must be True or False$"),
             ({"sensors": ["te", "te"]}, r"^sensor 'te' is named more than once$"),
             ({"sensors": []}, r"^sensors: name at least one sensor$"),
             ({"options": {"tfq": {}}}, r"^options for 'tfq': no method of this evaluation \(tfp\) has that name$"),
             ({"options": {"tfp": 3}}, r"^options for 'tfp': must be a dict of reconstruct\(\) keywords, not int$"),
             ({"options": {"tfp": {"window": 3}}}, r"^options for 'tfp': the window is the evaluation's own argument"),
             ({"options": "x"}, r"^options: must be a dict, not str$"),
             ({"weights": {"tfp": "x"}}, r"^weights key 'tfp': must be a \(method, sensor\) pair of this evaluation$")]
    for options, words in cases:
        with pytest.raises(InputError, match=words):
            evaluate(sequences, lambda c, l, r: np.zeros(l.shape, np.uint8), **{"methods": ["tfp"], "sensors": ["te"],
                                                                                "progress": False, **options})
    with pytest.raises(ConfigError, match="^sensor 'te': configuration must be a SensorConfig"):
        evaluate(sequences, lambda c, l, r: None, methods=["tfp"], sensors=["te"], configs={"te": "te"}, progress=False)


def test_evaluate_refuses_sequences_a_simulator_and_frames_it_cannot_score_before_any_work():
    """``sequences=None`` and ``simulate=None`` were TypeErrors, a simulator returning a 2-D array an
    IndexError deep in a method, and frames smaller than SSIM's window were refused only after every
    stream had been simulated and reconstructed."""
    light = np.full((9, 12, 12), 0.5, np.float32)
    arguments = {"methods": ["tfp"], "sensors": ["te"], "progress": False}
    with pytest.raises(InputError, match=r"^sequences: give \(label, light\) pairs, e\.g\. .*, not NoneType$"):
        evaluate(None, lambda c, l, r: None, **arguments)
    with pytest.raises(InputError, match=r"^simulate: must be a function simulate\(config, light, rng\) -> words"):
        evaluate([("a", light)], None, **arguments)
    for returned in (np.zeros((2, 2)), [1]):
        with pytest.raises(InputError, match=r"^simulate returned .*: it must return the integer readout words of "
                                             r"the light's shape \(9, 12, 12\)$"):
            evaluate([("a", light)], lambda c, l, r, returned=returned: returned, **arguments)
    called = []
    with pytest.raises(InputError, match="^SSIM needs frames of at least 11 x 11 pixels, got 8 x 8$"):
        evaluate([("a", np.full((9, 8, 8), 0.5, np.float32))], lambda c, l, r: called.append(1), **arguments)
    assert not called


def test_the_report_helpers_refuse_an_evaluation_sequence_or_folder_they_cannot_use(tmp_path):
    """``table_markdown({})`` and friends were AttributeErrors deep in the table, ``plot_strip`` of an
    unknown sequence a KeyError, a results folder that is a file mkdir's FileExistsError, and a path
    holding a NUL character the system's "embedded null byte" ValueError."""
    from tespike.golden.paths import check_input_file
    from tespike.recon.report import plot_strip, results_csv, table_csv, table_markdown, write_outputs
    for helper in (table_markdown, table_csv, results_csv):
        with pytest.raises(InputError, match=f"^{helper.__name__}: the evaluation must be an Evaluation, not dict$"):
            helper({})
    light = np.full((9, 12, 12), 0.5, np.float32)
    evaluation = evaluate([("a", light)], lambda c, l, r: simulate_scene(c, l, seed=r), methods=["tfp"],
                          sensors=["te"], progress=False, repeats=1)
    with pytest.raises(InputError, match=r"^plot_strip: no sequence 'zz' in this evaluation \(its sequences: a\)$"):
        plot_strip(evaluation, "zz", tmp_path / "s.png")
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="^results folder .* is a file, not a folder$"):
        write_outputs(evaluation, tmp_path / "file")
    with pytest.raises(InputError, match="holds a NUL character, which no file name can$"):
        check_input_file("a\x00b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
