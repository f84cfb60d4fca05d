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
to the shortest: a few dozen elementwise passes over the stream, no loop
over pixels.
"""

from __future__ import annotations

import torch

#: Window lengths (readouts, odd, centred) of the ladder, short to long.
LENGTHS = (1, 3, 9, 27, 61)


def window_means(light: torch.Tensor, lengths: tuple[int, ...] = LENGTHS):
    """(N, T, H, W) light -> for each centred window length, short to long: (light summed over it, its mean).

    Windows are cut at the ends of the span. Sums are differences of one
    float64 cumulative sum (exact for HDR values), written straight into
    light's dtype: the middle readouts as two slices, the readouts whose
    window is cut at either end from the cumulative's ends.
    """
    n, t, h, w = light.shape
    cum = light.to(torch.float64).cumsum(1)                  # cum[:, i] = sum light[:i + 1]
    index = torch.arange(t, dtype=light.dtype, device=light.device)
    out = []
    for length in lengths:
        half = length // 2
        if half == 0:
            out.append((light, light))                      # the readout itself, exactly
            continue
        total = light.new_empty(n, t, h, w)
        first, last = half + 1, t - 1 - half                  # readouts whose window is not cut
        if first <= last:
            torch.sub(cum[:, first + half:last + half + 1], cum[:, :last - half], out=total[:, first:last + 1])
        for i in range(t):
            if not first <= i <= last:
                top = cum[:, min(i + half, t - 1)]
                total[:, i] = top - cum[:, i - half - 1] if i - half - 1 >= 0 else top
        count = (index + half + 1).clamp(max=t) - (index - half).clamp(min=0)
        out.append((total, total / count[:, None, None]))
    return out


def firing_rates(light: torch.Tensor, orders: tuple[int, ...], threshold: float) -> torch.Tensor:
    """(N, T, H, W) light -> (N, len(orders), T, H, W) order-k firing rates at every readout (scene units).

    The rate of order k at readout t is the mean light over the shortest
    window of :data:`LENGTHS` centred on t that gathers ``k * threshold`` of
    light (the longest when none does).
    """
    x = light.detach().clamp(min=0)
    ladder = window_means(x)
    longest = ladder[-1][1]
    rates = longest.new_empty(x.shape[0], len(orders), *x.shape[1:])
    rates.copy_(longest[:, None].expand_as(rates))
    for total, mean in reversed(ladder[:-1]):                 # long to short: the shortest enough wins
        for i, order in enumerate(orders):
            torch.where(total >= order * float(threshold), mean, rates[:, i], out=rates[:, i])
    return rates
