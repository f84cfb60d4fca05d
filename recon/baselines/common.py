"""What the three learned baselines share: input checks, windows, residual blocks, their tail and its sizes.

Every baseline takes the project's one stream format into learned methods,
(N, span, H, W) decoded light in scene units (``tespike.recon.decoding.decode_light``),
key moment at ``span // 2``, and returns (N, 1, H, W) light at the key moment.
HDR light is compressed with the project's mu-law before the first layer
(:mod:`tespike.recon.mulaw`), as the project's network does. Each reads its
sub-streams into features its own way, then ends in the same tail
(:class:`AlignedBaseline`): pyramid alignment to the key
(:class:`tespike.recon.learning.align.PyramidAlign`), a 1 x 1 fusion, residual
reconstruction blocks, and the project's output head
(:class:`tespike.recon.learning.head.BlendHead`: a per-pixel choice among training-free
estimates plus a correction), so it starts from a sensible image and trains
stably on HDR scenes.
"""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from ..learning.align import PyramidAlign
from ..learning.head import BlendHead
from ..learning.layers import conv3
from ..learning.sizes import PyramidSizes, SubstreamSizes
from ..reach import Support, support


def centred(x: torch.Tensor, length: int) -> torch.Tensor:
    """(N, T, ...) -> the ``length`` readouts around the middle of T (T and length odd)."""
    start = (x.shape[1] - length) // 2
    return x[:, start:start + length]


class ResBlock(nn.Module):
    """x + conv(act(conv(x))): the residual block of EDVR / Spk2ImgNet (reach: 2 dilation)."""

    def __init__(self, channels: int, dilation: int = 1):
        super().__init__()
        self.body = nn.Sequential(conv3(channels, channels, dilation=dilation), nn.LeakyReLU(0.1),
                                  conv3(channels, channels, dilation=dilation))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)

    def support(self, x: Support) -> Support:
        return x.union(support(self.body, x))


@dataclasses.dataclass(frozen=True)
class BaselineSizes(PyramidSizes):
    """The sizes of a baseline's tail (:class:`AlignedBaseline`) beyond :class:`PyramidSizes`:
    ``offset_groups`` of the alignment's deformable convolutions (channels a multiple of them)
    and ``recon_blocks``, the residual blocks after fusion."""

    offset_groups: int = 1
    recon_blocks: int = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        self._need_ints("offset_groups")
        self._need_ints("recon_blocks", least=0)
        self._need("channels", self.channels % self.offset_groups == 0, "a multiple of offset_groups")


@dataclasses.dataclass(frozen=True)
class BaselineSubstreams(SubstreamSizes):
    """The sub-streams Spk2ImgNet and BSF read (their papers' windows and sub-spans): 5 of 21
    readouts, 10 apart (61 readouts, the TE paper's variant of both, the key one in the middle)."""

    substreams: int = 5
    window: int = 21
    stride: int = 10


class AlignedBaseline(nn.Module):
    """A baseline: (N, span, H, W) decoded light -> (N, 1, H, W) light at the key moment (readout span // 2).

    A subclass reads the light into (N, S, C, h, w) features, the key's in the middle, its own
    way: it builds those parts after ``super().__init__(sizes)``, then calls :meth:`build_tail`
    (parts are made in this order: a seeded initialisation depends on it), and defines
    ``features(light)`` and, on supports, ``features_support(light)``. The rest is the tail
    all three share (align, fuse, reconstruct, head). Its sizes are a :class:`BaselineSizes`
    with ``span``.
    """

    def __init__(self, sizes: BaselineSizes):
        super().__init__()
        self.sizes = sizes

    def build_tail(self, count: int, **align_parts) -> None:
        """``count``: the sub-streams' features to align; ``align_parts``: the method's own parts of
        its cascaded pyramid alignment (:class:`tespike.recon.learning.align.PyramidAlign`)."""
        s, c = self.sizes, self.sizes.channels
        self.align = PyramidAlign(c, s.levels, s.dcn_kernel, s.offset_groups, s.max_offset, cascade=True,
                                  **align_parts)
        self.fuse = nn.Sequential(nn.Conv2d(count * c, c, 1), nn.LeakyReLU(0.1))
        self.reconstruct = nn.Sequential(*[ResBlock(c) for _ in range(s.recon_blocks)])
        self.head = BlendHead(c, s.unshuffle, s.mu)

    def forward(self, light: torch.Tensor, inside: torch.Tensor | None, spike_light: float) -> torch.Tensor:
        """``inside`` (N, span) bool: the readouts that lie in the stream (None: all); ``spike_light``:
        the sensor's light of one spike per readout (``SensorConfig.spike_light``); see recon/learning/head.py."""
        self.sizes.check_input(light)
        feats = self.features(light)
        fused = self.reconstruct(self.fuse(self.align(feats).flatten(1, 2)))
        return self.head(fused, light, inside, spike_light)

    def support(self, light: Support) -> Support:
        """:meth:`forward` on supports."""
        feats = self.align.support(self.features_support(light))
        return self.head.support(support(self.reconstruct, support(self.fuse, feats)), light)
