"""A pixel's dark law from its dark stream, and the light of a window of readouts estimated under it.

A per-pixel mean dark rate cannot subtract a dark charge that changes from
readout to readout: with the paper's eq. 13 (60000 / N(140, 50) electrons) a
pixel's dark spikes per readout have a standard deviation near their mean and a
tail that falls as 1 / d^2 (about 5 % of readouts above 1000 electrons). The
calibration therefore keeps the pixel's **dark law**: :data:`LAW_ATOMS` quantiles
of its decoded dark spikes per readout (:func:`law_atoms`), each standing for an
equal share of its dark readouts, and the reach of the law's tail (the largest
dark readout over its pixel's mean atom, over the frame). A readout of the pixel
under light is modelled as

    y = own + dark,   own ~ Poisson(lambda) spikes,   dark ~ the pixel's law,

the law being its atoms ``a_q`` (weight 1 / Q each) and two tails for readouts
the atoms do not hold (a pixel's tail atoms are few and far apart): above the
bulk's largest atom ``s`` (the bulk: below), up to the tail's reach times the
pixel's mean atom, a density ``tau s / d^2`` (the 1 / d^2 tail of a dark
rate whose intervals can be short), below the lowest atom a flat density
``tau / a_min``, ``tau`` = 1 / (2 Q) (the share of dark readouts beyond the outer
atoms' quantile levels). A readout that only a tail explains says nothing of the
pixel's own light: its own light is taken as the window's.

The window's light ``lambda`` (:func:`law_light`) is the best of a fixed grid of
levels (:data:`GRID`) and the mean-subtracted candidate by the window's
likelihood, refined by :data:`EM_STEPS` expectation-maximisation steps: each
readout's dark charge is replaced by its expectation given the readout and
``lambda``, and ``lambda`` by the window's mean of what is left. In that
expectation every atom of the law's **bulk** (inside Tukey's fences,
:data:`FENCE` interquartile ranges beyond the quartiles) gives the bulk's mean
charge, not its own: a TE or ML pixel carries its residual charge from readout
to readout, so its own and dark spikes do not add as independent counts (a
readout's count is their charge quantised with the carried residual) and
only the window's sum is conserved; measured, the likelihood's own bulk atom
lost 3 dB against the mean with the paper's eq. 12 at 1/4 x. Readouts the law
puts in its tail (beyond the fences, or beyond the top atom) are the ones a
mean cannot absorb: there the readout's own atom, or the window's light, is taken
(the lower tail, readouts below every atom, is charged the bulk's mean too).
A law without tail (eq. 12) gives the mean-subtracted window exactly.
The last step's per-readout own light is what TFI re-codes
(:func:`tespike.recon.calibration.dark_free_light`).

With no dark current in the calibration (every atom 0, so both tails are
empty) each readout's expected dark charge is exactly 0 and the result is
exactly the window's mean decoded light, summed in TFP's order: calibrated
TFP is then plain TFP, a calibration and not another estimator.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from tespike.golden.errors import InputError, is_count

#: Atoms of each pixel's dark law (quantile levels (i + 0.5) / Q of its dark readouts); measured
#: with eq. 13 on the held-out scenes: 16 atoms 0.6 dB below 64, 128 and 256 within 0.1 dB of it.
LAW_ATOMS = 64
#: Tukey's fences of the law's bulk, in interquartile ranges beyond the quartiles.
FENCE = 1.5
#: Light levels (spikes per readout) whose window likelihood is evaluated: geometric from 1e-4 to ~60.
GRID = tuple(1e-4 * 1.3 ** i for i in range(52))
#: Expectation-maximisation steps after the grid's best level.
EM_STEPS = 3
#: Pixels x readouts x atoms of one block of work (bounds memory; results do not depend on it).
BLOCK_ELEMENTS = 1 << 22


def check_atoms(atoms) -> int:
    """A dark law's number of quantiles, an integer >= 1 (2.5 had given 3 atoms, 0 and -2 an empty law)."""
    if not is_count(atoms, 1):
        raise InputError(f"dark law atoms {atoms!r}: must be an integer >= 1")
    return atoms


def law_atoms(dark_spikes: np.ndarray, atoms: int = LAW_ATOMS) -> np.ndarray:
    """Decoded dark spikes per readout (K, ...) -> the (atoms, ...) float32 quantiles at levels
    (i + 0.5) / atoms, each an observed value (the inverted empirical distribution function)."""
    check_atoms(atoms)
    dark_spikes = np.asarray(dark_spikes)
    if dark_spikes.ndim < 1 or not dark_spikes.shape[0]:
        raise InputError(f"dark spikes shape {dark_spikes.shape}: need at least one readout (K, ...)")
    K = dark_spikes.shape[0]
    ordered = np.sort(np.asarray(dark_spikes, np.float64), axis=0)
    index = np.ceil((np.arange(atoms) + 0.5) / atoms * K).astype(np.int64) - 1
    return ordered[np.clip(index, 0, K - 1)].astype(np.float32)


class DarkLaw:
    """The readouts ``y`` (K, P) spikes of pixels with atoms (Q, P), prepared for the likelihood of
    any level ``lambda`` (broadcast against (K, P)): what does not depend on ``lambda`` once."""

    def __init__(self, y: torch.Tensor, atoms: torch.Tensor, ceiling: torch.Tensor):
        atoms = atoms.to(y.device, torch.float64)
        self.ceiling = ceiling.to(y.device, torch.float64)
        Q, P = atoms.shape
        self.y = y
        self.low = atoms.min(0).values
        self.mean = atoms.mean(0)
        # equal atoms merged (a TE pixel's are mostly a few whole spike counts): (P, U) values, weights
        ordered = atoms.t().sort(1).values
        new = torch.ones_like(ordered, dtype=torch.bool)
        new[:, 1:] = ordered[:, 1:] != ordered[:, :-1]
        group = new.cumsum(1) - 1
        U = int(group.max()) + 1
        self.atoms = torch.zeros(P, U, dtype=torch.float64, device=y.device).scatter_(1, group, ordered)
        weight = torch.zeros(P, U, dtype=torch.float64, device=y.device).scatter_add_(1, group, torch.ones_like(ordered))
        x = y.unsqueeze(-1) - self.atoms                            # (K, P, U) own spikes if the dark was atom u
        q1, q3 = ordered[:, Q // 4:Q // 4 + 1], ordered[:, (3 * Q) // 4:(3 * Q) // 4 + 1]
        inside = (self.atoms >= q1 - FENCE * (q3 - q1)) & (self.atoms <= q3 + FENCE * (q3 - q1)) & (weight > 0)
        bulk_mean = (torch.where(inside, weight * self.atoms, 0.0).sum(1, keepdim=True)
                     / torch.where(inside, weight, 0.0).sum(1, keepdim=True))
        self.charged = torch.where(inside, bulk_mean, self.atoms)   # the dark charge each atom is given
        self.bulk_mean = bulk_mean.squeeze(1)
        self.start = torch.where(inside, self.atoms, 0.0).max(1).values    # where the upper tail starts
        ok = (x >= 0) & (weight > 0)                                # Poisson(lam) can give the rest
        self.x = torch.where(ok, x, 0.0)
        self.base = torch.where(ok, (weight / Q).log() - torch.lgamma(self.x + 1), -math.inf)
        log_tau = -math.log(2 * Q)
        self.log_up = torch.where(self.start > 0, log_tau + self.start.clamp(min=1e-300).log(), -math.inf)
        self.log_low = torch.where(self.low > 0, log_tau - self.low.clamp(min=1e-300).log(), -math.inf)

    def shifted(self, j: int) -> "DarkLaw":
        """The same pixels with readout k + j at k (repeating the edge readouts)."""
        other = object.__new__(DarkLaw)
        other.__dict__.update(self.__dict__)
        index = torch.arange(self.y.shape[0], device=self.y.device).add(j).clamp(0, self.y.shape[0] - 1)
        other.y, other.x, other.base = self.y[index], self.x[index], self.base[index]
        return other

    def _parts(self, lam):
        """(bulk log-likelihoods (K, P, U) less lam, the upper and lower tail's (K, P) less lam, the
        dark charge the upper tail gives each readout)."""
        excess = self.y - lam                                      # the dark charge if the own light is lam
        above = (excess > self.start) & (excess <= self.ceiling)
        tail_up = torch.where(above, self.log_up - 2 * torch.where(above, excess, 1.0).log(), -math.inf)
        if lam.dim() == 0:
            bulk = torch.add(self.base, self.x, alpha=float(lam.log()))
        else:
            bulk = torch.addcmul(self.base, self.x, lam.log().unsqueeze(-1))
        tail_low = torch.where(excess < self.low, self.log_low, -math.inf)
        return bulk, tail_up + lam, tail_low + lam, excess

    def log_likelihood(self, lam: torch.Tensor) -> torch.Tensor:
        """log p(y | lam) of every readout (K, P)."""
        bulk, up, low, _ = self._parts(lam)
        return torch.logaddexp(torch.logsumexp(bulk, -1), torch.logaddexp(up, low)) - lam

    def upper_tail_share(self, lam: torch.Tensor) -> torch.Tensor:
        """The posterior probability (K, P) that each readout's dark charge is in the law's upper tail
        (its excess over ``lam`` then the dark charge), given ``y`` and ``lam``."""
        bulk, up, low, _ = self._parts(lam)
        total = torch.logaddexp(torch.logsumexp(bulk, -1), torch.logaddexp(up, low))
        return (up - total).exp()

    def expected_dark(self, lam: torch.Tensor) -> torch.Tensor:
        """The dark charge each readout is given (spikes): the bulk's mean for a bulk atom or the lower
        tail, its atom for a tail atom, ``y - lam`` for the upper tail, weighted by their posterior
        probability given ``y`` and ``lam``; exactly 0 where every atom is 0 (both tails then empty)."""
        bulk, up, low, excess = self._parts(lam)
        total = torch.logaddexp(torch.logsumexp(bulk, -1), torch.logaddexp(up, low))
        weights = (bulk - total.unsqueeze(-1)).exp_()
        return ((weights * self.charged).sum(-1) + (up - total).exp() * excess
                + (low - total).exp() * self.bulk_mean)


def _shifted(x: torch.Tensor, j: int) -> torch.Tensor:
    """x[k + j] at k (rows past either end: repeated edge, masked by the caller)."""
    K = x.shape[0]
    index = torch.arange(K, device=x.device).add(j).clamp(0, K - 1)
    return x[index]


def law_light(light: torch.Tensor, spike_light: float, atoms: torch.Tensor, ceiling: torch.Tensor, radius: int,
              dtype: torch.dtype = torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """Decoded light (K, P) of pixels with dark law ``atoms`` (Q, P) -> (the window's own light,
    TFP's windows of ``2 radius + 1`` readouts truncated at the ends, in ``dtype``; each readout's
    own light, its decoded light less its expected dark charge at its window's level, float64).

    Scene units throughout (``spike_light`` = the light of one spike in one readout). Pixels are
    taken in blocks of :data:`BLOCK_ELEMENTS` readouts x atoms (bounded memory)."""
    parts = [_law_light_block(light[:, s], spike_light, atoms[:, s], ceiling[s], radius, dtype)
             for s in _pixel_blocks(light.shape, atoms.shape[0])] or [(light.to(dtype), light.to(torch.float64))]
    return torch.cat([p[0] for p in parts], 1), torch.cat([p[1] for p in parts], 1)


def tail_free_light(light: torch.Tensor, spike_light: float, atoms: torch.Tensor, ceiling: torch.Tensor,
                    radius: int, mean_dark: torch.Tensor) -> torch.Tensor:
    """Decoded light (K, P) of pixels with dark law ``atoms`` (Q, P) and mean dark rate ``mean_dark``
    (P,), light units -> each readout's light less that rate, except in the share of its posterior that
    puts its dark charge in the law's upper tail at its window's level (:meth:`DarkLaw.upper_tail_share`;
    the window as :func:`law_light`'s), where it is less that charge: the mean-rate correction the
    learned methods were trained with, with only what a mean cannot absorb taken out
    (:func:`tespike.recon.learning.infer.law_input`); exactly the mean rate's where the law has no
    tail. float64, pixels in blocks as :func:`law_light`'s."""
    parts = []
    for s in _pixel_blocks(light.shape, atoms.shape[0]):
        block = light[:, s].to(torch.float64)
        if block.shape[0] == 0:
            parts.append(block)
            continue
        law, y, lam, _ = _window_level(block / spike_light, atoms[:, s], ceiling[s], radius)
        share = law.upper_tail_share(lam)
        parts.append(block - (share * (y - lam) * spike_light + (1 - share) * mean_dark[s].to(torch.float64)))
    return torch.cat(parts, 1) if parts else light.to(torch.float64)


def _pixel_blocks(shape: tuple[int, int], atoms: int) -> list[slice]:
    """Slices of the P pixels of (K, P) light taken together: :data:`BLOCK_ELEMENTS` readouts x atoms."""
    K, P = shape
    step = max(1, BLOCK_ELEMENTS // max(1, K * (atoms + 2)))
    return [slice(s, s + step) for s in range(0, P, step)]


def _window_level(y, atoms, ceiling, radius):
    """The law of readouts ``y`` (K, P) spikes (K > 0) and each readout's window level ``lam`` (K, P):
    the best of the grid's levels and the mean-subtracted candidate by the window's likelihood,
    refined by expectation-maximisation -> (law, y, lam, (offsets, valid, count)), the
    last the window's geometry in TFP's order of summation."""
    law = DarkLaw(y, atoms, ceiling)
    K = y.shape[0]
    r = min(radius, K - 1)
    k = torch.arange(K, device=y.device)
    lo, hi = (k - radius).clamp(min=0), (k + radius + 1).clamp(max=K)
    count = (hi - lo).to(torch.float64).view(K, 1)
    offsets = [0] + [s * j for j in range(1, r + 1) for s in (-1, 1)]      # TFP's order of summation
    valid = {j: ((k + j >= 0) & (k + j < K)).view(K, 1) for j in offsets}

    def window_sum(values):
        csum = torch.cat([torch.zeros_like(values[:1]), values.cumsum(0)])
        return csum[hi] - csum[lo]

    best, lam = None, None
    for g in GRID:
        level = torch.tensor(g, dtype=torch.float64, device=y.device)
        total = window_sum(law.log_likelihood(level))
        if best is None:
            best, lam = total, level.expand_as(total)
        else:
            better = total > best
            best, lam = torch.where(better, total, best), torch.where(better, level, lam)
    plain = (window_sum(y) / count - law.mean).clamp(min=GRID[0])
    total = sum(torch.where(valid[j], law.shifted(j).log_likelihood(plain), 0.0) for j in offsets)
    lam = torch.where(total > best, plain, lam)
    for _ in range(EM_STEPS - 1):
        own = sum(torch.where(valid[j], _shifted(y, j) - law.shifted(j).expected_dark(lam), 0.0) for j in offsets)
        lam = (own / count).clamp(min=GRID[0])
    return law, y, lam, (offsets, valid, count)


def _law_light_block(light, spike_light, atoms, ceiling, radius, dtype):
    """:func:`law_light` of one block of pixels."""
    light = light.to(torch.float64)
    if light.shape[0] == 0:
        return light.to(dtype), light
    law, _, lam, (offsets, valid, count) = _window_level(light / spike_light, atoms, ceiling, radius)
    own = light - law.expected_dark(lam) * spike_light            # readout k's own light at its window's lam
    total = own.to(dtype)
    for j in offsets[1:]:
        total = torch.where(valid[j], total + (_shifted(light, j) - law.shifted(j).expected_dark(lam)
                                               * spike_light).to(dtype), total)
    return total / count.to(dtype), own
