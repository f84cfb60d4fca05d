"""Light intensity-based refinement (LIR, paper section 5.4, Fig. 3 (c), eq. 6).

The temporal mean of the key sub-stream is a rough estimate of the light at
the key moment; concatenated with the sub-stream it gives, through two
convolutions, the intensity feature ``I``. Multi-head attention over the
fused feature ``F~`` is guided by it as in eq. 6,
``att = (Y_i o V_i) softmax(K_i^T Q_i / gamma_i)``, where ``K_i^T Q_i`` is a
(C/k x C/k) matrix per head, so the cost is linear in H x W.

Two choices the paper leaves open, made so that any frame size works and a
frame split into overlapping tiles gives the whole-frame result:
``K_i^T Q_i`` is averaged over a ``attention_window`` neighbourhood of each
pixel (a box filter of the per-pixel outer products) instead of over the
whole frame, with Q and K L2-normalised per pixel inside each head so every
entry lies in [-1, 1] and ``gamma_i`` is a temperature; and the positional
encoding ``P`` is a depthwise 3 x 3 convolution of ``F~`` (a conditional
positional encoding: a learned table of H x W entries would fix the frame size).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..reach import Support, support, union
from .features import channels_last
from ..learning.layers import conv3


def box_mean(x: torch.Tensor, size: int) -> torch.Tensor:
    """Mean over the size x size neighbourhood of every pixel, counting only pixels inside
    the frame (``avg_pool2d(..., stride=1, count_include_pad=False)``), separably: a column
    mean then a row mean (the counts factor). Each output reads its neighbourhood only, so
    a pixel farther away leaves it bit-identical (running sums along the whole frame, used
    before, were 10 times slower here and let every earlier pixel's rounding in)."""
    r = size // 2
    x = F.avg_pool2d(x, (size, 1), stride=1, padding=(r, 0), count_include_pad=False)
    return F.avg_pool2d(x, (1, size), stride=1, padding=(0, r), count_include_pad=False)


class IntensityFeature(nn.Module):
    """(key sub-stream (N, window, H, W), temporal mean (N, 1, H, W)) -> I (N, C, H/u, W/u)."""

    def __init__(self, window: int, channels: int, unshuffle: int = 1):
        super().__init__()
        self.unshuffle = nn.PixelUnshuffle(unshuffle)
        self.convs = nn.Sequential(conv3((window + 1) * unshuffle ** 2, channels),
                                   nn.ReLU(), conv3(channels, channels))

    def forward(self, substream: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
        return self.convs(channels_last(self.unshuffle(torch.cat((mean, substream), 1))))

    def support(self, substream: Support, mean: Support) -> Support:
        return support(self.convs, support(self.unshuffle, union(mean, substream)))


class GuidedAttention(nn.Module):
    """Eq. 6: (F~ (N, C, h, w), I (N, C, h, w)) -> F_o (N, C, h, w)."""

    def __init__(self, channels: int, heads: int, window: int):
        super().__init__()
        self.heads, self.window = heads, window
        self.query = nn.Conv2d(channels, channels, 1)      # the three fully connected layers,
        self.key = nn.Conv2d(channels, channels, 1)        # applied to every token
        self.value = nn.Conv2d(channels, channels, 1)
        self.gamma = nn.Parameter(torch.ones(heads))       # learnable scale per head
        self.project = nn.Conv2d(channels, channels, 1)
        self.position = nn.Conv2d(channels, channels, 3, padding=1, groups=channels)

    def forward(self, x: torch.Tensor, guide: torch.Tensor) -> torch.Tensor:
        n, c, h, w = x.shape
        k, d = self.heads, c // self.heads
        q = F.normalize(self.query(x).reshape(n, k, d, h, w), dim=2)
        key = F.normalize(self.key(x).reshape(n, k, d, h, w), dim=2)
        yv = (guide * self.value(x)).reshape(n, k, d, h, w)                # Y_i o V_i
        outer = (key[:, :, :, None] * q[:, :, None, :]).reshape(n, k * d * d, h, w)
        gram = box_mean(outer, self.window).reshape(n, k, d, d, h, w)     # K_i^T Q_i, local
        weights = torch.softmax(gram / self.gamma.reshape(1, k, 1, 1, 1, 1), dim=2)
        att = torch.einsum("nkiyx,nkijyx->nkjyx", yv, weights).reshape(n, c, h, w)
        return self.project(att) + self.position(x)

    def support(self, x: Support, guide: Support) -> Support:
        """:meth:`forward` on supports: the box mean of the outer products reaches window // 2."""
        q, key, value = (support(layer, x) for layer in (self.query, self.key, self.value))
        gram = union(key, q).taps(self.window // 2)
        att = union(guide, value, gram)
        return union(support(self.project, att), support(self.position, x))
