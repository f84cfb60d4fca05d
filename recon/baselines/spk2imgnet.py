"""Spk2ImgNet (Zhao et al., CVPR 2021), re-implemented from the paper for decoded light, 61 readouts.

The paper's pipeline, in its order:

1. the stream around the key moment is cut into overlapping windows (here
   5 windows of 21 readouts, 10 apart: the 61-readout variant of the TE
   paper, key window in the middle);
2. hierarchical adaptive representation: each window is read at several
   temporal lengths around its centre (short ones keep motion sharp, long
   ones average the noise), each length through its own convolutions, and a
   pixel-wise attention (a softmax over the lengths, per channel) weighs them;
3. residual feature extraction (residual blocks, shared by the windows);
4. pyramid deformable alignment of every window's feature to the key
   window's (EDVR's PCD: three levels, offsets propagated coarse to fine,
   a cascading refinement);
5. fusion of the aligned features and reconstruction (residual blocks, one
   output convolution).

Adapted here (see docs/baselines.md): the input is decoded light, compressed
with the mu-law; the output is the shared head of every learned method
(:class:`tespike.recon.learning.head.BlendHead`, after common.py's tail): a
per-pixel blend of training-free estimates plus a correction;
``unshuffle`` folds the frame for a CPU size (pixel-unshuffle, every pixel
kept), a u x u convolution of stride u embedding each temporal length first.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import torch
from torch import nn

from ..learning.layers import conv3, substreams
from ..mulaw import compress
from ..reach import Support, support, union
from .common import AlignedBaseline, BaselineSizes, BaselineSubstreams, ResBlock, centred


@dataclasses.dataclass(frozen=True)
class Spk2ImgNetSizes(BaselineSizes, BaselineSubstreams):
    """Every size of Spk2ImgNet.

    ``substreams`` windows of ``window`` readouts ``stride`` apart (span
    (substreams - 1) * stride + window = 61); ``lengths``: the temporal lengths
    (odd, <= window) of the adaptive representation; ``blocks``: residual blocks
    of feature extraction; the rest (feature width, the pyramid alignment, frame
    folding, the mu-law, the blocks after fusion): :class:`BaselineSizes`.
    """

    PAPER: ClassVar[dict] = {"unshuffle": 1, "channels": 64, "blocks": 13, "recon_blocks": 10, "offset_groups": 8}
    LABEL: ClassVar[str] = "spk2imgnet"

    lengths: tuple[int, ...] = (5, 11, 21)
    blocks: int = 2

    def __post_init__(self) -> None:
        super().__post_init__()
        self._need_substreams()
        self._need_ints("blocks", least=0)
        self._need("lengths", isinstance(self.lengths, tuple) and len(self.lengths) >= 1
                   and all(type(k) is int and k >= 1 and k % 2 == 1 and k <= self.window for k in self.lengths),
                   "a tuple of odd integers from 1 to window")


class AdaptiveRepresentation(nn.Module):
    """(B, window, H, W) compressed light -> (B, C, H / u, W / u): several temporal lengths, attention-weighted.

    Each length's first layer is a u x u convolution of stride u: a
    pixel-unshuffle by u followed by a 1 x 1 convolution, without the copy.
    """

    def __init__(self, sizes: Spk2ImgNetSizes):
        super().__init__()
        c, u = sizes.channels, sizes.unshuffle
        self.lengths = sizes.lengths
        self.branches = nn.ModuleList(
            nn.Sequential(nn.Conv2d(k, c, u, stride=u), nn.LeakyReLU(0.1), conv3(c, c), nn.LeakyReLU(0.1))
            for k in sizes.lengths)
        self.attention = conv3(len(sizes.lengths) * c, len(sizes.lengths) * c)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        feats = torch.stack([branch(centred(x, k)) for k, branch in zip(self.lengths, self.branches)], 1)
        b, k, c, h, w = feats.shape
        weights = torch.softmax(self.attention(feats.reshape(b, k * c, h, w)).reshape(b, k, c, h, w), dim=1)
        return (weights * feats).sum(1)

    def support(self, x: Support) -> Support:
        feats = union(*(support(branch, x) for branch in self.branches))
        return union(support(self.attention, feats), feats)


class Spk2ImgNet(AlignedBaseline):
    """(N, 61, H, W) decoded light -> (N, 1, H, W) light at the key moment (readout 30)."""

    def __init__(self, sizes: Spk2ImgNetSizes = Spk2ImgNetSizes()):
        super().__init__(sizes)
        c = sizes.channels
        self.represent = AdaptiveRepresentation(sizes)
        self.extract = nn.Sequential(conv3(c, c), nn.LeakyReLU(0.1), *[ResBlock(c) for _ in range(sizes.blocks)])
        self.build_tail(sizes.substreams)

    def features(self, light: torch.Tensor) -> torch.Tensor:
        """Each window's adaptive representation, then residual extraction: (N, S, C, h, w)."""
        s = self.sizes
        windows = substreams(compress(light, s.mu), s.substreams, s.window, s.stride)
        feats = torch.stack([self.represent(window) for window in windows.unbind(1)], 1)
        return self.extract(feats.flatten(0, 1)).unflatten(0, feats.shape[:2])

    def features_support(self, light: Support) -> Support:
        """:meth:`features` on supports (windows and the mu-law act per pixel)."""
        return support(self.extract, support(self.represent, light))
