"""The mu-law of the paper's eq. 11, in one place: its constant, the tone map people are shown
(numpy) and the compression the metrics and every learned method use (torch).

The torch functions work through the tensors' own methods, so this module imports neither
torch nor matplotlib: ``tespike view``, the demo's pictures and the benchmarks' plots use
:func:`tone_map` without paying torch's start (1.7 s, measured here).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from tespike.golden.errors import InputError, is_positive_number

if TYPE_CHECKING:
    import torch

#: The paper's mu-law constant (its eq. 11).
MU = 5000.0

#: Largest code :func:`expand` accepts: light up to (1 + mu)^2 / mu, thousands of times the
#: design light (beyond which every sensor here saturates), so the output is always finite.
MAX_CODE = 2.0


def tone_map(light: np.ndarray, peak: float, mu: float = MU) -> np.ndarray:
    """Divide by the ground truth's peak, clip to [0, 1], mu-law (paper eq. 11); float64: the
    numpy twin of :func:`compress` for the pictures."""
    check_mu(mu)
    if not is_positive_number(peak):        # (0, a negative or NaN peak had drawn a flat picture)
        raise InputError(f"tone map peak {peak!r}: must be a finite number > 0")
    light = np.asarray(light)
    if light.dtype.kind not in "fiub":     # (a complex light had lost its imaginary part with a warning)
        raise InputError(f"tone map light: dtype {light.dtype} is not real numbers")
    with np.errstate(over="ignore"):      # a tiny peak (subnormal): light / peak is inf, white as it should be
        h = np.clip(np.asarray(light, np.float64) / peak, 0.0, 1.0)
    # log1p(mu h) / log1p(mu) written as h g(mu h) / g(mu), g(x) = log1p(x) / x: the same to a few ulps,
    # and the linear limit where mu h underflows (a subnormal mu drew a two-level picture)
    return h * _log1p_ratio(mu * h) / float(_log1p_ratio(np.float64(mu)))


def _log1p_ratio(x: np.ndarray) -> np.ndarray:
    """``log1p(x) / x`` for ``x >= 0``, 1 at 0 (its limit)."""
    x = np.asarray(x, np.float64)
    out = np.ones_like(x)
    positive = x > 0
    out[positive] = np.log1p(x[positive]) / x[positive]
    return out


def check_mu(mu) -> float:
    """``mu``, a finite number > 0, refused in one line otherwise (0 had made every code NaN, -1 was
    math's "domain error")."""
    if not is_positive_number(mu):
        raise InputError(f"mu-law mu {mu!r}: must be a finite number > 0 (the paper's is {MU:g})")
    return float(mu)


def _check_tensor(light) -> None:
    if not (hasattr(light, "clamp") and hasattr(light, "log1p")):
        raise InputError(f"mu-law light: must be a torch tensor, not {type(light).__name__} "
                         "(tone_map takes numpy arrays)")


def compress(light: "torch.Tensor", mu: float) -> "torch.Tensor":
    """mu-law: light >= 0 (scene units) -> [0, ~1] (1 at the design light)."""
    check_mu(mu)
    _check_tensor(light)
    return (mu * light.clamp(min=0)).log1p() / math.log1p(mu)


def compress_(light: "torch.Tensor", mu: float) -> "torch.Tensor":
    """:func:`compress` in place (returns ``light``, overwritten): for large inputs that
    need no gradient, e.g. the baselines' firing-rate stacks, which would otherwise be
    held twice."""
    check_mu(mu)
    _check_tensor(light)
    return light.clamp_(min=0).mul_(mu).log1p_().div_(math.log1p(mu))


def expand(code: "torch.Tensor", mu: float) -> "torch.Tensor":
    """Inverse of :func:`compress` on [0, MAX_CODE]; codes outside are clamped to it."""
    check_mu(mu)
    _check_tensor(code)
    return (code.clamp(0.0, MAX_CODE) * math.log1p(mu)).expm1() / mu
