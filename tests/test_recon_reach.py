"""tespike.recon.reach: every learned method's receptive reach is derived from its modules, an upper bound, and tight."""

import dataclasses

import pytest
import torch
from torch import nn

from tespike.golden.config import SensorConfig
from tespike.recon.baselines import BASELINES
from tespike.recon.learned import learned_methods, method_radius
from tespike.recon.net.features import MSFEG
from tespike.recon.net.model import TESpikeNet
from tespike.recon.net.sizes import NetSizes
from tespike.recon.reach import FRAME, Support, support
from tests.test_recon_baselines import SMALL, hdr_light
from tests.test_recon_learning_infer import TINY

#: The TE sensor's light of one spike per readout (every learned module is told its sensor's).
ONE_SPIKE = SensorConfig.preset("te").spike_light


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_conv_rules_are_the_exact_geometry():
    """Centre-to-centre displacements, frame pixels: a 3 x 3 stride-2 convolution, a pixel-unshuffle, upsampling."""
    assert Support().conv(3, padding=1) == Support(-1, 1, 1)
    assert Support().conv(3, stride=2, padding=1) == Support(-1.5, 0.5, 2)      # reads 2j - 1 .. 2j + 1
    assert Support().unshuffle(4) == Support(-1.5, 1.5, 4)
    assert Support().unshuffle(4).shuffle(4) == Support(-3, 3, 1)                     # a 4 x 4 block, both ways
    assert Support(0, 0, 2).upsample(2) == Support(-1.5, 1.5, 1)                # 3/4 of a coarse pixel
    assert Support().window(8).window(8) == Support().window(8)                 # same windows: no further
    with pytest.raises(ValueError, match="grids of scale"):
        Support().union(Support(0, 0, 2))


@pytest.mark.parametrize("name, changes", [
    ("net", {"dcn_kernel": 5}), ("net", {"attention_window": 31}), ("net", {"max_offset": 16.0}),
    ("net", {"levels": 4}), ("net", {"refine": False}),
    ("spk2imgnet", {"dcn_kernel": 5}), ("spk2imgnet", {"blocks": 4}),
    ("bsf", {"attention_radius": 4}), ("bsf", {"blocks": 4}),
    ("mambaspike", {"filter_kernel": 7}), ("mambaspike", {"scan_window": 16}),
])
def test_a_size_change_changes_the_derived_reach(name, changes):
    _, sizes_cls = learned_methods()[name]
    base = sizes_cls.preset("cpu")
    grown = dataclasses.replace(base, **changes)
    assert method_radius(grown) != method_radius(base)


def test_a_kernel_change_in_a_module_changes_the_reach(monkeypatch):
    """Nothing is kept by hand: widening MSFEG's largest kernel (7 -> 9) adds one folded pixel (u frame pixels)."""
    sizes = NetSizes.preset("cpu")
    before = support(TESpikeNet(sizes), FRAME)
    monkeypatch.setattr(MSFEG, "KERNELS", (1, 3, 5, 9))
    after = support(TESpikeNet(sizes), FRAME)
    assert (before.lo - after.lo, after.hi - before.hi) == (sizes.unshuffle, sizes.unshuffle)


def test_a_module_without_a_rule_is_refused():
    model = nn.Sequential(nn.Conv2d(1, 1, 3, padding=1), nn.Upsample(scale_factor=2))
    with pytest.raises(TypeError, match="no reach rule for Upsample"):
        support(model, FRAME)


def saturated(model: nn.Module, sign: float) -> nn.Module:
    """Random float64 weights, every DCN offset pinned at sign * max_offset (the far end of its bound)."""
    model = model.double()
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn(p.shape, generator=g, dtype=p.dtype) * 0.1)
        for m in model.modules():
            if hasattr(m, "offset_out") and hasattr(m, "dcn"):
                m.offset_out.weight.zero_()
                m.offset_out.bias[:m.dcn.offset_channels] = 50.0 * sign
    return model


def small_model(name):
    if name == "net":
        return TESpikeNet(TINY)
    model_cls, sizes_cls = BASELINES[name]
    changes = {"parsings": 1, "unshuffle": 1, "channels": 4} if name == "mambaspike" else {}
    return model_cls(sizes_cls(**{**SMALL[name], **changes}))


@pytest.mark.parametrize("name", ["net", *BASELINES])
@torch.no_grad()
def test_the_bound_holds_and_is_tight(name):
    """Offsets at their bound: a row just beyond the radius leaves the centre bit-identical (float64),
    and a row at 3/4 of the radius still moves it (the bound is not far looser than the field)."""
    model = saturated(small_model(name), -1.0)          # taps pulled up: the field reaches farthest above
    radius = method_radius(model.sizes)
    f = model.sizes.pyramid_factor
    side = -(-(2 * radius + 2 * f + 8) // f) * f
    light = hdr_light((1, model.sizes.span, side, side)).double()
    c = side // 2
    base = model(light, None, ONE_SPIKE)[0, 0, c, c]

    def moves(*rows):
        x = light.clone()
        for dy in rows:
            x[0, :, c + dy, :] *= 50.0
        return bool(model(x, None, ONE_SPIKE)[0, 0, c, c] != base)

    beyond = radius + 1
    assert not moves(-beyond, beyond)
    x = light.clone()
    x[0, :, :, c - beyond] *= 50.0
    x[0, :, :, c + beyond] *= 50.0
    assert model(x, None, ONE_SPIKE)[0, 0, c, c] == base
    assert moves(-(3 * radius) // 4)
