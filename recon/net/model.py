"""The whole reconstruction network of the paper's Figure 3: MSFEG -> SPA -> LIR -> one convolution.

Input: decoded light (golden's one decoder; scene units, I = 1 is the design
light) of ``sizes.span`` readouts around the key moment, (N, span, H, W),
with H and W multiples of ``sizes.pyramid_factor`` (:mod:`recon.net.infer`
pads any frame). The HDR range is compressed by the mu-law
``log(1 + mu x) / log(1 + mu)`` before the first convolution (the network
sees the stream, never the ground truth); the network predicts, in that
compressed domain, a correction to the compressed temporal mean of the key
sub-stream, and the output is expanded back to light, >= 0 and finite. The paper's
eq. 7 divides the output by the quantum efficiency; here the output is in
scene units already (the decoder has divided by it), so that division is
folded into the output.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from .align import SPA
from .features import MSFEG
from .refine import GuidedAttention, IntensityFeature
from .sizes import NetSizes


def compress(light: torch.Tensor, mu: float) -> torch.Tensor:
    """mu-law: light >= 0 (scene units) -> [0, ~1] (1 at the design light)."""
    return torch.log1p(mu * light.clamp(min=0)) / math.log1p(mu)


#: Largest code :func:`expand` accepts: light up to (1 + mu)^2 / mu, thousands of times the
#: design light (beyond which every sensor here saturates), so the output is always finite.
MAX_CODE = 2.0


def expand(code: torch.Tensor, mu: float) -> torch.Tensor:
    """Inverse of :func:`compress` on [0, MAX_CODE]; codes outside are clamped to it."""
    return torch.expm1(code.clamp(0.0, MAX_CODE) * math.log1p(mu)) / mu


class TESpikeNet(nn.Module):
    """(N, span, H, W) decoded light -> (N, 1, H, W) light at the key moment (the middle readout)."""

    def __init__(self, sizes: NetSizes = NetSizes()):
        super().__init__()
        self.sizes = s = sizes
        self.encoder = MSFEG(s.window, s.channels, s.unshuffle, s.gradient)
        self.spa = SPA(s)
        self.intensity = IntensityFeature(s.window, s.channels, s.unshuffle) if s.refine else None
        self.attention = GuidedAttention(s.channels, s.heads, s.attention_window) if s.refine else None
        self.head = nn.Conv2d(s.channels, s.unshuffle ** 2, 3, padding=1)
        self.unfold = nn.PixelShuffle(s.unshuffle)
        nn.init.zeros_(self.head.weight)        # start from the temporal mean
        nn.init.zeros_(self.head.bias)

    def substreams(self, x: torch.Tensor) -> torch.Tensor:
        """(N, span, H, W) -> (N, S, window, H, W): the sub-streams of eq. 4, key in the middle."""
        s = self.sizes
        index = torch.arange(s.substreams, device=x.device)[:, None] * s.stride \
            + torch.arange(s.window, device=x.device)[None, :]
        return x[:, index]

    def forward(self, light: torch.Tensor) -> torch.Tensor:
        s = self.sizes
        n, span, h, w = light.shape
        if span != s.span or h % s.pyramid_factor or w % s.pyramid_factor:
            raise ValueError(f"input (N, {span}, {h}, {w}): need span {s.span} and H, W multiples of "
                             f"{s.pyramid_factor}")
        subs_light = self.substreams(light)
        key_light = subs_light[:, s.substreams // 2]
        subs = compress(subs_light, s.mu)
        features = self.encoder(subs.reshape(n * s.substreams, s.window, h, w))
        features = features.reshape(n, s.substreams, *features.shape[1:])
        fused = self.spa(features)
        base = compress(key_light.mean(1, keepdim=True), s.mu)      # rough light at the key moment
        if self.attention is not None:
            fused = self.attention(fused, self.intensity(subs[:, s.substreams // 2], base))
        return expand(base + self.unfold(self.head(fused)), s.mu)


def parameter_count(model: nn.Module) -> int:
    """Trainable parameters (the frozen eq. 8 kernels are buffers, not counted)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
