"""Fast light-to-stream simulator, distributed like the cycle-exact model (SPEC sections 3, 6).

:func:`simulate_scene` gives readout words with the same distribution as
:func:`golden.sensor.simulate` driven by :func:`golden.light.poisson_stimulus`
(accumulator starting at 0, residual carried across readouts), but draws
random numbers per readout interval instead of per pixel clock wherever the
dynamics allow. Each pixel-readout takes one of these paths, chosen from its
light and its carried charge only (never from a random draw of its own, so
the choice cannot bias the result); docs/simulator.md has the derivation.

``lazy``     dim light (interval mean at most 2 theta), no dark electrons,
             ``acc < theta``: no draw until the next threshold crossing, whose
             light-time is Gamma(theta - acc), then Gamma(theta) from crossing
             to crossing; an interval only subtracts its mean from what
             remains (:meth:`SceneSimulator._lazy_path`).
``event``    ``acc < theta`` and no clock can get more than ``min(theta, 2^E - 1)``
             electrons (bound below). Then no clock holds two threshold
             crossings, so every crossing is a spike in its own clock and no
             input saturates: the interval total ``T ~ Poisson(expected) + dark``
             fixes the spike count ``floor((acc + T) / theta)`` and the residual
             ``(acc + T) mod theta``; given T the electrons sit in iid uniform
             positions over the L clocks, so the clock of the ``2^b1``-th spike
             (TE overflow) is ``floor(L * Beta(n, T - n + 1))`` with
             ``n = 2^b1 * theta - acc``, the n-th of T uniform order statistics.
``bright``   every clock surely gets at least ``theta`` electrons: a spike in every
             clock (word known), the accumulator only grows, so it ends at
             ``min(acc + sum(e) - L theta, 2^A - 1)``; ``sum(e)`` is
             ``Poisson(expected) + dark`` when no input can saturate, ``L (2^E - 1)``
             when every input surely does, and need not be drawn at all when
             the accumulator surely ends full.
``queue``    light below one threshold per clock, no clipping (Lundberg bound):
             spikes follow the threshold crossings through a unit-rate queue;
             the last w clocks are drawn per clock to settle the backlog left
             at readout, the TE overflow clock comes from Gamma-gap order
             statistics of the first crossings (:meth:`SceneSimulator._queue_path`).
``full``     light above one threshold per clock and a spike in every clock
             sure (Lundberg bound on the walk from the carried charge): word
             known, accumulator from a window of the last clocks
             (:meth:`SceneSimulator._full_path`).
``head``     a carried backlog under dim light, or light above one threshold
             per clock on an accumulator too low for the full path's bound:
             the first h clocks per clock (cycle-exact), then the rest of the
             interval by the event, queue or full path from the state reached,
             chosen from that state (:meth:`SceneSimulator._head_path`).
``clock``    anything else (light within about 10 % of one threshold per clock,
             where charge backs up and the accumulator can clip): per-clock
             electrons for these pixels only; where they are few, the queue
             of crossings over all clocks in a few array passes, kept where
             no clock clipped (:meth:`SceneSimulator._walk_clocks`), else the
             cycle-exact model :class:`golden.sensor.PixelArray` on them.

ML msb (SPEC section 3): every path finds the spikes of the interval as for
the count readout; the counter is then ``min(sfc + spikes, 2^ml_bits - 1)``
from the carried remainder ``sfc``, the word its bit_length, and the new
remainder what is left below that bit (:meth:`SceneSimulator._ml_words`). The
remainder is a function of past spike counts, so each path stays exact in
distribution; lazy pixels still read out their remainder.

"Surely" means: each such event fails with probability below
``2^-64 / (CHECKS x pixel-readouts x L)`` (:func:`golden.light.log_budget`,
rigorous tail bounds in :mod:`golden.light`); a pixel-readout relies on at
most CHECKS of them, so the law of the whole output stream differs from the
exact one by less than 2^-64 in total variation. With ``noise=False`` nothing is
random and every pixel takes the per-clock path on the deterministic
stimulus of :func:`golden.light.deterministic_clock_electrons`.

Where the ideas live: this module holds the simulator (its state and the
paths) and the public API; :mod:`golden.fastsim_classify` decides each
pixel-readout's path and returns what the paths need (no state kept between
calls); :mod:`golden.fastsim_stripes` splits a frame into stripes and runs
them on worker processes.
"""

from __future__ import annotations

import numpy as np

from .config import SensorConfig
from .errors import InputError
from .fastsim_classify import (BRIGHT, CLOCK, EVENT, FULL, HEAD, LAZY, MAX_BACKLOG, MIN_WINDOW, QUEUE,
                               SIMULATION_PATHS, groups, path_levels, round_window)
from .fastsim_stripes import (MAX_STRIPES, STRIPE_PIXELS, STRIPE_ROWS, check_workers, run_stripes,
                              spawn_generators, stripe_slices)
from .io import check_scene, word_dtype
from .noise import PixelNoise, pixel_noise
from .light import (as_generator, deterministic_clock_electrons, electrons_per_readout, log_budget,
                    log_poisson_tail_above, log_poisson_tail_below)
from .reference import PixelState
from .resources import keep_freed_memory
from .poisson import PoissonSampler
from .sensor import PixelArray

__all__ = ["CHECKS", "MAX_BACKLOG", "MAX_STRIPES", "MIN_WINDOW", "SIMULATION_METHODS", "SIMULATION_PATHS",
           "STRIPE_PIXELS", "STRIPE_ROWS", "SceneSimulator", "check_workers", "iter_scene_stimulus",
           "lindley_ends", "scene_stimulus", "simulate_scene", "spawn_generators", "stripe_simulators",
           "stripe_slices"]

#: Bounded events a pixel-readout can rely on (input saturation, clipping,
#: backlog, firing, window certification, ...); each gets 1/CHECKS of the budget.
CHECKS = 8

#: Spawn key of the generator that draws lazy pixels' charge when :attr:`SceneSimulator.acc`
#: is read (beyond any child index a caller spawns in practice).
PEEK_KEY = 0x7065656B

#: How :class:`SceneSimulator` draws electrons: the fast paths, or per pixel clock everywhere.
SIMULATION_METHODS = ("fast", "per-clock")

#: Per-clock draws of one call below which numpy's sampler is used (no table).
SMALL_DRAW = 4096

#: Pixel clocks x pixels of per-clock electrons held at once (bounds memory).
CLOCK_CHUNK_ELEMENTS = 1 << 21

#: Pixels up to which the per-clock path first tries the unclipped walk
#: (:meth:`SceneSimulator._walk_clocks`): a few array passes over all clocks instead of
#: the cycle-exact model's five per clock, whose Python cost dominates for few pixels.
WALK_PIXELS = 512


class SceneSimulator:
    """An H x W array of pixels lit by a scene, one readout interval at a time.

    Holds the carried accumulator (``acc``, int64, flat), the ML msb counter
    remainder (``sfc``, int64, flat; 0 otherwise) and, for ``noise=False``, the
    carried charge fraction. ``method="per-clock"`` sends every pixel down
    the per-clock path (the full path the shortcuts are tested against).
    ``path_counts`` counts pixel-readouts per path.
    """

    def __init__(self, config: SensorConfig, shape: tuple[int, int], *, rng=None,
                 dark_current: str | None = None, noise: bool = True,
                 method: str = "fast", total_pixel_readouts: int | None = None,
                 sensor=None, pixels: PixelNoise | None = None):
        _check_method(method)
        self.config = config
        self.shape = tuple(shape)
        # sensor non-idealities as per-pixel rates (golden.noise): a Sensor, or its
        # PixelNoise for these pixels (a stripe's share of a frame's maps)
        self.pixels = pixels if pixels is not None else pixel_noise(dark_current, sensor, self.shape)
        self.dark_model = self.pixels.dark_model
        if not noise and self.dark_model is not None:
            raise InputError(f"dark current {self.dark_model!r} is random; "
                             "it cannot be combined with noise switched off")
        self.noise = noise
        self.method = method
        self.rng = as_generator(rng)
        n = self.shape[0] * self.shape[1]
        self._acc = np.zeros(n, np.int64)                  # carried charge (lazy pixels: at their last sync)
        # lazy pixels (dim light, see _lazy_path): light-time still to the next
        # threshold crossing, and from the last sync to that crossing
        self.sampler = None                                # PoissonSampler, made on first use
        self._lazy = np.zeros(n, bool)
        self._remaining = np.zeros(n)
        self._span = np.zeros(n)
        self.sfc = np.zeros(n, np.int64)                   # msb: remainder left in the counter
        self.fraction = np.zeros(n)
        self._no_dark = np.zeros(n, np.int64)              # read only
        # at most CHECKS bounded events per pixel-readout, each below the budget
        self.budget = log_budget(total_pixel_readouts or n, config.clocks_per_readout) - np.log(CHECKS)
        self.path_counts = dict.fromkeys(SIMULATION_PATHS + ("fallback",), 0)
        self.levels = path_levels(config, float(self.budget))
        self.readouts = 0                                  # readout intervals simulated
        seq = getattr(self.rng.bit_generator, "seed_seq", None)
        if not isinstance(seq, np.random.SeedSequence):
            seq = np.random.SeedSequence()                 # a seedless generator: fresh entropy, once
        self._peek_seed = (seq.entropy, tuple(seq.spawn_key) + (PEEK_KEY,), seq.pool_size)  # read only

    @property
    def acc(self) -> np.ndarray:
        """The carried charge of every pixel (flat int64). Reading it is free of side
        effects: it changes no state, draws nothing from the simulator's generator (later
        words are those of a run without the read) and gives the same values when read
        again before the next readout. With no lazy pixel it is the simulator's own array
        (writes set the charge the next readout starts from); otherwise a read-only copy in
        which each lazy pixel's charge is drawn from its law given everything simulated so
        far (:meth:`_lazy_charge`), from a generator made afresh for the read from the
        simulator's seed and the number of readouts done (:meth:`_peek_generator`). To set
        charges while pixels are lazy, assign the whole array (``sim.acc = values``)."""
        lazy = np.flatnonzero(self._lazy)
        if not lazy.size:
            return self._acc
        acc = self._acc.copy()
        acc[lazy] += self._lazy_charge(lazy, self._peek_generator())
        acc.flags.writeable = False
        return acc

    @acc.setter
    def acc(self, values) -> None:
        """Set every pixel's carried charge (lazy pixels leave their path: their
        charge is now known, and what follows depends on it alone)."""
        self._acc[:] = values
        self._lazy[:] = False

    def _peek_generator(self) -> np.random.Generator:
        """A new generator for one read of :attr:`acc`: a child of the simulator's seed
        sequence keyed by :data:`PEEK_KEY` and :attr:`readouts`, made without spawning (the
        simulator's own stream and counter are untouched), so a read is a function of the
        seed and the readouts done. A seedless generator's reads take one fresh entropy,
        drawn at the simulator's making."""
        entropy, key, pool_size = self._peek_seed
        return np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=key + (self.readouts,),
                                                            pool_size=pool_size))

    # -- one readout interval -------------------------------------------------
    def readout(self, light: np.ndarray) -> np.ndarray:
        """Light of one interval (H, W), checked >= 0 and finite -> words (H, W) int64."""
        L = self.config.clocks_per_readout
        expected = self.pixels.photo(electrons_per_readout(np.asarray(light).reshape(-1)))
        self.readouts += 1
        dark = self.pixels.dark(expected.size, self.rng) if self.dark_model else self._no_dark
        words = np.zeros(expected.shape, np.int64)
        if not self.noise:
            idx = np.arange(expected.size)
            self._clock_path(idx, expected, dark, words)
            self.path_counts["clock"] += idx.size
            return words.reshape(self.shape)
        if self.method == "per-clock":
            idx = np.arange(expected.size)
            self._clock_path(idx, expected, dark, words)
            self.path_counts["clock"] += idx.size
            return words.reshape(self.shape)

        lazy = self._lazy_path(expected, dark, words)
        n_lazy = int(np.count_nonzero(lazy))
        if n_lazy == expected.size:                        # a dark frame: nothing else to do
            self.path_counts["lazy"] += n_lazy
            return words.reshape(self.shape)
        lam = expected / L                                 # photo-electrons per clock
        mean = lam + dark / L if self.dark_model else lam  # with dark electrons
        plan = self.levels.classify(lazy, n_lazy, lam, mean, dark, self._acc)
        counts = np.bincount(plan.path, minlength=len(SIMULATION_PATHS))
        for code, name in enumerate(SIMULATION_PATHS):
            if not counts[code]:
                continue
            self.path_counts[name] += int(counts[code])
            if code == LAZY:                               # done by _lazy_path
                continue
            if code == EVENT and counts[code] == expected.size:
                sel = slice(None)                          # the whole frame: no gather / scatter
            else:
                sel = np.flatnonzero(plan.path == code)
            if code == EVENT:
                self._event_path(sel, expected, dark, words)
            elif code == BRIGHT:
                self._bright_path(sel, expected, lam, dark, words)
            elif code in (QUEUE, FULL):
                # grouped by window length (multiples of MIN_WINDOW) so each group is one block
                size = plan.length[sel]
                too_long = size > L // 2
                if too_long.any():
                    self.path_counts[name] -= int(too_long.sum())
                    self.path_counts["clock"] += int(too_long.sum())
                    self._clock_path(sel[too_long], expected, dark, words)
                for w, group in groups(sel[~too_long], size[~too_long]):
                    if code == QUEUE:
                        self._queue_path(group, w, plan.b_max[group], lam, words)
                    else:
                        self._full_path(group, w, lam, words)
            elif code == HEAD:
                for h, group in groups(sel, plan.length[sel]):
                    self._head_path(group, h, expected, lam, words)
            elif code == CLOCK:
                self._clock_path(sel, expected, dark, words)
        return words.reshape(self.shape)

    def _lazy_path(self, expected, dark, words):
        """Dim light (interval mean at most ``levels.mean_lazy``, 2 theta; no dark electrons,
        ``acc < theta``): no random draw until the next threshold crossing.

        In light-time (tau grows by expected per interval) the electrons are a
        unit-rate Poisson process, so the crossing, ``n = theta - acc``
        electrons after a sync, comes ``Gamma(n)`` later. Each interval only
        subtracts expected from the light-time remaining; an interval that reaches
        it fires that spike (a crossing is a spike in its own clock, as on the
        event path) and the charge restarts from 0 at the crossing electron: a
        sync, whose next crossing is ``Gamma(theta)`` later (memoryless), maybe
        again within the interval (a further spike). The charge between syncs
        is drawn only when a pixel leaves this path (:meth:`_sync`). TE overflow
        needs ``(2^b1 - 1) theta`` electrons after a crossing in one interval,
        surely not at this light (bound).
        -> the pixels on this path (a flat mask)."""
        c = self.config
        theta = c.threshold
        eligible = (expected <= self.levels.mean_lazy) & (self._acc < theta)
        if self.dark_model:
            eligible &= dark == 0
        changed = np.flatnonzero(eligible != self._lazy)   # (one pass; few pixels change)
        if changed.size:
            was = self._lazy[changed]
            leave = changed[was]
            if leave.size:
                self._sync(leave)
            enter = changed[~was]
            if enter.size:
                self._span[enter] = self._remaining[enter] = self.rng.standard_gamma(theta - self._acc[enter])
        self._lazy = eligible
        # a whole-frame pass, no gather: the other pixels' values are never read
        np.subtract(self._remaining, expected, out=self._remaining)
        hit = eligible & (self._remaining <= 0.0)
        cross = np.flatnonzero(hit)
        if c.is_msb:                                       # msb reads out a remainder left
            self._ml_words(np.flatnonzero(eligible & ~hit & (self.sfc > 0)), 0, words)
        if cross.size:
            spikes = np.ones(cross.size, np.int64)
            span = self.rng.standard_gamma(float(theta), cross.size)
            remaining = self._remaining[cross] + span
            again = np.flatnonzero(remaining <= 0.0)
            while again.size:                              # another crossing in the interval
                spikes[again] += 1
                span[again] = self.rng.standard_gamma(float(theta), again.size)
                remaining[again] += span[again]
                again = again[remaining[again] <= 0.0]
            self._acc[cross] = 0
            self._remaining[cross] = remaining
            self._span[cross] = span
            if c.is_te:
                words[cross] = spikes
            else:
                self._ml_words(cross, spikes, words)
        return eligible

    def _sync(self, sel):
        """Lazy pixels ``sel`` leave the path with their charge drawn (:meth:`_lazy_charge`)."""
        if not sel.size:
            return
        self._acc[sel] += self._lazy_charge(sel, self.rng)
        self._lazy[sel] = False

    def _lazy_charge(self, sel, rng):
        """Electrons lazy pixels ``sel`` have gathered since their sync, drawn with
        ``rng``: given the crossing at light-time ``span`` after the sync, of which
        ``span - remaining`` has passed, the ``n - 1`` electrons before it are iid
        uniform over the span, so ``Binomial(n - 1, (span - remaining) / span)`` of them
        have come."""
        n = self.config.threshold - self._acc[sel]
        span = self._span[sel]
        elapsed = span - self._remaining[sel]
        return rng.binomial(n - 1, np.where(span > 0, elapsed / np.where(span > 0, span, 1.0), 0.0))

    def _head_path(self, sel, h, expected, lam, words):
        """The first ``h`` clocks per clock through the cycle-exact model, then
        the rest of the interval by the cheapest path the state reached allows:
        event (``acc < theta`` and light below the event level), full (its bound
        holds from the charge reached), else per clock from that state. The
        choice depends on the head only, never on the rest's electrons, which
        are independent of it, so each outcome keeps its exact law; spikes and
        the TE overflow clock of the rest are shifted by the head's."""
        c = self.config
        theta, L = c.threshold, c.clocks_per_readout
        n, rest = sel.size, L - h
        e = np.minimum(self._clock_draws(lam[sel], h), c.input_max)
        array = PixelArray(c, (1, n))
        array.state.acc[0] = self._acc[sel]
        array.state.sfc[0] = self.sfc[sel]
        array.feed(e.reshape(h, 1, n))
        st = array.state
        acc_h, sfc_h, ovf, m = st.acc[0], st.sfc[0], st.ovf[0], st.m[0]
        lam_s = lam[sel]
        # the rest's path, from the state after the head and the light only
        levels = self.levels
        event = (acc_h < theta) & (lam_s <= levels.mean_event)
        queue = ~event & (acc_h < theta) & (lam_s < levels.rho_queue * theta)
        size, b_max = np.zeros(n), np.zeros(n)              # the rest's window lengths, backlog bounds
        if queue.any():
            i = np.flatnonzero(queue)
            queue[i], b_max[i], size[i] = levels.queue_plan(lam_s[i] / theta)
        full = ~event & (lam_s > theta)
        if full.any():
            i = np.flatnonzero(full)
            full[i], size[i] = levels.full_plan(lam_s[i], acc_h[i])
        size = round_window(size)
        queue &= size <= rest // 2
        full &= size <= rest // 2
        spikes = np.zeros(n, np.int64)                      # spikes of the rest
        at = np.full(n, -1, np.int64)                       # TE: clock of the overflow in the rest
        # TE: spikes still needed to overflow (none once it has: a count never reached)
        need = np.where(ovf, L + 1, c.p_max - sfc_h) if c.is_te else np.full(n, L + 1, np.int64)
        settled = np.ones(n, bool)                          # False: words written per clock
        if event.any():
            i = np.flatnonzero(event)
            total = self.rng.poisson(expected[sel[i]] * (rest / L))
            level = acc_h[i] + total
            spikes[i] = level // theta
            self._acc[sel[i]] = level - spikes[i] * theta
            over = spikes[i] >= need[i]
            if over.any():
                k = need[i[over]] * theta - acc_h[i[over]]  # electron that makes the overflow spike
                position = self.rng.beta(k, total[over] - k + 1)
                at[i[over]] = h + np.minimum((position * rest).astype(np.int64), rest - 1)
        for tail in (queue, full):
            i = np.flatnonzero(tail)
            for w, j in groups(i, size[i]):
                if tail is queue:
                    ok, got, end, clock, window, drawn = self._queue_walk(sel[j], w, lam, acc_h[j],
                                                                          rest, need[j], b_max[j])
                    at[j[ok & (clock >= 0)]] = h + clock[ok & (clock >= 0)]
                else:
                    ok, end, window, drawn = self._full_walk(sel[j], w, lam, acc_h[j], rest)
                    got = np.full(j.size, rest, np.int64)   # a spike in every clock of the rest
                    hit = ok & (rest >= need[j])
                    at[j[hit]] = h + need[j[hit]] - 1
                self._acc[sel[j[ok]]] = end[ok]
                spikes[j[ok]] = got[ok]
                bad = j[~ok]
                if bad.size:
                    self._fallback(sel[bad], window[:, ~ok], drawn[~ok], words, self._head_state(st, bad, h))
                    settled[bad] = False
        slow = np.flatnonzero(~event & ~queue & ~full)
        if slow.size:
            e = np.minimum(self._clock_draws(lam_s[slow], rest), c.input_max)
            self.path_counts["fallback"] += slow.size
            self._run_clocks(sel[slow], e, words, self._head_state(st, slow, h))
            settled[slow] = False
        done = np.flatnonzero(settled)
        if c.is_te:
            word = np.minimum(sfc_h[done] + spikes[done], c.p_max)
            late = at[done] >= 0
            word[late] = (1 << c.d) | (at[done][late] // c.clocks_per_tick + 1)
            early = ovf[done]
            word[early] = (1 << c.d) | m[done][early]
            words[sel[done]] = word
        elif c.is_msb:
            self.sfc[sel[done]] = sfc_h[done]
            self._ml_words(sel[done], spikes[done], words)
        else:
            self._ml_words(sel[done], sfc_h[done] + spikes[done], words)

    @staticmethod
    def _head_state(state, i, h):
        """The state of pixels ``i`` of a head's (1, n) array, at clock ``h``."""
        return PixelState(h, state.acc[:, i].copy(), state.sfc[:, i].copy(),
                          state.ovf[:, i].copy(), state.m[:, i].copy())

    # -- windows of per-clock electrons at the end of the interval -------------
    def _window_draw(self, sel, w, lam, clocks=None):
        """Electrons of the last ``w`` of ``clocks`` clocks (default L; iid Poisson),
        ``(w, n)`` clock-major, and the total of the other ``clocks - w``; the order
        in which independent clocks are drawn does not change their law."""
        clocks = self.config.clocks_per_readout if clocks is None else clocks
        window = self._clock_draws(lam[sel], w)
        rest = self.rng.poisson(lam[sel] * (clocks - w))
        return window, rest

    def _fallback(self, sel, window, rest, words, start=None):
        """Per-clock path for pixels whose window did not settle their outcome:
        the drawn window and rest total are kept (the rest spread as a uniform
        multinomial, which is its law given the total), so nothing is redrawn.
        ``start``: the pixels' state part-way through the interval (after a
        head, :meth:`_head_path`); by default the start of the interval."""
        if not sel.size:
            return
        c = self.config
        clocks = c.clocks_per_readout - (start.clock if start is not None else 0)
        w = window.shape[0]
        head = self.rng.multinomial(rest, np.full(clocks - w, 1.0 / (clocks - w)))
        e = np.minimum(np.concatenate([head.T, window], axis=0), c.input_max)
        self.path_counts["fallback"] += sel.size
        self._run_clocks(sel, e, words, start)

    def _queue_path(self, sel, w, b_max, lam, words):
        """Light below one threshold per clock and no clipping (bound): spikes
        and the accumulator from :meth:`_queue_walk` over the whole interval
        (window ``w`` clocks, backlog bounds ``b_max``)."""
        c = self.config
        ok, spikes, end, at, window, rest = self._queue_walk(
            sel, w, lam, self._acc[sel], c.clocks_per_readout, np.full(sel.size, c.p_max, np.int64), b_max)
        self._fallback(sel[~ok], window[:, ~ok], rest[~ok], words)
        done = sel[ok]
        self._acc[done] = end[ok]
        if not c.is_te:
            self._ml_words(done, spikes[ok], words)
            return
        words[done] = np.where(at[ok] >= 0, (1 << c.d) | (at[ok] // c.clocks_per_tick + 1), spikes[ok])

    def _queue_walk(self, sel, w, lam, acc0, clocks, need, b_max):
        """``clocks`` clocks of light below one threshold per clock from charge
        ``acc0 < theta``, no clipping (bound): spikes follow the crossings of the
        threshold levels through a unit-rate queue.

        Without clipping, spike j fires at ``s_j = max(c_j, s_{j-1} + 1)``, c_j
        the clock where the charge reaches ``j theta``; the count at the end is
        the crossings minus the backlog left. The backlog entering the window
        of the last ``w`` clocks is at most ``b_max`` (per pixel, bound); the Lindley
        recursion over the window from 0 and from ``b_max`` agreeing settles the
        end backlog. TE: the clock of spike ``need`` (per pixel) when it fires,
        from the first ``need`` crossings, all before the window.
        -> (ok, spikes, end accumulator, that clock or -1, window, rest total);
        pixels not ``ok`` go per clock with the window and rest drawn."""
        c = self.config
        theta = c.threshold
        window, rest = self._window_draw(sel, w, lam, clocks)
        level0 = acc0 + rest                               # charge before the window
        levels = np.cumsum(window, axis=0)
        levels += level0
        # the queue's walk W_k = crossings up to window clock k, minus k
        walk = levels // theta
        walk -= (level0 // theta + 1) + np.arange(w)[:, None]
        b_lo, b_hi = lindley_ends(walk, np.zeros(sel.size, np.int64), b_max.astype(np.int64))
        ok = b_lo == b_hi
        level_end = levels[-1]
        spikes = level_end // theta - b_lo
        at = np.full(sel.size, -1, np.int64)
        if not c.is_te:
            return ok, spikes, level_end - theta * spikes, at, window, rest
        over = ok & (spikes >= need)
        ok &= ~over | ((need * theta - acc0) <= rest)       # the crossings' ranks lie in the rest
        over &= ok
        span = clocks - w
        needs = need[over]
        # one need for all (the queue path's 2^b1) skips np.unique's sort
        for p in needs[:1] if needs.size and (needs == needs[0]).all() else np.unique(needs):
            i = np.flatnonzero(over & (need == p))
            a, t = acc0[i], rest[i]
            shapes = np.empty((i.size, p + 1))
            shapes[:, 0] = theta - a                       # electron of the first crossing
            shapes[:, 1:p] = theta
            shapes[:, p] = t - (p * theta - a) + 1
            gaps = self.rng.standard_gamma(shapes)
            position = np.cumsum(gaps[:, :p], axis=1) / gaps.sum(axis=1, keepdims=True)
            cross = np.minimum((position * span).astype(np.int64), span - 1)
            at[i] = (cross - np.arange(1, p + 1)).max(axis=1) + p   # s_p = max_i (c_i + p - i)
        return ok, spikes, level_end - theta * spikes, at, window, rest

    def _full_path(self, sel, w, lam, words):
        """Light above one threshold per clock, a spike in every clock (bound):
        the word is known and the accumulator comes from :meth:`_full_walk`."""
        ok, end, window, rest = self._full_walk(sel, w, lam, self._acc[sel], self.config.clocks_per_readout)
        self._fallback(sel[~ok], window[:, ~ok], rest[~ok], words)
        done = sel[ok]
        self._acc[done] = end[ok]
        self._firing_words(done, words)

    def _full_walk(self, sel, w, lam, acc0, clocks):
        """End accumulator of ``clocks`` clocks that surely all fire (bound): the
        walk ``acc0 + sum(e - theta)`` held at or below ``2^A - 1`` ends at
        ``min(acc0 - R, acc_max - M)``, R the sum of ``theta - e`` and M its
        largest suffix sum. M is read from a window of the last ``w`` clocks
        where the rest provably cannot exceed it (bound) -> (ok, end, window, rest):
        pixels not ``ok`` go per clock with the window and rest drawn."""
        c = self.config
        theta, acc_max = c.threshold, c.acc_max
        window, rest = self._window_draw(sel, w, lam, clocks)
        deficit = theta - window
        suffix = np.cumsum(deficit[::-1], axis=0)
        m_win = np.maximum(suffix.max(axis=0), 0)
        r_win = suffix[-1]
        lam_s = lam[sel]
        s = 2.0 * (lam_s - theta) / lam_s
        ok = -s * (m_win + 1 - r_win) < self.budget
        total_deficit = r_win + (clocks - w) * theta - rest
        end = np.minimum(acc0 - total_deficit, acc_max - m_win)
        # under the sure event every clock fires, so end >= 0; clip only guards
        # the 2^-64 failure event against an illegal state
        return ok, np.clip(end, 0, acc_max), window, rest

    def _event_path(self, sel, expected, dark, words):
        """``sel``: flat indices, or ``slice(None)`` for the whole frame."""
        c = self.config
        theta, L = c.threshold, c.clocks_per_readout
        acc0 = self._acc[sel]
        total = self.rng.poisson(expected[sel])
        if self.dark_model:
            total += dark[sel]
        level = acc0 + total
        spikes = level // theta                            # (np.divmod is 3x slower on int64)
        residual = level - spikes * theta
        if not c.is_te:
            self._acc[sel] = residual
            self._ml_words(sel, spikes, words)
            return
        over = np.flatnonzero(spikes >= c.p_max)
        if over.size:
            n = c.p_max * theta - acc0[over]               # electron that makes the 2^b1-th spike
            t = total[over]
            position = self.rng.beta(n, t - n + 1)         # n-th of t uniform order statistics
            clock = np.minimum((position * L).astype(np.int64), L - 1)
            spikes[over] = (1 << c.d) | (clock // c.clocks_per_tick + 1)
        self._acc[sel] = residual                           # after acc0 (maybe a view) is used
        words[sel] = spikes

    def _bright_path(self, sel, expected, lam, dark, words):
        c = self.config
        theta, L, top, acc_max = c.threshold, c.clocks_per_readout, c.input_max, c.acc_max
        acc0 = self._acc[sel]
        lam_s = lam[sel]
        end = np.full(sel.size, acc_max, np.int64)
        # every clock saturated at 2^E - 1: a deterministic sum
        all_top = log_poisson_tail_below(lam_s, top - 1) < self.budget
        # accumulator surely full after the first clock: nothing to draw
        full = np.zeros(sel.size, bool)
        if top >= theta + acc_max:
            full = log_poisson_tail_below(lam_s, theta + acc_max - 1) < self.budget
        # no input can saturate: the sum is Poisson(expected) + dark
        unclipped = log_poisson_tail_above(lam_s + dark[sel] / L, top + 1) < self.budget
        need = ~full & ~all_top
        if (need & ~unclipped).any():
            # inputs that may or may not saturate: per clock (exact), rare in practice
            mixed = need & ~unclipped
            self.path_counts["bright"] -= int(mixed.sum())
            self.path_counts["clock"] += int(mixed.sum())
            self._clock_path(sel[mixed], expected, dark, words)
            need &= unclipped
            keep = ~mixed
        else:
            keep = np.ones(sel.size, bool)
        top_sel = all_top & ~full
        end[top_sel] = np.minimum(acc0[top_sel] + L * (top - theta), acc_max)
        if need.any():
            total = self.rng.poisson(expected[sel][need]) + dark[sel][need]
            # under the sure event total >= L theta; max(.., 0) only guards the
            # 2^-64 failure event against an illegal negative state
            end[need] = np.clip(acc0[need] + total - L * theta, 0, acc_max)
        self._acc[sel[keep]] = end[keep]
        self._firing_words(sel[keep], words)

    def _firing_words(self, sel, words):
        """Words of pixels ``sel`` that fired on every clock of the interval (L spikes)."""
        if self.config.is_msb:
            self._ml_words(sel, self.config.clocks_per_readout, words)
        else:
            words[sel] = self.levels.bright_word

    def _ml_words(self, sel, spikes, words):
        """ML words of pixels ``sel`` (flat indices or a slice) from their spike
        counts in the interval: the counter ``min(sfc + spikes, 2^ml_bits - 1)``
        (it saturates one spike at a time, so the clipped sum is exact); count
        reads it all, msb reads its top bit's index and keeps the remainder."""
        c = self.config
        if not c.is_msb:
            words[sel] = np.minimum(spikes, c.ml_max)
            return
        count = np.minimum(self.sfc[sel] + spikes, c.ml_max)
        words[sel] = self.levels.msb_word[count]
        self.sfc[sel] = self.levels.msb_rest[count]

    def _clock_path(self, sel, expected, dark, words):
        """Exact per-clock simulation of the pixels ``sel`` (flat indices).

        Electrons are drawn straight into the clock-major layout the engine
        steps through (iid clocks: the layout does not change their law)."""
        for part, e in self._clock_chunks(sel, expected, dark):
            self._run_clocks(part, e, words)

    def _clock_chunks(self, sel, expected, dark):
        """Per-clock electrons ``(L, n)`` of the pixels ``sel``, chunk by chunk: the
        one place the per-clock path draws them (:meth:`clock_stimulus` reuses it)."""
        c = self.config
        L = c.clocks_per_readout
        step = max(1, CLOCK_CHUNK_ELEMENTS // L)
        for start in range(0, sel.size, step):
            part = sel[start:start + step]
            if self.noise:
                e = self._clock_electrons(expected[part], dark[part])
            else:
                e, self.fraction[part] = deterministic_clock_electrons(c, expected[part], self.fraction[part])
                e = np.ascontiguousarray(e.T)
            yield part, e

    def clock_stimulus(self, light: np.ndarray) -> np.ndarray:
        """Per-clock electrons ``(L, H, W)`` of one interval, drawn exactly as
        :meth:`readout` draws them with ``method="per-clock"`` (same random numbers
        in the same order), without running the pixels: the cycle-exact model on
        these electrons gives that readout's words. Smallest unsigned dtype."""
        from .light import stimulus_dtype
        if self.noise and self.method != "per-clock":
            raise InputError("clock_stimulus needs method='per-clock' (or noise switched off)")
        L = self.config.clocks_per_readout
        expected = self.pixels.photo(electrons_per_readout(np.asarray(light).reshape(-1)))
        dark = self.pixels.dark(expected.size, self.rng) if self.dark_model else self._no_dark
        out = np.empty((L, expected.size), stimulus_dtype(self.config))
        for part, e in self._clock_chunks(np.arange(expected.size), expected, dark):
            out[:, part] = e
        return out.reshape((L,) + self.shape)

    def _clock_electrons(self, expected, dark):
        """Random electrons ``(L, n)`` of one interval, the law of
        :func:`golden.light.clock_electrons` (Poisson per clock, dark electrons
        multinomial over the clocks, saturated at ``2^E - 1``; no draw where
        every clock surely saturates)."""
        c = self.config
        L, top = c.clocks_per_readout, c.input_max
        lam = expected / L
        sure = log_poisson_tail_below(lam, top - 1) < self.budget
        if sure.all():
            return np.full((L, expected.size), top, np.int64)
        draw = np.flatnonzero(~sure)
        e = self._clock_draws(lam[draw], L)
        d = dark[draw]
        if d.any():
            e += self.rng.multinomial(d, np.full(L, 1.0 / L)).T
        np.minimum(e, top, out=e)
        if draw.size == expected.size:
            return e
        out = np.full((L, expected.size), top, np.int64)
        out[:, draw] = e
        return out

    def _clock_draws(self, lam, clocks):
        """Per-clock photo-electrons ``(clocks, n)``, iid Poisson(lam[j]) in column j.

        The fast method draws them with :class:`golden.poisson.PoissonSampler`
        (tables of the integer part of the mean, 3-5x cheaper than numpy's
        sampler per draw; same law to float64 precision, tables cut where the
        tail is below the per-clock budget); ``method="per-clock"``, the
        reference the shortcuts are tested against, and :meth:`clock_stimulus`
        keep numpy's ``Generator.poisson``, as do calls of fewer than SMALL_DRAW
        draws (a table costs about 0.25 ms to build, 10^4 draws' worth)."""
        if self.method == "per-clock" or lam.size * clocks < SMALL_DRAW:
            return self.rng.poisson(lam[None, :], size=(clocks, lam.size))
        if self.sampler is None:
            self.sampler = PoissonSampler(self.budget)
        return self.sampler.draw(self.rng, lam, clocks=clocks)

    def _walk_clocks(self, sel, e, words):
        """Pixels ``sel`` from the start of the interval on electrons ``e`` (L, n), where
        no clock clips the accumulator: there the pixel is a queue whose arrivals are the
        crossings ``D_t = floor((acc0 + e_1 + .. + e_t) / theta)`` and which serves one a
        clock, so the backlog ``B_t = D_t - S_t`` (S_t spikes so far, ``B_0 = D_0``)
        follows Lindley, ``B_t = W_t - min(0, min_{1<=k<=t} W_k)`` with ``W_t = D_t - t``,
        and the charge is ``acc0 + e_1 + .. + e_t - theta S_t``. A pixel whose charge so
        computed never exceeds ``2^A - 1`` had the very trajectory of the cycle-exact
        model (its ``min`` never acted); the others are left to it, on the same
        electrons (a check of the outcome, not a bound: nothing is drawn again).
        -> mask of the pixels settled here."""
        c = self.config
        theta = c.threshold
        acc0 = self._acc[sel]
        level = np.cumsum(e, axis=0)
        level += acc0
        crossed = level // theta
        walk = crossed - np.arange(1, e.shape[0] + 1)[:, None]
        low = np.minimum.accumulate(walk, axis=0)
        np.minimum(low, 0, out=low)
        spikes = crossed - (walk - low)                     # S_t = D_t - B_t
        charge = level - theta * spikes
        ok = charge.max(axis=0) <= c.acc_max
        done, total = sel[ok], spikes[-1, ok]
        self._acc[done] = charge[-1, ok]
        if not c.is_te:
            self._ml_words(done, total, words)
            return ok
        over = total >= c.p_max
        at = np.argmax(spikes[:, ok] >= c.p_max, axis=0)   # the clock of spike 2^b1 (0-based)
        words[done] = np.where(over, (1 << c.d) | (at // c.clocks_per_tick + 1), total)
        return ok

    def _run_clocks(self, sel, e, words, start=None):
        """The cycle-exact model (:class:`golden.sensor.PixelArray`, clock for clock
        the literal rule of SPEC section 3) on electrons ``e`` (clocks, n) of pixels
        ``sel``, from the start of the interval or from ``start`` (a
        :class:`golden.reference.PixelState` of shape (1, n) part-way through it)."""
        if start is None and self.method == "fast" and 0 < sel.size <= WALK_PIXELS:
            settled = self._walk_clocks(sel, e, words)
            if settled.all():
                return
            sel, e = sel[~settled], e[:, ~settled]
        array = PixelArray(self.config, (1, sel.size))
        if start is None:
            array.state.acc[0] = self._acc[sel]
            array.state.sfc[0] = self.sfc[sel]             # 0 except the msb remainder
        else:
            array.state = start
        w = array.feed(e.reshape(e.shape[0], 1, sel.size))
        words[sel] = w[0, 0]
        self._acc[sel] = array.state.acc[0]
        if self.config.is_msb:
            self.sfc[sel] = array.state.sfc[0]


def lindley_ends(walk: np.ndarray, *b0s: np.ndarray) -> list[np.ndarray]:
    """Backlogs after the unit-rate queue ``b <- max(b + x_j - 1, 0)`` over the
    rows of a window, from each start backlog in ``b0s`` (n,), given the walk
    ``W_k = sum_{j<=k} (x_j - 1)`` (w, n), in closed form (Lindley):
    ``b_w = max(b0 + W_w, W_w - min_{1<=k<=w} W_k) = W_w - min(-b0, min_k W_k)``;
    one reduction for all starts instead of a Python step per clock."""
    low = walk.min(axis=0)
    return [walk[-1] - np.minimum(-b0, low) for b0 in b0s]


def stripe_simulators(config: SensorConfig, shape: tuple[int, int], *, seed=None,
                      dark_current: str | None = None, total_pixel_readouts: int | None = None,
                      sensor=None):
    """(row slices, one noisy fast :class:`SceneSimulator` per stripe) of an H x W frame.

    Stripe i draws from child i of ``seed`` (:func:`spawn_generators`); a single
    stripe is one simulator on the seed's own generator, exactly
    ``SceneSimulator(rng=seed)``. Pixels are independent given the light, so
    the stripes have the law of one simulator over the frame; each stripe's
    error budget counts ``total_pixel_readouts`` (the whole scene), so the
    2^-64 bound for the whole stream is unchanged. ``sensor``'s maps are drawn for
    the whole frame; each stripe gets its rows of them.
    """
    H, W = shape
    rows = stripe_slices(H, W)
    rngs = [seed] if len(rows) == 1 else spawn_generators(seed, len(rows))
    frame = pixel_noise(dark_current, sensor, (H, W))
    return rows, [SceneSimulator(config, (len(range(H)[r]), W), rng=rng, pixels=frame.rows(r, W),
                                 total_pixel_readouts=total_pixel_readouts or H * W)
                  for r, rng in zip(rows, rngs)]


def simulate_scene(config: SensorConfig, scene: np.ndarray, *, seed=None,
                   dark_current: str | None = None, noise: bool = True,
                   progress: bool = False, method: str = "fast",
                   workers: int | None = 1, sensor=None) -> np.ndarray:
    """Scene light ``(K, H, W)`` -> readout words ``(K, H, W)`` (smallest word dtype).

    ``seed``: int, numpy Generator or ``None`` (fresh entropy). ``method="per-clock"``
    draws electrons per pixel clock everywhere (slow; the reference the fast
    paths are tested against). ``progress`` shows a tqdm bar on stderr for runs
    longer than a few seconds. The noisy fast method simulates horizontal
    stripes (:func:`stripe_simulators`) on ``workers`` processes (this one and
    forked ones; ``None``: the cores available, at most the stripe count; 1 by
    default, so a library caller that runs threads of its own, e.g. torch,
    never forks unless it asks to; ``tespike simulate`` asks for the cores);
    the words depend on the seed and the frame's shape, not on ``workers``.
    ``method="per-clock"`` and ``noise=False`` run one :class:`SceneSimulator` in
    this process (the per-clock electrons of :func:`iter_scene_stimulus`).
    ``sensor``: a :class:`golden.noise.Sensor` (non-idealities with their per-pixel
    maps from its sensor seed), instead of ``dark_current``.
    """
    scene = check_scene(scene, scan_values=False)       # values: one readout at a time
    K, H, W = scene.shape
    _check_method(method)
    keep_freed_memory()                                 # (speed only: see golden.resources)
    if noise and method == "fast":
        rows, sims = stripe_simulators(config, (H, W), seed=seed, dark_current=dark_current,
                                       total_pixel_readouts=scene.size, sensor=sensor)
        return run_stripes(rows, sims, scene, word_dtype(config), workers=workers, progress=progress)
    check_workers(workers, 1)
    sim = SceneSimulator(config, (H, W), rng=seed, dark_current=dark_current, noise=noise,
                         method=method, total_pixel_readouts=scene.size, sensor=sensor)
    words = np.empty((K, H, W), word_dtype(config))
    readouts = range(K)
    if progress:
        from tqdm import tqdm
        readouts = tqdm(readouts, desc="simulate", unit="readout", delay=2.0, leave=False)
    for k in readouts:
        words[k] = sim.readout(check_scene(np.asarray(scene[k:k + 1]))[0])
    return words


def iter_scene_stimulus(config: SensorConfig, scene: np.ndarray, *, seed=None,
                        dark_current: str | None = None, noise: bool = True, sensor=None):
    """Yield the per-clock electrons ``(L, H, W)`` of each readout interval of ``scene``.

    The noise model and seed semantics of :func:`simulate_scene`: the electrons
    are the very ones ``simulate_scene(..., seed=seed, method="per-clock")``
    draws, so :func:`golden.sensor.simulate` on their concatenation returns
    that call's words bit for bit, and has the law of the fast method's words
    (same seed, other random numbers: the fast paths draw per interval).
    One readout interval is held at a time.
    """
    scene = check_scene(scene, scan_values=False)
    K, H, W = scene.shape
    sim = SceneSimulator(config, (H, W), rng=seed, dark_current=dark_current, noise=noise,
                         method="per-clock", total_pixel_readouts=scene.size, sensor=sensor)
    for k in range(K):
        yield sim.clock_stimulus(check_scene(np.asarray(scene[k:k + 1]))[0])


def scene_stimulus(config: SensorConfig, scene: np.ndarray, **options) -> np.ndarray:
    """:func:`iter_scene_stimulus` as one ``(K L, H, W)`` array (for crops: it holds
    ``K L H W`` values)."""
    from .light import stimulus_dtype
    scene = check_scene(scene, scan_values=False)
    K, H, W = scene.shape
    L = config.clocks_per_readout
    out = np.empty((K * L, H, W), stimulus_dtype(config))
    for k, e in enumerate(iter_scene_stimulus(config, scene, **options)):
        out[k * L:(k + 1) * L] = e
    return out


def _check_method(method) -> None:
    if method not in SIMULATION_METHODS:
        raise InputError(f"simulation method {method!r} unknown (known: {', '.join(SIMULATION_METHODS)})")
