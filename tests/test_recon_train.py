"""tespike.recon.train and ``tespike train``: a few steps, the log and plot, resume equal to one run."""

import csv

import numpy as np
import pytest
import torch

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.recon.learned import load_weights
from tespike.recon.train import TrainOptions, train, training_loss
from tespike.recon.engine.clips import EngineRecipe
from tests.cli import assert_refused, run_tespike

RECIPE = {"height": 32, "width": 32, "long": (8, 20), "short": (1, 7)}


def options(**kw):
    base = dict(steps=4, crop=32, batch=2, recipe=RECIPE, checkpoint_seconds=1e9, threads=1, workers=0,
                pool=2, refresh=2, validate_every=0)
    return TrainOptions(**{**base, **kw})


def test_a_few_steps_write_weights_log_and_plot(tmp_path):
    out = train(options(), tmp_path / "w.pt")
    model, config, meta = load_weights(out)
    assert config.mode == "te" and meta["steps"] == 4 and meta["parameters"] > 0
    with open(tmp_path / "w.run" / "log.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["step"]) for r in rows] == [1, 2, 3, 4]
    assert (tmp_path / "w.run" / "curves.png").stat().st_size > 1000


def test_validation_keeps_the_best_weights(tmp_path, monkeypatch):
    """The weights written are those of the best validation score, recorded with it."""
    import tespike.recon.train as train_module
    scores = iter([20.0, 25.0, 22.0])
    monkeypatch.setattr(train_module, "validate", lambda model, cases, config, device: {"a": (v := next(scores)),
                                                                                        "mean": v})
    monkeypatch.setattr("tespike.recon.engine.validation.validation_set", lambda config: [])
    out = train(options(steps=3, validate_every=1), tmp_path / "v.pt")
    meta = load_weights(out)[2]
    assert meta["steps"] == 2 and meta["validation"]["mean"] == 25.0 and meta["final_step"] == 3
    with open(tmp_path / "v.run" / "validation.csv") as handle:
        assert [float(r["mean"]) for r in csv.DictReader(handle)] == [20.0, 25.0, 22.0]


def test_validation_scores_every_held_out_case():
    from tespike.recon.engine.validation import CASES, validation_psnr, validation_set
    cases = validation_set(SensorConfig(), 16, 24)
    assert [c.label for c in cases] == [c.label for c in CASES]
    assert all(c.words.shape == c.light.shape for c in cases)
    perfect = validation_psnr(lambda case: case.light, cases)
    assert all(v == float("inf") for v in perfect.values())
    rough = validation_psnr(lambda case: case.light * 1.5, cases)
    assert all(10 < v < 60 for v in rough.values())
    assert set(rough) == {c.label for c in cases} | {"shot", "noisy", "mean"}


def test_the_extended_validation_cases_add_noisy_sensors_inside_the_engine_range():
    """The extended set keeps the eight selection cases' streams and adds noisy cases whose sensors lie
    inside the range the engine draws training sensors from (NOISE_DRAW)."""
    from tespike.recon.engine.clips import NOISE_DRAW
    from tespike.recon.engine.validation import CASES, EXTENDED_CASES, VALIDATION_SENSORS, validation_set
    for name, fields in VALIDATION_SENSORS.items():
        for key, value in fields.items():
            allowed = NOISE_DRAW[key]
            assert (value in allowed) if isinstance(value, str) else allowed[0] <= value <= allowed[1], (name, key)
    assert all(case.sensor for case in EXTENDED_CASES)
    config = SensorConfig()
    base, extended = validation_set(config, 8, 12), validation_set(config, 8, 12, extended=True)
    assert [c.label for c in extended] == [c.label for c in CASES + EXTENDED_CASES]
    assert len({c.label for c in extended}) == len(extended)
    assert all(np.array_equal(a.words, b.words) for a, b in zip(base, extended))


@pytest.mark.parametrize("args, kwargs, words", [
    (("te",), {}, "validation_set: configuration must be a SensorConfig"),
    ((SensorConfig(), -3), {}, "validation_set frame (height, width) (-3, 128)"),
    ((SensorConfig(), 8, 2.5), {}, "validation_set frame (height, width) (8, 2.5)"),
    ((SensorConfig(), 8, 0), {}, "validation_set frame (height, width) (8, 0)"),
    ((SensorConfig(),), {"extended": "yes"}, "validation_set extended = 'yes': must be True or False"),
], ids=["preset-name", "negative-height", "float-width", "empty-width", "extended-string"])
def test_validation_set_refuses_what_it_cannot_take_in_one_line(args, kwargs, words):
    """A preset's name, a frame of no pixels or a fractional size was numpy's traceback or a warning
    about an empty mean, from deep inside the cases' light; now one line naming the argument."""
    from tespike.golden.errors import ConfigError
    from tespike.recon.engine.validation import validation_set
    with pytest.raises((InputError, ConfigError)) as refused:
        validation_set(*args, **kwargs)
    assert str(refused.value).startswith(words) and "\n" not in str(refused.value)


def test_validation_makes_each_noisy_case_law_input_once(monkeypatch):
    """A run scores every checkpoint on the same noisy streams: each case's law input is made at its
    first use on a device and served again (the images equal those made afresh); inputs of another
    stream are refused."""
    import tespike.recon.learning.infer as infer
    from tespike.recon.engine.validation import validation_set
    from tespike.recon.train import validate
    config = SensorConfig.preset("te")
    cases = [c for c in validation_set(config, 16, 24) if c.calibration is not None]
    assert len(cases) >= 2 and all(c.calibration.dark_law is not None for c in cases)
    made = []
    original = infer.law_input
    monkeypatch.setattr(infer, "law_input", lambda *a, **k: made.append(a[0]) or original(*a, **k))
    from tespike.recon.learned import weights_path
    model = load_weights(weights_path(config, "net"))[0]
    first = validate(model, cases, config, "cpu")
    calls = len(made)
    assert calls >= len(cases)
    assert validate(model, cases, config, "cpu") == first and len(made) == calls
    fresh = infer.reconstruct_model(model, cases[0].words, config, tile=None, calibration=cases[0].calibration)
    kept = infer.reconstruct_model(model, cases[0].words, config, tile=None, calibration=cases[0].calibration,
                                   inputs=cases[0].law_inputs())
    assert np.array_equal(fresh, kept)
    with pytest.raises(ValueError, match="another stream"):
        infer.reconstruct_model(model, cases[1].words, config, tile=None, calibration=cases[1].calibration,
                                inputs=cases[0].law_inputs())


def test_resume_continues_exactly(tmp_path):
    cache = tmp_path / "cache"
    straight = train(options(steps=4), tmp_path / "a.pt")
    train(options(steps=2), tmp_path / "b.pt")
    resumed = train(options(steps=4), tmp_path / "b.pt", resume=True)
    a, b = (load_weights(p)[0].state_dict() for p in (straight, resumed))
    assert all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("where", ["forward", "backward"])
def test_resume_after_an_interrupt_inside_a_step_continues_exactly(tmp_path, monkeypatch, where):
    """Ctrl-C inside step 3 (its batch drawn, the model not yet updated) saved the batch generator
    past that batch: the resumed run trained on other batches (weights off by 1e-4)."""
    import tespike.recon.train as trainer
    straight = train(options(steps=5), tmp_path / "a.pt")
    calls = {"n": 0}
    real_loss, real_backward = trainer.training_loss, torch.Tensor.backward

    def interrupt_on_third():
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt

    def loss(*args, **kwargs):
        if where == "forward":
            interrupt_on_third()
        return real_loss(*args, **kwargs)

    def backward(self, *args, **kwargs):
        real_backward(self, *args, **kwargs)
        if where == "backward":
            interrupt_on_third()
    monkeypatch.setattr(trainer, "training_loss", loss)
    monkeypatch.setattr(torch.Tensor, "backward", backward)
    with pytest.raises(KeyboardInterrupt) as info:
        train(options(steps=5), tmp_path / "b.pt")
    assert "at step 2" in "".join(getattr(info.value, "__notes__", []))
    monkeypatch.undo()
    resumed = train(options(steps=5), tmp_path / "b.pt", resume=True)
    a, b = (load_weights(p)[0].state_dict() for p in (straight, resumed))
    assert all(torch.equal(a[k], b[k]) for k in a)
    with open(tmp_path / "b.run" / "log.csv") as handle:
        assert [row["step"] for row in csv.DictReader(handle)] == ["1", "2", "3", "4", "5"]


def test_a_failed_final_checkpoint_keeps_the_logs_of_the_weights_it_wrote(tmp_path, monkeypatch):
    """A full disk at the last checkpoint (the weights already written) removed the whole run folder."""
    import errno

    import tespike.recon.train as trainer

    def full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
    monkeypatch.setattr(trainer, "_save_checkpoint", full)
    with pytest.raises(OSError):
        train(options(steps=2), tmp_path / "w.pt")
    assert (tmp_path / "w.pt").is_file() and (tmp_path / "w.run" / "log.csv").is_file()
    monkeypatch.undo()
    with pytest.raises(KeyboardInterrupt):                # a run that made nothing leaves no folder
        monkeypatch.setattr(trainer, "draw_batch", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
        train(options(steps=2), tmp_path / "v.pt")
    assert not (tmp_path / "v.run").exists()


def test_resume_refuses_other_options(tmp_path):
    cache = tmp_path / "cache"
    train(options(steps=1), tmp_path / "c.pt")
    with pytest.raises(InputError, match=r"other options \(loss 'l1', not 'mu-l1'\)"):   # (the option named)
        train(options(steps=2, loss="mu-l1"), tmp_path / "c.pt", resume=True)


def test_losses():
    pred, truth = torch.tensor([0.5, 0.0]), torch.tensor([0.25, 0.0])
    assert float(training_loss(pred, truth, "l1")) == pytest.approx(0.125)
    assert float(training_loss(truth, truth, "mu-l1")) == 0.0
    with pytest.raises(InputError, match="loss"):
        TrainOptions(steps=1, loss="l2")
    with pytest.raises(InputError, match="budget"):
        TrainOptions()
    with pytest.raises(InputError, match="warmup = 100000001: its first step's rate"):
        TrainOptions(steps=1, lr=1e-2, warmup=10 ** 8 + 1)     # (1e11 trained at 1e-15: no weight moved)
    TrainOptions(steps=1, lr=1e-2, warmup=10 ** 8)


def test_the_halving_schedule_stops_at_the_smallest_rate():
    from tespike.recon.train import MIN_LR, lr_factor
    opts = TrainOptions(steps=1, lr=1e-10, steps_per_epoch=1, halve_every=1)
    assert [lr_factor(opts, step) * opts.lr for step in range(3)] == [1e-10, MIN_LR, MIN_LR]


def test_ablation_case_trains_the_switched_network(tmp_path):
    out = train(options(steps=1, ablation=4), tmp_path / "a.pt")
    sizes = load_weights(out)[0].sizes
    assert (sizes.gradient, sizes.dcn, sizes.similarity, sizes.motion_bias, sizes.refine) == \
        (True, True, True, False, False)
    with pytest.raises(InputError, match="ablation case 7"):
        options(ablation=7)


def test_cli_refusals(tmp_path):
    assert_refused(run_tespike("train", "--config", "te", "--out", tmp_path / "w.pt"), "budget")
    assert_refused(run_tespike("train", "--config", "te", "--out", tmp_path / "no" / "w.pt", "--steps", "1"),
                   "does not exist")
    assert_refused(run_tespike("train", "--config", "te", "--loss", "l9", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "loss")
    assert_refused(run_tespike("train", "--config", "te", "--ablation", "0", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "ablation case 0")
    # (1e-300 and 1e-40 trained on all-black float32 clips with exit 0; 1e300 "diverged")
    for low, high in (("0.3", "0.1"), ("0", "1"), ("1", "inf"), ("1e-300", "1"), ("1e-40", "1e-40"), ("1", "1e300")):
        assert_refused(run_tespike("train", "--config", "te", "--peak", low, high, "--out", tmp_path / "w.pt",
                                   "--steps", "1"), f"--peak {float(low):g} {float(high):g}", "1e-06 <= low")
    # --noisy-input with no noisy clip; an --hdr folder without frames (was met after --force removed a run)
    assert_refused(run_tespike("train", "--config", "te", "--noisy-input", "law", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "--noisy-input law", "--noise-fraction")
    assert_refused(run_tespike("train", "--config", "te", "--out", "/dev/full", "--steps", "1"),   # (trained,
                   "--out '/dev/full' is a device or FIFO")                                    # then failed)
    (tmp_path / "empty").mkdir()
    assert_refused(run_tespike("train", "--config", "te", "--hdr", tmp_path / "empty", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "holds no frames")
    assert_refused(run_tespike("train", "--config", "te", "--panoramas", tmp_path / "none", "--out",
                               tmp_path / "w.pt", "--steps", "1"), "--panoramas")
    # a typo of a few zeros: refused before any process is started or any clip is made
    assert_refused(run_tespike("train", "--config", "te", "--workers", "100000", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "workers = 100000", "0..256")
    assert_refused(run_tespike("train", "--config", "te", "--pool", "10000000", "--workers", "0",
                               "--out", tmp_path / "w.pt", "--steps", "1"), "a pool of 10000000 clips", "memory")
    assert not (tmp_path / "w.pt").exists() and not (tmp_path / "w.run").exists()


def test_peak_sets_the_clips_brightness(tmp_path, monkeypatch):
    import tespike.recon.train as trainer
    from tespike.cosim.cli import main

    seen, commands = [], []
    monkeypatch.setattr(trainer, "train", lambda options, out, **kw: (seen.append(options),
                                                                     commands.append(kw["command"])))
    assert main(["train", "--out", str(tmp_path / "w.pt"), "--steps", "1", "--peak", "0.01", "0.3", "-q"]) == 0
    assert seen[0].data_recipe().peak == (0.01, 0.3)
    # the run records the command it was given (in-process too: it recorded the host's sys.argv)
    assert commands[0] == f"tespike train --out {tmp_path / 'w.pt'} --steps 1 --peak 0.01 0.3 -q"
    assert main(["train", "--out", str(tmp_path / "w.pt"), "--steps", "1", "-q"]) == 0
    assert seen[1].data_recipe().peak == EngineRecipe().peak
    from tespike.recon.scenes import write_hdr
    (tmp_path / "panos").mkdir()
    write_hdr(tmp_path / "panos" / "hall.hdr", np.full((128, 256, 3), 0.5, np.float32))
    assert main(["train", "--out", str(tmp_path / "w.pt"), "--steps", "1", "--panoramas", str(tmp_path / "panos"),
                 "-q"]) == 0
    assert seen[2].data_recipe().panoramas == EngineRecipe().panoramas + (str(tmp_path / "panos" / "hall.hdr"),)
    # a panorama smaller than the engine's window: its clips would repeat its edge rows (it trained)
    write_hdr(tmp_path / "panos" / "small.hdr", np.full((8, 8, 3), 0.5, np.float32))
    with pytest.raises(InputError, match=r"small.hdr' is 8 x 8, smaller than the engine's 128 x 128 window"):
        EngineRecipe(panoramas=(str(tmp_path / "panos" / "small.hdr"),))


def test_method_and_crop_checked():
    with pytest.raises(InputError, match="unknown learned method"):
        options(method="nope")
    with pytest.raises(InputError, match="crop = 40"):
        options(crop=40)
    with pytest.raises(InputError, match="larger than the engine"):
        options(crop=64)
    # (1e30 trained to a loss that never moved; 1e-40 wrote the initial weights back unchanged)
    for lr in (0.0, -1e-3, float("nan"), float("inf"), 1e30, 1.5, 1e-40, 1e-320, 9e-11):
        with pytest.raises(InputError, match="learning rate"):
            options(lr=lr)
    assert options(lr=1.0).lr == 1.0 and options(lr=1e-10).lr == 1e-10


def test_init_warm_starts_every_matching_tensor(tmp_path):
    """--init copies the tensors whose name and shape match (a new head keeps its initial values)."""
    import dataclasses

    from tespike.recon.net.model import TESpikeNet
    from tespike.recon.net.sizes import NetSizes
    from tespike.recon.learning.weights import save_weights
    from tespike.recon.train import warm_start
    old = TESpikeNet(dataclasses.replace(NetSizes(), head="mean"))
    for p in old.parameters():
        torch.nn.init.normal_(p)
    save_weights(tmp_path / "old.pt", old, SensorConfig.preset("te"), {}, "net")
    new = TESpikeNet(NetSizes())
    head_before = new.head.conv.weight.clone()
    copied, trained_for = warm_start(new, str(tmp_path / "old.pt"), "net")
    assert trained_for == SensorConfig.preset("te")
    assert "encoder.embed.weight" in copied or any(name.startswith("encoder.") for name in copied)
    assert not any(name.startswith("head.") for name in copied)
    assert torch.equal(new.head.conv.weight, head_before)
    for name in copied:
        assert torch.equal(new.state_dict()[name], old.state_dict()[name])
    with pytest.raises(InputError, match="not bsf's BSF"):
        warm_start(new, str(tmp_path / "old.pt"), "bsf")
    out = train(options(init=str(tmp_path / "old.pt")), tmp_path / "w.pt")
    assert load_weights(out)[2]["options"]["init"] == str(tmp_path / "old.pt")
    # the record says what the warm start gave: tensors copied, and the sensor it was trained for
    init = load_weights(out)[2]["init"]
    assert init["tensors_copied"] == len(copied) < init["tensors"] and init["trained_for"]["mode"] == "te"
    # --resume continues a warm-started run without --init (its start is in the checkpoint) and records it
    out = train(options(steps=6), tmp_path / "w.pt", resume=True)
    meta = load_weights(out)[2]
    assert meta["steps"] == 6 and meta["options"]["init"] == str(tmp_path / "old.pt") and meta["init"] == init


def test_a_warm_start_from_another_sensor_says_so(tmp_path, capsys):
    """--init weights trained for the TE camera start an ML run: allowed (a start is a start), said on
    stderr and recorded; the same sensor's weights start one without a word."""
    te = train(options(), tmp_path / "te.pt")
    capsys.readouterr()
    out = train(options(config="ml", init=str(te)), tmp_path / "ml.pt")
    err = capsys.readouterr().err
    assert "was trained for" in err and "te.pt" in err and "of this run's" in err
    assert load_weights(out)[2]["init"]["trained_for"]["mode"] == "te"
    train(options(init=str(te)), tmp_path / "te2.pt")
    assert "was trained for" not in capsys.readouterr().err
    ablated = train(options(ablation=4), tmp_path / "ab.pt")       # fewer tensors: a start of part of the run
    capsys.readouterr()
    train(options(init=str(ablated)), tmp_path / "whole.pt")
    err = capsys.readouterr().err
    assert "holds another size or ablation" in err and "the others afresh" in err, err


def test_init_refusals(tmp_path):
    assert_refused(run_tespike("train", "--config", "te", "--init", tmp_path / "none.pt", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "none.pt' does not exist")
    assert_refused(run_tespike("train", "--config", "te", "--init", tmp_path, "--out", tmp_path / "v.pt",
                               "--steps", "1"), "is a directory")              # (it said "no such weights file")
    (tmp_path / "w.pt").write_bytes(b"x")
    assert_refused(run_tespike("train", "--config", "te", "--init", tmp_path / "w.pt", "--out", tmp_path / "w.pt",
                               "--steps", "1"), "--init")
    assert (tmp_path / "w.pt").read_bytes() == b"x"


def test_cli_keeps_no_copy_of_the_trainers_defaults(tmp_path, monkeypatch, capsys):
    """tespike train passes on only the trainer's flags a user gave; the rest, and --help's
    defaults, come from TrainOptions (they had drifted: 200 vs 250 steps per epoch)."""
    import dataclasses

    import tespike.recon.train as trainer
    from tespike.cosim.cli import build_parser, main
    from tespike.cosim.commands.train_cmd import TRAINER_FLAGS

    defaults = {f.name: f.default for f in dataclasses.fields(TrainOptions)}
    args = build_parser("train").parse_args(["train", "--out", "w.pt", "--steps", "1"])
    assert not any(hasattr(args, flag) for flag in TRAINER_FLAGS)
    seen = []
    monkeypatch.setattr(trainer, "train", lambda options, out, **kw: seen.append(options))
    assert main(["train", "--out", str(tmp_path / "w.pt"), "--steps", "1", "--batch", "2", "-q"]) == 0
    assert seen[0].batch == 2
    assert all(getattr(seen[0], flag) == defaults[flag] for flag in TRAINER_FLAGS if flag != "batch")
    with pytest.raises(SystemExit):
        build_parser("train").parse_args(["train", "--help"])
    assert f"steps per epoch (default {defaults['steps_per_epoch']})" in " ".join(capsys.readouterr().out.split())


def test_learning_rate_warms_up_then_halves_as_the_papers_schedule():
    """Without warm-up the schedule is StepLR's exactly; with it the first steps ramp up linearly."""
    from tespike.recon.train import lr_factor
    plain = options(halve_every=2, steps_per_epoch=3)
    parameter = torch.nn.Parameter(torch.zeros(1))
    optimizer = torch.optim.SGD([parameter], lr=1.0)
    steplr = torch.optim.lr_scheduler.StepLR(optimizer, 6, 0.5)
    expected = []
    for _ in range(20):
        expected.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        steplr.step()
    assert [lr_factor(plain, step) for step in range(20)] == expected
    warm = options(halve_every=2, steps_per_epoch=3, warmup=4)
    assert [lr_factor(warm, step) for step in range(8)] == [0.25, 0.5, 0.75, 1.0, 1.0, 1.0, 0.5, 0.5]
    with pytest.raises(InputError, match="warmup"):
        options(warmup=-1)


def test_a_checkpoint_written_before_the_options_rename_is_read(tmp_path):
    """TrainOptions.sensor is now ``config`` (the --config it was given): a checkpoint that still says
    ``sensor`` resumes with it; options that are not a mapping are one line naming the file."""
    import dataclasses

    from tespike.recon.learning.weights import write_torch_file
    from tespike.recon.train import CHECKPOINT_KEYS, TrainOptions, read_checkpoint
    old = dataclasses.asdict(TrainOptions(config="ml-msb", steps=3))
    old["sensor"] = old.pop("config")
    path = tmp_path / "checkpoint.pt"
    write_torch_file(path, {**dict.fromkeys(CHECKPOINT_KEYS, 0), "options": old})
    _, options = read_checkpoint(path)
    assert options.config == "ml-msb" and options.sensor_config() == SensorConfig.preset("ml-msb")
    write_torch_file(path, {**dict.fromkeys(CHECKPOINT_KEYS, 0), "options": "te"})
    with pytest.raises(InputError, match="checkpoint.*holds options this trainer cannot take"):
        read_checkpoint(path)


@pytest.mark.parametrize("option, refusal", [
    ({"lr": "x"}, r"^learning rate 'x' must be in"), ({"lr": True}, r"^learning rate True must be in"),
    ({"checkpoint_seconds": -1}, r"^checkpoint_seconds = -1: must be a finite number >= 0$"),
    ({"threads": 0}, r"^threads = 0: must be an integer >= 1"), ({"threads": "2"}, r"^threads = '2': must be"),
    ({"config": 3}, r"^config = 3: must be a preset's name or a configuration's JSON text"),
    ({"recipe": 3}, r"^recipe = 3: must be a dict"), ({"init": 3}, r"^init: a path must be a str or an os.PathLike"),
])
def test_options_of_the_wrong_kind_are_refused_when_made(option, refusal):
    """As a library caller makes them (the command checks its flags first): each had been a TypeError
    there or later in the run ('lr': a comparison; 'config': json; 'recipe': a mapping), or taken
    (True as the rate 1, a checkpoint every -1 s, threads 0 until torch refused them)."""
    with pytest.raises(InputError, match=refusal):
        TrainOptions(steps=1, **option)


def test_the_loss_the_resume_switch_and_the_options_are_checked_in_one_line(tmp_path):
    """``training_loss(p, t, 'l2')`` (or None) had computed mu-l1 silently; ``train(..., resume='no')``
    resumed, ``train({}, out)`` was an AttributeError of ``device``."""
    t = torch.ones(2)
    for loss in ("l2", None):
        with pytest.raises(InputError, match=f"^loss = {loss!r}: must be one of l1, mu-l1$"):
            training_loss(t, t * 0, loss)
    with pytest.raises(InputError, match="^resume = 'no': must be True or False$"):
        train(TrainOptions(steps=1), tmp_path / "w.pt", resume="no")
    with pytest.raises(InputError, match="^train: the options must be TrainOptions, not dict$"):
        train({}, tmp_path / "w.pt")
    assert not list(tmp_path.iterdir())


def test_the_data_engine_refuses_recipes_clips_and_dead_leaves_it_would_misdraw_in_one_line():
    """A weight of '0.6' had been converted and an infinity taken (NaN probabilities at the first
    clip), a seed of -1 or 2.5 failed in the first clip, one panorama's name was read letter by letter,
    a missing folder was found at its first clip; a recipe's seed was replaced by the run's silently and
    a preset's misspelt name was "not valid JSON"; a clip index of -1 was numpy's error; dead leaves
    with a flicker period of 0 were NaN light and a size exponent of 1 a ZeroDivisionError."""
    from tespike.recon.engine.clips import make_clip
    from tespike.recon.engine.deadleaves import DeadLeavesParams, dead_leaves
    cases = [({"weights": (("deadleaves", "0.6"),)}, "engine recipe weights"),
             ({"weights": (("deadleaves", float("inf")),)}, "engine recipe weights"),
             ({"weights": (("deadleaves", 0.5), ("deadleaves", 0.5))}, "engine recipe weights: a family is named twice"),
             ({"seed": -1}, "engine recipe seed = -1"), ({"seed": 2.5}, "engine recipe seed = 2.5"),
             ({"panoramas": "city"}, "engine recipe panoramas 'city'"),
             ({"long": (48,)}, r"engine recipe long = \(48,\)"), ({"short_fraction": "0.3"}, "engine recipe short_fraction"),
             ({"peak": ("a", "b")}, r"engine recipe peak = \('a', 'b'\)"),
             ({"folders": ("/nonexistent-folder",)}, "engine recipe: folder '/nonexistent-folder' does not exist")]
    for fields, words in cases:
        with pytest.raises(InputError, match="^" + words):
            EngineRecipe(**fields)
    with pytest.raises(InputError, match="^engine recipe: must be a dict of its fields, not NoneType$"):
        EngineRecipe.from_dict(None)
    with pytest.raises(InputError, match="^recipe seed 5: the data engine's seed is the run's own"):
        TrainOptions(steps=1, recipe={"seed": 5})
    with pytest.raises(InputError, match=r"^config = 'tee': neither a preset \(te, ml, ml-msb\) nor"):
        TrainOptions(steps=1, config="tee")
    recipe = EngineRecipe(height=8, width=8)
    for index in (-1, 2.5, "0", True):
        with pytest.raises(InputError, match=f"^clip index {index!r}: must be an integer >= 0$"):
            make_clip(recipe, SensorConfig(), index)
    for fields, words in (({"flicker_period": (0.0, 0.0)}, "flicker_period"), ({"size_exponent": (1.0, 1.0)}, "size_exponent"),
                          ({"radius": (0.0, 0.5)}, "radius"), ({"soft_fraction": float("nan")}, "soft_fraction"),
                          ({"sources": (-1, 2)}, "sources")):
        with pytest.raises(InputError, match=f"^dead leaves {words} = "):
            DeadLeavesParams(**fields)
    with pytest.raises(InputError, match=r"^dead leaves of 0 x 8 x 8: frames, height and width must be integers >= 1$"):
        dead_leaves(np.random.default_rng(0), 0, 8, 8)
