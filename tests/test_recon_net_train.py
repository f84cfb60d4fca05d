"""recon.net.train and ``tespike train``: a few steps, the log and plot, resume equal to one run."""

import csv

import pytest
import torch

from golden.config import SensorConfig
from golden.errors import InputError
from recon.net.infer import load_weights
from recon.net.train import TrainOptions, train, training_loss
from tests.cli import assert_refused, run_tespike

RECIPE = {"sequences": 2, "frames": 64, "height": 32, "width": 32}


def options(**kw):
    base = dict(steps=4, crop=32, batch=2, recipe=RECIPE, checkpoint_seconds=1e9, threads=1)
    return TrainOptions(**{**base, **kw})


def test_a_few_steps_write_weights_log_and_plot(tmp_path):
    out = train(options(), tmp_path / "w.pt", cache=tmp_path / "cache")
    model, config, meta = load_weights(out)
    assert config.mode == "te" and meta["steps"] == 4 and meta["parameters"] > 0
    with open(tmp_path / "w.run" / "log.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["step"]) for r in rows] == [1, 2, 3, 4]
    assert (tmp_path / "w.run" / "loss.png").stat().st_size > 1000


def test_resume_continues_exactly(tmp_path):
    cache = tmp_path / "cache"
    straight = train(options(steps=4), tmp_path / "a.pt", cache=cache)
    train(options(steps=2), tmp_path / "b.pt", cache=cache)
    resumed = train(options(steps=4), tmp_path / "b.pt", cache=cache, resume=True)
    a, b = (load_weights(p)[0].state_dict() for p in (straight, resumed))
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_resume_refuses_other_options(tmp_path):
    cache = tmp_path / "cache"
    train(options(steps=1), tmp_path / "c.pt", cache=cache)
    with pytest.raises(InputError, match="other options"):
        train(options(steps=2, loss="mu-l1"), tmp_path / "c.pt", cache=cache, resume=True)


def test_losses():
    pred, truth = torch.tensor([0.5, 0.0]), torch.tensor([0.25, 0.0])
    assert float(training_loss(pred, truth, "l1")) == pytest.approx(0.125)
    assert float(training_loss(truth, truth, "mu-l1")) == 0.0
    with pytest.raises(InputError, match="loss"):
        TrainOptions(steps=1, loss="l2")
    with pytest.raises(InputError, match="budget"):
        TrainOptions()


def test_ablation_case_trains_the_switched_network(tmp_path):
    out = train(options(steps=1, ablation=4), tmp_path / "a.pt", cache=tmp_path / "cache")
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
    assert not (tmp_path / "w.pt").exists()


def test_user_hdr_folders_join_the_training_set(tmp_path):
    import numpy as np

    from recon.net.data import DataRecipe, training_set
    from recon.scenes import write_hdr
    folder = tmp_path / "seq"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(64):
        write_hdr(folder / f"f{k:03d}.hdr", rng.uniform(0.01, 3.0, (40, 36, 3)).astype(np.float32))
    recipe = DataRecipe(**{**RECIPE, "folders": (str(folder),)})
    light, words = training_set(SensorConfig(), recipe, cache=tmp_path / "cache")
    assert light.shape == words.shape == (3, 64, 32, 32)
    assert float(light[2].max()) == 1.0                      # normalised per sequence
    assert recipe.key() != DataRecipe(**RECIPE).key()
    with pytest.raises(InputError, match="less than"):
        training_set(SensorConfig(), DataRecipe(**{**RECIPE, "folders": (str(folder),), "height": 48}),
                     cache=tmp_path / "cache")


def test_cache_key_tells_shipped_from_full_size_panoramas(monkeypatch, tmp_path):
    """Light from the shipped 128 x 256 copies differs from the full-size files': other cache files."""
    from recon.net.data import DataRecipe
    monkeypatch.delenv("TESPIKE_HDRI_DIR", raising=False)
    shipped = DataRecipe(**RECIPE).key()
    monkeypatch.setenv("TESPIKE_HDRI_DIR", str(tmp_path))
    assert DataRecipe(**RECIPE).key() != shipped
