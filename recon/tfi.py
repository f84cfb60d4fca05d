"""TFI: texture from inter-spike intervals, adapted to TE and ML streams (paper section 6.4).

A TE or ML readout word says how many spikes fired in its interval (directly,
or through the overflow time). A non-zero code at readout n that follows the
previous non-zero code at readout p says: the charge of about r_n spikes
(r_n = the decoded amount at n) was collected during the readouts p+1..n.
TFI gives every readout of that segment the same light

    I(k) = light(word[n]) / (n - p)        for p < k <= n,

with n the first non-zero code at or after k and p the last non-zero code
before k. Where codes are dense (bright light, p = n - 1) this is the decoded
level of the word itself; where they are sparse (dark light, many zero codes)
it is one spike's worth (or the decoded amount) over the spike interval, as
in the paper's TFI. Averaged over a stream it gives exactly the decoded
spikes per readout (each segment contributes its r_n over its n - p readouts).

Edges, documented choices:
- start: before the first non-zero code, p = -1 (the stream start). This is
  exact for the SPEC's sensor, whose charge accumulator starts at 0;
- end (no non-zero code at or after k): the charge since p is below one
  threshold, so the light is at most one spike over the ``end - p`` readouts
  since p; the estimate is ``min(I(p), that bound)`` (the light of the last
  segment if it is lower, which it is for steady light), or just the bound if
  there was no non-zero code at all. An all-zero stream of K readouts gives
  the floor ``theta / 42000 / K`` everywhere, not 0.

Search (``search``): ``"stream"`` (default) looks for p and n over the whole
stream, so the longest spike interval N_s is the stream length; ``"window"``
restricts the search to the window ``[k - r, k + r]`` as the paper's 9-frame
slices do: p is at least ``k - r - 1`` (the window start, so the interval and
the light are bounded: N_s = window) and n at most ``k + r`` (otherwise the end
rule applies with ``end = k + r``).

Vectorised: cummax / cummin of indices along time, then gathers.
"""

from __future__ import annotations

import torch


def tfi(light: torch.Tensor, nonzero: torch.Tensor, spike_light: float, radius: int,
        search: str = "stream") -> torch.Tensor:
    """Spike-interval light of every readout.

    ``light``: decoded light (K, P) in scene units; ``nonzero``: (K, P) bool,
    the codes that are not 0; ``spike_light``: light of one spike in one
    readout (threshold / 42000); ``radius``: window radius (used only when
    ``search == "window"``). Returns float64 (K, P).
    """
    if search not in ("stream", "window"):
        raise ValueError(f"search = {search!r}: must be 'stream' or 'window'")
    K = light.shape[0]
    light = light.to(torch.float64)
    if K == 0:
        return light
    dev = light.device
    k = torch.arange(K, device=dev).view((K,) + (1,) * (light.dim() - 1))
    minus_one = torch.full_like(nonzero[:1], -1, dtype=torch.int64)
    last = torch.where(nonzero, k, -1).cummax(0).values                  # last non-zero <= k
    p = torch.cat([minus_one, last[:-1]])                                 # last non-zero < k
    n = torch.where(nonzero, k, K).flip(0).cummin(0).values.flip(0)       # first non-zero >= k
    if search == "window":
        p = torch.maximum(p, k - radius - 1)
        found = n <= torch.clamp(k + radius, max=K - 1)
        end = torch.clamp(k + radius, max=K - 1)
        p_is_code = p >= k - radius          # p is a real non-zero code inside the window
    else:
        found = n < K
        end = torch.full_like(k, K - 1)
        p_is_code = p >= 0
    p_is_code = p_is_code & (p >= 0)
    r_n = torch.gather(light, 0, n.clamp(max=K - 1))
    value = torch.where(found, r_n / (n - p).to(torch.float64), torch.nan)
    bound = spike_light / (end - p).to(torch.float64)
    # the estimate at a non-zero code p never needs the end rule (n(p) = p)
    value_at_p = torch.gather(value, 0, p.clamp(min=0))
    tail = torch.where(p_is_code, torch.minimum(value_at_p, bound), bound)
    return torch.where(found, value, tail)
