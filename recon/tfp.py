"""TFP: texture from playback, adapted to TE and ML streams (paper section 6.4).

The light at readout k is the mean decoded light (the spike-firing rate, in
scene units) over the window ``[k - r, k + r]``. Near the ends of the stream
the window is truncated to the readouts that exist (the mean over fewer
readouts), so every readout k = 0..K-1 gets an estimate and no readout is
counted twice. Vectorised along time, in the dtype of the light given: windows up to
:data:`SHIFTED_SUM_MAX_WINDOW` readouts are summed as shifted slices (each
output is a sum of its own window only, so a bright past never costs the
precision of a dark present); wider ones with one cumulative sum, in float64
whatever the light's dtype (a float32 one lost a dim present after a long bright past).
"""

from __future__ import annotations

import torch

from tespike.golden.errors import InputError, is_count

#: Widest window summed as shifted slices; wider windows use a cumulative sum.
SHIFTED_SUM_MAX_WINDOW = 33


def tfp(light: torch.Tensor, radius: int) -> torch.Tensor:
    """Windowed mean of decoded light ``(K, ...)`` along dim 0 -> same shape and float dtype."""
    check_radius(radius)
    K = light.shape[0]
    if not light.dtype.is_floating_point:
        light = light.to(torch.float64)
    if K == 0:
        return light
    k = torch.arange(K, device=light.device)
    lo = (k - radius).clamp(min=0)
    hi = (k + radius + 1).clamp(max=K)
    count = (hi - lo).to(light.dtype).view((K,) + (1,) * (light.dim() - 1))
    r = min(radius, K - 1)
    if 2 * r + 1 <= SHIFTED_SUM_MAX_WINDOW:
        total = light.clone()
        for j in range(1, r + 1):             # loop over window offsets, not pixels or frames
            total[j:] += light[:-j]
            total[:-j] += light[j:]
        return total / count
    # in float64 whatever the input's dtype: a float32 running sum after 1e5 bright readouts had lost
    # a dim present's light (4.2e-4 read as 2.2e-4)
    wide = light.to(torch.float64)
    csum = torch.cat([torch.zeros_like(wide[:1]), wide.cumsum(0)])
    return ((csum[hi] - csum[lo]) / count.to(torch.float64)).to(light.dtype)


def check_radius(radius) -> int:
    """``radius``, an integer >= 0 (a window ``[k - r, k + r]``), refused in one line otherwise: a
    negative one had given TFP the light negated (a window of -1 readouts) and TFI a shifted search."""
    if not is_count(radius):
        raise InputError(f"window radius {radius!r}: must be an integer >= 0")
    return int(radius)
