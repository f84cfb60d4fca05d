"""tespike.recon.baselines: Spk2ImgNet, BSF and MambaSpike against the contract the trainer and tiled inference rely on."""

import dataclasses
import json

import pytest
import torch

from tespike.golden.config import SensorConfig

from tespike.golden.errors import InputError
from tespike.recon.baselines import BASELINES, PAPER_PARAMETERS
from tespike.recon.learned import method_radius
from tespike.recon.learning.align import LocalCrossAttention, PyramidAlign, neighbourhood
from tespike.recon.learning.layers import parameter_count, substreams
from tespike.recon.baselines.represent import LENGTHS, firing_rates, window_means
from tespike.recon.baselines.scan import SPAN, MambaBlock, selective_scan, selective_scan_reference
from tespike.recon.learning.deform import ModulatedDeformConv2d

#: The TE sensor's light of one spike per readout (every learned module is told its sensor's).
ONE_SPIKE = SensorConfig.preset("te").spike_light

NAMES = tuple(BASELINES)

#: Small sizes of every method: every part present, seconds to run.
SMALL = {
    "spk2imgnet": {"unshuffle": 1, "channels": 8, "blocks": 1, "recon_blocks": 1, "levels": 2, "max_offset": 2.0,
                   "offset_groups": 2},
    "bsf": {"unshuffle": 1, "channels": 8, "blocks": 2, "recon_blocks": 1, "levels": 2, "max_offset": 2.0,
            "attention_radius": 1, "orders": (1, 4)},
    "mambaspike": {"unshuffle": 2, "channels": 8, "temporal_patch": 3, "moment_stride": 3, "levels": 2,
                   "max_offset": 2.0, "scan_window": 4, "head_dim": 4, "state": 4, "chunk": 4, "parsings": 2},
}
SMALL["mambaspike1"] = {**SMALL["mambaspike"], "parsings": 1}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def small(name, **changes):
    model_cls, sizes_cls = BASELINES[name]
    return model_cls(sizes_cls(**{**SMALL[name], **changes}))


def randomise(model: torch.nn.Module, seed: int = 0) -> torch.nn.Module:
    """The zero-initialised layers (output, DCN offsets) made random and small, so every path is live."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in model.parameters():
            if not p.any():
                p.copy_(torch.randn(p.shape, generator=g) * 0.05)
    return model


def hdr_light(shape, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.exp(torch.randn(shape, generator=g) * 2.0)            # HDR: ~1e-3 .. ~1e3


@pytest.mark.parametrize("name", NAMES)
def test_sizes_presets_and_round_trip(name):
    _, sizes_cls = BASELINES[name]
    for preset in ("cpu", "paper"):
        sizes = sizes_cls.preset(preset)
        assert sizes.span == 61
        again = sizes_cls.from_dict(json.loads(json.dumps(sizes.to_dict())))
        assert again == sizes
    with pytest.raises(InputError, match=f"unknown {name} size 'huge'"):
        sizes_cls.preset("huge")
    with pytest.raises(InputError, match="unknown .* key 'nope'"):
        sizes_cls.from_dict({"nope": 1})
    with pytest.raises(InputError, match="channels"):
        sizes_cls(channels=0)
    with pytest.raises(InputError, match="max_offset"):
        sizes_cls(max_offset=-1.0)
    if "substreams" in sizes_cls.__dataclass_fields__:       # weights written before the rename still load
        former = {"windows" if k == "substreams" else "step" if k == "stride" else k: v
                  for k, v in sizes_cls(substreams=3, stride=20).to_dict().items()}
        assert sizes_cls.from_dict(former) == sizes_cls(substreams=3, stride=20)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sizes_cls().channels = 3


@pytest.mark.parametrize("name", NAMES)
def test_shapes_on_any_multiple_of_the_pyramid_factor(name):
    model = small(name)
    f = model.sizes.pyramid_factor
    for h, w in ((f, f), (2 * f, 3 * f)):
        out = model(hdr_light((2, 61, h, w)), None, ONE_SPIKE)
        assert out.shape == (2, 1, h, w)
    with pytest.raises(ValueError, match="span 61"):
        model(torch.rand(1, 60, f, f), None, ONE_SPIKE)
    with pytest.raises(ValueError, match=f"multiples of {f}"):
        model(torch.rand(1, 61, f + 1, f), None, ONE_SPIKE)


@pytest.mark.parametrize("name", NAMES)
def test_untrained_output_is_the_heads_initial_blend(name):
    """The project's head (recon.learning.head) starts from its blend of training-free estimates, features unused."""
    model = small(name)
    f = model.sizes.pyramid_factor
    light = hdr_light((1, 61, f, 2 * f))
    feature = torch.zeros(1, model.head.conv.in_channels, f // model.head.shuffle.upscale_factor,
                          2 * f // model.head.shuffle.upscale_factor)
    assert torch.allclose(model(light, None, ONE_SPIKE), model.head(feature, light, None, ONE_SPIKE), rtol=1e-4)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("value", [0.0, 1e4])
def test_extreme_input_is_finite_and_nonnegative(name, value):
    model = randomise(small(name))
    f = model.sizes.pyramid_factor
    light = torch.full((1, 61, f, f), value)
    light[0, 30, 0, 0] = 0.0 if value else 1e4                       # one odd pixel
    out = model(light, None, ONE_SPIKE)
    assert torch.isfinite(out).all() and (out >= 0).all()


@pytest.mark.parametrize("name", NAMES)
def test_cpu_preset_runs(name):
    model_cls, sizes_cls = BASELINES[name]
    sizes = sizes_cls.preset("cpu")
    f = sizes.pyramid_factor
    model = model_cls(sizes).eval().to(memory_format=torch.channels_last)      # as the project's inference
    with torch.inference_mode():
        out = model(hdr_light((1, 61, f, 2 * f)), None, ONE_SPIKE)
    assert out.shape == (1, 1, f, 2 * f) and torch.isfinite(out).all()


@pytest.mark.parametrize("name", NAMES)
def test_gradients_reach_every_parameter(name):
    model = randomise(small(name))
    f = model.sizes.pyramid_factor
    light = hdr_light((1, 61, 2 * f, 2 * f))
    model(light, None, ONE_SPIKE).log1p().mean().backward()
    dead = [key for key, p in model.named_parameters() if p.grad is None or not p.grad.abs().sum() > 0]
    assert not dead


@pytest.mark.parametrize("name", NAMES)
def test_three_steps_reduce_the_loss(name):
    torch.manual_seed(0)
    model = small(name)
    f = model.sizes.pyramid_factor
    light = hdr_light((2, 61, 2 * f, 2 * f), seed=1)
    target = light[:, 28:33].mean(1, keepdim=True) * 1.5
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)

    def loss():
        return (model(light, None, ONE_SPIKE).log1p() - target.log1p()).abs().mean()

    first = loss()
    for _ in range(3):
        opt.zero_grad()
        value = loss()
        value.backward()
        opt.step()
    assert float(loss().detach()) < float(first.detach())


@pytest.mark.parametrize("name", NAMES)
def test_paper_parameter_count(name):
    """The 'paper' size has the paper's Table 10 parameters to within 5 %; 'cpu' is small."""
    model_cls, sizes_cls = BASELINES[name]
    paper = parameter_count(model_cls(sizes_cls.preset("paper")))
    assert abs(paper / PAPER_PARAMETERS[name] - 1) < 0.05, paper
    cpu = parameter_count(model_cls(sizes_cls.preset("cpu")))
    assert 80_000 <= cpu <= 300_000, cpu


@pytest.mark.parametrize("name", NAMES)
@torch.no_grad()
def test_method_radius_bounds_the_field(name):
    """A pixel beyond the radius leaves the centre alone; a change near the centre moves it."""
    changes = {"parsings": 1, "unshuffle": 1, "channels": 4} if name == "mambaspike" else {}
    model = randomise(small(name, **changes)).double()
    radius = method_radius(model.sizes)
    f = model.sizes.pyramid_factor
    side = -(-(2 * radius + 2 * f + 2) // f) * f
    light = hdr_light((1, 61, side, side)).double()
    c = side // 2
    base = model(light, None, ONE_SPIKE)[0, 0, c, c].item()
    far = light.clone()
    for dy, dx in ((radius + 1, 0), (0, -(radius + 1)), (radius + 1, radius + 1), (-(radius + 1), 0)):
        far[0, :, c + dy, c + dx] *= 50.0
    assert model(far, None, ONE_SPIKE)[0, 0, c, c].item() == base
    near = light.clone()
    near[0, :, c + 1, c] *= 50.0
    assert model(near, None, ONE_SPIKE)[0, 0, c, c].item() != pytest.approx(base, rel=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_alignment_uses_the_projects_dcn(name):
    model = small(name)
    dcns = [m for m in model.modules() if isinstance(m, ModulatedDeformConv2d)]
    assert dcns and ModulatedDeformConv2d.__module__ == "tespike.recon.learning.deform"
    assert all(type(m) is ModulatedDeformConv2d for m in dcns)


def test_bsf_alignment_has_local_cross_attention():
    model = small("bsf")
    assert any(isinstance(m, LocalCrossAttention) for m in model.modules())
    assert not any(isinstance(m, LocalCrossAttention) for m in small("spk2imgnet").modules())


def test_pyramid_alignment_starts_near_identity_offsets():
    """Zero-initialised offsets: aligned features of identical key and reference do not depend on far pixels."""
    align = PyramidAlign(4, 2, max_offset=1.0, cascade=True)
    key = torch.rand(1, 4, 8, 8)
    out = align.align(key, key[:, None].repeat(1, 2, 1, 1, 1))
    assert out.shape == (1, 2, 4, 8, 8) and torch.isfinite(out).all()
    features = torch.rand(1, 3, 4, 8, 8)                 # the whole: references aligned, the key kept in the middle
    stacked = align(features)
    assert stacked.shape == (1, 3, 4, 8, 8) and torch.equal(stacked[:, 1], features[:, 1])
    assert torch.equal(PyramidAlign(4, 0)(features), features)         # no levels: no alignment


def test_firing_rates():
    light = torch.full((1, 61, 2, 2), 3.0)
    light[0, :, 0, 0] = 0.0                                     # dark
    light[0, :, 0, 1] = 0.01                                    # 0.61 light in the whole span: below one spike
    light[0, :30, 1, 1], light[0, 30:, 1, 1] = 1.0, 100.0       # a step
    rates = firing_rates(light, (1, 4, 16), 1.0)
    assert rates.shape == (1, 3, 61, 2, 2)
    assert torch.equal(rates[0, :, :, 1, 0], torch.full((3, 61), 3.0))     # constant light: its value
    assert torch.equal(rates[0, :, :, 0, 0], torch.zeros(3, 61))
    assert torch.allclose(rates[0, :, 30, 0, 1], torch.full((3,), 0.01))
    assert torch.allclose(rates[0, :, 45, 1, 1], torch.full((3,), 100.0))  # bright: short intervals
    assert float(rates[0, 0, 10, 1, 1]) == pytest.approx(1.0)               # order 1 at 1: the readout
    assert float(rates[0, 2, 10, 1, 1]) == pytest.approx(1.0)               # order 16 within the flat part
    assert 1.0 < float(rates[0, 2, 28, 1, 1]) < 100.0                       # order 16 near the step: mixed
    hdr = hdr_light((1, 61, 3, 3)) + 1.0
    assert torch.allclose(firing_rates(hdr, (1,), 1.0)[:, 0], hdr)          # >= 1 spike per readout


@pytest.mark.parametrize("chunk", [1, 4, 7, 32])
def test_chunked_scan_equals_the_recurrence(chunk):
    g = torch.Generator().manual_seed(chunk)
    z, length, heads, p, n = 3, 21, 2, 4, 5
    u = torch.randn(z, length, heads, p, generator=g, dtype=torch.float64)
    log_decay = -SPAN / chunk * torch.rand(z, length, heads, generator=g, dtype=torch.float64)
    b = torch.randn(z, length, n, generator=g, dtype=torch.float64)
    c = torch.randn(z, length, n, generator=g, dtype=torch.float64)
    assert torch.allclose(selective_scan(u, log_decay, b, c, chunk), selective_scan_reference(u, log_decay, b, c),
                          atol=1e-12)


def test_mamba_block_is_bidirectional_and_local_to_its_sequence():
    block = MambaBlock(8, 2, 4, 4, 4).double()
    x = torch.randn(2, 10, 8, dtype=torch.float64)
    out = block(x)
    later = x.clone()
    later[0, 9, 0] += 1.0                                # (one channel: LayerNorm ignores a common shift)
    moved = block(later)
    # the last step reaches the first (backward scan); decayed over 9 steps the change is small (~1e-6),
    # far above float64 rounding but below allclose's default tolerance
    assert float((moved[0, 0] - out[0, 0]).detach().abs().max()) > 1e-10
    assert torch.allclose(moved[1], out[1])                 # another sequence is untouched


def test_substreams_are_centred_on_the_key():
    t = torch.arange(61.0)[None, :, None, None]
    subs = substreams(t, 5, 21, 10)
    assert subs[0, 2, 10, 0, 0] == 30 and subs[0, 0, 0, 0, 0] == 0 and subs[0, 4, 20, 0, 0] == 60


@pytest.mark.parametrize("readouts", [7, 61])
def test_window_sums_equal_direct_sums(readouts):
    light = hdr_light((2, readouts, 3, 2)).double()
    for length, (total, mean) in zip(LENGTHS, window_means(light)):
        half = length // 2
        direct = torch.stack([light[:, max(0, i - half):i + half + 1].sum(1) for i in range(readouts)], 1)
        count = torch.tensor([min(readouts, i + half + 1) - max(0, i - half) for i in range(readouts)])
        assert torch.allclose(total, direct, rtol=1e-12)
        assert torch.allclose(mean, direct / count[:, None, None].double(), rtol=1e-12)


def test_local_cross_attention_equals_its_unfolded_definition():
    torch.manual_seed(0)
    att = LocalCrossAttention(8, 2).double()
    key, ref = torch.randn(2, 8, 9, 11, dtype=torch.float64), torch.randn(2, 8, 9, 11, dtype=torch.float64)
    k, v = neighbourhood(att.k(ref), 2), neighbourhood(att.v(ref), 2)           # (B, C, 25, h, w), zeros outside
    weights = torch.softmax((att.q(key)[:, :, None] * k).sum(1) / 8 ** 0.5, dim=1)
    attended, shift = att(key, ref)
    assert torch.allclose(attended, (weights[:, None] * v).sum(2), atol=1e-12)
    dy = torch.arange(-2, 3, dtype=torch.float64).repeat_interleave(5)
    assert torch.allclose(shift[:, 0], (weights * dy[:, None, None]).sum(1), atol=1e-12)


def test_mambaspike_parsings_follow_the_camera():
    """Several parsings on the msb camera only (its readout leaves the counter's rest unread), one on
    TE and the full count; the spade row's one-branch MambaSpike has one on every camera, and refuses more."""
    from tespike.recon.baselines.mambaspike import MSB_PARSINGS
    for camera, parsings in (("te", 1), ("ml", 1), ("ml-msb", MSB_PARSINGS)):
        config = SensorConfig.preset(camera)
        assert BASELINES["mambaspike"][1].for_camera("cpu", config).parsings == parsings
        assert BASELINES["mambaspike1"][1].for_camera("cpu", config).parsings == 1
    assert MSB_PARSINGS > 1
    with pytest.raises(InputError, match="parsings = 2: must be 1"):
        BASELINES["mambaspike1"][1](parsings=2)
