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
``k * threshold`` of light, or over the longest (the whole span, as far as
it reaches) when none does; so a bright pixel's rate is its light in the
readout itself and a dark pixel's its mean over the span; zero light gives
zero. The window sums come from one float64 cumulative sum along time (exact
for HDR values), the choice from comparisons and one gather: vectorised, no
loop over pixels, a few dozen elementwise passes over the stream.
"""

from __future__ import annotations

import torch

#: Window lengths (readouts, odd, centred) of the ladder, short to long; the last covers the span.
LENGTHS = (1, 3, 7, 15, 31, 63)


def window_means(light: torch.Tensor, lengths: tuple[int, ...] = LENGTHS):
    """(N, T, H, W) light -> for each centred window length: (light summed over it, its mean).

    Windows are cut at the ends of the span; sums are formed in float64 (one
    cumulative sum, edge-padded so every window is two slices) and returned
    in light's dtype.
    """
    n, t, h, w = light.shape
    r = max(lengths) // 2
    cum = light.to(torch.float64).cumsum(1)
    cum = torch.cat((cum.new_zeros(n, r + 1, h, w), cum, cum[:, -1:].expand(n, r, h, w)), 1)  # cum[:, r + i] = sum light[:i]
    index = torch.arange(t, dtype=light.dtype, device=light.device)
    for length in lengths:
        half = length // 2
        total = (cum[:, r + half + 1:r + half + 1 + t] - cum[:, r - half:r - half + t]).to(light.dtype)
        count = (index + half + 1).clamp(max=t) - (index - half).clamp(min=0)
        yield total, total / count[:, None, None]


def firing_rates(light: torch.Tensor, orders: tuple[int, ...], threshold: float) -> torch.Tensor:
    """(N, T, H, W) light -> (N, len(orders), T, H, W) order-k firing rates at every readout (scene units).

    The rate of order k at readout t is the mean light over the shortest
    window of :data:`LENGTHS` centred on t that gathers ``k * threshold`` of
    light (the longest when none does).
    """
    x = light.detach().clamp(min=0)
    rates = [None] * len(orders)
    for total, mean in reversed(list(window_means(x))):      # long to short: the shortest enough wins
        for i, order in enumerate(orders):
            rates[i] = mean if rates[i] is None else torch.where(total >= order * float(threshold), mean, rates[i])
    return torch.stack(rates, 1)
