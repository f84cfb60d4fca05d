"""Sensor non-idealities of the light front end: a noise description and one sensor's pixel maps.

SPEC section 6 makes photon shot noise the only default noise; everything here
is an option, off by default, and none of it is a :class:`SensorConfig` key (the
configuration describes the circuit the RTL builds; this describes the silicon
it was made on, docs/simulator.md "Sensor non-idealities"). The RTL is
unchanged: these effects only change the electrons it receives.

:class:`SensorNoise` describes a kind of sensor (JSON file form, :func:`load_noise`):

* ``dark_current``: the paper's eq. 12 or eq. 13 (:func:`tespike.golden.light.dark_electrons`),
  one draw per pixel and readout, times ``dark_level`` and the pixel's dark scale;
* ``dsnu``: dark-signal non-uniformity, the relative standard deviation of the
  per-pixel dark scale (log-normal, mean 1; EMVA 1288's DSNU over the mean dark signal);
* ``hot_pixels``, ``hot_factor``: the fraction of pixels whose dark scale is
  ``hot_factor`` times larger (hot pixels);
* ``prnu``: photo-response non-uniformity, the relative standard deviation of the
  per-pixel photo gain (log-normal, mean 1; EMVA 1288's PRNU);
* ``comparator_offset``: the standard deviation of each pixel's comparator
  threshold offset, relative to theta (normal, cut at 4 sigma). A pixel whose
  comparator fires at ``theta (1 + delta)`` fires like one that collects
  ``1 / (1 + delta)`` of the electrons, so the offset is modelled as that gain
  on every electron the pixel counts, photo and dark alike.

:class:`Sensor` is one physical sensor: a description and a **sensor seed**. Its
per-pixel maps (:meth:`Sensor.maps`) come from the sensor seed alone, each map
from its own child of it, so one sensor records many streams (each with its own
noise seed) under the same non-uniformity, and turning one option on never
changes another's map. The maps are applied upstream, as per-pixel rates: the
pixel's photo-electrons are ``Poisson(gain x 42000 I)`` and its dark electrons
``round(dark_scale x dark_level x x)`` with ``x`` the dark model's draw, so the
simulators downstream see only per-pixel means and dark counts, as before.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from pathlib import Path

import numpy as np

from .config import parse_json
from .errors import InputError, is_count, one_line
from .io import check_frame_shape
from .light import DARK_NORMAL, check_dark_current, dark_electrons, eq13_dark_per_readout

#: Bounds of each option (inclusive): name -> (lowest, highest).
NOISE_RANGES = {
    "dark_level": (0.0, 1e6),
    "dsnu": (0.0, 2.0),
    "hot_pixels": (0.0, 1.0),
    "hot_factor": (1.0, 1e6),
    "prnu": (0.0, 0.5),
    "comparator_offset": (0.0, 0.2),
}

#: Smallest non-zero value of each per-pixel map's option: below it the map cannot change a word (a
#: relative spread of 1e-6 moves a pixel's mean by under one electron in a million; a hot-pixel share
#: of 1e-9 draws none in the largest scene a command takes), so a smaller one would make --sensor-seed
#: and a second noise file look like another sensor while changing nothing.
MAP_SMALLEST = {"dsnu": 1e-6, "prnu": 1e-6, "comparator_offset": 1e-6, "hot_pixels": 1e-9}

#: Smallest ``dark_level`` under a dark model, and smallest ``hot_factor - 1`` with hot pixels, for the
#: same reason: a dark pixel's electrons are rounded per readout, and 1e-12 x the models' 400-535 e- x
#: the largest hot factor (1e6) is under 0.001, so no pixel gets one; a hot factor within 1e-6 of 1
#: changes a hot pixel's dark scale as little as the maps' smallest spreads do.
DARK_LEVEL_SMALLEST = 1e-12
HOT_FACTOR_SMALLEST_EXCESS = 1e-6

#: A hot pixel's dark scale factor unless the noise description gives one (it needs hot_pixels > 0).
HOT_FACTOR = 20.0

#: The comparator offset's normal law is cut at this many standard deviations,
#: so ``1 + delta`` stays at least 1 - 4 x 0.2 = 0.2 > 0.
OFFSET_CUT = 4.0

#: Order of the sensor seed's children: one per map.
MAP_STREAMS = ("dsnu", "hot_pixels", "prnu", "comparator_offset")


@dataclasses.dataclass(frozen=True)
class SensorNoise:
    """A kind of sensor's non-idealities (all off by default: shot noise only)."""

    dark_current: str | None = None     # None / "none", "eq12", "eq13"
    dark_level: float = 1.0             # x the dark model's electrons
    dsnu: float = 0.0                   # relative std of the per-pixel dark scale
    hot_pixels: float = 0.0             # fraction of hot pixels
    hot_factor: float = HOT_FACTOR      # a hot pixel's dark scale factor
    prnu: float = 0.0                   # relative std of the per-pixel photo gain
    comparator_offset: float = 0.0      # std of the threshold offset, / theta

    def __post_init__(self):
        object.__setattr__(self, "dark_current", check_dark_current(self.dark_current))
        for key, (low, high) in NOISE_RANGES.items():
            value = getattr(self, key)
            # (an int of any size is finite: math.isfinite would overflow on one past float's range)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not (isinstance(value, int) or math.isfinite(value)):
                raise InputError(f"sensor noise {key} = {one_line(repr(value), 40)}: must be a finite number")
            if not low <= value <= high:
                raise InputError(f"sensor noise {key} = {one_line(repr(value), 40)}: must be in [{low:g}, {high:g}]")
            if 0 < value < MAP_SMALLEST.get(key, 0.0):
                raise InputError(f"sensor noise {key} = {one_line(repr(value), 40)}: must be 0 or at least "
                                 f"{MAP_SMALLEST[key]:g} (a smaller one changes no pixel)")
            object.__setattr__(self, key, float(value))
        if self.dark_current is not None and self.dark_level < DARK_LEVEL_SMALLEST:
            raise InputError(f"sensor noise: dark_level {self.dark_level:g} makes dark_current {self.dark_current!r} "
                             f"draw nothing (give at least {DARK_LEVEL_SMALLEST:g}, or leave the dark current out "
                             "for none)")
        if self.hot_pixels and self.hot_factor < 1.0 + HOT_FACTOR_SMALLEST_EXCESS:
            raise InputError(f"sensor noise: hot_factor {self.hot_factor!r} makes the hot pixels like the others "
                             f"(give a factor of at least 1 + {HOT_FACTOR_SMALLEST_EXCESS:g}, or no hot_pixels)")
        if self.dark_current is None and (self.dsnu or self.hot_pixels or self.dark_level != 1.0):
            raise InputError("sensor noise: dark_level, dsnu and hot_pixels shape the dark current; "
                             "they need dark_current 'eq12' or 'eq13'")

    @property
    def has_maps(self) -> bool:
        """Whether any per-pixel map differs from 1 (else the sensor seed does not matter)."""
        return bool(self.dsnu or self.hot_pixels or self.prnu or self.comparator_offset)

    @property
    def is_ideal(self) -> bool:
        """Shot noise only: SPEC section 6's default."""
        return self.dark_current is None and not self.has_maps

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["dark_current"] = self.dark_current or "none"
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, values: dict, what: str = "sensor noise") -> "SensorNoise":
        """From a JSON object; an unknown key is refused by name."""
        if not isinstance(values, dict):
            raise InputError(f"{what} must be a JSON object, not {type(values).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(f"{what}: unknown key {unknown[0]!r} (known: {', '.join(sorted(known))})")
        null = [key for key, value in values.items() if value is None]
        if null:               # JSON null is not "use the default", as in a configuration
            raise InputError(f"{what}: {null[0]} = null: give its value or leave the key out")
        dark = values.get("dark_current", None)
        if dark is not None and not isinstance(dark, str):
            raise InputError(f"{what}: dark_current = {dark!r} must be 'none', 'eq12' or 'eq13'")
        try:
            return cls(**values)
        except InputError as exc:                  # a value's own check: say which file holds it
            if what == "sensor noise":
                raise
            raise InputError(f"{what}: {str(exc).removeprefix('sensor noise ')}") from None


def load_noise(path: str | Path) -> SensorNoise:
    """``N.json`` -> :class:`SensorNoise`, or one line naming the file and the problem."""
    from .paths import check_input_file
    check_input_file(path, "sensor noise")
    what = f"sensor noise file {str(path)!r}"
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{what} is not readable JSON: {exc}") from None
    values = parse_json(text, what, InputError)
    noise = SensorNoise.from_dict(values, what)
    if noise.hot_factor != HOT_FACTOR and not noise.hot_pixels:     # (to_json writes the default always)
        raise InputError(f"{what}: hot_factor = {noise.hot_factor:g} scales the hot pixels' dark current; it "
                         "needs hot_pixels > 0 (without them it would be ignored)")
    return noise


@dataclasses.dataclass(frozen=True)
class SensorMaps:
    """One sensor's per-pixel maps over an H x W frame (float64): the photo gain
    (PRNU x comparator offset) and the dark scale (DSNU x hot pixels x comparator offset)."""

    gain: np.ndarray
    dark_scale: np.ndarray

    def mean_dark_electrons(self, noise: SensorNoise) -> np.ndarray:
        """Expected dark electrons per readout of every pixel (before rounding)."""
        if not isinstance(noise, SensorNoise):           # (a model's name had been an AttributeError)
            raise InputError(f"mean_dark_electrons: noise must be a SensorNoise, not {type(noise).__name__}")
        return self.dark_scale * noise.dark_level * model_mean(noise.dark_current)


@dataclasses.dataclass(frozen=True)
class Sensor:
    """One physical sensor: its kind (:class:`SensorNoise`) and its sensor seed."""

    noise: SensorNoise = SensorNoise()
    seed: int = 0

    def __post_init__(self):
        if not isinstance(self.noise, SensorNoise):
            raise InputError(f"sensor noise {self.noise!r}: must be a SensorNoise (e.g. "
                             f"SensorNoise(dark_current='eq12') or load_noise(path)), not {type(self.noise).__name__}")
        if not is_count(self.seed):
            raise InputError(f"sensor seed {self.seed!r}: must be an integer >= 0")

    def maps(self, shape: tuple[int, int]) -> SensorMaps:
        """The per-pixel maps of an H x W frame, a function of the sensor seed and the shape."""
        H, W = check_frame_shape(shape, "sensor frame shape")
        children = np.random.SeedSequence(int(self.seed)).spawn(len(MAP_STREAMS))
        rng = {name: np.random.default_rng(child) for name, child in zip(MAP_STREAMS, children)}
        n = self.noise
        dark_scale = _lognormal(rng["dsnu"], n.dsnu, (H, W))
        if n.hot_pixels:
            dark_scale = np.where(rng["hot_pixels"].random((H, W)) < n.hot_pixels,
                                  dark_scale * n.hot_factor, dark_scale)
        gain = _lognormal(rng["prnu"], n.prnu, (H, W))
        if n.comparator_offset:
            z = rng["comparator_offset"].standard_normal((H, W))
            offset_gain = 1.0 / (1.0 + n.comparator_offset * np.clip(z, -OFFSET_CUT, OFFSET_CUT))
            gain, dark_scale = gain * offset_gain, dark_scale * offset_gain
        return SensorMaps(gain, dark_scale)

    def pixels(self, shape: tuple[int, int]) -> "PixelNoise":
        """The noise of every pixel of an H x W frame (flat, raster order)."""
        shape = check_frame_shape(shape, "sensor frame shape")
        if not self.noise.has_maps:
            return PixelNoise(self.noise, None, None)
        maps = self.maps(shape)
        return PixelNoise(self.noise, maps.gain.reshape(-1), maps.dark_scale.reshape(-1))


def _lognormal(rng: np.random.Generator, relative_std: float, shape) -> np.ndarray:
    """Log-normal values of mean 1 and relative standard deviation ``relative_std`` (ones if 0)."""
    if not relative_std:
        return np.ones(shape)
    sigma2 = math.log1p(relative_std ** 2)
    return np.exp(rng.standard_normal(shape) * math.sqrt(sigma2) - 0.5 * sigma2)


@dataclasses.dataclass(frozen=True)
class PixelNoise:
    """The noise of a set of pixels as the simulators use it: the description and
    the pixels' flat gain and dark scale (``None``: all 1)."""

    noise: SensorNoise
    gain: np.ndarray | None
    dark_scale: np.ndarray | None

    @property
    def dark_model(self) -> str | None:
        return self.noise.dark_current

    def photo(self, expected: np.ndarray) -> np.ndarray:
        """Expected photo-electrons per readout of the nominal pixel -> of these pixels."""
        return expected if self.gain is None else expected * self.gain

    def dark(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Dark electrons of one readout interval of the ``n`` pixels (int64)."""
        if not is_count(n):                              # (-1 had been numpy's error, 2.5 a TypeError)
            raise InputError(f"dark electrons of {n!r} pixels: must be an integer >= 0")
        if self.dark_scale is not None and n != self.dark_scale.size:
            raise InputError(f"dark electrons of {n} pixels: these maps hold {self.dark_scale.size}")
        scale = self.dark_scale
        if self.noise.dark_level != 1.0:
            scale = (np.ones(n) if scale is None else scale) * self.noise.dark_level
        return dark_electrons(self.dark_model, (n,), rng, scale=scale)

    def rows(self, rows: slice, width: int) -> "PixelNoise":
        """The pixels of rows ``rows`` (a slice, any step) of a frame ``width`` pixels wide."""
        if not isinstance(rows, slice):
            raise InputError(f"rows {rows!r}: must be a slice of the frame's rows")
        if self.gain is None:
            return self
        if not (is_count(width, 1) and self.gain.size % width == 0):   # (a reshape error)
            raise InputError(f"width {width!r}: must be an integer >= 1 dividing the {self.gain.size} pixels")
        return PixelNoise(self.noise, self.gain.reshape(-1, width)[rows].reshape(-1),
                          self.dark_scale.reshape(-1, width)[rows].reshape(-1))


def check_noise_switch(noise) -> bool:
    """``noise`` where it is True or False (a string such as ``"no"`` had been taken as True)."""
    if not isinstance(noise, (bool, np.bool_)):
        raise InputError(f"noise {noise!r}: must be True or False (False: electrons delivered "
                         "deterministically)")
    return bool(noise)


def pixel_noise(dark_current: str | None, sensor: Sensor | None, shape: tuple[int, int], *,
                noise: bool = True) -> PixelNoise:
    """The :class:`PixelNoise` of an H x W frame from either the ``dark_current`` keyword (the
    shorthand of a sensor of that dark current and no maps, as ``--dark-current`` is of a noise
    file holding only ``dark_current``) or a :class:`Sensor`, not both; with ``noise`` False
    (electrons delivered deterministically) a random dark current is refused. The library's
    check of the light front end's options (the fast simulator and
    :func:`tespike.golden.stimulus.poisson_stimulus` alike); the command checks the same rules
    first, before reading a scene, in its flags' words (``cosim.commands.common.light_front_end``)."""
    noise = check_noise_switch(noise)
    if sensor is not None and check_dark_current(dark_current) is not None:
        raise InputError("give the dark current either alone or inside the sensor noise, not both")
    if sensor is None:
        sensor = Sensor(SensorNoise(dark_current=dark_current))
    if not isinstance(sensor, Sensor):
        raise InputError(f"sensor must be a golden.noise.Sensor, not {type(sensor).__name__}")
    pixels = sensor.pixels(shape)
    if not noise and pixels.dark_model is not None:
        raise InputError(f"dark current {pixels.dark_model!r} is random; "
                         "it cannot be combined with noise switched off")
    return pixels


def model_mean(model: str | None) -> float:
    """Mean dark electrons per readout of a dark model before rounding: eq. 12's normal mean;
    for eq. 13 the mean of :func:`~tespike.golden.light.eq13_dark_per_readout` over its normal
    interval draw (midpoint rule on 2 x 10^6 points over 12 standard deviations)."""
    if not (model is None or isinstance(model, str)):  # (a list: the cache's "unhashable type")
        raise InputError(f"dark current model {model!r}: must be a name (none, eq12, eq13) or None")
    return _model_mean(check_dark_current(model))


@functools.lru_cache(maxsize=None)
def _model_mean(model: str | None) -> float:
    if model is None:
        return 0.0
    mean, sd = DARK_NORMAL[model]
    if model == "eq12":
        return mean
    x = np.linspace(mean - 12 * sd, mean + 12 * sd, 2_000_001)
    mid, dx = 0.5 * (x[1:] + x[:-1]), x[1] - x[0]
    density = np.exp(-0.5 * ((mid - mean) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
    return float((eq13_dark_per_readout(mid) * density).sum() * dx)
