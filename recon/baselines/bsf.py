"""BSF (Zhao et al., CVPR 2024, "Boosting spike camera image reconstruction from a perspective
of dealing with spike fluctuations"), re-implemented from the paper for decoded light.

The paper's pipeline, in its order:

1. representation: the spike interval around every moment and the firing
   rates of several orders (the rate over the interval spanning k spikes),
   which average a bright pixel over a short time and a dark one over a long
   time: the spikes' fluctuations are evened out where light is scarce, and
   motion stays sharp where it is plentiful (:mod:`.represent` derives both
   from decoded light);
2. the span is cut into sub-spans around the key moment (here 5 of 21
   readouts, 10 apart: 61 readouts), each read into a feature by a
   multi-order encoder (one embedding per order, fused) and residual blocks
   with growing dilation;
3. pyramid alignment of every sub-span's feature to the key's with
   deformable convolution whose offsets come from a local cross-attention
   between key and reference at each level (:class:`tespike.recon.learning.align.LocalCrossAttention`);
4. fusion and reconstruction.

Adapted here (docs/baselines.md): input in the mu-law domain; the output is
the shared head of every learned method (:class:`tespike.recon.learning.head.BlendHead`,
after common.py's tail): a per-pixel blend of training-free estimates plus a
correction; ``unshuffle`` folds the frame for a CPU size.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import torch
from torch import nn

from ..learning.layers import conv3
from ..mulaw import compress_
from ..reach import Support, support, union
from .common import AlignedBaseline, BaselineSizes, BaselineSubstreams, ResBlock
from .represent import firing_rates


@dataclasses.dataclass(frozen=True)
class BSFSizes(BaselineSizes, BaselineSubstreams):
    """Every size of BSF.

    ``substreams`` sub-spans of ``window`` readouts ``stride`` apart (span 61);
    ``orders``: firing-rate orders (spikes spanned; order 1 is the inverse
    of the spike interval); ``threshold``: light x readouts per virtual spike
    (scene units; 1 = one spike per readout at the design light);
    ``blocks``: dilated residual blocks of the encoder (dilations 1, 2, 1, 2, ...);
    ``attention_radius``: the local cross-attention's neighbourhood is
    (2 r + 1)^2 pixels of each level; the rest: :class:`BaselineSizes`.
    """

    PAPER: ClassVar[dict] = {"unshuffle": 1, "channels": 64, "blocks": 4, "recon_blocks": 3, "offset_groups": 4}
    LABEL: ClassVar[str] = "bsf"

    orders: tuple[int, ...] = (1, 4, 16)
    threshold: float = 1.0
    blocks: int = 2
    attention_radius: int = 2

    def __post_init__(self) -> None:
        super().__post_init__()
        self._need_substreams()
        self._need_ints("attention_radius")
        self._need_ints("blocks", least=0)
        self._need("orders", isinstance(self.orders, tuple) and len(self.orders) >= 1
                   and all(type(k) is int and k >= 1 for k in self.orders), "a tuple of integers >= 1")
        self._need_positive("threshold")


class MultiOrderEncoder(nn.Module):
    """(N, orders, span, H, W) compressed rates -> (N, S, C, H / u, W / u) features of the S sub-spans.

    A sub-span of one order is a slice of the input (no copy of the
    overlapping sub-spans); its embedding is a u x u convolution of stride u
    (a pixel-unshuffle by u and a 1 x 1 convolution, without the copy).
    """

    def __init__(self, sizes: BSFSizes):
        super().__init__()
        s = self.sizes = sizes
        c, u, k = s.channels, s.unshuffle, len(s.orders)
        self.embed = nn.ModuleList(nn.Conv2d(s.window, c, u, stride=u) for _ in range(k))
        self.fuse = conv3(k * c, c)
        self.act = nn.LeakyReLU(0.1)
        self.blocks = nn.Sequential(*[ResBlock(c, dilation=1 + i % 2) for i in range(s.blocks)])

    def forward(self, rates: torch.Tensor) -> torch.Tensor:
        s = self.sizes
        n = rates.shape[0]
        subs = [torch.cat([self.act(embed(rates[:, i, start:start + s.window]))
                           for i, embed in enumerate(self.embed)], 1)
                for start in range(0, s.substreams * s.stride, s.stride)]
        x = torch.stack(subs, 1).flatten(0, 1)
        x = self.blocks(self.act(self.fuse(x)))
        return x.reshape(n, s.substreams, *x.shape[1:])

    def support(self, rates: Support) -> Support:
        embedded = union(*(support(embed, rates) for embed in self.embed))
        return support(self.blocks, support(self.fuse, embedded))


class BSF(AlignedBaseline):
    """(N, 61, H, W) decoded light -> (N, 1, H, W) light at the key moment (readout 30)."""

    def __init__(self, sizes: BSFSizes = BSFSizes()):
        super().__init__(sizes)
        self.encoder = MultiOrderEncoder(sizes)
        self.build_tail(sizes.substreams, attention_radius=sizes.attention_radius)

    def features(self, light: torch.Tensor) -> torch.Tensor:
        """Multi-order firing rates, mu-law compressed, encoded per sub-span: (N, S, C, h, w)."""
        s = self.sizes
        rates = firing_rates(light, s.orders, s.threshold)                    # (N, orders, span, H, W)
        return self.encoder(compress_(rates, s.mu))                             # compressed in place (no gradient)

    def features_support(self, light: Support) -> Support:
        """:meth:`features` on supports (the firing rates are per pixel)."""
        return self.encoder.support(light)
