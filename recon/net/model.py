"""The whole reconstruction network of the paper's Figure 3: MSFEG -> SPA -> LIR -> one convolution.

Input: decoded light (golden's one decoder; scene units, I = 1 is the design
light) of ``sizes.span`` readouts around the key moment, (N, span, H, W),
with H and W multiples of ``sizes.pyramid_factor`` (:mod:`tespike.recon.learning.infer`
pads any frame). The HDR range is compressed by the mu-law
``log(1 + mu x) / log(1 + mu)`` before the first convolution (the network
sees the stream, never the ground truth); the output head
(:mod:`tespike.recon.learning.head`, ``sizes.head``) predicts, in that compressed domain, a
per-pixel softmax blend of training-free estimates (centred means and TFI) plus a
correction (``"blend"``, the default; the legacy ``"mean"`` head corrects the temporal mean
of the key sub-stream alone), and the output is expanded back to light, >= 0 and finite. The paper's
eq. 7 divides the output by the quantum efficiency; here the output is in
scene units already (the decoder has divided by it), so that division is
folded into the output.
"""

from __future__ import annotations

import torch
from torch import nn

from ..learning.head import BlendHead
from ..learning.layers import conv3, substreams
from ..mulaw import compress, expand
from ..reach import Support, support
from .align import SPA
from .features import MSFEG
from .refine import GuidedAttention, IntensityFeature
from .sizes import NetSizes


class TESpikeNet(nn.Module):
    """(N, span, H, W) decoded light -> (N, 1, H, W) light at the key moment (the middle readout)."""

    def __init__(self, sizes: NetSizes = NetSizes()):
        super().__init__()
        self.sizes = s = sizes
        self.encoder = MSFEG(s.window, s.channels, s.unshuffle, s.gradient)
        self.spa = SPA(s)
        self.intensity = IntensityFeature(s.window, s.channels, s.unshuffle) if s.refine else None
        self.attention = GuidedAttention(s.channels, s.heads, s.attention_window) if s.refine else None
        if s.head == "blend":
            self.head = BlendHead(s.channels, s.unshuffle, s.mu)
        else:                                   # "mean": a correction to the key sub-stream's mean
            self.head = conv3(s.channels, s.unshuffle ** 2)
            self.shuffle = nn.PixelShuffle(s.unshuffle)
            nn.init.zeros_(self.head.weight)    # start from the temporal mean
            nn.init.zeros_(self.head.bias)

    def forward(self, light: torch.Tensor, inside: torch.Tensor | None, spike_light: float) -> torch.Tensor:
        """``inside`` (N, span) bool: the readouts that lie in the stream (None: all); ``spike_light``:
        the sensor's light of one spike per readout (``SensorConfig.spike_light``); see recon/learning/head.py."""
        s = self.sizes
        s.check_input(light)
        n, _, h, w = light.shape
        subs_light = substreams(light, s.substreams, s.window, s.stride)
        key_light = subs_light[:, s.substreams // 2]
        subs = compress(subs_light, s.mu)
        features = self.encoder(subs.reshape(n * s.substreams, s.window, h, w))
        features = features.reshape(n, s.substreams, *features.shape[1:])
        fused = self.spa(features)
        base = compress(key_light.mean(1, keepdim=True), s.mu)      # rough light at the key moment
        if self.attention is not None:
            fused = self.attention(fused, self.intensity(subs[:, s.substreams // 2], base))
        if s.head == "blend":
            return self.head(fused, light, inside, spike_light)
        return expand(base + self.shuffle(self.head(fused)), s.mu)

    def support(self, light: Support) -> Support:
        """:meth:`forward` on supports (sub-streams, means and the mu-law act per pixel)."""
        fused = support(self.spa, support(self.encoder, light))
        if self.attention is not None:
            fused = self.attention.support(fused, support(self.intensity, light, light))
        if self.sizes.head == "blend":
            return self.head.support(fused, light)
        return support(self.shuffle, support(self.head, fused)).union(light)

