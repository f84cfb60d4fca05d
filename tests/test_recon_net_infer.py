"""recon.net.infer: any stream length and frame size, tiles equal to the whole frame, stiff inputs."""

import dataclasses
import warnings

import numpy as np
import pytest
import torch

from golden.config import SensorConfig
from golden.errors import InputError
from golden.fastsim import simulate_scene
from recon.net.infer import frame, load_weights, reconstruct_net, tile_margin, weights_path
from recon.net.model import TESpikeNet
from recon.net.sizes import NetSizes
from recon.net.train import save_weights

TINY = NetSizes(channels=8, heads=2, window=3, stride=2, unshuffle=2, levels=2, max_offset=1.0,
                attention_window=3)


def random_weights(path, config, sizes=TINY, seed=0):
    """A network with random (non-zero) weights everywhere, so every input pixel matters."""
    torch.manual_seed(seed)
    model = TESpikeNet(sizes)
    with torch.no_grad():
        for p in model.parameters():
            p.normal_(0.0, 0.05)
    save_weights(path, model, config, {"what": "random test weights"})
    return path


@pytest.fixture
def te_weights(tmp_path):
    return random_weights(tmp_path / "te.pt", SensorConfig())


def test_tiles_equal_the_whole_frame(te_weights):
    model, config, _ = load_weights(te_weights)
    margin = tile_margin(model.sizes)
    rng = np.random.default_rng(1)
    words = simulate_scene(config, rng.uniform(0, 1, (12, 20, 3 * margin)).astype(np.float32), seed=2)
    with torch.inference_mode():
        whole = frame(model, words, config, 5, tile=None)
        tiled = frame(model, words, config, 5, tile=2 * model.sizes.pyramid_factor)
    assert whole.shape == (20, 3 * margin)
    assert torch.allclose(whole, tiled, rtol=1e-4, atol=1e-6), (whole - tiled).abs().max()


def test_far_pixels_do_not_matter(te_weights):
    """The receptive field is finite (bounded offsets, local attention): the tile margin is honest."""
    model, config, _ = load_weights(te_weights)
    margin = tile_margin(model.sizes)
    width = 2 * margin + 16
    words = np.zeros((6, 8, width), np.uint8)
    changed = words.copy()
    changed[:, :, -1] = 15
    with torch.inference_mode():
        a, b = (frame(model, w, config, 3) for w in (words, changed))
    assert torch.allclose(a[:, :8], b[:, :8], atol=1e-6)
    assert not torch.allclose(a[:, -8:], b[:, -8:])


@pytest.mark.parametrize("shape", [(1, 1, 1), (1, 5, 7), (3, 17, 9), (TINY.span + 4, 6, 33)])
def test_any_length_and_size(te_weights, shape):
    words = np.random.default_rng(0).integers(0, 16, shape).astype(np.uint8)
    out = reconstruct_net(words, SensorConfig(), weights=te_weights)
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
        out = reconstruct_net(words, config, weights=te_weights)
    assert np.isfinite(out).all() and (out >= 0).all()


def test_weights_for_another_configuration_are_refused(te_weights):
    with pytest.raises(InputError, match="trained for.*te-.*the stream is ml-"):
        reconstruct_net(np.zeros((2, 3, 3), np.uint8), SensorConfig(mode="ml"), weights=te_weights)
    with pytest.raises(InputError, match="none of them"):
        weights_path(SensorConfig(b1=3))


def test_not_a_weights_file_is_refused(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a torch file")
    with pytest.raises(InputError, match="not a tespike weights file"):
        load_weights(bad)
