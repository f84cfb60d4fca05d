"""recon.learned and the registry's learned methods: weights per method and preset, refusals in one line.

Weights are tiny ones made here in a temporary folder (``WEIGHTS_DIR`` patched): no
test depends on shipped baseline weights.
"""

from pathlib import Path

import numpy as np
import pytest
import torch

import recon.learned
from golden.config import SensorConfig
from golden.errors import InputError
from golden.io import save_stream
from recon.learned import LEARNED, method_classes, method_span, weights_path
from recon.methods import RECON_METHODS, available_methods, missing_weights, reconstruct
from recon.stream import legal_codes

TE, ML = SensorConfig.preset("te"), SensorConfig.preset("ml")


def save_tiny(folder, method, config, file_name=None, seed=0):
    """Weights of ``method`` at its cpu size (random, seeded) saved as the shipped form."""
    from recon.net.train import save_weights
    torch.manual_seed(seed)
    module, sizes = method_classes(method)
    model = module(sizes.preset("cpu")).eval()
    path = folder / (file_name or recon.learned.weights_name(method, "te" if config == TE else "ml"))
    save_weights(path, model, config, {"test": True}, method)
    return path, model


def tiny_stream(rng, config=TE, shape=(5, 8, 8)):
    return rng.choice(legal_codes(config), size=shape)


def test_registry_has_every_learned_method_as_a_spatial_method():
    assert tuple(RECON_METHODS) == ("tfp", "tfi", *LEARNED)
    assert LEARNED == ("spk2imgnet", "bsf", "mambaspike", "net")
    for name in LEARNED:
        assert RECON_METHODS[name].frames is not None and RECON_METHODS[name].block is None
        assert "window" not in RECON_METHODS[name].options
        assert method_span(name) == method_classes(name)[1].preset("cpu").span


def test_weights_folder_is_the_networks():
    import recon.net
    folder = Path(recon.net.__file__).resolve().parent / "weights"
    assert recon.learned.WEIGHTS_DIR == folder
    assert weights_path(TE, "net") == folder / "te.pt"             # the shipped network
    assert recon.learned.weights_name("bsf", "ml-msb") == "bsf-ml-msb.pt"


def test_a_baseline_reconstructs_with_its_weights(empty_weights_dir, rng):
    path, model = save_tiny(empty_weights_dir, "bsf", TE)
    assert weights_path(TE, "bsf") == path == empty_weights_dir / "bsf-te.pt"
    words = tiny_stream(rng)
    from recon.net.infer import reconstruct_model
    images = reconstruct(words, TE, "bsf")
    assert images.shape == (5, 8, 8) and images.dtype == np.float32 and np.isfinite(images).all()
    assert np.array_equal(images, reconstruct_model(model, words, TE))
    assert missing_weights("bsf", TE) is None and available_methods([TE]) == ("tfp", "tfi", "bsf")


def test_missing_weights_are_refused_naming_the_file_and_the_training(empty_weights_dir, rng):
    with pytest.raises(InputError, match=r"mambaspike-te\.pt' is missing .*tespike train --method mambaspike "
                                         r"--config te"):
        reconstruct(tiny_stream(rng), TE, "mambaspike")
    assert "mambaspike-te.pt" in missing_weights("mambaspike", TE)
    assert missing_weights("tfp", TE) is None
    odd = SensorConfig(threshold=200)
    with pytest.raises(InputError, match="none of the presets"):
        weights_path(odd, "bsf")


def test_weights_of_another_method_or_sensor_are_refused(empty_weights_dir, rng):
    save_tiny(empty_weights_dir, "spk2imgnet", TE, file_name="bsf-te.pt")
    with pytest.raises(InputError, match="hold a Spk2ImgNet, not bsf's BSF"):
        reconstruct(tiny_stream(rng), TE, "bsf")
    save_tiny(empty_weights_dir, "spk2imgnet", ML, file_name="spk2imgnet-te.pt")
    with pytest.raises(InputError, match="were trained for"):
        reconstruct(tiny_stream(rng), TE, "spk2imgnet")


def run_here(capsys, *args):
    from cosim.cli import main
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_reconstruct_with_a_baseline(empty_weights_dir, tmp_path, rng, capsys):
    _, model = save_tiny(empty_weights_dir, "bsf", TE)
    words = tiny_stream(rng)
    stream = tmp_path / "S.npz"
    save_stream(stream, words, TE)
    out = tmp_path / "R.npy"
    code, _, err = run_here(capsys, "reconstruct", "--stream", stream, "--method", "bsf", "--out", out)
    assert code == 0, err
    assert np.array_equal(np.load(out), reconstruct(words, TE, "bsf"))
    out.unlink()
    for args, word in [(("--method", "mambaspike"), "mambaspike-te.pt' is missing"),
                       (("--method", "bsf", "--window", "5"), "'bsf' sees the 61 readouts its sizes fix"),
                       (("--method", "bsf", "--search", "window"), "--search applies to method 'tfi'")]:
        code, _, err = run_here(capsys, "reconstruct", "--stream", stream, *args, "--out", out)
        lines = err.strip().splitlines()
        assert code != 0 and len(lines) == 1 and word in lines[0], err
        assert not out.exists() and not list(tmp_path.glob("*.part"))
