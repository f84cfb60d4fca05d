"""The output head every learned method shares: a per-pixel choice among training-free estimates, plus a correction.

Why: a network that predicts a correction to one fixed estimate (say the
mean light of 13 readouts) must undo that estimate's failure itself: the
motion blur of a long mean under a moving camera, the noise of a short one in
the dark. Which temporal support is right is a local decision (how fast the
pixel's light changes, how many spikes it sees), and every training-free
estimate the project has answers it for one case only: on held-out pans TFI
beats every windowed mean by 7 dB, on fast bright dead leaves the single
readout beats TFI by 5 dB, in the dark the 61-readout mean wins; the best of
them chosen per pixel (an oracle) is 5 to 14 dB above each alone
(``benchmarks/bench_net.py --candidates``).

So the head sees, at the key moment, :data:`RADII`'s centred means of the
decoded light and the spike-interval estimate (TFI, searched inside the
span, with the sensor's one-spike bound where no spike follows), all
compressed by the mu-law, and predicts from the method's features a softmax
weight for each (per pixel) and a correction:

    code = sum_j softmax(logits)_j * compress(estimate_j) + correction,

expanded back to light. The head's convolution starts at zero weights with a
bias that favours TFI and the 9-readout mean (TFP's window), so an untrained
method already returns a sensible image.
"""

from __future__ import annotations

import torch
from torch import nn

from ..reach import Support, support
from ..settings import DEFAULT_WINDOW
from .layers import conv3
from ..mulaw import compress, expand

#: Radii (readouts either side of the key) of the centred means the head chooses among.
RADII = (0, 1, 2, 4, 7, 12, 20, 30)
#: Initial logits: TFI and TFP's mean over its default window first (the bias of an untrained head).
INITIAL_LOGITS = {"tfi": 2.0, DEFAULT_WINDOW // 2: 1.0}
#: How the code meets its floor (no light below 0) in training: ``clamp`` passes no gradient
#: below it, so a pixel whose code went negative on true light is never pulled back;
#: ``straight-through`` clamps the same in the forward pass and passes the gradient as if
#: unclamped (what the loss says of the clamped output reaches the code). Inference and
#: validation (eval mode) clamp alike under both.
FLOORS = ("clamp", "straight-through")


def estimate_count() -> int:
    """Estimates the head chooses among: the centred means and TFI."""
    return len(RADII) + 1


def _inside(light: torch.Tensor, inside: torch.Tensor | None) -> torch.Tensor:
    """(N, T, 1, 1) bool: which readouts of the span lie in the stream (all, without ``inside``)."""
    n, t = light.shape[:2]
    if inside is None:
        return torch.ones((n, t, 1, 1), dtype=torch.bool, device=light.device)
    if inside.shape != (n, t):
        raise ValueError(f"inside has shape {tuple(inside.shape)}: need (N, T) = {(n, t)}")
    if not bool(inside[:, t // 2].all()):
        raise ValueError("the key moment (the middle readout) must lie in the stream")
    return inside.view(n, t, 1, 1)


def spike_interval_light(light: torch.Tensor, inside: torch.Tensor | None, spike_light: float) -> torch.Tensor:
    """TFI (``recon/tfi.py``) at the middle readout of (N, T, H, W) decoded light, searched inside the span.

    ``inside`` (N, T) marks the readouts that lie in the stream (those past
    its ends are padding); without it every readout does. With n the first
    readout at or after the key whose light is non-zero and p the last one
    before it (the readout before the stream's first when none: the sensor's
    accumulator starts at 0), the estimate is ``light[n] / (n - p)``. Past
    the last spike the charge since p is below one threshold: the light is
    at most ``spike_light`` (one spike per readout, :attr:`SensorConfig.spike_light`)
    over the ``end - p`` readouts since p, capped by the light of the
    interval that ends at p; without any spike, that bound alone. So this is TFI searched in the span's window (``tfi(...,
    search="window")``), at the stream's ends too, and the whole-stream TFI
    on a stream of at most T // 2 + 1 readouts; one difference: where that
    capping interval began before the span, it is counted from the span's
    start (TFI counts it from p's own window, which the span does not hold).
    ``spike_light`` is required: every learned method is trained and run for
    one sensor, whose value it is.
    """
    n_, t, h, w = light.shape
    key = t // 2
    inside = _inside(light, inside)
    index = torch.arange(t, device=light.device).view(1, t, 1, 1)
    start = torch.where(inside, index, t).amin(1, keepdim=True) - 1          # "p" before the first spike
    end = torch.where(inside, index, -1).amax(1, keepdim=True)
    spiking = (light > 0) & inside
    after = torch.where(spiking[:, key:], index[:, key:], t).amin(1, keepdim=True)
    before = torch.maximum(torch.where(spiking[:, :key], index[:, :key], -1).amax(1, keepdim=True), start)
    at_next = light.gather(1, after.clamp(max=t - 1)) / (after - before).to(light.dtype)
    earlier = torch.maximum(torch.where(spiking & (index < before), index, -1).amax(1, keepdim=True), start)
    last = light.gather(1, before.clamp(min=0))
    previous = last / (before - earlier).clamp(min=1).to(light.dtype)
    bound = spike_light / (end - before).to(light.dtype)  # end - before >= 1: the key lies in the stream, after p
    tail = torch.where(before > start, torch.minimum(previous, bound), bound)
    return torch.where(after < t, at_next, tail)


def key_estimates(light: torch.Tensor, inside: torch.Tensor | None, spike_light: float) -> torch.Tensor:
    """(N, T, H, W) decoded light -> (N, len(RADII) + 1, H, W): centred means of :data:`RADII`, then TFI.

    Each mean is TFP's (``recon/tfp.py``): over the readouts of its window
    that lie in the stream (``inside``, ``spike_light``: as :func:`spike_interval_light`). A
    radius beyond the span's half is cut to it, so the head's shape does not
    depend on the span.
    """
    key = light.shape[1] // 2
    weight = _inside(light, inside).to(light.dtype)
    sums = torch.cumsum(light * weight, 1)
    counts = torch.cumsum(weight, 1)
    means = []
    for r in (min(r, key) for r in RADII):       # loop over the few radii, not over pixels
        below = key - r - 1
        total = sums[:, key + r] - (sums[:, below] if below >= 0 else 0)
        count = counts[:, key + r] - (counts[:, below] if below >= 0 else 0)
        means.append(total / count)
    return torch.cat([torch.stack(means, 1), spike_interval_light(light, inside, spike_light)], 1)


class BlendHead(nn.Module):
    """Feature at 1/u of the frame and the decoded span -> light: a softmax blend of estimates plus a correction."""

    def __init__(self, channels: int, unshuffle: int, mu: float):
        super().__init__()
        self.mu = float(mu)
        self.estimates = estimate_count()
        self.floor = "clamp"                               # FLOORS; set for training by set_floor
        outputs = self.estimates + 1                       # logits, then the correction
        self.conv = conv3(channels, outputs * unshuffle ** 2)
        self.shuffle = nn.PixelShuffle(unshuffle)
        nn.init.zeros_(self.conv.weight)
        with torch.no_grad():
            bias = torch.zeros(outputs)
            for name, value in INITIAL_LOGITS.items():
                bias[self.estimates - 1 if name == "tfi" else RADII.index(name)] = value
            self.conv.bias.copy_(bias.repeat_interleave(unshuffle ** 2))

    def forward(self, feature: torch.Tensor, light: torch.Tensor, inside: torch.Tensor | None,
                spike_light: float) -> torch.Tensor:
        """``inside`` (N, T): the span's readouts that lie in the stream (None: all); ``spike_light``:
        the sensor's light of one spike per readout (see :func:`spike_interval_light`)."""
        out = self.shuffle(self.conv(feature))
        weights = torch.softmax(out[:, :self.estimates], 1)
        codes = compress(key_estimates(light, inside, spike_light), self.mu)
        code = (weights * codes).sum(1, keepdim=True) + out[:, self.estimates:]
        if self.training and self.floor == "straight-through":
            code = code + (code.clamp(min=0) - code).detach()
        return expand(code, self.mu)

    def support(self, feature: Support, light: Support) -> Support:
        """The estimates are per pixel of the light; the weights and correction come from the feature."""
        return support(self.shuffle, support(self.conv, feature)).union(light)


def set_floor(model: nn.Module, floor: str) -> nn.Module:
    """Set every :class:`BlendHead` of ``model`` to one of :data:`FLOORS` (training only); return it."""
    if floor not in FLOORS:
        raise ValueError(f"floor {floor!r}: must be one of {', '.join(FLOORS)}")
    for module in model.modules():
        if isinstance(module, BlendHead):
            module.floor = floor
    return model
