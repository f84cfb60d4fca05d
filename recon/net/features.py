"""Multi-scale feature extraction with gradient (MSFEG, paper section 5.2, Fig. 3 (a), eq. 8).

One encoder, shared by the five sub-streams: convolutions of kernel 1, 3, 5
and 7 side by side (motion at several scales), and the frozen horizontal and
vertical Sobel and the Laplacian kernels of eq. 8 applied to every readout of
the sub-stream (the TE codes grow with light, so their gradients carry edges),
fused by one convolution into the feature ``F_i``.
"""

from __future__ import annotations

import torch
from torch import nn

from ..reach import Support, support, union
from ..learning.layers import conv3

#: The paper's eq. 8: Sobel G_x, Sobel G_y and the Laplacian L.
GRADIENT_KERNELS = torch.tensor([
    [[1.0, 0.0, -1.0], [2.0, 0.0, -2.0], [1.0, 0.0, -1.0]],
    [[1.0, 2.0, 1.0], [0.0, 0.0, 0.0], [-1.0, -2.0, -1.0]],
    [[0.0, 1.0, 0.0], [1.0, -4.0, 1.0], [0.0, 1.0, 0.0]],
])


def channels_last(x: torch.Tensor) -> torch.Tensor:
    """NHWC layout: oneDNN's convolutions with few channels run several times faster in it."""
    return x.contiguous(memory_format=torch.channels_last)


class GradientFilters(nn.Module):
    """The three frozen 3 x 3 kernels of eq. 8 on every input channel: C -> 3 C channels."""

    def __init__(self, in_channels: int):
        super().__init__()
        self.in_channels = in_channels
        weight = GRADIENT_KERNELS[None].repeat(in_channels, 1, 1, 1).reshape(3 * in_channels, 1, 3, 3)
        self.register_buffer("weight", weight)        # a buffer: never trained

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return nn.functional.conv2d(x, self.weight.to(x.dtype), padding=1, groups=self.in_channels)

    def support(self, x: Support) -> Support:
        return x.conv(self.weight.shape[-1], padding=1)


class MSFEG(nn.Module):
    """(N, window, H, W) sub-stream -> (N, channels, H / u, W / u) feature.

    The gradients are taken at full resolution; then stream and gradients are
    folded by ``unshuffle`` = u (pixel-unshuffle: every pixel kept, u^2 more
    channels) so the convolutions run at 1 / u of the frame. A 1 x 1
    convolution embeds the folded readouts into ``channels`` before the
    multi-scale convolutions (otherwise the 7 x 7 kernels would see
    window * u^2 channels and cost most of the network). ``gradient=False``
    is the ablation without the eq. 8 branch (paper Table 3 case 1).
    """

    KERNELS = (1, 3, 5, 7)

    def __init__(self, window: int, channels: int, unshuffle: int = 1, gradient: bool = True):
        super().__init__()
        folded = window * unshuffle ** 2
        branch = channels // len(self.KERNELS)
        self.unshuffle = nn.PixelUnshuffle(unshuffle)
        self.embed = nn.Conv2d(folded, channels, 1)
        self.scales = nn.ModuleList(nn.Conv2d(channels, branch, k, padding=k // 2) for k in self.KERNELS)
        self.gradient = GradientFilters(window) if gradient else None
        grad_channels = channels // 2 if gradient else 0
        self.gradient_proj = nn.Conv2d(3 * folded, grad_channels, 1) if gradient else None
        self.fuse = conv3(branch * len(self.KERNELS) + grad_channels, channels)
        self.act = nn.LeakyReLU(0.1)

    def folded_forward(self, x: torch.Tensor) -> torch.Tensor:
        """The definition, step by step: gradients, pixel-unshuffle, 1 x 1 convolutions."""
        embedded = self.act(self.embed(channels_last(self.unshuffle(x))))
        parts = [scale(embedded) for scale in self.scales]
        if self.gradient is not None:
            parts.append(self.gradient_proj(channels_last(self.unshuffle(self.gradient(x)))))
        return self.act(self.fuse(self.act(torch.cat(parts, dim=1))))

    def support(self, x: Support) -> Support:
        """The reach of :meth:`folded_forward` (the same function as :meth:`forward`)."""
        embedded = support(self.embed, support(self.unshuffle, x))
        parts = [support(scale, embedded) for scale in self.scales]
        if self.gradient is not None:
            parts.append(support(self.gradient_proj, support(self.unshuffle, support(self.gradient, x))))
        return support(self.fuse, union(*parts))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """:meth:`folded_forward` computed without its full-resolution intermediates.

        A pixel-unshuffle by u followed by a 1 x 1 convolution is a u x u convolution
        of stride u; a 3 x 3 filter followed by that is a (u + 2) x (u + 2) convolution
        of stride u with padding 1, whose kernel is composed here from the frozen
        eq. 8 kernels and the trained projection. Same function, same parameters,
        no 3 x window full-resolution gradient images to write and fold.
        """
        u = self.unshuffle.downscale_factor
        window = x.shape[1]
        c = self.embed.out_channels
        embed = self.embed.weight.reshape(c, window, u, u)
        embedded = self.act(nn.functional.conv2d(channels_last(x), embed, self.embed.bias, stride=u))
        parts = [scale(embedded) for scale in self.scales]
        if self.gradient is not None:
            g = self.gradient_proj.out_channels
            proj = self.gradient_proj.weight.reshape(g, window, 3, u, u)    # (out, readout, kernel, i, j)
            kernels = self.gradient.weight.reshape(window, 3, 3, 3)[0].to(proj.dtype)   # (kernel, dy, dx)
            composed = proj.new_zeros(g, window, u + 2, u + 2)
            for dy in range(3):
                for dx in range(3):
                    composed[:, :, dy:dy + u, dx:dx + u] += torch.einsum("ockij,k->ocij", proj, kernels[:, dy, dx])
            parts.append(nn.functional.conv2d(channels_last(x), composed, self.gradient_proj.bias,
                                              stride=u, padding=1))
        return self.act(self.fuse(self.act(torch.cat(parts, dim=1))))
