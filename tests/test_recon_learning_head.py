"""The shared output head: its estimates equal TFP and TFI, and an untrained head returns their initial blend."""

import dataclasses

import numpy as np
import pytest
import torch

from tespike.golden.config import SensorConfig
from tespike.golden.fastsim import simulate_scene
from tespike.recon.learning.head import INITIAL_LOGITS, RADII, BlendHead, key_estimates, spike_interval_light
from tespike.recon.mulaw import compress, expand
from tespike.recon.mulaw import MU
from tespike.recon.decoding import decode_light
from tespike.recon.tfi import tfi
from tespike.recon.tfp import tfp


TE = SensorConfig.preset("te")


def sparse_stream(seed: int, span: int = 61, size: int = 12) -> torch.Tensor:
    """Decoded light of a real TE stream whose pixels span dense to very sparse codes."""
    rng = np.random.default_rng(seed)
    levels = 10.0 ** rng.uniform(-5.5, 0.5, size=(1, size, size))
    light = np.repeat(levels, span, 0)
    words = simulate_scene(SensorConfig.preset("te"), light, seed=seed, workers=1)
    return decode_light(words, SensorConfig.preset("te"), dtype=torch.float64)


@pytest.mark.parametrize("span", [61, 11])
def test_means_are_tfp_at_the_key(span):
    light = sparse_stream(1, span)
    key = span // 2
    got = key_estimates(light[None], None, TE.spike_light)[0]
    for j, r in enumerate(RADII):
        assert torch.allclose(got[j], tfp(light, min(r, key))[key], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("seed", [2, 3])
@pytest.mark.parametrize("length", [61, 97])
def test_spike_interval_is_windowed_tfi_at_every_readout(seed, length):
    """Told the sensor's spike light, the head's TFI is ``tfi(search="window")`` over its span, tails,
    spike-free pixels and the stream's padded ends included; the one difference: past the last spike
    with one spike p in the span before the key, the cap (the light of the interval ending at p) counts
    that interval from the span's start, where TFI counts it from p's own window (outside the span)."""
    radius = 30
    light = sparse_stream(seed, length)
    spans, inside = stream_spans(light)
    got = spike_interval_light(spans, inside, TE.spike_light)[:, 0]
    nonzero = light > 0
    reference = tfi(light, nonzero, TE.spike_light, radius, search="window")
    counts = torch.cat([torch.zeros_like(nonzero[:1], dtype=torch.int64), nonzero.long().cumsum(0)])
    k = torch.arange(length)
    def spikes(first, last):            # spikes in readouts first..last (clipped to the stream), per key
        return counts[(last + 1).clamp(0, length)] - counts[first.clamp(0, length)]
    after = spikes(k, k + radius)
    before = spikes(k - radius, k - 1)
    exact = (after > 0) | (before != 1)
    assert (~nonzero.any(0)).any() and nonzero.all(0).any()      # spike-free and dense pixels both exercised
    assert (~exact).any()
    assert torch.allclose(got[exact], reference[exact], rtol=1e-12, atol=0)
    end = torch.clamp(k + radius, max=length - 1).view(-1, 1, 1)
    last = torch.where(nonzero, k.view(-1, 1, 1), -1).cummax(0).values      # last spike at or before each readout
    bound = TE.spike_light / (end - last).to(light.dtype)
    assert (got[~exact] <= bound[~exact] * (1 + 1e-12)).all() and (got[~exact] > 0).all()


def test_untrained_head_returns_its_initial_blend():
    head = BlendHead(8, 2, MU)
    light = sparse_stream(5)[None].float()
    out = head(torch.randn(1, 8, 6, 6), light, None, TE.spike_light)
    logits = torch.zeros(len(RADII) + 1)
    for name, value in INITIAL_LOGITS.items():
        logits[-1 if name == "tfi" else RADII.index(name)] = value
    weights = torch.softmax(logits, 0).view(1, -1, 1, 1)
    expected = expand((weights * compress(key_estimates(light, None, TE.spike_light), MU)).sum(1, keepdim=True), MU)
    assert torch.allclose(out, expected, rtol=1e-5)
    assert dataclasses.is_dataclass(SensorConfig)


def test_extreme_light_is_finite():
    head = BlendHead(4, 1, MU)
    light = torch.zeros(1, 61, 4, 4)
    light[0, :, 0, 0] = 1e6
    light[0, 50, 1, 1] = 1e-9
    out = head(torch.randn(1, 4, 4, 4) * 1e3, light, None, TE.spike_light)
    assert torch.isfinite(out).all() and (out >= 0).all()


def stream_spans(light: torch.Tensor, span: int = 61) -> tuple[torch.Tensor, torch.Tensor]:
    """Every key's padded span and its inside mask, as inference builds them."""
    from tespike.recon.learning.span import key_span, span_inside
    K = light.shape[0]
    spans = torch.stack([light[key_span(K, k, span)] for k in range(K)])
    inside = torch.from_numpy(np.stack([span_inside(K, k, span) for k in range(K)]))
    return spans, inside


@pytest.mark.parametrize("length", [1, 5, 16, 31])
def test_estimates_equal_tfp_and_tfi_on_whole_short_streams(length):
    """Told which readouts are padding, the head's estimates are TFP's and TFI's exactly, at every readout."""
    light = sparse_stream(length + 7, length)
    spans, inside = stream_spans(light)
    got = key_estimates(spans, inside, TE.spike_light)
    for j, r in enumerate(RADII):
        assert torch.allclose(got[:, j], tfp(light, r), rtol=1e-12, atol=1e-15)
    reference = tfi(light, light > 0, TE.spike_light, 0)
    assert torch.allclose(got[:, -1], reference, rtol=1e-12, atol=0)


def test_inside_must_hold_the_key():
    light = torch.rand(1, 5, 2, 2)
    with pytest.raises(ValueError, match="key moment"):
        key_estimates(light, torch.tensor([[True, True, False, True, True]]), 1.0)
    with pytest.raises(ValueError, match="shape"):
        key_estimates(light, torch.ones(1, 4, dtype=torch.bool), 1.0)


def test_straight_through_floor_pulls_negative_codes_back_and_changes_no_output():
    """A code driven below zero gives zero light under both floors; in training only the
    straight-through floor lets the loss reach it (the clamp's gradient is zero there), and in
    eval mode the two heads are one function."""
    from tespike.recon.learning.head import FLOORS, set_floor

    torch.manual_seed(0)
    head = BlendHead(8, 2, MU)
    with torch.no_grad():
        head.conv.weight.normal_(0, 0.1)
        head.conv.bias[-4:] = -3.0                # the correction channels: every code far below 0
    feature, light = torch.randn(2, 8, 4, 4), torch.rand(2, 13, 8, 8) * 0.01
    truth = torch.full((2, 1, 8, 8), 0.005)
    grads, outputs = {}, {}
    for floor in FLOORS:
        set_floor(head, floor).train()
        head.zero_grad()
        out = head(feature, light, None, TE.spike_light)
        (compress(out, MU) - compress(truth, MU)).abs().mean().backward()
        grads[floor] = head.conv.bias.grad[-4:].clone()
        head.eval()
        with torch.no_grad():
            outputs[floor] = head(feature, light, None, TE.spike_light)
        assert float(out.detach().abs().max()) == 0.0
    assert float(grads["clamp"].abs().max()) == 0.0
    assert bool((grads["straight-through"] < 0).all())            # descent raises the correction
    assert torch.equal(outputs["clamp"], outputs["straight-through"])
    with pytest.raises(ValueError, match="floor"):
        set_floor(head, "relu")


def test_train_command_offers_the_heads_floors():
    """tespike train's --floor choices (typed in the parser, which imports no recon) are FLOORS,
    and TrainOptions refuses another in one line."""
    from tespike.cosim.cli import build_parser
    from tespike.golden.errors import InputError
    from tespike.recon.learning.head import FLOORS
    from tespike.recon.train import TrainOptions

    parser = build_parser("train")
    for floor in FLOORS:
        assert parser.parse_args(["train", "--out", "w.pt", "--steps", "1", "--floor", floor]).floor == floor
    with pytest.raises(SystemExit):
        parser.parse_args(["train", "--out", "w.pt", "--steps", "1", "--floor", "relu"])
    assert TrainOptions(steps=1, floor="straight-through").model().head.floor == "straight-through"
    with pytest.raises(InputError, match="floor"):
        TrainOptions(steps=1, floor="relu")
