"""Similarity-based pyramid alignment (SPA, paper section 5.3, Fig. 3 (b), eq. 5 and 9).

Every reference feature is aligned to the key feature coarse to fine over a
pyramid of ``levels`` (3 in the paper). At each level, two convolutions of
(key, reference) give the DCN's offsets and masks, fused with the
upsampled offset features of the coarser level (offsets propagate up); a
modulated deformable convolution (eq. 5) aligns the reference; below the
coarsest level the similarity predictor SP gates the upsampled coarser
result before it is merged with this level's DCN output, and the motion
bias predictor MBP adds a bias (eq. 9). The aligned references and the key
are fused by two convolutions into ``F~``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..reach import Support, support, union
from .deform import ModulatedDeformConv2d
from .sizes import NetSizes


def conv3(cin: int, cout: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, stride=stride, padding=1)


def upsample(x: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)


class TwoConv(nn.Sequential):
    """Two 3 x 3 convolutions with a ReLU between: the paper's SP and MBP (appendix A.1.3)."""

    def __init__(self, cin: int, cout: int):
        super().__init__(conv3(cin, cout), nn.ReLU(), conv3(cout, cout))


class LevelAlignment(nn.Module):
    """One pyramid level l of eq. 9 for a batch of (key, reference) pairs."""

    def __init__(self, channels: int, sizes: NetSizes, coarsest: bool):
        super().__init__()
        c, k = channels, sizes.dcn_kernel
        self.coarsest, self.max_offset = coarsest, float(sizes.max_offset)
        self.act = nn.LeakyReLU(0.1)
        self.offset_in = conv3(2 * c, c)
        self.offset_fuse = None if coarsest else conv3(2 * c, c)
        self.offset_mid = conv3(c, c)
        self.dcn = ModulatedDeformConv2d(c, c, k)
        self.offset_out = conv3(c, self.dcn.offset_channels + self.dcn.mask_channels)
        nn.init.zeros_(self.offset_out.weight)     # start as a plain convolution: zero offsets,
        nn.init.zeros_(self.offset_out.bias)       # masks 0.5
        self.similarity = TwoConv(2 * c, c) if (sizes.similarity and not coarsest) else None
        self.merge = None if coarsest else conv3(2 * c, c)
        self.motion_bias = TwoConv(2 * c, c) if sizes.motion_bias else None

    def forward(self, key, ref, coarser_offset_feature=None, coarser_aligned=None):
        """-> (offset feature, aligned reference ~F_{i,l}) at this level."""
        feature = self.act(self.offset_in(torch.cat((key, ref), 1)))
        if not self.coarsest:
            feature = self.act(self.offset_fuse(torch.cat((feature, upsample(coarser_offset_feature)), 1)))
        feature = self.act(self.offset_mid(feature))
        raw = self.offset_out(feature)
        n_off = self.dcn.offset_channels
        offset = self.max_offset * torch.tanh(raw[:, :n_off])
        mask = torch.sigmoid(raw[:, n_off:])
        aligned = self.dcn(ref, offset, mask)                            # ^F_{i,l}, eq. 5
        if not self.coarsest:
            up = upsample(coarser_aligned)                               # ~F^up_{i,l+1}
            if self.similarity is not None:
                up = torch.sigmoid(self.similarity(torch.cat((up, key), 1))) * up     # s o ~F^up
            aligned = self.act(self.merge(torch.cat((aligned, up), 1)))  # ~F^re_{i,l}
        if self.motion_bias is not None:
            aligned = aligned + self.motion_bias(torch.cat((aligned, key), 1))        # + b_{i,l}
        return feature, aligned

    def support(self, key: Support, ref: Support, coarser_offset_feature: Support | None = None,
                coarser_aligned: Support | None = None) -> tuple[Support, Support]:
        """:meth:`forward` on supports."""
        feature = support(self.offset_in, union(key, ref))
        if not self.coarsest:
            feature = support(self.offset_fuse, union(feature, coarser_offset_feature.upsample(2)))
        feature = support(self.offset_mid, feature)
        raw = support(self.offset_out, feature)
        aligned = self.dcn.support(ref, raw, raw, self.max_offset)
        if not self.coarsest:
            up = coarser_aligned.upsample(2)
            if self.similarity is not None:
                up = union(support(self.similarity, union(up, key)), up)
            aligned = support(self.merge, union(aligned, up))
        if self.motion_bias is not None:
            aligned = union(aligned, support(self.motion_bias, union(aligned, key)))
        return feature, aligned


class SPA(nn.Module):
    """(N, S, C, h, w) features of S sub-streams (key in the middle) -> fused (N, C, h, w)."""

    def __init__(self, sizes: NetSizes):
        super().__init__()
        c = sizes.channels
        self.sizes = sizes
        self.act = nn.LeakyReLU(0.1)
        pyramid = sizes.levels if sizes.dcn else 1
        self.down = nn.ModuleList(nn.Sequential(conv3(c, c, 2), nn.LeakyReLU(0.1), conv3(c, c), nn.LeakyReLU(0.1))
                                  for _ in range(pyramid - 1))
        self.levels = nn.ModuleList(LevelAlignment(c, sizes, coarsest=(level == pyramid - 1))
                                    for level in range(pyramid)) if sizes.dcn else None
        self.fusion = nn.Sequential(conv3(sizes.substreams * c, c), nn.LeakyReLU(0.1), conv3(c, c))

    def align(self, key: torch.Tensor, refs: torch.Tensor) -> torch.Tensor:
        """key (N, C, h, w), refs (N, R, C, h, w) -> aligned refs (N, R, C, h, w)."""
        n, r, c, h, w = refs.shape
        keys = [key.repeat_interleave(r, 0)]
        rs = [refs.reshape(n * r, c, h, w)]
        for down in self.down:                     # one pyramid, shared by key and references
            keys.append(down(keys[-1]))
            rs.append(down(rs[-1]))
        offset_feature = aligned = None
        for level in reversed(range(len(self.levels))):
            offset_feature, aligned = self.levels[level](keys[level], rs[level], offset_feature, aligned)
        return aligned.reshape(n, r, c, h, w)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        n, s, c, h, w = features.shape
        middle = s // 2
        key = features[:, middle]
        refs = torch.cat((features[:, :middle], features[:, middle + 1:]), 1)
        if self.levels is not None:
            refs = self.align(key, refs)
        stacked = torch.cat((refs[:, :middle], key[:, None], refs[:, middle:]), 1)
        return self.act(self.fusion(stacked.reshape(n, s * c, h, w)))

    def support(self, features: Support) -> Support:
        """:meth:`forward` on supports (every sub-stream's feature has the same)."""
        key = refs = features
        if self.levels is not None:
            keys, rs = [key], [refs]
            for down in self.down:
                keys.append(support(down, keys[-1]))
                rs.append(support(down, rs[-1]))
            offset_feature = aligned = None
            for level in reversed(range(len(self.levels))):
                offset_feature, aligned = self.levels[level].support(keys[level], rs[level], offset_feature, aligned)
            refs = aligned
        return support(self.fusion, union(refs, key))
