"""The simulator's state and its readout: which path each pixel takes, then each path run.

:class:`SceneSimulator` holds an H x W array's carried state and, for each
readout interval, asks the lazy path for its pixels (:mod:`.lazy`), the
other families for the rest (:mod:`.plan`) and runs each path's pixels in
the order of :data:`SIMULATION_PATHS` (the order fixes which random numbers
each path draws, so a seed gives one stream). The paths themselves live in
their families' modules, each with its classification.
"""

from __future__ import annotations

import numpy as np

from ..config import SensorConfig
from ..errors import InputError, is_count
from ..io import check_frame_shape, scan_light
from ..light import as_generator, electrons_per_readout, log_budget
from ..noise import PixelNoise, pixel_noise
from .clock import clock_chunks, clock_path
from .head import head_paths
from .interval import bright_path, event_path, event_pixels
from .lazy import LazyState, lazy_charge, lazy_path
from .window import window_path
from .codes import BRIGHT, CLOCK, EVENT, FULL, HEAD, LAZY, QUEUE, SIMULATION_PATHS
from .plan import path_levels
from .words import word_tables

#: Bounded events a pixel-readout can rely on (input saturation, clipping,
#: backlog, firing, window certification, ...); each gets 1/CHECKS of the budget.
CHECKS = 8

#: Spawn key of the generator that draws lazy pixels' charge when :attr:`SceneSimulator.acc`
#: is read (beyond any child index a caller spawns in practice).
PEEK_KEY = 0x7065656B

#: How :class:`SceneSimulator` draws electrons: the fast paths, or per pixel clock everywhere.
SIMULATION_METHODS = ("fast", "per-clock")


class SceneSimulator:
    """An H x W array of pixels lit by a scene, one readout interval at a time.

    Holds the carried accumulator (``carried``, int64, flat; lazy pixels' at
    their last sync, :attr:`acc` gives every pixel's), the lazy pixels' state
    (``lazy``, :class:`tespike.golden.fastsim.lazy.LazyState`), the ML msb counter
    remainder (``sfc``, int64, flat; 0 otherwise) and, for ``noise=False``, the
    carried charge fraction. ``method="per-clock"`` sends every pixel down
    the per-clock path (the full path the shortcuts are tested against).
    ``path_counts`` counts pixel-readouts per path (``lazy``: those the lazy path settled,
    pixels that crossed out of it into event light included).
    """

    def __init__(self, config: SensorConfig, shape: tuple[int, int], *, rng=None,
                 dark_current: str | None = None, noise: bool = True,
                 method: str = "fast", total_pixel_readouts: int | None = None,
                 sensor=None, pixels: PixelNoise | None = None):
        config = SensorConfig.required(config, "SceneSimulator")
        check_method(method)
        if total_pixel_readouts is not None and not is_count(total_pixel_readouts, 1):
            raise InputError(f"total_pixel_readouts {total_pixel_readouts!r}: must be a positive integer "
                             "(the pixel-readouts of the whole scene, which the error budget counts)")
        self.config = config
        self.shape = check_frame_shape(shape, "simulator shape")
        # sensor non-idealities as per-pixel rates (golden.noise): a Sensor, or its
        # PixelNoise for these pixels (a stripe's share of a frame's maps)
        self.pixels = pixels if pixels is not None else pixel_noise(dark_current, sensor, self.shape,
                                                                    noise=noise)
        self.dark_model = self.pixels.dark_model
        self.noise = noise
        self.method = method
        self.rng = as_generator(rng)
        n = self.shape[0] * self.shape[1]
        self.carried = np.zeros(n, np.int64)               # carried charge (lazy pixels: at their last sync)
        self.lazy = LazyState(n)
        self.sampler = None                                # PoissonSampler, made on first use
        self.sfc = np.zeros(n, np.int64)                   # msb: remainder left in the counter
        self.fraction = np.zeros(n)
        self.no_dark = np.zeros(n, np.int64)               # read only
        self.plan_length = np.zeros(n)                     # a readout's window and head lengths
        self.plan_b_max = np.zeros(n)                      # ... and queue backlog bounds (Plan)
        self.plan_lam = np.zeros(n)                        # a mostly lazy readout's rates per clock,
        self.plan_mean = np.zeros(n)                       # at its other pixels only (readout)
        # at most CHECKS bounded events per pixel-readout, each below the budget
        self.budget = log_budget(total_pixel_readouts or n, config.clocks_per_readout) - np.log(CHECKS)
        self.path_counts = dict.fromkeys(SIMULATION_PATHS + ("fallback",), 0)
        self.levels = path_levels(config, float(self.budget))
        self.tables = word_tables(config)
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
        far (:func:`tespike.golden.fastsim.lazy.lazy_charge`), from a generator made afresh for the read
        from the simulator's seed and the number of readouts done (:meth:`_peek_generator`).
        To set charges while pixels are lazy, assign the whole array (``sim.acc = values``)."""
        on = np.flatnonzero(self.lazy.mask)
        if not on.size:
            return self.carried
        acc = self.carried.copy()
        acc[on] += lazy_charge(self, on, self._peek_generator())
        acc.flags.writeable = False
        return acc

    @acc.setter
    def acc(self, values) -> None:
        """Set every pixel's carried charge (lazy pixels leave their path: their
        charge is now known, and what follows depends on it alone): integers in
        0 .. acc_max, one a pixel or one for all, refused in one line otherwise (2.7 had been
        truncated to 2, -5 simulated, booleans taken as 1 and 0)."""
        values = np.asarray(values)
        if values.dtype.kind not in "iu" or values.shape not in ((), self.carried.shape, self.shape):
            raise InputError(f"acc: must be integers, one a pixel ({self.carried.size}, or {self.shape}) or one "
                             f"for all, not {values.dtype} {values.shape}")
        if values.size and (int(values.min()) < 0 or int(values.max()) > self.config.acc_max):
            raise InputError(f"acc: charges must lie in 0 .. {self.config.acc_max} (acc_max), got "
                             f"{int(values.min())} .. {int(values.max())}")
        self.carried[:] = values.reshape(-1) if values.ndim else values
        self.lazy.mask[:] = False

    def _peek_generator(self) -> np.random.Generator:
        """A new generator for one read of :attr:`acc`: a child of the simulator's seed
        sequence keyed by :data:`PEEK_KEY` and :attr:`readouts`, made without spawning (the
        simulator's own stream and counter are untouched), so a read is a function of the
        seed and the readouts done. A seedless generator's reads take one fresh entropy,
        drawn at the simulator's making."""
        entropy, key, pool_size = self._peek_seed
        return np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=key + (self.readouts,),
                                                            pool_size=pool_size))

    def readout(self, light: np.ndarray, what: str = "light") -> np.ndarray:
        """Light of one interval (H, W) -> words (H, W) int64. The light is checked here (a
        float array of this shape, every value finite and >= 0; ``what`` names it in a
        refusal), so that a caller need not scan it first."""
        light = self._checked(light, what)
        L = self.config.clocks_per_readout
        expected = self.pixels.photo(electrons_per_readout(light).reshape(-1))
        self.readouts += 1
        dark = self.pixels.dark(expected.size, self.rng) if self.dark_model else self.no_dark
        words = np.zeros(expected.shape, np.int64)
        if not self.noise or self.method == "per-clock":
            clock_path(self, np.arange(expected.size), expected, dark, words)
            self.path_counts["clock"] += expected.size
            return words.reshape(self.shape)

        on_lazy = lazy_path(self, expected, dark, words)
        n_lazy = int(np.count_nonzero(on_lazy))
        if n_lazy == expected.size:                        # a dark frame: nothing else to do
            self.path_counts["lazy"] += n_lazy
            return words.reshape(self.shape)
        # photo-electrons per clock (lam) and with dark electrons (mean); where most pixels are
        # lazy, of the others alone (the paths read them there only): no pass over the frame
        pixels = np.flatnonzero(~on_lazy) if 2 * n_lazy > expected.size else None
        if pixels is None:
            lam = expected / L
            mean = lam + dark / L if self.dark_model else lam
        else:
            lam = self.plan_lam
            lam[pixels] = expected[pixels] / L
            mean = lam
            if self.dark_model:
                mean = self.plan_mean
                mean[pixels] = lam[pixels] + dark[pixels] / L
        plan = self.levels.classify(pixels, on_lazy, n_lazy, lam, mean, dark, self.carried, self.plan_length,
                                    self.plan_b_max)
        self.path_counts["lazy"] += n_lazy                 # (done by lazy_path)
        for code, name in enumerate(SIMULATION_PATHS):
            if code == LAZY:
                continue
            on_path = plan.path == code                    # (a comparison and a count per code:
            count = int(np.count_nonzero(on_path))         # a third of a bincount's time on int8)
            if not count:
                continue
            self.path_counts[name] += count
            if plan.pixels is not None:                    # planned on the non-lazy pixels alone
                sel = plan.pixels[on_path]
            else:
                sel = event_pixels(on_path, count) if code == EVENT else np.flatnonzero(on_path)
            if code == EVENT:
                event_path(self, sel, expected, dark, words)
            elif code == BRIGHT:
                bright_path(self, sel, expected, lam, dark, words)
            elif code in (QUEUE, FULL):
                window_path(self, code, sel, plan, expected, dark, lam, words)
            elif code == HEAD:
                head_paths(self, sel, plan.length, expected, lam, words)
            elif code == CLOCK:
                clock_path(self, sel, expected, dark, words)
        return words.reshape(self.shape)

    def clock_stimulus(self, light: np.ndarray, what: str = "light") -> np.ndarray:
        """Per-clock electrons ``(L, H, W)`` of one interval, drawn exactly as
        :meth:`readout` draws them with ``method="per-clock"`` (same random numbers
        in the same order), without running the pixels: the cycle-exact model on
        these electrons gives that readout's words. Smallest unsigned dtype."""
        from ..light import stimulus_dtype
        if self.noise and self.method != "per-clock":
            raise InputError("clock_stimulus needs method='per-clock' (or noise switched off)")
        light = self._checked(light, what)
        L = self.config.clocks_per_readout
        expected = self.pixels.photo(electrons_per_readout(light).reshape(-1))
        dark = self.pixels.dark(expected.size, self.rng) if self.dark_model else self.no_dark
        out = np.empty((L, expected.size), stimulus_dtype(self.config))
        for part, e in clock_chunks(self, np.arange(expected.size), expected, dark):
            out[:, part] = e
        return out.reshape((L,) + self.shape)

    def _checked(self, light, what: str) -> np.ndarray:
        """``light`` as an array, refused in one line unless it is one interval's float light
        of this simulator's shape with every value finite and >= 0 (SPEC section 6)."""
        light = np.asarray(light)
        if light.dtype.kind != "f" or light.shape != self.shape:
            raise InputError(f"{what}: a readout interval's light must be a float array of shape "
                             f"{self.shape} (got {light.dtype} of shape {light.shape})")
        scan_light(light, what)
        return light


def check_method(method) -> None:
    """Refuse a simulation method not in :data:`SIMULATION_METHODS`."""
    if method not in SIMULATION_METHODS:
        raise InputError(f"simulation method {method!r} unknown (known: {', '.join(SIMULATION_METHODS)})")
