"""Fast light-to-stream simulator, distributed like the cycle-exact model (SPEC sections 3, 6).

:func:`simulate_scene` gives readout words with the same distribution as
:func:`golden.sensor.simulate` driven by :func:`golden.light.poisson_stimulus`
(accumulator starting at 0, residual carried across readouts), but draws
random numbers per readout interval instead of per pixel clock wherever the
dynamics allow. Each pixel-readout takes one of these paths, chosen from its
light and its carried charge only (never from a random draw of its own, so
the choice cannot bias the result); docs/simulator.md has the derivation.

``dark``     no light, no dark electrons, ``acc < theta``: nothing changes, word 0.
``event``    ``acc < theta`` and no clock can get more than ``min(theta, 2^E - 1)``
             electrons (bound below). Then no clock holds two threshold
             crossings, so every crossing is a spike in its own clock and no
             input saturates: the interval total ``T ~ Poisson(mu) + dark``
             fixes the spike count ``floor((acc + T) / theta)`` and the residual
             ``(acc + T) mod theta``; given T the electrons sit in iid uniform
             positions over the L clocks, so the clock of the ``2^b1``-th spike
             (TE overflow) is ``floor(L * Beta(n, T - n + 1))`` with
             ``n = 2^b1 * theta - acc``, the n-th of T uniform order statistics.
``bright``   every clock surely gets at least ``theta`` electrons: a spike in every
             clock (word known), the accumulator only grows, so it ends at
             ``min(acc + sum(e) - L theta, 2^A - 1)``; ``sum(e)`` is
             ``Poisson(mu) + dark`` when no input can saturate, ``L (2^E - 1)``
             when every input surely does, and need not be drawn at all when
             the accumulator surely ends full.
``clock``    anything else (light near the threshold per clock, where charge
             backs up and the accumulator can clip, or a carried backlog):
             per-clock electrons for these pixels only, run through the literal
             update rule :func:`golden.reference.step_reference`.

"Surely" means: the complement has probability below ``2^-64`` summed over
the whole scene (:func:`golden.light.log_budget`, rigorous tail bounds in
:mod:`golden.light`), so the law of the whole output differs from the exact
one by less than 2^-64 in total variation. With ``noise=False`` nothing is
random and every pixel takes the per-clock path on the deterministic
stimulus of :func:`golden.light.deterministic_clock_electrons`.
"""

from __future__ import annotations

import numpy as np

from .config import SensorConfig
from .errors import InputError
from .io import check_scene, word_dtype
from .light import (as_generator, check_dark_current, clock_electrons, dark_electrons,
                    deterministic_clock_electrons, electrons_per_readout, log_budget,
                    log_poisson_tail_above, log_poisson_tail_below)
from .reference import PixelState, step_reference

PATHS = ("dark", "event", "bright", "clock")
METHODS = ("fast", "per-clock")

#: Pixel clocks x pixels of per-clock electrons held at once (bounds memory).
CLOCK_CHUNK_ELEMENTS = 1 << 21


class SceneSimulator:
    """An H x W array of pixels lit by a scene, one readout interval at a time.

    Holds the carried accumulator (``acc``, int64, flat) and, for ``noise=False``,
    the carried charge fraction. ``method="per-clock"`` sends every pixel down
    the per-clock path (the full path the shortcuts are tested against).
    ``path_counts`` counts pixel-readouts per path.
    """

    def __init__(self, config: SensorConfig, shape: tuple[int, int], *, rng=None,
                 dark_current: str | None = None, noise: bool = True,
                 method: str = "fast", total_pixel_readouts: int | None = None):
        if method not in METHODS:
            raise InputError(f"simulation method {method!r} unknown (known: {', '.join(METHODS)})")
        self.config = config
        self.shape = tuple(shape)
        self.dark_model = check_dark_current(dark_current)
        if not noise and self.dark_model is not None:
            raise InputError(f"dark current {self.dark_model!r} is random; "
                             "it cannot be combined with noise switched off")
        self.noise = noise
        self.method = method
        self.rng = as_generator(rng)
        n = self.shape[0] * self.shape[1]
        self.acc = np.zeros(n, np.int64)
        self.fraction = np.zeros(n)
        self.budget = log_budget(total_pixel_readouts or n, config.clocks_per_readout)
        self.path_counts = dict.fromkeys(PATHS, 0)
        c = config
        if c.is_te:
            ovf_clock = c.p_max - 1                       # spike in every clock
            self._bright_word = ((1 << c.d) | (ovf_clock // c.clocks_per_tick + 1)
                                 if c.p_max <= c.clocks_per_readout else c.clocks_per_readout)
        else:
            self._bright_word = min(c.clocks_per_readout, c.ml_max)

    # -- one readout interval -------------------------------------------------
    def readout(self, light: np.ndarray) -> np.ndarray:
        """Light of one interval (H, W), checked >= 0 and finite -> words (H, W) int64."""
        c = self.config
        theta, L = c.threshold, c.clocks_per_readout
        mu = electrons_per_readout(np.asarray(light).reshape(-1))
        dark = dark_electrons(self.dark_model, mu.shape, self.rng)
        words = np.zeros(mu.shape, np.int64)
        acc = self.acc

        if not self.noise:
            idx = np.arange(mu.size)
            self._clock_path(idx, mu, dark, words)
            self.path_counts["clock"] += idx.size
            return words.reshape(self.shape)
        if self.method == "per-clock":
            idx = np.arange(mu.size)
            self._clock_path(idx, mu, dark, words)
            self.path_counts["clock"] += idx.size
            return words.reshape(self.shape)

        lam = mu / L                                       # photo-electrons per clock
        mean = lam + dark / L                              # with dark electrons
        low = acc < theta
        path = np.full(mu.size, 3, np.int8)                # 3 = clock
        # event: P(some clock > min(theta, 2^E - 1) electrons) below budget
        cap = min(theta, c.input_max)
        path[low & (log_poisson_tail_above(mean, cap + 1) < self.budget)] = 1
        # bright: every clock >= theta electrons (photo-electrons alone suffice)
        if c.input_max >= theta:
            path[log_poisson_tail_below(lam, theta - 1) < self.budget] = 2
        path[low & (mu == 0) & (dark == 0)] = 0
        for code, name in enumerate(PATHS):
            sel = np.flatnonzero(path == code)
            if not sel.size:
                continue
            self.path_counts[name] += sel.size
            if code == 1:
                self._event_path(sel, mu, dark, words)
            elif code == 2:
                self._bright_path(sel, mu, lam, dark, words)
            elif code == 3:
                self._clock_path(sel, mu, dark, words)
        return words.reshape(self.shape)

    def _event_path(self, sel, mu, dark, words):
        c = self.config
        theta, L = c.threshold, c.clocks_per_readout
        acc0 = self.acc[sel]
        total = self.rng.poisson(mu[sel]) + dark[sel]
        level = acc0 + total
        spikes = level // theta
        self.acc[sel] = level - spikes * theta
        if not c.is_te:
            words[sel] = np.minimum(spikes, c.ml_max)
            return
        over = spikes >= c.p_max
        w = spikes.copy()
        if over.any():
            n = c.p_max * theta - acc0[over]               # electron that makes the 2^b1-th spike
            t = total[over]
            position = self.rng.beta(n, t - n + 1)         # n-th of t uniform order statistics
            clock = np.minimum((position * L).astype(np.int64), L - 1)
            w[over] = (1 << c.d) | (clock // c.clocks_per_tick + 1)
        words[sel] = w

    def _bright_path(self, sel, mu, lam, dark, words):
        c = self.config
        theta, L, top, acc_max = c.threshold, c.clocks_per_readout, c.input_max, c.acc_max
        words[sel] = self._bright_word
        acc0 = self.acc[sel]
        lam_s = lam[sel]
        end = np.full(sel.size, acc_max, np.int64)
        # every clock saturated at 2^E - 1: a deterministic sum
        all_top = log_poisson_tail_below(lam_s, top - 1) < self.budget
        # accumulator surely full after the first clock: nothing to draw
        full = np.zeros(sel.size, bool)
        if top >= theta + acc_max:
            full = log_poisson_tail_below(lam_s, theta + acc_max - 1) < self.budget
        # no input can saturate: the sum is Poisson(mu) + dark
        unclipped = log_poisson_tail_above(lam_s + dark[sel] / L, top + 1) < self.budget
        need = ~full & ~all_top
        if (need & ~unclipped).any():
            # inputs that may or may not saturate: per clock (exact), rare in practice
            mixed = need & ~unclipped
            self.path_counts["bright"] -= int(mixed.sum())
            self.path_counts["clock"] += int(mixed.sum())
            self._clock_path(sel[mixed], mu, dark, words)
            need &= unclipped
            keep = ~mixed
        else:
            keep = np.ones(sel.size, bool)
        top_sel = all_top & ~full
        end[top_sel] = np.minimum(acc0[top_sel] + L * (top - theta), acc_max)
        if need.any():
            total = self.rng.poisson(mu[sel][need]) + dark[sel][need]
            # under the sure event total >= L theta; max(.., 0) only guards the
            # 2^-64 failure event against an illegal negative state
            end[need] = np.clip(acc0[need] + total - L * theta, 0, acc_max)
        self.acc[sel[keep]] = end[keep]

    def _clock_path(self, sel, mu, dark, words):
        """Exact per-clock simulation of the pixels ``sel`` (flat indices)."""
        c = self.config
        L = c.clocks_per_readout
        step = max(1, CLOCK_CHUNK_ELEMENTS // L)
        for start in range(0, sel.size, step):
            part = sel[start:start + step]
            if self.noise:
                e = clock_electrons(c, mu[part], dark[part], self.rng, self.budget)
            else:
                e, self.fraction[part] = deterministic_clock_electrons(c, mu[part], self.fraction[part])
            state = PixelState.zeros((1, part.size))
            state.acc[0] = self.acc[part]
            w, state = step_reference(c, e.T.reshape(L, 1, part.size), state)
            words[part] = w[0, 0]
            self.acc[part] = state.acc[0]


def simulate_scene(config: SensorConfig, scene: np.ndarray, *, seed=None,
                   dark_current: str | None = None, noise: bool = True,
                   progress: bool = False, method: str = "fast") -> np.ndarray:
    """Scene light ``(K, H, W)`` -> readout words ``(K, H, W)`` (smallest word dtype).

    ``seed``: int, numpy Generator or ``None`` (fresh entropy). ``method="per-clock"``
    draws electrons per pixel clock everywhere (slow; the reference the fast
    paths are tested against). ``progress`` shows a tqdm bar on stderr for runs
    longer than a few seconds.
    """
    scene = check_scene(scene)
    K, H, W = scene.shape
    sim = SceneSimulator(config, (H, W), rng=seed, dark_current=dark_current, noise=noise,
                         method=method, total_pixel_readouts=scene.size)
    words = np.empty((K, H, W), word_dtype(config))
    readouts = range(K)
    if progress:
        from tqdm import tqdm
        readouts = tqdm(readouts, desc="simulate", unit="readout", delay=2.0, leave=False)
    for k in readouts:
        words[k] = sim.readout(scene[k])
    return words
