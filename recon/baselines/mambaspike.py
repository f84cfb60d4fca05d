"""MambaSpike: the selective-scan reconstruction of the multi-level (ML) spike camera, for decoded light.

The TE paper compares with "MambaSpike", the reconstruction Zhu et al.
proposed with the ML spike camera (its reference [67]; IEEE TCSVT, "a new
spike camera model of high-speed imaging for high dynamic range
scenarios"). Its published description: spike intervals and spike levels
both enter; a temporal-spatial selective scan (Mamba) extracts the
correlation within the stream; a pyramid adaptive filtering and alignment
module aligns features coarse to fine; for the ML camera the stream is
parsed several ways ("multiple parsings", because the MSB readout leaves
part of the counter unread), for TE one parsing branch (TE paper, section
6). Its layer-by-layer design is not published in what we could read; the
choices below follow that description and the closest published designs
(Vision Mamba's bidirectional blocks, local window scans as in LocalMamba,
Spk2ImgNet/EDVR's pyramid alignment), and are listed in docs/baselines.md.

1. representation per readout: the level (decoded light) and the spike
   interval (as a firing rate, :mod:`.represent`), mu-law compressed;
   parsing branch p re-reads the stream with a virtual threshold 4^p times
   coarser (TE: one branch);
2. temporal selective scan: each pixel's (folded) readouts, grouped into
   tokens of ``temporal_patch`` readouts centred on the key, are a sequence
   scanned by bidirectional Mamba blocks (:mod:`.scan`);
3. ``moments`` token features around the key (the key in the middle) are
   read out; spatial selective scan: bidirectional Mamba blocks over the
   pixels of each ``scan_window`` x ``scan_window`` window (rows then
   columns, alternating), so the receptive field stays bounded;
4. pyramid alignment of every moment to the key with the project's DCN,
   each level followed by an adaptive per-pixel filter;
5. fusion and reconstruction (residual blocks), then the shared head of every
   learned method (:class:`tespike.recon.learning.head.BlendHead`, after common.py's
   tail): a per-pixel blend of training-free estimates plus a correction.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import torch
import torch.nn.functional as F
from torch import nn

from ..mulaw import compress_
from ..reach import Support, support, union
from .common import AlignedBaseline, BaselineSizes
from .represent import firing_rates
from .scan import MambaBlock


#: Parsing branches on the msb camera (the paper's "multiple parsings"): virtual thresholds
#: 1, 4 and 16 x the interval's spike (branch p re-reads at 4^p).
MSB_PARSINGS = 3


@dataclasses.dataclass(frozen=True)
class MambaSpikeSizes(BaselineSizes):
    """Every size of MambaSpike.

    ``span``-readout input (``readouts``, odd; 61); ``parsings``: parsing
    branches (1 for TE, as the TE paper; more for ML); ``temporal_patch``:
    readouts per temporal token (odd); ``moments`` token features ``moment_stride``
    tokens apart go to the alignment; ``expand``, ``state``, ``head_dim``,
    ``chunk``: the Mamba blocks (inner width expand x channels, state size,
    channels per decay head, scan chunk); ``temporal_blocks``,
    ``spatial_blocks``; ``scan_window``: side of a spatial scan window
    (pixels at 1 / unshuffle); ``filter_kernel``: the alignment's adaptive
    filter; ``threshold``: the interval's virtual spike (scene units x
    readouts); the rest: :class:`BaselineSizes`.
    """

    PAPER: ClassVar[dict] = {"unshuffle": 2, "channels": 96, "state": 16, "temporal_patch": 1, "moment_stride": 10,
                             "temporal_blocks": 4, "spatial_blocks": 4, "recon_blocks": 1, "offset_groups": 8}
    LABEL: ClassVar[str] = "mambaspike"

    readouts: int = 61
    parsings: int = 1
    temporal_patch: int = 5
    moments: int = 5
    moment_stride: int = 3
    expand: int = 2
    state: int = 8
    head_dim: int = 8
    chunk: int = 13
    temporal_blocks: int = 1
    spatial_blocks: int = 1
    scan_window: int = 8
    filter_kernel: int = 3
    threshold: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        self._need_ints("readouts", "parsings", "temporal_patch", "moments", "moment_stride",
                        "expand", "state", "head_dim", "chunk", "scan_window", "filter_kernel")
        self._need_ints("temporal_blocks", "spatial_blocks", least=0)
        for key in ("readouts", "temporal_patch", "moments", "filter_kernel"):
            self._need(key, getattr(self, key) % 2 == 1, "odd (centred on the key moment)")
        self._need("moment_stride", (self.moments // 2) * self.moment_stride <= self.tokens // 2,
                   f"such that the moments lie within the {self.tokens} tokens")
        self._need("head_dim", (self.expand * self.channels) % self.head_dim == 0,
                   "a divisor of expand x channels")
        self._need_positive("threshold")

    @classmethod
    def for_camera(cls, name: str, config):
        """The paper's parsings: several on the msb camera, whose readout leaves the counter's
        rest unread (:data:`MSB_PARSINGS`), one where the whole count or TE word is read."""
        sizes = cls.preset(name)
        msb = config.mode == "ml" and config.ml_readout == "msb"
        return dataclasses.replace(sizes, parsings=MSB_PARSINGS) if msb else sizes

    @property
    def tokens(self) -> int:
        """Temporal tokens per pixel (the readouts padded at both ends to whole tokens)."""
        return -(-self.readouts // self.temporal_patch) | 1

    @property
    def span(self) -> int:
        return self.readouts

    @property
    def pyramid_factor(self) -> int:
        """Multiple of the pyramid's and of the scan windows' grid (so tiles see the same windows)."""
        return math.lcm(self.unshuffle << (self.levels - 1), self.unshuffle * self.scan_window)


class TokenEmbedding(nn.Module):
    """(N, 2, T, H, W) -> (N, C, T / patch, H / u, W / u): one token per patch readouts x u x u pixels.

    A 3-D convolution of stride = kernel, its weight kept 4-D, (C, 2 x patch, u, u),
    so the model converts to channels_last as the project's inference does.
    """

    def __init__(self, channels: int, patch: int, unshuffle: int):
        super().__init__()
        self.patch, self.unshuffle = patch, unshuffle
        self.weight = nn.Parameter(torch.empty(channels, 2 * patch, unshuffle, unshuffle))
        self.bias = nn.Parameter(torch.empty(channels))
        fan_in = 2 * patch * unshuffle ** 2                 # Conv3d's default initialisation
        nn.init.kaiming_uniform_(self.weight, a=math.sqrt(5))
        nn.init.uniform_(self.bias, -1 / math.sqrt(fan_in), 1 / math.sqrt(fan_in))

    def forward(self, rep: torch.Tensor) -> torch.Tensor:
        c, u = self.weight.shape[0], self.unshuffle
        weight = self.weight.reshape(c, 2, self.patch, u, u)
        return F.conv3d(rep, weight, self.bias, stride=(self.patch, u, u))

    def support(self, rep: Support) -> Support:
        return rep.conv(self.weight.shape[-1], stride=self.unshuffle)


class ParsingBranch(nn.Module):
    """One parsing: (N, T, H, W) light -> (N, moments, C, h, w) temporally scanned token features."""

    def __init__(self, sizes: MambaSpikeSizes, coarseness: float):
        super().__init__()
        s = self.sizes = sizes
        c, u = s.channels, s.unshuffle
        self.threshold = s.threshold * coarseness
        self.embed = TokenEmbedding(c, s.temporal_patch, u)
        self.blocks = nn.ModuleList(MambaBlock(c, s.expand, s.state, s.head_dim, s.chunk)
                                    for _ in range(s.temporal_blocks))
        self.norm = nn.LayerNorm(c)

    def forward(self, light: torch.Tensor) -> torch.Tensor:
        s = self.sizes
        n, t, h, w = light.shape
        rep = torch.stack((light.detach().clamp(min=0), firing_rates(light, (1,), self.threshold)[:, 0]), 1)
        rep = compress_(rep, s.mu)                                          # mu-law, in place: (N, 2, T, H, W)
        pad = (s.tokens * s.temporal_patch - t) // 2                         # whole tokens, the key in the middle
        if pad:
            rep = F.pad(rep, (0, 0, 0, 0, pad, pad), mode="replicate")
        feats = self.embed(rep)                                              # (N, C, L, h, w)
        c, hh, ww = feats.shape[1], feats.shape[3], feats.shape[4]
        seq = feats.permute(0, 3, 4, 2, 1).reshape(n * hh * ww, s.tokens, c)
        for block in self.blocks:
            seq = block(seq)
        middle = s.tokens // 2
        picks = middle + (torch.arange(s.moments, device=light.device) - s.moments // 2) * s.moment_stride
        seq = self.norm(seq[:, picks])                                       # (N h w, M, C)
        return seq.reshape(n, hh, ww, s.moments, c).permute(0, 3, 4, 1, 2)

    def support(self, light: Support) -> Support:
        """The representation and the temporal scan act per (folded) pixel: the embedding's reach only."""
        return self.embed.support(light)


class WindowScan(nn.Module):
    """(B, C, h, w) -> same: a bidirectional Mamba block over each window's pixels, in rows or columns."""

    def __init__(self, sizes: MambaSpikeSizes, columns: bool):
        super().__init__()
        s = sizes
        self.window, self.columns = s.scan_window, columns
        self.block = MambaBlock(s.channels, s.expand, s.state, s.head_dim, s.chunk)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, h, w = x.shape
        k = self.window
        win = x.reshape(b, c, h // k, k, w // k, k)
        order = (0, 2, 4, 5, 3, 1) if self.columns else (0, 2, 4, 3, 5, 1)   # (B, wy, wx, scan..., C)
        seq = win.permute(*order).reshape(-1, k * k, c)
        seq = self.block(seq).reshape(b, h // k, w // k, k, k, c)
        inverse = (0, 5, 1, 4, 2, 3) if self.columns else (0, 5, 1, 3, 2, 4)
        return seq.permute(*inverse).reshape(b, c, h, w)

    def support(self, x: Support) -> Support:
        """Every pixel of a window reads the whole window (a second scan on the same windows adds nothing)."""
        return x.window(self.window)


@dataclasses.dataclass(frozen=True)
class MambaSpikeOneBranchSizes(MambaSpikeSizes):
    """MambaSpike with one parsing branch on every camera: the paper's Tables 1-2 row marked
    with a spade on the ML side (method ``mambaspike1``)."""

    LABEL: ClassVar[str] = "mambaspike1"

    @classmethod
    def for_camera(cls, name: str, config):
        return dataclasses.replace(cls.preset(name), parsings=1)

    def __post_init__(self) -> None:
        super().__post_init__()
        self._need("parsings", self.parsings == 1, "1 (the one-branch MambaSpike)")


class MambaSpike(AlignedBaseline):
    """(N, 61, H, W) decoded light -> (N, 1, H, W) light at the key moment (readout 30)."""

    def __init__(self, sizes: MambaSpikeSizes = MambaSpikeSizes()):
        super().__init__(sizes)
        s, c = sizes, sizes.channels
        self.parsings = nn.ModuleList(ParsingBranch(s, 4.0 ** p) for p in range(s.parsings))
        self.merge = nn.Conv2d(s.parsings * c, c, 1) if s.parsings > 1 else None
        self.spatial = nn.Sequential(*[WindowScan(s, columns=bool(i % 2)) for i in range(s.spatial_blocks)])
        self.build_tail(s.moments, filter_kernel=s.filter_kernel)

    def features(self, light: torch.Tensor) -> torch.Tensor:
        """The parsings' temporal scans, merged, then the spatial scans: (N, moments, C, h, w)."""
        feats = [branch(light) for branch in self.parsings]                 # (N, M, C, h, w) each
        n, m, c, h, w = feats[0].shape
        if self.merge is not None:
            feats = [self.merge(torch.cat(feats, 2).reshape(n * m, -1, h, w)).reshape(n, m, c, h, w)]
        return self.spatial(feats[0].reshape(n * m, c, h, w)).reshape(n, m, c, h, w)

    def features_support(self, light: Support) -> Support:
        """:meth:`features` on supports."""
        feats = union(*(branch.support(light) for branch in self.parsings))
        if self.merge is not None:
            feats = support(self.merge, feats)
        return support(self.spatial, feats)
