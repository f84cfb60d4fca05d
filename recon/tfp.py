"""TFP: texture from playback, adapted to TE and ML streams (paper section 6.4).

The light at readout k is the mean decoded light (the spike-firing rate, in
scene units) over the window ``[k - r, k + r]``. Near the ends of the stream
the window is truncated to the readouts that exist (the mean over fewer
readouts), so every readout k = 0..K-1 gets an estimate and no readout is
counted twice. Vectorised with one cumulative sum along time, in float64.
"""

from __future__ import annotations

import torch


def tfp(light: torch.Tensor, radius: int) -> torch.Tensor:
    """Windowed mean of decoded light ``(K, ...)`` along dim 0 -> same shape, float64."""
    K = light.shape[0]
    if K == 0:
        return light.to(torch.float64)
    light = light.to(torch.float64)
    csum = torch.cat([torch.zeros_like(light[:1]), light.cumsum(0)])
    k = torch.arange(K, device=light.device)
    lo = (k - radius).clamp(min=0)
    hi = (k + radius + 1).clamp(max=K)
    shape = (K,) + (1,) * (light.dim() - 1)
    return (csum[hi] - csum[lo]) / (hi - lo).to(torch.float64).view(shape)
