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
in the paper's TFI. Averaged over the readouts up to a pixel's last non-zero
code it gives exactly the decoded spikes per readout there (each segment
contributes its r_n over its n - p readouts); the readouts after it add the
end rule's estimate, at most one spike's worth in all, so over a whole
stream TFI reads high where spikes are few: by up to one spike per pixel
(1.36 times the decoded mean for independent single spikes at 0.02 a
readout over 100 readouts, measured).

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

Vectorised: running maximum / minimum of readout indices along time (a
doubling scan: log2(K) whole-array steps, in the narrowest integer type that
holds K, which is several times faster than torch.cummax on CPU), then gathers.
"""

from __future__ import annotations

import torch

from tespike.golden.errors import InputError

from .settings import TFI_SEARCH
from .tfp import check_radius


def _index_dtype(K: int) -> torch.dtype:
    """Narrowest signed integer type holding -K..K (memory traffic dominates the scans)."""
    return torch.int16 if K < (1 << 15) - 1 else torch.int32 if K < (1 << 31) - 1 else torch.int64


def running_max(x: torch.Tensor) -> torch.Tensor:
    """Inclusive running maximum along dim 0 (doubling scan; equals ``x.cummax(0).values``)."""
    x = x.clone()
    step = 1
    while step < x.shape[0]:
        x[step:] = torch.maximum(x[step:], x[:-step])
        step *= 2
    return x


def running_min_reversed(x: torch.Tensor) -> torch.Tensor:
    """Inclusive running minimum along dim 0 from the end: out[k] = min(x[k:])."""
    x = x.clone()
    step = 1
    while step < x.shape[0]:
        x[:-step] = torch.minimum(x[:-step], x[step:])
        step *= 2
    return x


def tfi(light: torch.Tensor, nonzero: torch.Tensor, spike_light: float, radius: int,
        search: str = "stream") -> torch.Tensor:
    """Spike-interval light of every readout.

    ``light``: decoded light (K, ...) in scene units, any float dtype (the
    result has the same); ``nonzero``: same shape, bool, the codes that are
    not 0; ``spike_light``: light of one spike in one readout (threshold /
    42000); ``radius``: window radius (used only when ``search == "window"``).
    """
    if search not in TFI_SEARCH:
        raise InputError(f"search = {search!r}: must be one of {', '.join(TFI_SEARCH)}")
    check_radius(radius)
    K = light.shape[0]
    if not light.dtype.is_floating_point:
        light = light.to(torch.float64)
    if K == 0:
        return light.clone()
    dev, ftype = light.device, light.dtype
    radius = min(radius, K)          # a wider window sees the same readouts
    itype = _index_dtype(2 * K + 2)  # holds every index expression below (k + radius, ...)
    k = torch.arange(K, device=dev, dtype=itype).view((K,) + (1,) * (light.dim() - 1))
    # p: last non-zero code before k (-1: the stream start), by a running maximum
    p = torch.empty(light.shape, dtype=itype, device=dev)
    p[0] = -1
    p[1:] = running_max(torch.where(nonzero[:-1], k[:-1], -1))
    # n: first non-zero code at or after k (K: none), by a running minimum backwards
    n = running_min_reversed(torch.where(nonzero, k, K))
    if search == "window":
        p_raw = p
        p = torch.maximum(p_raw, k - radius - 1)
        end = torch.clamp(k + radius, max=K - 1)
        found = n <= end
    else:
        end = torch.full_like(k, K - 1)
        found = n < K
    n = n.clamp_(max=K - 1).long()
    bound = spike_light / (end - p).to(ftype)    # end rule: at most one spike since p
    if search == "window":
        # p depends on k's window: the decoded light at n over n - p(k) readouts
        value = torch.gather(light, 0, n) / (n - p).to(ftype)
        p_is_code = (p >= k - radius) & (p >= 0)      # p is a real non-zero code inside the window
        pc = p.clamp(min=0).long()                    # the light at p, as p's own window sees it
        p_before = torch.maximum(torch.gather(p_raw, 0, pc).long(), pc - radius - 1)
        previous = torch.gather(light, 0, pc) / (pc - p_before).to(ftype)
    else:
        # p(k) = p(n) in the whole-stream search: the estimate at the code n, filled back
        at_code = light / (k - p).to(ftype)
        value = torch.gather(at_code, 0, n)
        p_is_code = p >= 0                            # in the tail p is the pixel's last code
        previous = torch.gather(at_code, 0, p[-1:].clamp(min=0).long())
    tail = torch.where(p_is_code, torch.minimum(previous, bound), bound)
    return torch.where(found, value, tail)
