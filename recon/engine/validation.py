"""The held-out validation set: domains training never sees, scored while a network trains.

Every case is made from the validation seed domain (never a training seed):

- camera paths over the held-out panorama (``courtyard``): a long pan at the
  design light, a mixed path at 0.3 of it, a zoom at 0.03 (dim), and a short
  pan of 32 readouts;
- dead leaves with held-out generator parameters (steeper size law, fewer and
  harder-edged objects, five to six decades): a long clip and a short one of
  16 readouts, twice the design light;
- a long pan of the same kind and a long held-out dead-leaves clip (their own
  validation seeds, so other paths and objects) recorded by a noisy sensor
  (:data:`VALIDATION_SENSORS`: eq. 12 and eq. 13 dark current with DSNU, hot
  pixels, PRNU and comparator offset, validation sensor seeds) and read through
  its calibration (exact maps, the dark law of a dark stream it records), as the
  engine's noisy clips are and as inference reads a calibrated stream: so
  selection sees what a noisy sensor costs.

:data:`EXTENDED_CASES` add six noisy cases for benchmarks only (dim light under strong
dark current, other levels and spreads); selection keeps the eight above.

:func:`validation_set` returns light, words and the noisy cases' calibration for
one sensor configuration; :func:`validation_psnr` gives PSNR-mu (mu = 5000, each
frame divided by the ground truth's peak) of every case over all its frames (the
ends of each stream, where inference repeats the first or last readout, included),
``shot`` and ``noisy``, the means of the shot-noise-only cases and of the noisy
ones, and ``mean``, the mean of every case (the selection score).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import check_flag
from tespike.golden.fastsim import simulate_scene
from tespike.golden.io import check_frame_shape

from .clips import HELDOUT_PANORAMA, VALIDATION_DOMAIN, sensor_calibration
from .deadleaves import DeadLeavesParams, dead_leaves

#: Held-out generator parameters of the dead-leaves family (none of training's ranges' corners).
HELDOUT_DEADLEAVES = DeadLeavesParams(objects=(40, 90), size_exponent=(3.2, 3.6), decades=(5.0, 6.0),
                                      soft_fraction=0.1, object_speed=(1.0, 2.5))


@dataclasses.dataclass(frozen=True)
class Case:
    label: str
    family: str          # "panorama" or "deadleaves"
    motion: str
    frames: int
    peak: float
    sensor: str = ""     # a key of VALIDATION_SENSORS ("": shot noise only)


#: The noisy validation sensors (fixed, inside the engine's NOISE_DRAW range; golden.noise.SensorNoise fields).
VALIDATION_SENSORS = {
    "eq12": {"dark_current": "eq12", "dark_level": 1.0, "dsnu": 0.3, "hot_pixels": 0.01, "hot_factor": 20.0,
             "prnu": 0.03, "comparator_offset": 0.03},
    "eq13": {"dark_current": "eq13", "dark_level": 1.0, "dsnu": 0.3, "hot_pixels": 0.01, "hot_factor": 20.0,
             "prnu": 0.03, "comparator_offset": 0.03},
    # the extended set's sensors (EXTENDED_CASES): other levels and spreads inside NOISE_DRAW
    "eq13-0.6-nu": {"dark_current": "eq13", "dark_level": 0.6, "dsnu": 0.2, "hot_pixels": 0.005,
                    "hot_factor": 20.0, "prnu": 0.02, "comparator_offset": 0.02},
    "eq12-3": {"dark_current": "eq12", "dark_level": 3.0, "dsnu": 0.4, "hot_pixels": 0.015, "hot_factor": 10.0,
               "prnu": 0.04, "comparator_offset": 0.01},
    "eq13-2": {"dark_current": "eq13", "dark_level": 2.0, "dsnu": 0.1, "hot_pixels": 0.0, "hot_factor": 5.0,
               "prnu": 0.01, "comparator_offset": 0.04},
    "eq12-0.3": {"dark_current": "eq12", "dark_level": 0.3, "dsnu": 0.5, "hot_pixels": 0.02, "hot_factor": 40.0,
                 "prnu": 0.05, "comparator_offset": 0.05},
}

CASES = (
    Case("courtyard-pan", "panorama", "pan", 48, 1.0),
    Case("courtyard-mixed-0.3", "panorama", "mixed", 48, 0.3),
    Case("courtyard-zoom-0.03", "panorama", "zoom", 48, 0.03),
    Case("courtyard-short-32", "panorama", "pan", 32, 1.0),
    Case("deadleaves-heldout", "deadleaves", "", 48, 2.0),
    Case("deadleaves-short-16", "deadleaves", "", 16, 2.0),
    Case("courtyard-pan-eq12", "panorama", "pan", 48, 1.0, "eq12"),
    Case("deadleaves-heldout-eq13", "deadleaves", "", 48, 2.0, "eq13"),
)

#: Six more noisy cases, for benchmarks (``bench_net.py --validation --extended``), not for selection:
#: dim light under strong dark current, where the validation's two noisy cases (bright) say little,
#: at other dark levels and spreads. Their seeds follow CASES' (index 8 on), so CASES' are unchanged.
EXTENDED_CASES = (
    Case("courtyard-mixed-0.3-eq13", "panorama", "mixed", 48, 0.3, "eq13"),
    Case("courtyard-zoom-0.03-eq12", "panorama", "zoom", 48, 0.03, "eq12"),
    Case("deadleaves-0.5-eq13x0.6nu", "deadleaves", "", 48, 0.5, "eq13-0.6-nu"),
    Case("courtyard-pan-0.1-eq12x3", "panorama", "pan", 48, 0.1, "eq12-3"),
    Case("deadleaves-short-16-eq13x2", "deadleaves", "", 16, 1.0, "eq13-2"),
    Case("courtyard-mixed-1-eq12x0.3", "panorama", "mixed", 48, 1.0, "eq12-0.3"),
)


@dataclasses.dataclass(frozen=True)
class ValidationCase:
    label: str
    light: np.ndarray        # float32 (K, H, W)
    words: np.ndarray
    calibration: object = None    # a noisy case's Calibration (validation_calibration); None: shot noise only
    config: SensorConfig | None = None
    _law: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)

    def law_inputs(self, device="cpu"):
        """The learned methods' input of a noisy case (:class:`tespike.recon.learning.infer.LawInputs`,
        every block kept), made on ``device`` at its first use and kept: a run scores every
        checkpoint on the same streams, and the law is most of a CPU validation's time (the network's,
        on one core: 97 s the first time, 45 s after; docs/fair-training.md).
        None for a shot-noise case or a calibration without a dark law."""
        if self.calibration is None or self.calibration.dark_law is None:
            return None
        key = str(device)
        if key not in self._law:
            from ..learning.infer import LawInputs
            self._law[key] = LawInputs(self.words, self.config, self.calibration, device=device, keep=True)
        return self._law[key]


def case_light(case: Case, index: int, height: int, width: int) -> np.ndarray:
    """The light of ``case`` (number ``index`` of the set), float64, its peak set."""
    from ..scenes.panorama import panorama_sequence
    rng = np.random.default_rng(np.random.SeedSequence([VALIDATION_DOMAIN, index]))
    if case.family == "panorama":
        light = panorama_sequence(rng, case.frames, height, width, source=HELDOUT_PANORAMA,
                                  motion=case.motion, sources=1)
    else:
        light = dead_leaves(rng, case.frames, height, width, HELDOUT_DEADLEAVES)
    return light * (case.peak / float(light.max()))


def validation_sensor(case: Case, index: int):
    """The :class:`tespike.golden.noise.Sensor` of a noisy case (its own validation sensor seed)."""
    from tespike.golden.noise import Sensor, SensorNoise
    seed = int(np.random.SeedSequence([VALIDATION_DOMAIN, index, 2]).generate_state(1, np.uint64)[0] >> 2)
    return Sensor(SensorNoise(**VALIDATION_SENSORS[case.sensor]), seed)


def validation_calibration(case: Case, index: int, config: SensorConfig, shape: tuple[int, int]):
    """A noisy case's calibration (:func:`tespike.recon.engine.clips.sensor_calibration`: its sensor's
    exact maps and the dark law of a dark stream it records, on the case's own validation seed)."""
    seed = np.random.default_rng(np.random.SeedSequence([VALIDATION_DOMAIN, index, 3]))
    return sensor_calibration(validation_sensor(case, index), config, shape, seed)


def validation_set(config: SensorConfig, height: int = 96, width: int = 128, *,
                   extended: bool = False) -> list[ValidationCase]:
    """Every case of :data:`CASES` (and, ``extended``, of :data:`EXTENDED_CASES`) with its stream for
    ``config`` (validation seeds)."""
    config = SensorConfig.required(config, "validation_set")
    height, width = check_frame_shape((height, width), "validation_set frame (height, width)")
    extended = check_flag(extended, "validation_set extended")
    out = []
    for index, case in enumerate(CASES + (EXTENDED_CASES if extended else ())):
        light = case_light(case, index, height, width)
        noise = np.random.default_rng(np.random.SeedSequence([VALIDATION_DOMAIN, index, 1]))
        sensor = validation_sensor(case, index) if case.sensor else None
        words = simulate_scene(config, light, seed=noise, workers=1, sensor=sensor)
        calibration = None if sensor is None else validation_calibration(case, index, config, light.shape[1:])
        out.append(ValidationCase(case.label, light.astype(np.float32), words, calibration, config))
    return out


def validation_psnr(reconstruct: Callable[[ValidationCase], np.ndarray],
                    cases: list[ValidationCase]) -> dict[str, float]:
    """PSNR-mu (dB) of ``reconstruct(case) -> light`` on every case; ``shot``, ``noisy`` and ``mean``."""
    from ..metrics import psnr_mu
    out = {}
    for case in cases:
        values = psnr_mu(reconstruct(case), case.light)
        out[case.label] = float(np.mean(values[np.isfinite(values)])) if np.isfinite(values).any() else math.inf
    for key, members in (("shot", [c for c in cases if c.calibration is None]),
                         ("noisy", [c for c in cases if c.calibration is not None])):
        if members:
            out[key] = float(np.mean([out[c.label] for c in members]))
    out["mean"] = float(np.mean([out[c.label] for c in cases]))
    return out
