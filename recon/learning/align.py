"""Pyramid deformable alignment of sub-stream features to the key's (EDVR's PCD), for every learned method.

Every reference feature is aligned to the key feature coarse to fine over a
pyramid of ``levels``: at each level, convolutions of (key, reference) give
the offsets and masks of a modulated deformable convolution (paper eq. 5),
fused with the upsampled offset features of the coarser level; below the
coarsest level the aligned reference is merged with the upsampled coarser
result. Offsets are ``max_offset * tanh``, so the receptive field is bounded
(:meth:`PyramidAlign.support`, :mod:`tespike.recon.reach`) and tiled inference is exact.

The methods differ in the parts each level adds, all options of one module:

- the paper's network (SPA, section 5.3, eq. 9): ``similarity`` (SP gates the
  upsampled coarser result before the merge) and ``motion_bias`` (MBP adds a
  bias to the aligned feature), both two 3 x 3 convolutions (appendix A.1.3);
- the three baselines: EDVR's ``cascade`` (one more full-resolution level refining the result);
- BSF: ``attention_radius`` > 0, the offsets seeded by a local cross-attention
  between key and reference (:class:`LocalCrossAttention`);
- MambaSpike: ``filter_kernel`` > 0, an adaptive per-pixel filter after each level.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from ..reach import Support, support, union
from .deform import ModulatedDeformConv2d
from .layers import conv3, upsample


def neighbourhood(x: torch.Tensor, radius: int) -> torch.Tensor:
    """(B, C, h, w) -> (B, C, (2r+1)^2, h, w): every pixel's (2r+1)^2 neighbours (zeros outside)."""
    b, c, h, w = x.shape
    k = 2 * radius + 1
    return F.unfold(x, k, padding=radius).reshape(b, c, k * k, h, w)


class TwoConv(nn.Sequential):
    """Two 3 x 3 convolutions with a ReLU between: the paper's SP and MBP (appendix A.1.3)."""

    def __init__(self, cin: int, cout: int):
        super().__init__(conv3(cin, cout), nn.ReLU(), conv3(cout, cout))


class LocalCrossAttention(nn.Module):
    """Key queries the reference in a (2r+1)^2 neighbourhood: attended reference and expected displacement.

    BSF's local cross-attention: q from the key, k and v from the reference
    (1 x 1 projections), softmax over the neighbourhood of q . k / sqrt(C).
    Returns the attended reference feature (C channels) and the
    attention-weighted displacement (dy, dx) in pixels of the level, which
    seed the deformable offsets.
    """

    def __init__(self, channels: int, radius: int):
        super().__init__()
        self.radius = radius
        self.q = nn.Conv2d(channels, channels, 1)
        self.k = nn.Conv2d(channels, channels, 1)
        self.v = nn.Conv2d(channels, channels, 1)
        r = torch.arange(-radius, radius + 1, dtype=torch.float32)
        dy, dx = torch.meshgrid(r, r, indexing="ij")
        self.register_buffer("displacement", torch.stack((dy.reshape(-1), dx.reshape(-1))), persistent=False)

    def forward(self, key: torch.Tensor, ref: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One shifted slice per neighbour (zeros outside), never the (2r+1)^2-fold unfolded copy."""
        b, c, h, w = key.shape
        r, side = self.radius, 2 * self.radius + 1
        q = self.q(key)
        k = F.pad(self.k(ref), (r, r, r, r))
        v = F.pad(self.v(ref), (r, r, r, r))
        shifts = [(dy, dx) for dy in range(side) for dx in range(side)]       # row-major, as displacement
        scores = torch.stack([(q * k[:, :, dy:dy + h, dx:dx + w]).sum(1) for dy, dx in shifts], 1)
        attention = torch.softmax(scores / math.sqrt(c), dim=1)                 # (B, K, h, w)
        attended = sum(attention[:, i:i + 1] * v[:, :, dy:dy + h, dx:dx + w] for i, (dy, dx) in enumerate(shifts))
        shift = torch.einsum("bkhw,dk->bdhw", attention, self.displacement.to(attention.dtype))
        return attended, shift

    def support(self, key: Support, ref: Support) -> tuple[Support, Support]:
        """(attended, shift): both read the reference within ``radius`` pixels."""
        near = union(support(self.q, key), support(self.k, ref).taps(self.radius),
                     support(self.v, ref).taps(self.radius))
        return near, near


class AdaptiveFilter(nn.Module):
    """A k x k filter predicted per pixel (softmax-normalised) from (aligned, key), applied to aligned."""

    def __init__(self, channels: int, kernel: int):
        super().__init__()
        self.kernel = kernel
        self.predict = nn.Sequential(conv3(2 * channels, channels), nn.LeakyReLU(0.1),
                                     conv3(channels, kernel * kernel))

    def forward(self, aligned: torch.Tensor, key: torch.Tensor) -> torch.Tensor:
        weights = torch.softmax(self.predict(torch.cat((aligned, key), 1)), dim=1)
        patches = neighbourhood(aligned, self.kernel // 2)
        return aligned + (patches * weights[:, None]).sum(2)

    def support(self, aligned: Support, key: Support) -> Support:
        return union(aligned.taps(self.kernel // 2), support(self.predict, union(aligned, key)))


class AlignLevel(nn.Module):
    """One pyramid level l (the paper's eq. 9) for a batch of (key, reference) pairs.

    Offsets from (key, reference[, attention]) and the coarser level's offset
    feature; the DCN; below the coarsest level the merge with the upsampled
    coarser result (SP-gated where ``similarity``); then MBP's bias and the
    adaptive filter where asked. Parts are made in this order (a seeded
    initialisation depends on it).
    """

    def __init__(self, channels: int, dcn_kernel: int, offset_groups: int, max_offset: float, coarsest: bool,
                 *, attention_radius: int = 0, filter_kernel: int = 0, similarity: bool = False,
                 motion_bias: bool = False):
        super().__init__()
        c = channels
        self.coarsest, self.max_offset = coarsest, float(max_offset)
        self.act = nn.LeakyReLU(0.1)
        self.attention = LocalCrossAttention(c, attention_radius) if attention_radius else None
        self.offset_in = conv3(2 * c + (c + 2 if attention_radius else 0), c)
        self.offset_fuse = None if coarsest else conv3(2 * c, c)
        self.offset_mid = conv3(c, c)
        self.dcn = ModulatedDeformConv2d(c, c, dcn_kernel, offset_groups)
        self.offset_out = conv3(c, self.dcn.offset_channels + self.dcn.mask_channels)
        nn.init.zeros_(self.offset_out.weight)     # start as a plain convolution: zero offsets,
        nn.init.zeros_(self.offset_out.bias)       # masks 0.5
        self.similarity = TwoConv(2 * c, c) if (similarity and not coarsest) else None
        self.merge = None if coarsest else conv3(2 * c, c)
        self.motion_bias = TwoConv(2 * c, c) if motion_bias else None
        self.filter = AdaptiveFilter(c, filter_kernel) if filter_kernel else None

    def forward(self, key, ref, coarser_offset_feature=None, coarser_aligned=None):
        """-> (offset feature, aligned reference ~F_{i,l}) at this level."""
        parts = [key, ref]
        if self.attention is not None:
            attended, shift = self.attention(key, ref)
            parts += [attended, shift]
        feature = self.act(self.offset_in(torch.cat(parts, 1)))
        if not self.coarsest:
            feature = self.act(self.offset_fuse(torch.cat((feature, upsample(coarser_offset_feature)), 1)))
        feature = self.act(self.offset_mid(feature))
        raw = self.offset_out(feature)
        n_off = self.dcn.offset_channels
        offset = self.max_offset * torch.tanh(raw[:, :n_off])
        if self.attention is not None:      # the attention's displacement seeds every tap's offset
            offset = offset + shift.repeat(1, n_off // 2, 1, 1)
        aligned = self.dcn(ref, offset, torch.sigmoid(raw[:, n_off:]))             # ^F_{i,l}, eq. 5
        if not self.coarsest:
            up = upsample(coarser_aligned)                                         # ~F^up_{i,l+1}
            if self.similarity is not None:
                up = torch.sigmoid(self.similarity(torch.cat((up, key), 1))) * up   # s o ~F^up
            aligned = self.act(self.merge(torch.cat((aligned, up), 1)))            # ~F^re_{i,l}
        if self.motion_bias is not None:
            aligned = aligned + self.motion_bias(torch.cat((aligned, key), 1))      # + b_{i,l}
        if self.filter is not None:
            aligned = self.filter(aligned, key)
        return feature, aligned

    def support(self, key: Support, ref: Support, coarser_offset_feature: Support | None = None,
                coarser_aligned: Support | None = None) -> tuple[Support, Support]:
        """:meth:`forward` on supports; the attention's shift (at most its radius) adds to every offset."""
        parts, seed = [key, ref], 0
        if self.attention is not None:
            attended, shift = self.attention.support(key, ref)
            parts += [attended, shift]
            seed = self.attention.radius
        feature = support(self.offset_in, union(*parts))
        if not self.coarsest:
            feature = support(self.offset_fuse, union(feature, coarser_offset_feature.upsample(2)))
        raw = support(self.offset_out, support(self.offset_mid, feature))
        offset = union(raw, shift) if self.attention is not None else raw
        aligned = self.dcn.support(ref, offset, raw, self.max_offset + seed)
        if not self.coarsest:
            up = coarser_aligned.upsample(2)
            if self.similarity is not None:
                up = union(support(self.similarity, union(up, key)), up)
            aligned = support(self.merge, union(aligned, up))
        if self.motion_bias is not None:
            aligned = union(aligned, support(self.motion_bias, union(aligned, key)))
        if self.filter is not None:
            aligned = self.filter.support(aligned, key)
        return feature, aligned


class PyramidAlign(nn.Module):
    """(N, S, C, h, w) features of S sub-streams, key in the middle -> the same with every reference
    aligned to the key, coarse to fine over ``levels`` (0: no alignment, the features as they are).

    ``cascade``: EDVR's refinement by one more full-resolution level; the
    other keywords are :class:`AlignLevel`'s, the same at every level.
    """

    def __init__(self, channels: int, levels: int, dcn_kernel: int = 3, offset_groups: int = 1,
                 max_offset: float = 8.0, *, cascade: bool = False, **parts):
        super().__init__()
        c = channels
        self.down = nn.ModuleList(nn.Sequential(conv3(c, c, 2), nn.LeakyReLU(0.1), conv3(c, c), nn.LeakyReLU(0.1))
                                  for _ in range(levels - 1))
        self.levels = nn.ModuleList(AlignLevel(c, dcn_kernel, offset_groups, max_offset, level == levels - 1,
                                               **parts) for level in range(levels))
        self.cascade = AlignLevel(c, dcn_kernel, offset_groups, max_offset, True) if cascade else None

    def align(self, key: torch.Tensor, refs: torch.Tensor) -> torch.Tensor:
        """key (N, C, h, w), refs (N, R, C, h, w) -> aligned refs (N, R, C, h, w)."""
        n, r, c, h, w = refs.shape
        keys = [key.repeat_interleave(r, 0)]
        rs = [refs.reshape(n * r, c, h, w)]
        for down in self.down:                 # one pyramid, shared by key and references
            keys.append(down(keys[-1]))
            rs.append(down(rs[-1]))
        offset_feature = aligned = None
        for level in reversed(range(len(self.levels))):
            offset_feature, aligned = self.levels[level](keys[level], rs[level], offset_feature, aligned)
        if self.cascade is not None:
            _, aligned = self.cascade(keys[0], aligned)
        return aligned.reshape(n, r, c, h, w)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        if not len(self.levels):
            return features
        middle = features.shape[1] // 2
        key = features[:, middle]
        aligned = self.align(key, torch.cat((features[:, :middle], features[:, middle + 1:]), 1))
        return torch.cat((aligned[:, :middle], key[:, None], aligned[:, middle:]), 1)

    def support(self, features: Support) -> Support:
        """:meth:`forward` on supports (every sub-stream's feature has the same; the key's is among them)."""
        if not len(self.levels):
            return features
        keys, rs = [features], [features]
        for down in self.down:
            keys.append(support(down, keys[-1]))
            rs.append(support(down, rs[-1]))
        offset_feature = aligned = None
        for level in reversed(range(len(self.levels))):
            offset_feature, aligned = self.levels[level].support(keys[level], rs[level], offset_feature, aligned)
        if self.cascade is not None:
            aligned = self.cascade.support(keys[0], aligned)[1]
        return union(aligned, features)
