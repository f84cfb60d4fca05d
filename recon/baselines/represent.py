"""Spike-interval representation and multi-order firing rates, derived from decoded light.

BSF (Zhao et al., CVPR 2024) represents a binary spike stream by the
interval between the spikes around each moment (the "differential of spike
firing time", whose inverse is a firing rate) and by firing rates of several
orders: the rate over the interval spanning k spikes around the moment, so a
bright pixel is averaged over a short time and a dark one over a long time,
which evens out the spikes' fluctuations. MambaSpike (Zhu et al.) also uses
spike intervals beside the spike levels.

Here every learned method receives decoded light per readout (scene units),
for TE and ML alike. A pixel of light I integrates I per readout; a virtual
integrate-and-fire neuron of threshold ``threshold`` (scene units x readouts)
fires when the running sum of light crosses a multiple of it, so the
order-k interval around moment t is the time over which the accumulated
light grows by k thresholds around t, and the order-k rate is the light
gathered over that time divided by its length.

Computed, for speed, on a ladder of centred windows (``LENGTHS`` readouts,
cut at the ends of the span): the order-k rate at t is the mean light over
the shortest window of the ladder around t that gathers at least
``k * threshold`` of light, or over the longest when none does; so a bright
pixel's rate is its light in the readout itself and a dark pixel's its mean
over the longest window; zero light gives zero. The window sums come from
one cumulative sum along time (float64: exact for HDR values); the choice is
a comparison and a selection per window and order, from the longest window
to the shortest: a few dozen elementwise passes, run on a block of rows at
a time so they stay in cache (each pixel's rates depend on that pixel only),
no loop over pixels. "Exact" is relative: a sum is a float64 difference
rounded once to float32.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

#: Window lengths (readouts, odd, centred) of the ladder, short to long.
LENGTHS = (1, 3, 9, 27, 61)


def window_means(light: torch.Tensor, lengths: tuple[int, ...] = LENGTHS):
    """(N, T, H, W) light -> for each centred window length, short to long: (light summed over it, its mean).

    Windows are cut at the ends of the span. Sums are differences of one
    float64 cumulative sum (exact for HDR values), returned in light's dtype.
    """
    t = light.shape[1]
    cum = F.pad(light.to(torch.float64).cumsum(1), (0, 0, 0, 0, 1, 0))    # cum[:, i] = sum light[:i]
    index = torch.arange(t, device=light.device)
    out = []
    for length in lengths:
        half = length // 2
        if half == 0:
            out.append((light, light))                      # the readout itself, exactly
            continue
        hi, lo = (index + half + 1).clamp(max=t), (index - half).clamp(min=0)
        total = (cum.index_select(1, hi) - cum.index_select(1, lo)).to(light.dtype)
        out.append((total, total / (hi - lo).to(light.dtype)[:, None, None]))
    return out


#: Elements of one block of rows (256 KiB of float32; 1 MiB measured 20 % slower): the
#: dozen passes of the choice run on a block while it is in cache, instead of streaming the
#: whole stream through memory each time.
BLOCK = 1 << 16


def firing_rates(light: torch.Tensor, orders: tuple[int, ...], threshold: float) -> torch.Tensor:
    """(N, T, H, W) light -> (N, len(orders), T, H, W) order-k firing rates at every readout (scene units).

    The rate of order k at readout t is the mean light over the shortest
    window of :data:`LENGTHS` centred on t that gathers ``k * threshold`` of
    light (the longest when none does). Computed a block of rows at a time
    (each pixel's rates depend on that pixel alone).
    """
    x = light.detach().clamp(min=0)
    n, t, h, w = x.shape
    rates = x.new_empty(n, len(orders), t, h, w)
    rows = max(1, BLOCK // max(1, n * t * w))
    for top in range(0, h, rows):
        block = x[:, :, top:top + rows]
        out = rates[:, :, :, top:top + rows]
        ladder = window_means(block)
        out.copy_(ladder[-1][1][:, None].expand_as(out))
        for total, mean in reversed(ladder[:-1]):             # long to short: the shortest enough wins
            for i, order in enumerate(orders):
                out[:, i] = torch.where(total >= order * float(threshold), mean, out[:, i])
    return rates
