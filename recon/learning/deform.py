"""Modulated deformable convolution (DCNv2, the paper's eq. 5) in plain torch.

``torchvision.ops.deform_conv2d`` does not import beside torch 2.13.0 here,
and kornia's pure-torch version lives inside its ALIKED feature as an internal
module (no stable API, no offset-group or dilation contract), so the project
writes its own: every kernel tap is one bilinear ``grid_sample`` of the input
at the tap's displaced positions (zero outside the image, as torchvision),
weighted by its mask, and the taps are contracted with the weights in one
matrix product. The argument layout is torchvision's: ``offset`` is
(N, 2 * G * kh * kw, H', W') with (dy, dx) per tap, taps in row-major order,
offset group g first; ``mask`` is (N, G * kh * kw, H', W').
``tests/test_recon_learning_deform.py`` checks it against a direct float64 loop
and measures nothing: ``benchmarks/bench_net.py`` times it.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from ..reach import Support, union


def deform_conv2d(input: torch.Tensor, offset: torch.Tensor, weight: torch.Tensor,
                  bias: torch.Tensor | None = None, *, stride: int = 1, padding: int = 0,
                  dilation: int = 1, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Deformable convolution with torchvision's semantics (groups = 1)."""
    n, c, h, w = input.shape
    c_out, c_in, kh, kw = weight.shape
    if c_in != c:
        raise ValueError(f"weight expects {c_in} input channels, input has {c}")
    taps = kh * kw
    groups = offset.shape[1] // (2 * taps)
    if groups < 1 or offset.shape[1] != 2 * groups * taps or c % groups:
        raise ValueError(f"offset has {offset.shape[1]} channels: need 2 * G * {taps} with G dividing {c}")
    h_out, w_out = offset.shape[2], offset.shape[3]
    expect = ((h + 2 * padding - dilation * (kh - 1) - 1) // stride + 1,
              (w + 2 * padding - dilation * (kw - 1) - 1) // stride + 1)
    if (h_out, w_out) != expect:
        raise ValueError(f"offset is {h_out} x {w_out}, the output is {expect[0]} x {expect[1]}")
    if mask is None:
        mask = offset.new_ones(n, groups * taps, h_out, w_out)
    dtype, device = input.dtype, input.device
    # base sampling positions of every tap, in input pixels
    ys = (torch.arange(h_out, device=device, dtype=dtype) * stride - padding)[:, None]
    xs = (torch.arange(w_out, device=device, dtype=dtype) * stride - padding)[None, :]
    ky, kx = torch.meshgrid(torch.arange(kh, device=device, dtype=dtype) * dilation,
                            torch.arange(kw, device=device, dtype=dtype) * dilation, indexing="ij")
    ky, kx = ky.reshape(taps, 1, 1), kx.reshape(taps, 1, 1)
    off = offset.reshape(n, groups, taps, 2, h_out, w_out)
    py = ys + ky + off[:, :, :, 0]                  # (n, G, taps, h_out, w_out)
    px = xs + kx + off[:, :, :, 1]
    # grid_sample's normalised coordinates (align_corners=False): pixel i is at (2i + 1) / size - 1
    grid = torch.stack(((2 * px + 1) / w - 1, (2 * py + 1) / h - 1), dim=-1)
    grid = grid.reshape(n * groups, taps * h_out, w_out, 2)
    x = input.reshape(n * groups, c // groups, h, w)
    sampled = F.grid_sample(x, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    sampled = sampled.reshape(n, groups, c // groups, taps, h_out, w_out)
    sampled = sampled * mask.reshape(n, groups, 1, taps, h_out, w_out)
    # (n, c, taps, P) x (c_out, c * taps) -> (n, c_out, P)
    columns = sampled.reshape(n, c * taps, h_out * w_out)
    out = torch.matmul(weight.reshape(c_out, c * taps), columns).reshape(n, c_out, h_out, w_out)
    if bias is not None:
        out = out + bias.reshape(1, c_out, 1, 1)
    return out


class ModulatedDeformConv2d(nn.Module):
    """A k x k DCNv2 layer whose offsets and masks come from outside (same-size output)."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int = 3, offset_groups: int = 1):
        super().__init__()
        self.kernel_size, self.offset_groups = kernel_size, offset_groups
        self.weight = nn.Parameter(torch.empty(out_channels, in_channels, kernel_size, kernel_size))
        self.bias = nn.Parameter(torch.zeros(out_channels))
        nn.init.kaiming_uniform_(self.weight, a=math.sqrt(5))

    @property
    def offset_channels(self) -> int:
        return 2 * self.offset_groups * self.kernel_size ** 2

    @property
    def mask_channels(self) -> int:
        return self.offset_groups * self.kernel_size ** 2

    def support(self, x: Support, offset: Support, mask: Support, max_offset: float) -> Support:
        """Reach with offsets of at most ``max_offset`` pixels (the caller bounds them)."""
        return union(x.sample(self.kernel_size, max_offset), offset, mask)

    def forward(self, x: torch.Tensor, offset: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return deform_conv2d(x, offset, self.weight, self.bias, padding=self.kernel_size // 2, mask=mask)
