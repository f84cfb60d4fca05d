"""One training clip: a light sequence from a named family, its peak and length drawn, and its stream.

A clip is a pure function of (recipe, sensor configuration, index): the same
triple always gives the same light and the same words, and two indices never
share a random number (``np.random.SeedSequence([domain, seed, index])``). The
light is simulated by golden's fast simulator with fresh shot noise, so the
network sees a new noise draw with every clip.

Families (:data:`FAMILIES`), each a documented generator:

- ``deadleaves``: :func:`tespike.recon.engine.deadleaves.dead_leaves`, procedural HDR
  video built for generalisation (occlusion, power-law sizes, log-uniform
  radiance over up to six decades, textures, soft and sharp edges, object and
  camera motion, small bright and flickering sources);
- ``panorama``: a camera path (pan, tilt, rotate, zoom or all) over one of the
  training panoramas (the four shipped ones, never the held-out ``courtyard``,
  and any equirectangular .exr/.hdr files the recipe names, e.g. a folder given
  to ``tespike train --panoramas``), with 0..2 moving bright sources;
- ``folder``: a random window and time span of a user folder of .exr/.hdr
  frames (``recipe.folders``), played forwards or backwards.

Brightness: the clip's peak (its brightest pixel over all readouts) is drawn
log-uniformly in ``recipe.peak`` (0.01 .. 3 x the design light by default);
the network sees light in scene units, as at inference. Length: with
probability ``recipe.short_fraction`` the stream is short (log-uniform in
``recipe.short``, down to one readout), else uniform in ``recipe.long``;
key moments are drawn anywhere in it by :mod:`tespike.recon.engine.batches`.

Sensor noise (``recipe.noise_fraction``, 0 by default: shot noise only, the
clips of every recipe before it): that share of clips is recorded by a sensor
drawn at random over :data:`NOISE_DRAW` (:func:`draw_sensor`: the paper's eq. 12
or eq. 13 dark current at 0.05 .. 6 x its level, log-uniform, so from almost
none to beyond eq. 13; DSNU, hot pixels, PRNU and comparator offset uniform up
to their bounds; its own sensor seed). Such a clip carries its sensor's exact
mean dark rate and gain (:func:`sensor_maps`), and the batches correct its decoded
light with them, ``(x - dark) / gain`` (``noisy_input`` ``mean``, the default and
every shipped file's training); with ``noisy_input`` ``law`` it also carries the
dark law of a dark stream of :data:`~tespike.recon.calibration.CALIBRATION_READOUTS` readouts
(as many as the held-out benchmarks' calibrations take) that the sensor
records (:func:`sensor_calibration`), and the batches give the method exactly the
input inference gives it under such a calibration
(:func:`tespike.recon.learning.infer.law_input`: less the law's upper tail). Its
target is the scene light ``I``. Correcting the input rather than the output was
measured better for every learned method (docs/reconstruction.md "Calibration").
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count, is_positive_number
from tespike.golden.fastsim import simulate_scene

from ..calibration import CALIBRATION_READOUTS
from .deadleaves import DeadLeavesParams, dead_leaves

#: The panorama kept out of training: validation uses it.
HELDOUT_PANORAMA = "courtyard"
TRAIN_PANORAMAS = ("city", "forest", "studio", "sunset")
#: Files a user's panorama folder contributes (``tespike train --panoramas DIR``).
PANORAMA_SUFFIXES = (".exr", ".hdr")
FAMILIES = ("deadleaves", "panorama", "folder")
#: Seed domains: training clips and validation clips never share a seed.
TRAIN_DOMAIN, VALIDATION_DOMAIN = 17, 23
#: What a noisy clip's method sees (``EngineRecipe.noisy_input``): ``mean``, its decoded light
#: corrected by its sensor's exact mean dark rate and gain (every shipped file's training);
#: ``law``, also less the dark law's upper tail, exactly as inference reads a stream under a
#: calibration with a law (:func:`sensor_calibration`; measured: docs/fair-training.md).
NOISY_INPUTS = ("mean", "law")
#: The range noisy clips' sensors are drawn over (:func:`draw_sensor`): dark level x the
#: model's, log-uniform; the others uniform in [0, high] (golden.noise.SensorNoise fields).
NOISE_DRAW = {"dark_current": ("eq12", "eq13"), "dark_level": (0.05, 6.0), "dsnu": (0.0, 0.5),
              "hot_pixels": (0.0, 0.02), "hot_factor": (5.0, 50.0), "prnu": (0.0, 0.05),
              "comparator_offset": (0.0, 0.05)}


#: The clips' peaks (x the design light) the engine takes: far below, the light of float32 clips
#: loses its precision and then is 0 (all-black clips, trained on with exit 0); far above, the
#: network's float32 activations overflow (a run "diverged", blaming the learning rate). A
#: millionth of the design light is 0.04 electrons a readout, a million times saturates any sensor.
PEAK_LIMITS = (1e-6, 1e6)


def check_peak_range(peak, name: str) -> None:
    """A clips' peak range ``(low, high)`` (x the design light), refused in one line
    naming ``name`` unless ``low <= high``, both within :data:`PEAK_LIMITS` (the recipe and ``--peak``)."""
    low, high = peak
    if not (is_positive_number(low) and is_positive_number(high) and PEAK_LIMITS[0] <= low <= high <= PEAK_LIMITS[1]):
        raise InputError(f"{name}: need {PEAK_LIMITS[0]:g} <= low <= high <= {PEAK_LIMITS[1]:g} "
                         "(x the design light)")


@dataclasses.dataclass(frozen=True)
class EngineRecipe:
    """What the training clips are made of (every field is recorded with the weights)."""

    weights: tuple[tuple[str, float], ...] = (("deadleaves", 0.6), ("panorama", 0.4))
    height: int = 128
    width: int = 128
    long: tuple[int, int] = (48, 112)        # readouts of a long stream (uniform)
    short: tuple[int, int] = (1, 47)         # readouts of a short stream (log-uniform)
    short_fraction: float = 0.3
    peak: tuple[float, float] = (0.01, 3.0)  # x the design light, log-uniform
    panoramas: tuple[str, ...] = TRAIN_PANORAMAS   # names of shipped ones and/or .exr/.hdr paths
    folders: tuple[str, ...] = ()            # user .exr/.hdr frame folders (family "folder")
    folder_weight: float = 0.25              # share of folder clips when folders are given
    seed: int = 0
    noise_fraction: float = 0.0              # share of clips from a random noisy sensor (NOISE_DRAW)
    noisy_input: str = "mean"                # what a noisy clip's method sees: NOISY_INPUTS

    def __post_init__(self) -> None:
        self._check_kinds()
        object.__setattr__(self, "weights", tuple((n, float(w)) for n, w in self.weights))
        object.__setattr__(self, "panoramas", tuple(p if p in TRAIN_PANORAMAS or p == HELDOUT_PANORAMA
                                                    else str(Path(p).resolve()) for p in self.panoramas))
        object.__setattr__(self, "folders", tuple(str(Path(f).resolve()) for f in self.folders))
        for folder in self.folders:                      # (a missing one had failed at the first folder clip)
            if not Path(folder).is_dir():
                raise InputError(f"engine recipe: folder {folder!r} does not exist or is not a folder")
        for name, weight in self.weights:
            if name not in FAMILIES or name == "folder":
                raise InputError(f"engine family {name!r} unknown (known: deadleaves, panorama; "
                                 "folders are given as folders)")
            if not weight >= 0:
                raise InputError(f"engine family {name!r} weight {weight!r}: must be >= 0")
        for source in self.panoramas:
            if source == HELDOUT_PANORAMA or (source not in TRAIN_PANORAMAS
                                              and Path(source).stem.lower() == HELDOUT_PANORAMA):
                raise InputError(f"engine recipe: panorama {source!r} is held out for validation")
            if source not in TRAIN_PANORAMAS and not (Path(source).suffix.lower() in PANORAMA_SUFFIXES
                                                       and Path(source).is_file()):
                raise InputError(f"engine recipe: panorama {source!r} is neither one of "
                                 f"{', '.join(TRAIN_PANORAMAS)} nor an .exr/.hdr file")
        for key in ("height", "width"):
            if type(getattr(self, key)) is not int or getattr(self, key) < 8:
                raise InputError(f"engine recipe {key} = {getattr(self, key)!r}: must be an integer >= 8")
        from ..scenes.hdr_io import frame_size
        for source in self.panoramas:               # (a file: its header's size; a shipped one is 128 x 256)
            if source not in TRAIN_PANORAMAS:
                h, w = frame_size(source)
                if h < self.height or w < self.width:   # (its windows would repeat its edge rows)
                    raise InputError(f"panorama {source!r} is {h} x {w}, smaller than the engine's "
                                     f"{self.height} x {self.width} window")
        for key in ("long", "short"):
            lo, hi = getattr(self, key)
            if not (type(lo) is int and type(hi) is int and 1 <= lo <= hi):
                raise InputError(f"engine recipe {key} = {(lo, hi)!r}: need integers 1 <= low <= high")
        check_peak_range(self.peak, f"engine recipe peak = {self.peak!r}")
        if not 0 <= self.short_fraction <= 1 or not 0 <= self.folder_weight <= 1 \
                or not 0 <= self.noise_fraction <= 1:
            raise InputError("engine recipe short_fraction, folder_weight and noise_fraction must lie in [0, 1]")
        if self.noisy_input not in NOISY_INPUTS:
            raise InputError(f"engine recipe noisy_input = {self.noisy_input!r}: must be one of "
                             f"{', '.join(NOISY_INPUTS)}")
        if sum(w for _, w in self.weights) <= 0 and not self.folders:
            raise InputError("engine recipe: every family weight is 0 and no folder is given")

    def _check_kinds(self) -> None:
        """Each field of the kind it must hold, refused in one line before any is used: a weight given as
        text had been converted ('0.6') or an infinity taken (NaN probabilities at the first clip), a seed
        of -1 or 2.5 failed in the first clip, a panorama list given as one name read letter by letter."""
        def pair(value) -> bool:
            return isinstance(value, (tuple, list)) and len(value) == 2

        def number(value) -> bool:
            return value == 0 or is_positive_number(value)

        if not (isinstance(self.weights, (tuple, list)) and all(
                pair(w) and isinstance(w[0], str) and number(w[1]) for w in self.weights)):
            raise InputError(f"engine recipe weights {self.weights!r}: must be (family, weight) pairs, each "
                             "weight a finite number >= 0")
        names = [w[0] for w in self.weights]
        if len(set(names)) != len(names):
            raise InputError(f"engine recipe weights: a family is named twice ({', '.join(names)})")
        for key in ("panoramas", "folders"):
            value = getattr(self, key)
            if not (isinstance(value, (tuple, list)) and all(isinstance(v, (str, os.PathLike)) for v in value)):
                raise InputError(f"engine recipe {key} {value!r}: must be a sequence of names or paths")
        for key in ("long", "short", "peak"):
            if not pair(getattr(self, key)):
                raise InputError(f"engine recipe {key} = {getattr(self, key)!r}: must be a (low, high) pair")
        for key in ("short_fraction", "folder_weight", "noise_fraction"):
            if not number(getattr(self, key)):
                raise InputError(f"engine recipe {key} = {getattr(self, key)!r}: must be a number in [0, 1]")
        if not is_count(self.seed):
            raise InputError(f"engine recipe seed = {self.seed!r}: must be an integer >= 0")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "EngineRecipe":
        if not isinstance(data, dict):                   # (None had been a TypeError)
            raise InputError(f"engine recipe: must be a dict of its fields, not {type(data).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputError(f"unknown engine recipe key {unknown[0]!r}")
        fields = dict(data)
        for key in ("long", "short", "peak"):
            if key in fields and isinstance(fields[key], list):
                fields[key] = tuple(fields[key])
        if "weights" in fields and isinstance(fields["weights"], list):
            fields["weights"] = tuple(tuple(w) if isinstance(w, list) else w for w in fields["weights"])
        return cls(**fields)

    def family_table(self) -> tuple[tuple[str, ...], np.ndarray]:
        names = [n for n, _ in self.weights]
        weights = np.array([w for _, w in self.weights], np.float64)
        if weights.sum() > 0:
            weights = weights / weights.sum()
        if self.folders:
            share = self.folder_weight if weights.sum() > 0 else 1.0
            weights = np.append(weights * (1 - share), share)
            names.append("folder")
        return tuple(names), weights


@dataclasses.dataclass(frozen=True)
class Clip:
    """A stream and its ground truth: light float32 (K, H, W) and words (K, H, W)."""

    light: np.ndarray
    words: np.ndarray
    family: str
    index: int
    sensor: object = None        # the golden.noise.Sensor of a noisy clip (None: shot noise only)
    dark: np.ndarray | None = None    # float32 (H, W): its pixels' mean dark rate, scene units (noisy clips)
    gain: np.ndarray | None = None    # float32 (H, W): its pixels' gain (noisy clips)
    #: a noisy clip's :class:`tespike.recon.calibration.Calibration` (:func:`sensor_calibration`): these
    #: maps and the dark law of its sensor's dark stream, as inference reads a calibrated stream
    calibration: object = None


def clip_rng(recipe: EngineRecipe, index: int, domain: int = TRAIN_DOMAIN) -> np.random.Generator:
    """The generator of clip ``index`` of ``recipe`` in ``domain`` (training or validation), refused in
    one line for a recipe that is none, an index that is no count (-1 had been numpy's "expected
    non-negative integer", 2.5 a TypeError, '0' and True taken) or a domain that is neither."""
    if not isinstance(recipe, EngineRecipe):
        raise InputError(f"recipe: must be an EngineRecipe, not {type(recipe).__name__}")
    if not is_count(index):
        raise InputError(f"clip index {index!r}: must be an integer >= 0")
    if domain not in (TRAIN_DOMAIN, VALIDATION_DOMAIN) or isinstance(domain, bool):
        raise InputError(f"clip domain {domain!r}: must be TRAIN_DOMAIN ({TRAIN_DOMAIN}) or VALIDATION_DOMAIN "
                         f"({VALIDATION_DOMAIN})")
    return np.random.default_rng(np.random.SeedSequence([domain, recipe.seed, index]))


def draw_length(rng: np.random.Generator, recipe: EngineRecipe) -> int:
    if rng.uniform() < recipe.short_fraction:
        lo, hi = recipe.short
        return int(min(hi, math.floor(math.exp(rng.uniform(math.log(lo), math.log(hi + 1))))))
    return int(rng.integers(recipe.long[0], recipe.long[1] + 1))


def panorama_light(rng: np.random.Generator, frames: int, height: int, width: int,
                   sources: tuple[str, ...]) -> np.ndarray:
    """A camera path over one of ``sources`` with 0..2 moving bright sources (unnormalised)."""
    from ..scenes.panorama import MOTIONS, panorama_sequence
    source = sources[int(rng.integers(len(sources)))]
    motion = MOTIONS[int(rng.integers(len(MOTIONS)))]
    return panorama_sequence(rng, frames, height, width, source=source, motion=motion,
                             sources=int(rng.integers(0, 3)))


def folder_light(rng: np.random.Generator, folder: str, frames: int, height: int, width: int) -> np.ndarray:
    """A random window and time span of a folder of HDR frames (repeated to length if short)."""
    from ..scenes.hdr_io import load_hdr_sequence
    light = load_hdr_sequence(folder)
    k, h, w = light.shape
    if h < height or w < width:
        raise InputError(f"training folder {folder!r} frames are {h} x {w}, smaller than the "
                         f"engine's {height} x {width}")
    y, x = int(rng.integers(h - height + 1)), int(rng.integers(w - width + 1))
    start = int(rng.integers(k))
    order = np.arange(start, start + frames) % k
    if rng.uniform() < 0.5:
        order = order[::-1]
    return np.asarray(light[order, y:y + height, x:x + width], np.float64)


def clip_light(recipe: EngineRecipe, index: int, *, domain: int = TRAIN_DOMAIN,
               deadleaves: DeadLeavesParams = DeadLeavesParams()) -> tuple[np.ndarray, str, np.random.Generator]:
    """(light float64 (K, H, W) with its drawn peak, family, the clip's generator for the noise)."""
    rng = clip_rng(recipe, index, domain)
    names, weights = recipe.family_table()
    family = names[int(rng.choice(len(names), p=weights))]
    frames = draw_length(rng, recipe)
    h, w = recipe.height, recipe.width
    if family == "deadleaves":
        light = dead_leaves(rng, frames, h, w, deadleaves)
    elif family == "panorama":
        light = panorama_light(rng, frames, h, w, recipe.panoramas)
    else:
        light = folder_light(rng, recipe.folders[int(rng.integers(len(recipe.folders)))], frames, h, w)
    peak = math.exp(rng.uniform(math.log(recipe.peak[0]), math.log(recipe.peak[1])))
    top = float(light.max())
    if not top > 0:
        light = np.full_like(light, peak)      # a black folder frame: flat light at the peak
    else:
        light = light * (peak / top)
    if rng.uniform() < 0.5:                    # mirror: no left/right bias from the sources
        light = light[:, :, ::-1]
    return np.ascontiguousarray(light), family, rng


def draw_sensor(rng: np.random.Generator):
    """A random noisy sensor over :data:`NOISE_DRAW` (a :class:`tespike.golden.noise.Sensor`, its own seed)."""
    from tespike.golden.noise import MAP_SMALLEST, Sensor, SensorNoise
    d = NOISE_DRAW
    low, high = d["dark_level"]
    dark_current = d["dark_current"][int(rng.integers(len(d["dark_current"])))]       # (the draws' order kept)
    dark_level = math.exp(rng.uniform(math.log(low), math.log(high)))
    drawn = {key: float(rng.uniform(*d[key])) for key in ("dsnu", "hot_pixels", "hot_factor", "prnu", "comparator_offset")}
    # a value below a map's smallest changes no pixel (and is refused): it is that map's 0 (each map
    # draws from its own stream, so the others are unchanged)
    drawn = {key: 0.0 if value < MAP_SMALLEST.get(key, 0.0) else value for key, value in drawn.items()}
    noise = SensorNoise(dark_current=dark_current, dark_level=dark_level, **drawn)
    return Sensor(noise, int(rng.integers(1 << 62)))


def sensor_maps(sensor, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's exact calibration for frames of ``shape``: (mean dark rate in scene units per
    readout, gain), float32 (H, W); a pixel measures ``gain x I + dark`` on average."""
    from tespike.golden.config import DESIGN_ELECTRONS
    maps = sensor.maps(shape)
    dark = maps.mean_dark_electrons(sensor.noise) / DESIGN_ELECTRONS
    return (np.broadcast_to(dark, shape).astype(np.float32), np.broadcast_to(maps.gain, shape).astype(np.float32))


def sensor_calibration(sensor, config: SensorConfig, shape: tuple[int, int], seed,
                       dark_readouts: int = CALIBRATION_READOUTS):
    """A sensor's calibration as the learned methods read it: the exact per-pixel mean dark rate and
    gain (:func:`sensor_maps`, estimator ``exact``) and the dark law of a dark stream of
    ``dark_readouts`` readouts that the sensor records (``seed``: its shot and dark noise), as
    ``tespike calibrate`` keeps it (:func:`tespike.recon.calibration.estimate_dark_law`): the law
    inference corrects a learned method's input with (:func:`tespike.recon.learning.infer.law_input`)."""
    from ..calibration import Calibration, estimate_dark_law
    dark, gain = sensor_maps(sensor, shape)
    dark_words = simulate_scene(config, np.zeros((dark_readouts, *shape)), seed=seed, workers=1, sensor=sensor)
    law, tail = estimate_dark_law(dark_words, config)
    return Calibration(dark.astype(np.float64), gain.astype(np.float64), config, dark_readouts, 0, 0.0,
                       estimator="exact", dark_law=law, dark_tail=tail)


def make_clip(recipe: EngineRecipe, config: SensorConfig, index: int, *, domain: int = TRAIN_DOMAIN,
              deadleaves: DeadLeavesParams = DeadLeavesParams()) -> Clip:
    """Clip ``index`` of the recipe for ``config``: target light (float32) and its simulated words.

    With ``recipe.noise_fraction`` > 0 that share of clips is recorded by a random sensor
    (:func:`draw_sensor`) and carries its exact mean maps (:func:`sensor_maps`) and, with
    ``recipe.noisy_input`` ``law``, its calibration with a dark law (:func:`sensor_calibration`); no
    random number is drawn for it otherwise, so recipes without noise give the clips they always gave."""
    light, family, rng = clip_light(recipe, index, domain=domain, deadleaves=deadleaves)
    sensor = None
    if recipe.noise_fraction > 0 and rng.uniform() < recipe.noise_fraction:
        sensor = draw_sensor(rng)
    words = simulate_scene(config, light, seed=rng, workers=1, sensor=sensor)
    if sensor is None:
        return Clip(light.astype(np.float32), words, family, index)
    if recipe.noisy_input == "mean":          # no random number drawn: the clips every mean recipe gave
        dark, gain = sensor_maps(sensor, light.shape[1:])
        return Clip(light.astype(np.float32), words, family, index, sensor, dark, gain)
    calibration = sensor_calibration(sensor, config, light.shape[1:], rng)
    return Clip(light.astype(np.float32), words, family, index, sensor, calibration.dark.astype(np.float32),
                calibration.gain.astype(np.float32), calibration)


def panorama_files(folder: str | Path) -> tuple[str, ...]:
    """Every equirectangular .exr/.hdr file of ``folder`` (sorted, absolute), refused in one line
    when the folder is missing or holds none (``tespike train --panoramas``)."""
    path = Path(folder)
    if not path.is_dir():
        raise InputError(f"--panoramas {str(folder)!r}: not a folder")
    files = tuple(sorted(str(f.resolve()) for f in path.iterdir()
                         if f.suffix.lower() in PANORAMA_SUFFIXES and f.is_file()
                         and f.stem.lower() != HELDOUT_PANORAMA))
    if not files:
        raise InputError(f"--panoramas {str(folder)!r}: holds no .exr/.hdr panorama "
                         f"(other than the held-out {HELDOUT_PANORAMA!r})")
    return files
