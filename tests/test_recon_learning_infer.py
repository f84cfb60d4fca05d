"""tespike.recon.learning.infer: any learned method on any stream length and frame size, tiles equal to the whole frame, stiff inputs."""

import warnings

import numpy as np
import pytest
import torch

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.fastsim import simulate_scene
import tespike.recon.learning.infer as infer
from tespike.recon.learned import load_weights, weights_path
from tespike.recon.learning.infer import MIRROR_BORDER, default_tile, frame, mirrored_index, tile_margin, tiles
from tespike.recon.learning.weights import save_weights
from tespike.recon.methods import reconstruct
from tespike.recon.net.model import TESpikeNet
from tespike.recon.net.sizes import NetSizes

TINY = NetSizes(channels=8, heads=2, window=3, stride=2, unshuffle=2, levels=2, max_offset=1.0,
                attention_window=3)


def random_weights(path, config, sizes=TINY, seed=0):
    """A network with random (non-zero) weights everywhere, so every input pixel matters."""
    torch.manual_seed(seed)
    model = TESpikeNet(sizes)
    with torch.no_grad():
        for p in model.parameters():
            p.normal_(0.0, 0.05)
    save_weights(path, model, config, {"what": "random test weights"}, "net")
    return path


@pytest.fixture
def te_weights(tmp_path):
    return random_weights(tmp_path / "te.pt", SensorConfig())


def test_tiles_equal_the_whole_frame(te_weights):
    model, config, _ = load_weights(te_weights)
    margin = tile_margin(model)
    rng = np.random.default_rng(1)
    words = simulate_scene(config, rng.uniform(0, 1, (12, 20, 3 * margin)).astype(np.float32), seed=2)
    with torch.inference_mode():
        whole = frame(model, words, config, 5, tile=None)
        tiled = frame(model, words, config, 5, tile=2 * model.sizes.pyramid_factor)
    assert whole.shape == (20, 3 * margin)
    assert torch.allclose(whole, tiled, rtol=1e-4, atol=1e-6), (whole - tiled).abs().max()


def test_far_pixels_do_not_matter(te_weights):
    """The receptive field is finite (bounded offsets, local attention): the tile margin is honest,
    on both sides (a pixel before the centre as well as after it: no running sum across the frame)."""
    model, config, _ = load_weights(te_weights)
    margin = tile_margin(model)
    width = 2 * margin + 16
    words = np.random.default_rng(5).integers(0, 16, (6, 8, width)).astype(np.uint8)
    with torch.inference_mode():
        a = frame(model, words, config, 3)
        for column, kept in ((-1, slice(0, 8)), (0, slice(width - 8, width))):
            changed = words.copy()
            changed[:, :, column] = 15 - changed[:, :, column]
            b = frame(model, changed, config, 3)
            assert torch.equal(a[:, kept], b[:, kept])
            assert not torch.equal(a, b)


def test_tile_policy():
    """Default core: two margins; an axis within core + margin is not cut; smaller tiles are accepted."""
    tiny = TESpikeNet(TINY)
    f, margin = TINY.pyramid_factor, tile_margin(tiny)
    core = default_tile(tiny)
    assert core == 2 * margin and core % f == 0
    assert tiles(core + margin, 5 * core, tiny) == [(0, x, core + margin, min(core, 5 * core - x))
                                                    for x in range(0, 5 * core, core)]
    assert tiles(core, core, tiny) == [(0, 0, core, core)]                          # runs whole
    assert len(tiles(3 * margin, 40 * f, tiny, f)) == 3 * margin // f * 40         # smaller than the margin: fine
    assert tiles(10, 10, tiny, None) == [(0, 0, 12, 12)]                          # padded to f = 4
    with pytest.raises(InputError, match="multiple of the pyramid factor"):
        tiles(64, 64, tiny, f + 1)


@pytest.mark.parametrize("length", [1, 2, 3, 9, 17, 64])
def test_mirrored_index(length):
    """The frame, mirrored by MIRROR_BORDER or more on each side, to a multiple of the pyramid factor."""
    f = TINY.pyramid_factor
    index, first = mirrored_index(length, f), MIRROR_BORDER
    assert len(index) % f == 0 and len(index) >= length + 2 * MIRROR_BORDER
    assert (index[first:first + length] == np.arange(length)).all()
    assert index.min() == 0 and index.max() == length - 1
    if length > 1:
        assert (index[first - 1::-1][:length - 1] == np.arange(1, length)[:first]).all()           # reflected
        assert (index[first + length:][:length - 1] == np.arange(length - 2, -1, -1)[:len(index) - first - length]).all()


def test_the_network_sees_the_frame_mirrored(te_weights, monkeypatch):
    """Equal to the network on the explicitly mirrored frame (np.pad "reflect"), cut back."""
    model, config, _ = load_weights(te_weights)
    words = np.random.default_rng(4).integers(0, 16, (5, 11, 14)).astype(np.uint8)
    rows, cols = mirrored_index(11, model.sizes.pyramid_factor), mirrored_index(14, model.sizes.pyramid_factor)
    top = left = MIRROR_BORDER
    padded = np.pad(words, ((0, 0), (top, len(rows) - 11 - top), (left, len(cols) - 14 - left)), mode="reflect")
    with torch.inference_mode():
        got = frame(model, words, config, 2)
        monkeypatch.setattr(infer, "MIRROR_BORDER", 0)
        reference = frame(model, padded, config, 2)[top:top + 11, left:left + 14]
    assert torch.allclose(got, reference, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("shape", [(1, 1, 1), (1, 5, 7), (3, 17, 9), (TINY.span + 4, 6, 33)])
def test_any_length_and_size(te_weights, shape):
    words = np.random.default_rng(0).integers(0, 16, shape).astype(np.uint8)
    out = reconstruct(words, SensorConfig(), "net", weights=te_weights)
    assert out.shape == shape and out.dtype == np.float32 and np.isfinite(out).all()


def stiff_streams(config):
    top = (1 << config.d) | 1                        # TE: overflow in the first S_h cycle
    rng = np.random.default_rng(3)
    decades = (10.0 ** np.linspace(-8, 4, 48))[None, None, :].repeat(8, 0).repeat(5, 1)
    return {"zeros": np.zeros((8, 5, 48), np.uint8), "top": np.full((8, 5, 48), top, np.uint8),
            "decades": simulate_scene(config, decades.astype(np.float32), seed=rng),
            "one readout": np.full((1, 5, 48), 7, np.uint8)}


@pytest.mark.parametrize("name", ["zeros", "top", "decades", "one readout"])
def test_stiff_streams_are_finite_without_warnings(te_weights, name):
    config = SensorConfig()
    words = stiff_streams(config)[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = reconstruct(words, config, "net", weights=te_weights)
    assert np.isfinite(out).all() and (out >= 0).all()


def test_weights_for_another_configuration_are_refused(te_weights):
    with pytest.raises(InputError, match="trained for another configuration than the stream.s: mode = .ml. in the stream, .te. in the weights"):
        reconstruct(np.zeros((2, 3, 3), np.uint8), SensorConfig(mode="ml"), "net", weights=te_weights)
    with pytest.raises(InputError, match="none of the presets"):
        weights_path(SensorConfig(b1=3))


def test_a_weights_file_whose_configuration_lacks_a_key_is_refused(tmp_path):
    """A recorded configuration holds every key (as a stream's does): one without its threshold
    is refused, not read with the default threshold."""
    import torch
    payload = torch.load(weights_path(SensorConfig.preset("te")), map_location="cpu", weights_only=True)
    del payload["config"]["threshold"]
    torch.save(payload, tmp_path / "lacking.pt")
    with pytest.raises(InputError, match="lacks key 'threshold'"):
        load_weights(tmp_path / "lacking.pt")


def test_a_weights_path_that_is_no_regular_file_is_refused_at_once(tmp_path):
    """A FIFO given as --weights blocked reconstruct, evaluate and demo for good (opening it waits
    for a writer); a folder was read as a file."""
    import os
    os.mkfifo(tmp_path / "w.pt")
    with pytest.raises(InputError, match="'.*w.pt' is a FIFO, not a regular file"):
        load_weights(tmp_path / "w.pt")
    with pytest.raises(InputError, match="is a directory, not a regular file"):
        load_weights(tmp_path)


def test_not_a_weights_file_is_refused(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a torch file")
    with pytest.raises(InputError, match="not a tespike weights file"):
        load_weights(bad)


class _Runs:
    """A pickled object whose loading would run a shell command."""

    def __reduce__(self):
        import os
        return (os.system, ("echo loaded",))


def test_a_weights_file_holding_code_is_refused_without_torchs_unsafe_advice(tmp_path):
    """torch's refusal advised loading with weights_only=False, which would run the file's code."""
    path = tmp_path / "evil.pt"
    torch.save({"x": _Runs()}, path)
    with pytest.raises(InputError) as refused:
        load_weights(path)
    message = str(refused.value)
    assert "not loaded, as loading could run code" in message and "posix.system" in message, message
    assert "weights_only" not in message and "will likely succeed" not in message


@pytest.mark.parametrize("keep", ["one byte", "half", "all but one byte"])
def test_a_cut_short_weights_file_is_named_in_our_words(tmp_path, keep):
    """torch's own first line for a cut-short file speaks of weights_only defaults or of an
    internal assert, cut mid-word: the refusal says what the file is instead."""
    whole = weights_path(SensorConfig.preset("te")).read_bytes()
    cut = tmp_path / "cut.pt"
    cut.write_bytes(whole[:{"one byte": 1, "half": len(whole) // 2, "all but one byte": len(whole) - 1}[keep]])
    with pytest.raises(InputError) as refused:
        load_weights(cut)
    message = str(refused.value)
    assert "not a zip archive as torch writes: cut short, or another format" in message
    assert "weights_only" not in message and "PytorchStreamReader" not in message


@pytest.mark.parametrize("fault, words", [
    ("sizes none", "network sizes must be a mapping of size keys, not NoneType"),     # a traceback before
    ("nan tensor", "tensor 'encoder.embed.weight' holds a value that is not finite"),   # an R.npy of NaN, rc 0
    ("short tensor", "size mismatch for encoder.embed.weight"),                         # torch's first line alone
    ("int64 tensor", "tensor 'encoder.embed.weight' is torch.int64, not the module's torch.float32"),  # cast, rc 0
    ("float64 tensor", "tensor 'encoder.embed.weight' is torch.float64"),
])
def test_weights_that_cannot_give_light_are_refused_naming_why(tmp_path, fault, words):
    import torch
    payload = torch.load(weights_path(SensorConfig.preset("te")), weights_only=True)
    state = dict(payload["state_dict"])
    if fault == "sizes none":
        payload = {**payload, "sizes": None}
    elif fault == "nan tensor":
        state["encoder.embed.weight"] = state["encoder.embed.weight"] * float("nan")
    elif fault.endswith("64 tensor"):
        state["encoder.embed.weight"] = state["encoder.embed.weight"].to(getattr(torch, fault.split()[0]))
    else:
        state["encoder.embed.weight"] = state["encoder.embed.weight"][:1]
    torch.save({**payload, "state_dict": state} if fault != "sizes none" else payload, tmp_path / "w.pt")
    with pytest.raises(InputError, match="w.pt") as refused:
        load_weights(tmp_path / "w.pt")
    assert words in str(refused.value)


# -- the shipped weights, through the command line ---------------------------------------------
from tests.cli import assert_refused, run_tespike  # noqa: E402


@pytest.mark.parametrize("preset", ["te", "ml", "ml-msb"])
def test_shipped_weights_match_their_preset(preset):
    config = SensorConfig.preset(preset)
    model, trained_for, meta = load_weights(weights_path(config))
    assert trained_for == config and meta["steps"] > 0 and "tespike train" in meta["command"]


def test_cli_reconstruct_net(tmp_path):
    from tespike.golden.io import save_stream
    config = SensorConfig()
    light = np.random.default_rng(4).uniform(0.001, 0.5, (5, 9, 11)).astype(np.float32)
    save_stream(tmp_path / "S.npz", simulate_scene(config, light, seed=1), config)
    result = run_tespike("reconstruct", "--stream", tmp_path / "S.npz", "--method", "net", "--out", tmp_path / "R.npy")
    assert result.returncode == 0, result.stderr
    images = np.load(tmp_path / "R.npy")
    assert images.shape == (5, 9, 11) and images.dtype == np.float32 and np.isfinite(images).all()
    other = SensorConfig(b1=3, b2=3)
    save_stream(tmp_path / "O.npz", np.zeros((2, 3, 3), np.uint8), other)
    assert_refused(run_tespike("reconstruct", "--stream", tmp_path / "O.npz", "--method", "net",
                               "--out", tmp_path / "O.npy"), "none of the presets")
    assert not (tmp_path / "O.npy").exists()
    assert_refused(run_tespike("reconstruct", "--stream", tmp_path / "S.npz", "--method", "net", "--window", "5",
                               "--out", tmp_path / "W.npy"), "--window")


def test_inference_refuses_a_key_stream_model_or_calibration_it_cannot_use_in_one_line():
    """A key past the stream had repeated its last readout (or was head.py's ValueError), 2.5 an
    IndexError; a list of words an AttributeError, 2-D words an unpacking error, a model's name an
    AttributeError; law_input without a Calibration an AttributeError of ``law_tensors``; a pyramid
    factor of 0 a ZeroDivisionError; key_span of a fractional span gave floats."""
    from tespike.recon.learning.span import key_span
    config = SensorConfig()
    model = load_weights(weights_path(config))[0]
    words = np.zeros((12, 8, 8), np.uint8)
    for key in (100, 12, -1, 2.5, "3"):
        with pytest.raises(InputError, match=rf"^key readout {key!r}: must be an integer in 0 \.\. 11"):
            frame(model, words, config, key)
    for bad in ([[1]], np.zeros((8, 8), np.uint8), np.zeros((0, 8, 8), np.uint8)):
        with pytest.raises(InputError, match=r"^words shape .* must be \(K, H, W\) with K, H, W >= 1$"):
            frame(model, bad, config, 0)
    with pytest.raises(InputError, match="^words: readout words dtype float64 is not an integer type$"):
        frame(model, words.astype(float), config, 0)
    with pytest.raises(InputError, match="^model: must be a learned method's module"):
        frame("net", words, config, 0)
    for calibration in (None, "C.npz"):
        with pytest.raises(InputError, match="^law_input's calibration must be a Calibration"):
            infer.law_input(words, config, calibration)
    with pytest.raises(InputError, match="^mirrored_index: length 5 and factor 0 must be integers >= 1$"):
        mirrored_index(5, 0)
    with pytest.raises(InputError, match="^readouts 5 and span 2.5: must be integers >= 1$"):
        key_span(5, 2, 2.5)
    assert frame(model, words, config, 11).shape == (8, 8)
