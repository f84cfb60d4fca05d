"""The mu-law that compresses HDR light for every learned method, and its inverse."""

from __future__ import annotations

import math

import torch


def compress(light: torch.Tensor, mu: float) -> torch.Tensor:
    """mu-law: light >= 0 (scene units) -> [0, ~1] (1 at the design light)."""
    return torch.log1p(mu * light.clamp(min=0)) / math.log1p(mu)


def compress_(light: torch.Tensor, mu: float) -> torch.Tensor:
    """:func:`compress` in place (returns ``light``, overwritten): for large inputs that
    need no gradient, e.g. the baselines' firing-rate stacks, which would otherwise be
    held twice."""
    return light.clamp_(min=0).mul_(mu).log1p_().div_(math.log1p(mu))


#: Largest code :func:`expand` accepts: light up to (1 + mu)^2 / mu, thousands of times the
#: design light (beyond which every sensor here saturates), so the output is always finite.
MAX_CODE = 2.0


def expand(code: torch.Tensor, mu: float) -> torch.Tensor:
    """Inverse of :func:`compress` on [0, MAX_CODE]; codes outside are clamped to it."""
    return torch.expm1(code.clamp(0.0, MAX_CODE) * math.log1p(mu)) / mu
