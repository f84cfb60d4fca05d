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

PATHS = ("dark", "event", "bright", "queue", "full", "clock")

#: Largest backlog bound the queue path accepts, and its shortest window.
MAX_BACKLOG = 64
MIN_WINDOW = 8

#: Bounded events a pixel-readout can rely on (input saturation, clipping,
#: backlog, firing, window certification, ...); each gets 1/CHECKS of the budget.
CHECKS = 8
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
        # at most CHECKS bounded events per pixel-readout, each below the budget
        self.budget = log_budget(total_pixel_readouts or n, config.clocks_per_readout) - np.log(CHECKS)
        self.path_counts = dict.fromkeys(PATHS + ("fallback",), 0)
        self._window = np.zeros(n)
        self._b_max = np.zeros(n)
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
        path = np.full(mu.size, PATHS.index("clock"), np.int8)
        no_dark = dark == 0
        # inputs surely below saturation (needed by every path that sums charge)
        unclipped = log_poisson_tail_above(mean, c.input_max + 1) < self.budget
        # queue: light below the threshold per clock, the accumulator surely never clips
        rho = lam / theta
        s_queue = 2.0 * (1.0 - np.minimum(rho, 1.0))       # Lundberg exponent (see _queue_path)
        with np.errstate(divide="ignore"):
            log_l = np.log(L)
            clip_bound = log_l - s_queue * (c.acc_max + 2 - theta)
            # P(backlog >= b at the window) <= L exp(-s ((b - 1) theta + 1)): b_max + 1 is unlikely
            b_max = np.floor(((log_l - self.budget) / np.maximum(s_queue, 1e-300) - 1.0) / theta) + 1.0
        b_max = np.clip(np.where(np.isfinite(b_max), b_max, 1e9), 0, 1e9)
        window_q = 2.0 * (b_max + 2.0) / np.maximum(1.0 - rho, 1e-9)
        queue = (low & no_dark & unclipped & (rho < 1) & (clip_bound < self.budget)
                 & (b_max <= MAX_BACKLOG))
        path[queue] = PATHS.index("queue")
        self._window[queue] = window_q[queue]
        self._b_max[queue] = b_max[queue]
        # full: light above the threshold per clock, a spike in every clock surely
        s_full = 2.0 * np.maximum(lam - theta, 0.0) / np.maximum(lam, 1e-300)
        fire_bound = np.logaddexp(-s_full * (acc + 1.0), log_l - s_full * (c.acc_max + 1.0))
        gap = np.maximum(lam - theta, 1e-9)
        with np.errstate(over="ignore", divide="ignore"):
            window_f = 1.3 * -self.budget / np.maximum(s_full, 1e-300) / gap + 16.0 * lam / gap ** 2
        full = no_dark & unclipped & (lam > theta) & (fire_bound < self.budget)
        path[full] = PATHS.index("full")
        self._window[full] = window_f[full]
        # event: P(some clock > min(theta, 2^E - 1) electrons) below budget
        cap = min(theta, c.input_max)
        path[low & (log_poisson_tail_above(mean, cap + 1) < self.budget)] = PATHS.index("event")
        # bright: every clock >= theta electrons (photo-electrons alone suffice)
        if c.input_max >= theta:
            path[log_poisson_tail_below(lam, theta - 1) < self.budget] = PATHS.index("bright")
        path[low & (mu == 0) & (dark == 0)] = PATHS.index("dark")
        for code, name in enumerate(PATHS):
            sel = np.flatnonzero(path == code)
            if not sel.size:
                continue
            self.path_counts[name] += sel.size
            if name == "event":
                self._event_path(sel, mu, dark, words)
            elif name == "bright":
                self._bright_path(sel, mu, lam, dark, words)
            elif name in ("queue", "full"):
                # group by window length (powers of two) so each group is one block
                n_w = self._window[sel]
                size = np.maximum(MIN_WINDOW, 2 ** np.ceil(np.log2(np.maximum(n_w, 1.0))))
                too_long = size > L // 2
                if too_long.any():
                    self.path_counts[name] -= int(too_long.sum())
                    self.path_counts["clock"] += int(too_long.sum())
                    self._clock_path(sel[too_long], mu, dark, words)
                for w in np.unique(size[~too_long]):
                    group = sel[~too_long & (size == w)]
                    (self._queue_path if name == "queue" else self._full_path)(group, int(w), mu, lam, words)
            elif name == "clock":
                self._clock_path(sel, mu, dark, words)
        return words.reshape(self.shape)

    # -- windows of per-clock electrons at the end of the interval -------------
    def _window_draw(self, sel, w, mu, lam):
        """Electrons of the last ``w`` clocks (iid Poisson) and the total of the
        other ``L - w`` clocks; the order in which independent clocks are drawn
        does not change their law."""
        L = self.config.clocks_per_readout
        window = self.rng.poisson(lam[sel, None], size=(sel.size, w))
        rest = self.rng.poisson(mu[sel] * ((L - w) / L))
        return window, rest

    def _fallback(self, sel, window, rest, words):
        """Per-clock path for pixels whose window did not settle their outcome:
        the drawn window and rest total are kept (the rest spread as a uniform
        multinomial, which is its law given the total), so nothing is redrawn."""
        if not sel.size:
            return
        c = self.config
        L = c.clocks_per_readout
        w = window.shape[1]
        head = self.rng.multinomial(rest, np.full(L - w, 1.0 / (L - w)))
        e = np.minimum(np.concatenate([head, window], axis=1), c.input_max)
        self.path_counts["fallback"] += sel.size
        self._run_clocks(sel, e, words)

    def _queue_path(self, sel, w, mu, lam, words):
        """Light below one threshold per clock and no clipping (bound): spikes
        follow the crossings of the threshold levels through a unit-rate queue.

        Without clipping, spike j fires at ``s_j = max(c_j, s_{j-1} + 1)``, c_j
        the clock where the charge reaches ``j theta``; the count at readout is
        the crossings minus the backlog left at the end. The backlog entering
        the window is at most ``b_max`` (bound); the Lindley recursion over the
        window from 0 and from ``b_max`` agreeing settles the end backlog.
        """
        c = self.config
        theta, L = c.threshold, c.clocks_per_readout
        acc0 = self.acc[sel]
        window, rest = self._window_draw(sel, w, mu, lam)
        level0 = acc0 + rest                               # charge before the window
        levels = level0[:, None] + np.cumsum(window, axis=1)
        crossings = np.diff(levels // theta, axis=1, prepend=(level0 // theta)[:, None])
        b_lo = np.zeros(sel.size, np.int64)
        b_hi = self._b_max[sel].astype(np.int64)
        for j in range(w):
            x = crossings[:, j]
            b_lo = np.maximum(b_lo + x - 1, 0)
            b_hi = np.maximum(b_hi + x - 1, 0)
        ok = b_lo == b_hi
        level_end = levels[:, -1]
        spikes = level_end // theta - b_lo
        # TE overflow clock from the first 2^b1 crossings, all before the window
        p = c.p_max
        over = ok & (spikes >= p) if c.is_te else np.zeros(sel.size, bool)
        if c.is_te:
            ranks_ok = (p * theta - acc0) <= rest
            self._fallback(sel[over & ~ranks_ok], window[over & ~ranks_ok], rest[over & ~ranks_ok], words)
            ok &= ~(over & ~ranks_ok)
            over &= ranks_ok
        self._fallback(sel[~ok], window[~ok], rest[~ok], words)
        done = sel[ok]
        self.acc[done] = level_end[ok] - theta * spikes[ok]
        if not c.is_te:
            words[done] = np.minimum(spikes[ok], c.ml_max)
            return
        words[done] = spikes[ok]
        if over.any():
            a, t = acc0[over], rest[over]
            shapes = np.empty((a.size, p + 1))
            shapes[:, 0] = theta - a                       # electron of the first crossing
            shapes[:, 1:p] = theta
            shapes[:, p] = t - (p * theta - a) + 1
            gaps = self.rng.standard_gamma(shapes)
            position = np.cumsum(gaps[:, :p], axis=1) / gaps.sum(axis=1, keepdims=True)
            clocks = np.minimum((position * (L - w)).astype(np.int64), L - w - 1)
            first = (clocks - np.arange(1, p + 1)).max(axis=1) + p   # s_p = max_i (c_i + p - i)
            words[sel[over]] = (1 << c.d) | (first // c.clocks_per_tick + 1)

    def _full_path(self, sel, w, mu, lam, words):
        """Light above one threshold per clock, a spike in every clock (bound):
        the word is known and the accumulator is the walk ``acc + sum(e - theta)``
        held at or below ``2^A - 1``, i.e. ``min(acc - R, acc_max - M)`` with R the
        sum of ``theta - e`` over the interval and M its largest suffix sum. M is
        read from the window when the rest provably cannot exceed it (bound)."""
        c = self.config
        theta, L, acc_max = c.threshold, c.clocks_per_readout, c.acc_max
        acc0 = self.acc[sel]
        window, rest = self._window_draw(sel, w, mu, lam)
        deficit = theta - window
        suffix = np.cumsum(deficit[:, ::-1], axis=1)
        m_win = np.maximum(suffix.max(axis=1), 0)
        r_win = suffix[:, -1]
        lam_s = lam[sel]
        s = 2.0 * (lam_s - theta) / lam_s
        ok = -s * (m_win + 1 - r_win) < self.budget
        self._fallback(sel[~ok], window[~ok], rest[~ok], words)
        total_deficit = r_win + (L - w) * theta - rest
        end = np.minimum(acc0 - total_deficit, acc_max - m_win)
        done = sel[ok]
        # under the sure event every clock fires, so end >= 0; clip only guards
        # the 2^-64 failure event against an illegal state
        self.acc[done] = np.clip(end[ok], 0, acc_max)
        words[done] = self._bright_word

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
            self._run_clocks(part, e, words)

    def _run_clocks(self, sel, e, words):
        """The literal update rule on per-clock electrons ``e`` (n, L) of pixels ``sel``."""
        c = self.config
        L = c.clocks_per_readout
        state = PixelState.zeros((1, sel.size))
        state.acc[0] = self.acc[sel]
        w, state = step_reference(c, np.ascontiguousarray(e.T).reshape(L, 1, sel.size), state)
        words[sel] = w[0, 0]
        self.acc[sel] = state.acc[0]


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
