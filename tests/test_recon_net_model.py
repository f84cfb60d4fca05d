"""tespike.recon.net: every part of the paper's Figure 3 alone, the whole, its sizes and ablation switches."""

import dataclasses

import pytest
import torch

from tespike.golden.config import SensorConfig

from tespike.golden.errors import InputError
from tespike.recon.complexity import PAPER_TABLE10
from tespike.recon.learning.align import AlignLevel
from tespike.recon.net.align import SPA
from tespike.recon.net.features import GRADIENT_KERNELS, MSFEG, GradientFilters
from tespike.recon.learning.layers import parameter_count, substreams
from tespike.recon.mulaw import compress, expand
from tespike.recon.net.model import TESpikeNet
from tespike.recon.net.refine import GuidedAttention, IntensityFeature, box_mean
from tespike.recon.net.sizes import SWITCHES, NetSizes

#: The TE sensor's light of one spike per readout (every learned module is told its sensor's).
ONE_SPIKE = SensorConfig.preset("te").spike_light

SMALL = NetSizes(channels=8, heads=2, window=3, stride=2, substreams=5, unshuffle=2, attention_window=5)


def test_gradient_filters_are_eq8_and_frozen():
    assert GRADIENT_KERNELS[0].tolist() == [[1, 0, -1], [2, 0, -2], [1, 0, -1]]
    assert GRADIENT_KERNELS[1].tolist() == [[1, 2, 1], [0, 0, 0], [-1, -2, -1]]
    assert GRADIENT_KERNELS[2].tolist() == [[0, 1, 0], [1, -4, 1], [0, 1, 0]]
    filters = GradientFilters(2)
    assert not list(filters.parameters())              # buffers: never trained
    ramp = torch.arange(6.0).repeat(6, 1)[None, None].repeat(1, 2, 1, 1)   # x grows by 1 per column
    out = filters(ramp)
    assert out.shape == (1, 6, 6, 6)
    assert torch.allclose(out[0, 0, 2:-2, 2:-2], torch.full((2, 2), -8.0))  # Sobel x of a unit ramp
    assert torch.allclose(out[0, 1, 2:-2, 2:-2], torch.zeros(2, 2))
    assert torch.allclose(out[0, 2, 2:-2, 2:-2], torch.zeros(2, 2))         # Laplacian of a ramp


def test_msfeg_alone():
    enc = MSFEG(window=3, channels=8, unshuffle=2)
    assert enc(torch.rand(2, 3, 16, 12)).shape == (2, 8, 8, 6)
    assert MSFEG(3, 8, 1, gradient=False)(torch.rand(1, 3, 5, 7)).shape == (1, 8, 5, 7)


@pytest.mark.parametrize("unshuffle", [1, 2, 4])
def test_msfeg_fast_path_equals_its_definition(unshuffle):
    torch.manual_seed(unshuffle)
    enc = MSFEG(window=3, channels=8, unshuffle=unshuffle).double()
    x = torch.rand(2, 3, 8 * unshuffle, 4 * unshuffle, dtype=torch.float64)
    assert torch.allclose(enc(x), enc.folded_forward(x), atol=1e-12)


def test_level_alignment_starts_as_plain_convolution():
    """Zero-initialised offsets: the DCN is a convolution with masks 1/2."""
    level = AlignLevel(8, SMALL.dcn_kernel, 1, SMALL.max_offset, coarsest=True, similarity=True, motion_bias=True)
    key, ref = torch.rand(1, 8, 6, 6), torch.rand(1, 8, 6, 6)
    _, aligned = level(key, ref)
    dcn = level.dcn
    plain = 0.5 * torch.nn.functional.conv2d(ref, dcn.weight, padding=1) + dcn.bias.reshape(1, -1, 1, 1)
    bias = level.motion_bias(torch.cat((plain, key), 1))
    assert torch.allclose(aligned, plain + bias, atol=1e-5)


def test_spa_alone_and_without_dcn():
    feats = torch.rand(2, 5, 8, 8, 8)
    assert SPA(SMALL)(feats).shape == (2, 8, 8, 8)
    assert SPA(dataclasses.replace(SMALL, dcn=False))(feats).shape == (2, 8, 8, 8)


def test_spa_loads_weights_saved_under_its_former_names():
    """Weights written when SPA held the pyramid's ``down`` and ``levels`` itself load unchanged."""
    torch.manual_seed(3)
    spa = SPA(SMALL)
    former = {k.replace("align.", "", 1): v for k, v in spa.state_dict().items()}
    assert any(k.startswith("levels.") for k in former) and not any(k.startswith("align.") for k in former)
    again = SPA(SMALL)
    again.load_state_dict(former)                      # strict: every tensor found under its new name
    feats = torch.rand(1, 5, 8, 8, 8)
    assert torch.equal(again(feats), spa(feats))


def test_box_mean_equals_avg_pool():
    x = torch.randn(2, 3, 13, 9, dtype=torch.float64)
    ref = torch.nn.functional.avg_pool2d(x, 5, stride=1, padding=2, count_include_pad=False)
    assert torch.allclose(box_mean(x, 5), ref, atol=1e-12)


def test_attention_is_local_and_linear_in_pixels():
    att = GuidedAttention(8, 2, 5)
    x, y = torch.rand(1, 8, 20, 20), torch.rand(1, 8, 20, 20)
    out = att(x, y)
    assert out.shape == (1, 8, 20, 20)
    x2 = x.clone()
    x2[..., :3] += 1.0                                  # a change far away on the left ...
    assert torch.allclose(att(x2, y)[..., 10:], out[..., 10:], atol=1e-6)   # ... leaves the right alone
    assert IntensityFeature(3, 8, 2)(torch.rand(1, 3, 8, 8), torch.rand(1, 1, 8, 8)).shape == (1, 8, 4, 4)


def test_whole_network_starts_at_its_head_initial_blend():
    """Untrained, the network returns its head's initial blend of training-free estimates (features unused)."""
    model = TESpikeNet(SMALL)
    light = torch.rand(2, SMALL.span, 16, 16)
    out = model(light, None, ONE_SPIKE)
    expected = model.head(torch.zeros(2, SMALL.channels, 16 // SMALL.unshuffle, 16 // SMALL.unshuffle), light,
                          None, ONE_SPIKE)
    assert out.shape == (2, 1, 16, 16)
    assert torch.allclose(out, expected, rtol=1e-5, atol=1e-7)


def test_mean_head_starts_at_the_temporal_mean():
    sizes = dataclasses.replace(SMALL, head="mean")
    model = TESpikeNet(sizes)
    light = torch.rand(2, sizes.span, 16, 16)
    key = substreams(light, sizes.substreams, sizes.window, sizes.stride)[:, sizes.substreams // 2]
    assert torch.allclose(model(light, None, ONE_SPIKE), key.mean(1, keepdim=True), rtol=1e-4, atol=1e-7)


def test_compress_expand_inverse_and_nonnegative():
    x = torch.tensor([0.0, 1e-12, 1e-4, 0.3, 1.0, 5.0, 1e3], dtype=torch.float64)
    assert torch.allclose(expand(compress(x, 5000.0), 5000.0), x, rtol=1e-12)
    assert float(expand(torch.tensor(-0.5), 5000.0)) == 0.0
    top = expand(torch.tensor([2.0, 1e30, float("inf")]), 5000.0)     # bounded, never inf
    assert torch.isfinite(top).all() and float(top[0]) == float(top[2]) > 1e3


@pytest.mark.parametrize("case", range(1, 7))
def test_ablation_cases_build_and_run(case):
    sizes = SMALL.ablation(case)
    assert [getattr(sizes, key) for key in SWITCHES] == [i < case - 1 for i in range(5)]
    out = TESpikeNet(sizes)(torch.rand(1, sizes.span, 16, 16), None, ONE_SPIKE)
    assert out.shape == (1, 1, 16, 16) and torch.isfinite(out).all()


def test_parameter_counts():
    """The 'paper' size is the paper's 6.479 M parameters (Table 10) to within 5 %."""
    paper = parameter_count(TESpikeNet(NetSizes.preset("paper")))
    assert abs(paper / PAPER_TABLE10["net"].parameters - 1) < 0.05, paper
    cpu = parameter_count(TESpikeNet(NetSizes.preset("cpu")))
    assert cpu < paper / 10


def test_sizes_refuse_bad_values():
    with pytest.raises(InputError, match="window"):
        NetSizes(window=4)
    with pytest.raises(InputError, match="channels"):
        NetSizes(channels=10)
    with pytest.raises(InputError, match="unknown network size"):
        NetSizes.preset("huge")
    with pytest.raises(InputError, match="ablation"):
        NetSizes().ablation(7)
    assert NetSizes().span == 61
