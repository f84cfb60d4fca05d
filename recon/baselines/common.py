"""What the three learned baselines share: input checks, centred windows, residual blocks, and their tail.

Every baseline takes the project's one stream format into learned methods,
(N, span, H, W) decoded light in scene units (``tespike.recon.stream.decode_light``),
key moment at ``span // 2``, and returns (N, 1, H, W) light at the key moment.
HDR light is compressed with the project's mu-law before the first layer
(:mod:`tespike.recon.learning.mulaw`), as the project's network does. Each reads its
sub-streams into features its own way, then ends in the same tail
(:class:`AlignedBaseline`): pyramid alignment to the key
(:class:`tespike.recon.learning.align.PyramidAlign`), a 1 x 1 fusion, residual
reconstruction blocks, and the project's output head
(:class:`tespike.recon.learning.head.BlendHead`: a per-pixel choice among training-free
estimates plus a correction), so it starts from a sensible image and trains
stably on HDR scenes.
"""

from __future__ import annotations

import torch
from torch import nn

from ..learning.align import PyramidAlign
from ..learning.head import BlendHead
from ..learning.layers import conv3
from ..reach import Support, support


def check_input(light: torch.Tensor, span: int, factor: int) -> None:
    """Refuse an input of the wrong span or a frame size that is not a multiple of ``factor``."""
    if light.dim() != 4:
        raise ValueError(f"input has shape {tuple(light.shape)}: need (N, {span}, H, W)")
    n, s, h, w = light.shape
    if s != span or h % factor or w % factor:
        raise ValueError(f"input (N, {s}, {h}, {w}): need span {span} and H, W multiples of {factor}")


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


class AlignedBaseline(nn.Module):
    """A baseline's tail: (N, S, C, h, w) features, key in the middle -> (N, 1, H, W) light.

    A subclass builds its own feature extraction, then calls :meth:`build_tail`
    (parts are made in this order: a seeded initialisation depends on it), and
    ends its ``forward`` and ``support`` with :meth:`tail` and :meth:`tail_support`.
    Its sizes give ``channels``, ``recon_blocks``, ``unshuffle`` and ``mu``.
    """

    def build_tail(self, align: PyramidAlign, count: int) -> None:
        """``align``: the method's pyramid alignment; ``count``: the sub-streams' features it aligns."""
        s, c = self.sizes, self.sizes.channels
        self.align = align
        self.fuse = nn.Sequential(nn.Conv2d(count * c, c, 1), nn.LeakyReLU(0.1))
        self.reconstruct = nn.Sequential(*[ResBlock(c) for _ in range(s.recon_blocks)])
        self.head = BlendHead(c, s.unshuffle, s.mu)

    def tail(self, feats: torch.Tensor, light: torch.Tensor, inside: torch.Tensor | None,
             spike_light: float) -> torch.Tensor:
        """Align, fuse, reconstruct, head (``inside``, ``spike_light``: the head's)."""
        fused = self.reconstruct(self.fuse(self.align(feats).flatten(1, 2)))
        return self.head(fused, light, inside, spike_light)

    def tail_support(self, feats: Support, light: Support) -> Support:
        """:meth:`tail` on supports."""
        return self.head.support(support(self.reconstruct, support(self.fuse, self.align.support(feats))), light)
