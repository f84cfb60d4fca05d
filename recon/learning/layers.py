"""Small pieces every learned method builds from: the 3 x 3 convolution, the 2x upsampling, the
sub-streams of a span, and the parameter count."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def conv3(cin: int, cout: int, stride: int = 1, dilation: int = 1) -> nn.Conv2d:
    """A 3 x 3 convolution that keeps the frame size (at stride 1)."""
    return nn.Conv2d(cin, cout, 3, stride=stride, padding=dilation, dilation=dilation)


def upsample(x: torch.Tensor) -> torch.Tensor:
    """Bilinear 2x upsampling (a coarser pyramid level to the next finer one)."""
    return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)


def substreams(x: torch.Tensor, count: int, length: int, stride: int) -> torch.Tensor:
    """(N, T, ...) -> (N, count, length, ...): ``count`` sub-streams of ``length`` readouts, their
    starts ``stride`` readouts apart (the paper's eq. 4; the key one in the middle for an odd count)."""
    index = torch.arange(count, device=x.device)[:, None] * stride + torch.arange(length, device=x.device)
    return x[:, index]


def parameter_count(model: nn.Module) -> int:
    """Trainable parameters (frozen kernels kept as buffers are not counted)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
