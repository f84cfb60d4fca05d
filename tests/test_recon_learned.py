"""tespike.recon.learned and the registry's learned methods: weights per method and preset, refusals in one line.

Weights are tiny ones made here in a temporary folder (``WEIGHTS_DIR`` patched): no
test depends on shipped baseline weights.
"""

from pathlib import Path

import numpy as np
import pytest
import torch

import tespike.recon.learned
from tespike import recon
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.io import save_stream
from tespike.recon.learned import LEARNED, method_classes, method_span, weights_path
from tespike.recon.methods import RECON_METHODS, available_methods, missing_weights, reconstruct
from tespike.golden.decode import legal_words

TE, ML = SensorConfig.preset("te"), SensorConfig.preset("ml")


def save_tiny(folder, method, config, file_name=None, seed=0):
    """Weights of ``method`` at its cpu size (random, seeded) saved as the shipped form."""
    from tespike.recon.learning.weights import save_weights
    torch.manual_seed(seed)
    module, sizes = method_classes(method)
    model = module(sizes.preset("cpu")).eval()
    path = folder / (file_name or recon.learned.weights_name(method, "te" if config == TE else "ml"))
    save_weights(path, model, config, {"test": True}, method)
    return path, model


def tiny_stream(rng, config=TE, shape=(5, 8, 8)):
    return rng.choice(legal_words(config), size=shape)


def test_registry_has_every_learned_method_as_a_spatial_method():
    assert tuple(RECON_METHODS) == ("tfp", "tfi", *LEARNED)
    assert LEARNED == ("spk2imgnet", "bsf", "mambaspike1", "mambaspike", "net")
    for name in LEARNED:
        assert RECON_METHODS[name].frames is not None and RECON_METHODS[name].block is None
        assert "window" not in RECON_METHODS[name].options
        assert method_span(name) == method_classes(name)[1].preset("cpu").span


@pytest.mark.parametrize("name", LEARNED)
def test_every_learned_module_refuses_an_input_of_the_wrong_shape(name):
    """One rule for every module (the sizes' check_input): (N, span, H, W), H and W multiples of the
    pyramid factor; anything else is refused before a layer runs."""
    module, sizes_class = method_classes(name)
    sizes = sizes_class.preset("cpu")
    model = module(sizes).eval()
    span, f = sizes.span, sizes.pyramid_factor
    for bad in (torch.zeros(span, f, f), torch.zeros(1, span + 2, f, f), torch.zeros(1, span, f + 1, f),
                torch.zeros(1, span, f, 2 * f - 1)):
        with pytest.raises(ValueError, match="need"):
            model(bad, None, 0.01)


def test_weights_folder_is_beside_the_registry():
    folder = Path(recon.learned.__file__).resolve().parent / "weights"
    assert recon.learned.WEIGHTS_DIR == folder
    assert weights_path(TE, "net") == folder / "te.pt"             # the shipped network
    assert recon.learned.weights_name("bsf", "ml-msb") == "bsf-ml-msb.pt"


def test_a_baseline_reconstructs_with_its_weights(empty_weights_dir, rng):
    path, model = save_tiny(empty_weights_dir, "bsf", TE)
    assert weights_path(TE, "bsf") == path == empty_weights_dir / "bsf-te.pt"
    words = tiny_stream(rng)
    from tespike.recon.learning.infer import reconstruct_model
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
    # a TE configuration whose short name is the preset's (ML keys left out): the message said what differs
    with pytest.raises(InputError, match=r"\(ml_bits = 4 in the stream, 8 in the te preset\) is none of the presets"):
        weights_path(SensorConfig(ml_bits=4), "bsf")


def test_weights_of_another_method_or_sensor_are_refused(empty_weights_dir, rng):
    save_tiny(empty_weights_dir, "spk2imgnet", TE, file_name="bsf-te.pt")
    with pytest.raises(InputError, match=r"holds spk2imgnet weights \(a Spk2ImgNet\), not bsf.s BSF"):
        reconstruct(tiny_stream(rng), TE, "bsf")
    save_tiny(empty_weights_dir, "spk2imgnet", ML, file_name="spk2imgnet-te.pt")
    with pytest.raises(InputError, match="were trained for"):
        reconstruct(tiny_stream(rng), TE, "spk2imgnet")


def run_here(capsys, *args):
    from tespike.cosim.cli import main
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


def test_cli_reconstruct_with_weights_the_user_trained(empty_weights_dir, tmp_path, rng, capsys):
    """--weights: your own file, checked against the method and the stream's configuration; a
    configuration without shipped weights is told to train and pass --weights, which then works."""
    own = SensorConfig(b1=3, b2=3)
    path, _ = save_tiny(tmp_path, "bsf", own, file_name="mine.pt")
    words = tiny_stream(rng, own)
    stream, out = tmp_path / "S.npz", tmp_path / "R.npy"
    save_stream(stream, words, own)
    code, _, err = run_here(capsys, "reconstruct", "--stream", stream, "--method", "bsf", "--out", out)
    assert code != 0 and "train weights" in err and "--weights W.pt" in err and len(err.strip().splitlines()) == 1
    code, _, err = run_here(capsys, "reconstruct", "--stream", stream, "--method", "bsf", "--weights", path,
                            "--out", out)
    assert code == 0, err
    assert np.array_equal(np.load(out), reconstruct(words, own, "bsf", weights=path))
    out.unlink()
    save_stream(tmp_path / "T.npz", tiny_stream(rng), TE)
    (tmp_path / "empty.pt").write_bytes(b"")
    for args, word in [(("--stream", stream, "--method", "net", "--weights", path), "holds bsf weights (a BSF), not net's"),
                       (("--stream", tmp_path / "T.npz", "--method", "bsf", "--weights", path), "were trained for"),
                       (("--stream", stream, "--method", "tfi", "--weights", path), "--weights applies"),
                       (("--stream", stream, "--method", "bsf", "--weights", tmp_path / "empty.pt"), "empty"),
                       (("--stream", stream, "--method", "bsf", "--weights", tmp_path / "none.pt"), "none.pt")]:
        code, _, err = run_here(capsys, "reconstruct", *args, "--out", out)
        lines = err.strip().splitlines()
        assert code != 0 and len(lines) == 1 and word in lines[0], err
        assert not out.exists()


def test_evaluate_refuses_weights_for_a_method_it_does_not_run(tmp_path, capsys):
    """--weights of a method not in --methods would be ignored: refused, naming the method."""
    path, _ = save_tiny(tmp_path, "bsf", TE, file_name="mine.pt")
    code, _, err = run_here(capsys, "evaluate", "--methods", "tfp", "--weights", path, "--out", tmp_path / "ev")
    lines = err.strip().splitlines()
    assert code != 0 and len(lines) == 1 and "bsf is not among the methods" in lines[0], err
    assert not (tmp_path / "ev").exists()


def test_weights_by_sensor(tmp_path):
    from tespike.recon.learned import weights_by_sensor
    te_file, _ = save_tiny(tmp_path, "bsf", TE, file_name="a.pt")
    ml_file, _ = save_tiny(tmp_path, "net", ML, file_name="b.pt")
    configs = {"te": TE, "ml": ML, "noisy": TE}
    assert weights_by_sensor([te_file, ml_file], configs) == {("bsf", "te"): te_file, ("bsf", "noisy"): te_file,
                                                             ("net", "ml"): ml_file}
    with pytest.raises(InputError, match="b.pt' were trained for .*none of the sensors evaluated"):
        weights_by_sensor([ml_file], {"te": TE})
    with pytest.raises(InputError, match="both bsf weights for the te sensor"):
        weights_by_sensor([te_file, te_file], {"te": TE})


def test_mambaspike_and_mambaspike1_weights_are_told_apart_by_the_method_recorded(empty_weights_dir, rng, tmp_path):
    """Both methods build the same module class: mambaspike1's file was taken as mambaspike's (rc 0)."""
    from tespike.recon.learned import load_weights, weights_by_sensor, weights_method
    one, _ = save_tiny(empty_weights_dir, "mambaspike1", TE, file_name="mambaspike-te.pt")
    with pytest.raises(InputError, match="holds mambaspike1 weights .*not mambaspike's"):
        reconstruct(tiny_stream(rng), TE, "mambaspike")
    assert weights_method(one) == "mambaspike1" and load_weights(one, method="mambaspike1")[1] == TE
    assert weights_by_sensor([one], {"te": TE}) == {("mambaspike1", "te"): one}


def test_a_weights_file_whose_method_is_not_a_name_is_one_line(tmp_path, rng):
    from tespike.recon.learned import load_weights
    path, _ = save_tiny(tmp_path, "net", TE, file_name="w.pt")
    payload = torch.load(path, weights_only=False)
    for field, value, word in (("method", ["net"], "is not a method's name"), ("meta", [1], "not a mapping")):
        torch.save({**payload, field: value}, tmp_path / "c.pt")
        with pytest.raises(InputError, match=word):
            load_weights(tmp_path / "c.pt")


def test_demo_refuses_weights_it_would_not_run(tmp_path, capsys):
    """The demo runs a learned method only with weights for every sensor: one file for one sensor was ignored."""
    path, _ = save_tiny(tmp_path, "mambaspike1", TE, file_name="m1.pt")
    code, _, err = run_here(capsys, "demo", "--sensors", "te,ml", "--weights", path, "--out", tmp_path / "d")
    lines = err.strip().splitlines()
    assert code != 0 and len(lines) == 1 and "mambaspike1" in lines[0] and "none for ml " in lines[0], err
    assert not (tmp_path / "d").exists()


def test_weights_of_absurd_scale_or_size_are_refused_naming_the_file(tmp_path, rng):
    """Finite weights times 1e30 passed the NaN check and wrote a light file of NaN (rc 0); sizes no
    machine holds failed as a bare 'out of memory' naming no file."""
    from tespike.recon.learned import load_weights
    path, _ = save_tiny(tmp_path, "net", TE, file_name="w.pt")
    payload = torch.load(path, weights_only=False)
    scaled = {k: v * 1e30 if v.is_floating_point() else v for k, v in payload["state_dict"].items()}
    torch.save({**payload, "state_dict": scaled}, tmp_path / "big.pt")
    with pytest.raises(InputError, match="big.pt.* not finite"):
        reconstruct(tiny_stream(rng, shape=(5, 16, 16)), TE, "net", weights=tmp_path / "big.pt")
    sizes = dict(payload["sizes"])
    key = next(k for k, v in sizes.items() if isinstance(v, int) and not isinstance(v, bool) and v > 4)
    torch.save({**payload, "sizes": {**sizes, key: 10 ** 6}}, tmp_path / "huge.pt")
    with pytest.raises(InputError, match="huge.pt"):
        load_weights(tmp_path / "huge.pt")
