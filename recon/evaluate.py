"""Evaluation harness: sequences -> TE and ML streams -> every method -> scored measurements.

The harness measures; :mod:`tespike.recon.report` lays the :class:`Evaluation` out as the
paper's Table 1, CSV files, plots and strips.

For each light sequence ``I`` (K, H, W) and each sensor (the paper's
section 6.1 settings: TE with b1 = b2 = 4, ML with an 8-bit counter (see below), both at
their default thresholds), the stream is simulated once with photon shot
noise, then reconstructed by every method; each method is timed on the whole
sequence, ``repeats`` times, and the median wall time / K is its run time per
frame (single runs vary several-fold on a shared machine); the torch thread
count is recorded beside it.

Metrics (paper sections 6.4 and A.2.3): PSNR-mu and SSIM-mu with mu = 5000,
computed per frame after dividing prediction and ground truth by the ground
truth's peak over the *whole sequence* (the paper's appendix A.2.2
normalises each sequence by its maximum; built-in scenes already have peak
1.0, so this changes nothing for them and keeps user sequences comparable),
clipping to [0, 1] and mu-law tone mapping. Frames whose window of readouts
would reach past either end of the sequence are not scored (the first and
last ``window // 2``; all frames when the sequence is shorter than a window);
with a learned method in the run and sequences longer than its span (61
readouts), only the frames whose whole span lies inside the sequence are
scored, for every method alike (shorter sequences: the window's rule, the
learned methods seeing the end readouts repeated).
The per-frame values are averaged per sequence, then the sequence means are
averaged (paper section 6.4).

Simulation is passed in as a function (``simulate(config, light, rng) ->
words``), so that one harness scores any source of streams: the command
line and the benchmarks pass :func:`tespike.golden.fastsim.simulate_sequence`
(the fast simulator), the demo the streams its golden model and fast simulator
recorded before (one per sensor, the TE one cycle-exact).

Sensors are named by a key (a sensor, not the configuration's ``mode``; the
keys are ``--config`` presets): ``"ml-msb"`` is the ML camera the
paper's Tables 1 and 2 compare against, the dual-buffer camera that reads
only the counter's most significant bit (its appendix A.2.1, eq. 10), so it
is the table's ML column (``TFP_ML``, ``TFI_ML``); ``"te"`` the TE column;
``"ml"``, the full-count ML camera (a stronger, wider-output sensor than the
paper's), is added below the table as extra rows (``TFP_ML-count``, ...).
The noise sensors of :data:`NOISE_SENSORS` (``"te+eq12"``, ``"te+eq13"``: the TE
camera with the dark current of the paper's eq. 12 or 13, its Tables 6 to 9),
or any sensor of ``noise_sensors=`` (a :class:`tespike.golden.noise.Sensor` per sensor key:
dark level, non-uniformity, gain spread), get a table of their own
(:func:`tespike.recon.report.noise_markdown`). A sensor ``<noise sensor>+cal`` is the same
sensor reconstructed with its calibration (:mod:`tespike.recon.calibration`): per sequence
frame size, :data:`~tespike.recon.calibration.CALIBRATION_READOUTS` dark readouts and as many under a flat
light of :data:`CALIBRATION_FLAT`, simulated with the sensor (its own noise
seed), estimate the per-pixel dark rate, dark law and gain that correct every method
(recon.methods.reconstruct says where each method is corrected).

Metrics: PSNR-mu and SSIM-mu always; ``metrics=`` adds any further column of
:data:`tespike.recon.score.METRIC_KEYS` (PU21-PSNR, HDR-VQM, FovVideoVDP, conventions in
docs/metrics.md), computed by :func:`tespike.recon.score.score` on the scored frames;
FovVideoVDP, which costs about half a second per frame at any frame size here
(100 times PSNR-mu at 96 x 128), on the middle ``vdp_frames`` of them where
asked. HDR-VQM is its sequence value (15-frame tubes), the others frame means.

A learned method without shipped weights for a sensor is refused up front
when it was asked for by name; when the methods were left to the default
(every method), its cells say why they are empty (``Evaluation.missing``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable, Iterable, Sequence

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, check_flag, is_count
from tespike.golden.io import check_scene, word_dtype
from tespike.golden.resources import require_memory

from .calibration import CALIBRATION_READOUTS
from .names import label
from .settings import DEFAULT_WINDOW, check_known, check_window, names

#: Sensors evaluated by default: the paper's Table 1 columns (ML = the msb camera
#: of its eq. 10 on the left, TE on the right), then the full-count ML camera.
SENSORS = ("ml-msb", "te", "ml")
#: Noise sensors (the paper's Tables 6 to 9): key -> (sensor preset, dark-current model of golden.light).
NOISE_SENSORS = {"te+eq12": ("te", "eq12"), "te+eq13": ("te", "eq13")}
#: Suffix of a noise sensor reconstructed with its calibration (``"te+eq12+cal"``).
CALIBRATED = "+cal"
#: The flat calibration stream's light, scene units (below the TE overflow level;
#: benchmarks/calibration_error.py measured the error); each stream has CALIBRATION_READOUTS readouts.
CALIBRATION_FLAT = 0.03
#: Metrics every evaluation computes; the others of recon.score.METRIC_KEYS are asked for.
BASIC_METRICS = ("psnr_mu", "ssim_mu")
#: Memory of one sequence's work besides its words and images (reconstruction
#: blocks, metric bands, torch), for the up-front check of :func:`evaluate`.
WORKING_BYTES = 512 << 20

#: ``simulate(config, light, rng) -> words``; for a noise sensor also ``noise_sensor=`` (a keyword:
#: its :class:`tespike.golden.noise.Sensor`).
Simulate = Callable[..., np.ndarray]


def paper_configs() -> dict[str, SensorConfig]:
    """The paper's section 6.1 sensors at default thresholds: ML 8 bits with the msb
    readout (eq. 10), TE b1 = b2 = 4, the full-count ML camera (extra rows), and the
    TE camera of the noise sensors."""
    return {sensor: SensorConfig.preset(NOISE_SENSORS.get(sensor, (sensor,))[0])
            for sensor in (*SENSORS, *NOISE_SENSORS)}


def scored_frames(frames: int, window: int, span: int | None = None) -> slice:
    """Frames whose whole window of readouts lies inside the sequence (all if too short);
    with ``span`` (the readouts a learned method sees), frames whose span lies inside it
    too, where the sequence is longer than the span (else the window's frames)."""
    if not is_count(frames) or not is_count(window, 1) or not (span is None or is_count(span, 1)):
        raise InputError(f"scored_frames({frames!r}, {window!r}, {span!r}): frames must be an integer >= 0, "
                         "the window and span integers >= 1")       # (-3 frames had given slice(0, -3))
    reach = window if span is None or frames <= 2 * (span // 2) else max(window, span)
    half = reach // 2
    return slice(half, frames - half) if frames > 2 * half else slice(0, frames)


def default_noise_sensors(seed: int = 0) -> dict:
    """The paper's noise sensors (:data:`NOISE_SENSORS`) as :class:`tespike.golden.noise.Sensor`: its
    dark current, no non-uniformity, sensor seed ``seed``."""
    from tespike.golden.noise import Sensor, SensorNoise
    return {sensor: Sensor(SensorNoise(dark_current=model), seed) for sensor, (_, model) in NOISE_SENSORS.items()}


def noise_base(sensor: str, noise_sensors) -> str | None:
    """The noise sensor a sensor key uses (itself, or the one it calibrates), or None for an ideal sensor."""
    base = sensor[:-len(CALIBRATED)] if sensor.endswith(CALIBRATED) else sensor
    return base if base in noise_sensors else None


def calibrate_sensor(simulate: Simulate, config: SensorConfig, noise_sensor, shape: tuple[int, int], rng):
    """A calibration of ``noise_sensor`` (a :class:`tespike.golden.noise.Sensor`) for frames of ``shape``:
    dark and flat streams it records."""
    from .calibration import estimate
    dark = simulate(config, np.zeros((CALIBRATION_READOUTS, *shape), np.float32), rng, noise_sensor=noise_sensor)
    flat = simulate(config, np.full((CALIBRATION_READOUTS, *shape), CALIBRATION_FLAT, np.float32), rng,
                    noise_sensor=noise_sensor)
    return estimate(dark, flat, config, CALIBRATION_FLAT)


def check_methods(methods: Sequence[str]) -> tuple[str, ...]:
    """Refuse an empty method list or a name not in :data:`tespike.recon.methods.RECON_METHODS`
    (both evaluations: :func:`evaluate` and :func:`tespike.recon.dataset.evaluate.evaluate_store`)."""
    from .methods import RECON_METHODS
    methods = tuple(methods)
    for method in methods:
        check_known(method, RECON_METHODS)
    if not methods:
        raise InputError("no reconstruction method to evaluate")
    twice = next((method for i, method in enumerate(methods) if method in methods[:i]), None)
    if twice is not None:           # (two rows of one method, their run times averaged into both)
        raise InputError(f"reconstruction method {twice!r} is given twice: give each method once")
    return methods


def check_sequence_peak(sequence: str, peak: float) -> float:
    """Refuse a sequence whose peak light is not above 0: it normalises the metrics (Table 1)."""
    if not peak > 0:
        raise InputError(f"sequence {sequence!r} is all zero: its peak cannot normalise the metrics")
    return peak


def learned_span(methods: Sequence[str]) -> int | None:
    """The longest span of readouts the learned ones of ``methods`` see (None: none is learned)."""
    from .learned import LEARNED, method_span
    spans = [method_span(m) for m in methods if m in LEARNED]
    return max(spans) if spans else None


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One sequence x sensor x method."""

    sequence: str
    sensor: str
    method: str
    psnr_mu: float
    ssim_mu: float
    ms_per_frame: float
    frames_scored: int
    #: further metrics (nan where not computed), and the frames FovVideoVDP saw
    psnr_pu21: float = math.nan
    hdr_vqm: float = math.nan
    fovvideovdp: float = math.nan
    frames_vdp: int = 0


@dataclasses.dataclass
class Evaluation:
    """Every :class:`Measurement`, plus one tone-mapping-ready frame per sequence for the strips."""

    results: list[Measurement]
    methods: tuple[str, ...]
    sensors: tuple[str, ...]
    window: int
    strips: dict[str, dict] = dataclasses.field(default_factory=dict)
    #: run time: median of this many runs, with this many torch threads
    repeats: int = 1
    threads: int = 1
    #: with ``keep=True``: (sequence, sensor) -> words and (sequence, sensor, method) -> images
    streams: dict[tuple[str, str], np.ndarray] = dataclasses.field(default_factory=dict)
    images: dict[tuple[str, str, str], np.ndarray] = dataclasses.field(default_factory=dict)
    #: metric keys computed (recon.score.METRIC_KEYS order) and the frames FovVideoVDP was limited to
    metrics: tuple[str, ...] = BASIC_METRICS
    vdp_frames: int | None = None
    #: (method, sensor) -> why it was not run (a learned method's missing weights)
    missing: dict[tuple[str, str], str] = dataclasses.field(default_factory=dict)
    #: method -> {"parameters", "flops"} of the learned methods (:func:`tespike.recon.complexity.measure`)
    complexity: dict[str, dict] = dataclasses.field(default_factory=dict)
    #: frame size of the sequences (rows, columns), when all share one
    frame_size: tuple[int, int] | None = None
    #: readouts the learned methods see (None: none was run); sequences longer than it are
    #: scored only where every method's readouts lie inside them (:func:`scored_frames`)
    span: int | None = None
    #: sensor key -> the golden.noise.Sensor it simulates, for the noise and calibrated sensors
    noise_sensors: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        # names, each a string: one string had been read letter by letter ("tfp" as t, f, p)
        for field in ("methods", "sensors", "metrics"):
            value = getattr(self, field)
            names = () if isinstance(value, str) else tuple(value) if isinstance(value, (tuple, list)) else None
            if not names or not all(isinstance(name, str) for name in names):
                raise InputError(f"Evaluation {field} {value!r}: must be a tuple of names")
            setattr(self, field, names)

    def summary(self) -> dict[tuple[str, str], dict[str, float]]:
        """(method, sensor) -> mean over sequences of the per-sequence means."""
        out = {}
        for method in self.methods:
            for sensor in self.sensors:
                rows = [r for r in self.results if r.method == method and r.sensor == sensor]
                if rows:
                    out[method, sensor] = {key: float(np.mean([getattr(r, key) for r in rows]))
                                         for key in (*self.metrics, "ms_per_frame")}
                    out[method, sensor]["sequences"] = len(rows)
        return out


def evaluate(sequences: Iterable[tuple[str, np.ndarray]], simulate: Simulate, *,
             methods: Sequence[str] | None = None, sensors: Sequence[str] = SENSORS,
             configs: dict[str, SensorConfig] | None = None, window: int = DEFAULT_WINDOW, seed: int = 0,
             device: str = "cpu", progress: bool | str = True, keep: bool = False,
             options: dict[str, dict] | None = None, weights: dict[tuple[str, str], str] | None = None,
             repeats: int = 3,
             metrics: Sequence[str] = BASIC_METRICS, vdp_frames: int | None = None,
             missing: str | None = None, noise_sensors: dict | None = None) -> Evaluation:
    """Simulate every sequence in every sensor, reconstruct with every method, score.

    ``sequences``: (label, light (K, H, W)) pairs; ``methods``: keys of
    :data:`tespike.recon.methods.RECON_METHODS` (default all); ``seed`` makes the shot
    noise reproducible (one independent stream per sequence and sensor);
    ``progress``: a bar (True), nothing (False) or ``"lines"`` (one line per step on
    stderr, for a log file); ``keep`` keeps every stream and reconstruction in the result (memory!);
    ``options`` maps a method to extra keywords of :func:`tespike.recon.methods.reconstruct`
    (e.g. ``{"tfi": {"search": "window"}}``); ``weights``: (method, sensor) -> the
    learned method's weights file there (:func:`tespike.recon.learned.weights_by_sensor`; else
    the shipped ones); ``repeats``: runs timed per method (the median is reported). ``metrics``: keys of :data:`tespike.recon.score.METRIC_KEYS` (PSNR-mu
    and SSIM-mu are always computed); ``vdp_frames``: compute FovVideoVDP on the
    middle this many scored frames only (None: all). A sensor key of ``noise_sensors``
    (key -> :class:`tespike.golden.noise.Sensor`, over :func:`default_noise_sensors`: the
    :data:`NOISE_SENSORS`) is simulated with ``simulate(..., noise_sensor=noise_sensors[key])``;
    ``<key>+cal`` is that sensor again, reconstructed with a calibration from its own
    dark and flat streams (:func:`calibrate_sensor`, one per sequence frame size).
    ``missing``: ``"refuse"`` a learned method without weights for a sensor (the
    default when ``methods`` are named), or ``"note"`` it in
    ``Evaluation.missing`` and go on (the default for every method).
    """
    import torch
    from tqdm import tqdm

    from .methods import reconstruct

    methods, sensors, metrics = (None if methods is None else names(methods)), names(sensors), names(metrics)
    methods, metrics, configs, noise_sensors, absent = _checked_arguments(
        methods, sensors, configs, window, seed, repeats, metrics, vdp_frames, missing, noise_sensors, weights)
    _checked_run_options(methods, sensors, options, weights, progress, keep)
    further = [key for key in metrics if key not in BASIC_METRICS]
    sequences = _checked_sequences(sequences)
    if not callable(simulate):                           # (None had been a TypeError at the first sequence)
        raise InputError(f"simulate: must be a function simulate(config, light, rng) -> words, not "
                         f"{type(simulate).__name__}")
    if "ssim_mu" in metrics:                             # (refused only after the simulation and reconstruction)
        from .metrics import check_ssim_frames
        for _, light in sequences:
            check_ssim_frames(light.shape)
    labels = [name for name, _ in sequences]
    if len(set(labels)) != len(labels):
        raise InputError(f"sequence labels must be unique, got {labels}")

    bases = {sensor: noise_base(sensor, noise_sensors) for sensor in sensors}
    evaluation = Evaluation([], methods, tuple(sensors), window, repeats=repeats,
                            threads=torch.get_num_threads(), metrics=metrics, vdp_frames=vdp_frames,
                            missing=absent, noise_sensors={sensor: noise_sensors[base] for sensor, base in
                                                           bases.items() if base is not None})
    calibrations = {}                        # (sensor, frame shape) -> calibration
    span = evaluation.span = learned_span([m for m in methods if any((m, sensor) not in absent for sensor in sensors)])
    sizes = {tuple(light.shape[1:]) for _, light in sequences}
    evaluation.frame_size = sizes.pop() if len(sizes) == 1 else None
    warmed: set[tuple[str, str]] = set()
    total = len(sequences) * (len(sensors) * (1 + len(methods)) - len(absent))
    bar = (ProgressLines(total) if progress == "lines" else
           tqdm(total=total, desc="evaluate", unit="step", disable=not progress))
    for index, (name, light) in enumerate(sequences):
        light, peak = _checked_sequence(name, light)   # checked slice by slice, never copied whole
        check_sequence_peak(name, peak)
        K, H, W = light.shape
        word_bytes = max(word_dtype(configs[m]).itemsize for m in sensors)
        kept = len(sensors) * (word_bytes + 4 * len(methods)) if keep else 0
        require_memory(K * H * W * (word_bytes + 4 + kept) + WORKING_BYTES,
                       f"evaluating sequence {name!r} ({K} x {H} x {W})")
        frames = scored_frames(light.shape[0], window, span)
        middle = (frames.start + frames.stop - 1) // 2
        strip = {"gt": np.array(light[middle], np.float64), "peak": peak, "frame": middle}
        for sensor_index, sensor in enumerate(sensors):
            config = configs[sensor]
            bar.set_postfix_str(f"{name} {sensor} simulate")
            rng = np.random.default_rng([seed, index, sensor_index])
            words, calibration = _recorded(simulate, config, light, rng, sensor, bases[sensor], noise_sensors,
                                           calibrations, np.random.default_rng([seed, sensor_index, H, W]), bar,
                                           name)
            if keep:
                evaluation.streams[name, sensor] = words
            bar.update()
            for method in methods:
                if (method, sensor) in absent:
                    continue
                bar.set_postfix_str(f"{name} {label(method, sensor)}")
                kwargs = {**(options or {}).get(method, {}),
                          **({"weights": weights[method, sensor]} if (method, sensor) in (weights or {}) else {})}
                if (sensor, method) not in warmed:      # one-time costs (tables, torch) are not timed
                    reconstruct(words[:window, :4, :4], config, method, window=window, device=device, **kwargs)
                    warmed.add((sensor, method))
                images, seconds = _timed(reconstruct, words, config, method, window, device, calibration, kwargs,
                                         repeats)
                evaluation.results.append(_measurement(name, sensor, method, images, light, frames, peak, seconds,
                                                       further, vdp_frames, device))
                strip[sensor, method] = np.array(images[middle])     # a copy: the images can go
                if keep:
                    evaluation.images[name, sensor, method] = images
                bar.update()
        evaluation.strips[name] = strip
    bar.close()
    return evaluation


def _checked_sequences(sequences) -> list[tuple[str, np.ndarray]]:
    """``sequences`` as a list of (label, light) pairs, refused in one line where one is not such a
    pair (a light array given alone had been 'too many values to unpack') or none is given; the
    light's own checks come when it is simulated."""
    if isinstance(sequences, np.ndarray):
        raise InputError("sequences: give (label, light) pairs, e.g. [('scene', light)], not a light array")
    try:
        sequences = list(sequences)
    except TypeError:                                     # (None: "not iterable")
        raise InputError(f"sequences: give (label, light) pairs, e.g. [('scene', light)], not "
                         f"{type(sequences).__name__}") from None
    for item in sequences:
        if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str)
                and isinstance(item[1], np.ndarray) and item[1].ndim == 3):
            raise InputError(f"sequences: each must be a (label, light (K, H, W)) pair, got "
                             f"{type(item).__name__} {str(item)[:60]!r}")
    if not sequences:
        raise InputError("no sequences to evaluate")
    return sequences


def _checked_arguments(methods, sensors, configs, window, seed, repeats, metrics, vdp_frames, missing,
                       noise_sensors, weights):
    """:func:`evaluate`'s arguments checked (one line for the first bad one) -> (methods, metrics in
    their table order, configuration per sensor, noise sensors, (method, sensor) -> why a learned
    method is left out there)."""
    from .methods import RECON_METHODS, missing_weights
    from .score import METRIC_KEYS

    check_window(window)
    if missing is None:
        missing = "note" if methods is None else "refuse"
    if missing not in ("note", "refuse"):
        raise InputError(f"missing = {missing!r}: must be 'note' or 'refuse'")
    methods = check_methods(RECON_METHODS if methods is None else methods)
    unknown = [key for key in metrics if key not in METRIC_KEYS]
    if unknown:
        raise InputError(f"unknown metric {unknown[0]!r} (known: {', '.join(METRIC_KEYS)})")
    metrics = tuple(key for key in METRIC_KEYS if key in (*BASIC_METRICS, *metrics))
    if vdp_frames is not None and (type(vdp_frames) is not int or vdp_frames < 1):
        raise InputError(f"vdp_frames = {vdp_frames!r}: must be an integer >= 1")
    if not sensors:                                       # (max() of an empty sequence)
        raise InputError("sensors: name at least one sensor")
    twice = sorted({sensor for sensor in sensors if list(sensors).count(sensor) > 1})
    if twice:                                             # (its sequences had been counted twice)
        raise InputError(f"sensor {twice[0]!r} is named more than once")
    if configs is not None and not isinstance(configs, dict):
        raise InputError(f"configs: must map sensor names to configurations, not {type(configs).__name__}")
    configs = dict(paper_configs() if configs is None else configs)
    for name, config in configs.items():
        SensorConfig.required(config, f"sensor {name!r}")
    if noise_sensors is not None and not isinstance(noise_sensors, dict):
        raise InputError(f"noise_sensors: must map names to noise sensors, not {type(noise_sensors).__name__}")
    noise_sensors = default_noise_sensors() | dict(noise_sensors or {})
    for sensor in sensors:
        if sensor.endswith(CALIBRATED) and noise_base(sensor, noise_sensors) is None:
            raise InputError(f"sensor {sensor!r}: {sensor[:-len(CALIBRATED)]!r} is no noise sensor to calibrate")
        if sensor.endswith(CALIBRATED) and sensor not in configs and sensor[:-len(CALIBRATED)] in configs:
            configs[sensor] = configs[sensor[:-len(CALIBRATED)]]     # its noise sensor's configuration
    for sensor in sensors:
        if sensor not in configs:
            raise InputError(f"no sensor configuration for sensor {sensor!r}")
    absent = {}
    for sensor in sensors:
        for method in methods:
            reason = missing_weights(method, configs[sensor], (weights or {}).get((method, sensor)))
            if reason is not None and missing == "refuse":
                raise InputError(reason)
            if reason is not None:
                absent[method, sensor] = reason
    if type(seed) is not int or seed < 0:
        raise InputError(f"seed = {seed!r} must be an integer >= 0")
    if type(repeats) is not int or repeats < 1:
        raise InputError(f"repeats = {repeats!r} must be an integer >= 1")
    return methods, metrics, configs, noise_sensors, absent


def _checked_run_options(methods, sensors, options, weights, progress, keep) -> None:
    """:func:`evaluate`'s switches and per-method maps checked: ``progress`` True, False (None) or "lines" and
    ``keep`` a bool (the text "False" had been true), every ``options`` key a method of the run whose
    value is a dict of :func:`reconstruct` keywords other than the window (given once, to the run), and
    every ``weights`` key a (method, sensor) pair of the run (a typo had been dropped without a word)."""
    if not (progress is None or isinstance(progress, bool) or progress == "lines"):
        raise InputError(f"progress = {progress!r}: must be True, False (or None) or 'lines'")
    check_flag(keep, "keep")
    check_method_options(methods, options)
    if weights is not None and not isinstance(weights, dict):
        raise InputError(f"weights: must be a dict, not {type(weights).__name__}")
    for key in (weights or {}):
        if not (isinstance(key, tuple) and len(key) == 2 and key[0] in methods and key[1] in sensors):
            raise InputError(f"weights key {key!r}: must be a (method, sensor) pair of this evaluation")


def check_method_options(methods, options) -> None:
    """Every key of ``options`` a method of the run (``methods``) whose value is a dict of
    :func:`reconstruct` keywords other than the window (given once, to the run); a typo had been
    dropped without a word. :func:`evaluate` and the store's evaluation check them alike."""
    if options is not None and not isinstance(options, dict):
        raise InputError(f"options: must be a dict, not {type(options).__name__}")
    for method, kwargs in (options or {}).items():
        if method not in methods:
            raise InputError(f"options for {method!r}: no method of this evaluation "
                             f"({', '.join(methods)}) has that name")
        if not isinstance(kwargs, dict):
            raise InputError(f"options for {method!r}: must be a dict of reconstruct() keywords, "
                             f"not {type(kwargs).__name__}")
        if "window" in kwargs:
            raise InputError(f"options for {method!r}: the window is the evaluation's own argument "
                             "(window=), the same for every method")


def _simulated(words, light) -> np.ndarray:
    """The words a ``simulate`` function returned, refused in one line where they are no integer array
    of the light's shape (a 2-D one had been an IndexError deep in a method, a list a TypeError)."""
    if not (isinstance(words, np.ndarray) and words.dtype.kind in "iu" and words.shape == light.shape):
        raise InputError(f"simulate returned {type(words).__name__} "
                         f"{getattr(words, 'dtype', '')} {getattr(words, 'shape', '')}: it must return the "
                         f"integer readout words of the light's shape {light.shape}")
    return words


def _recorded(simulate, config, light, rng, sensor, base, noise_sensors, calibrations, calibration_rng, bar,
              name):
    """``sensor``'s stream of ``light`` -> (words, the calibration its reconstruction uses, or None):
    a noise sensor (``base``: its key, else None) records with its non-idealities, and ``<key>+cal``
    is calibrated once per frame size (``calibrations``, from dark and flat streams drawn with
    ``calibration_rng``); ``name``: the sequence's, for the progress ``bar``."""
    if base is None:
        return _simulated(simulate(config, light, rng), light), None
    words = _simulated(simulate(config, light, rng, noise_sensor=noise_sensors[base]), light)
    if not sensor.endswith(CALIBRATED):
        return words, None
    key = sensor, tuple(light.shape[1:])
    if key not in calibrations:
        bar.set_postfix_str(f"{name} {sensor} calibrate")
        try:
            calibrations[key] = calibrate_sensor(simulate, config, noise_sensors[base], key[1], calibration_rng)
        except InputError as exc:               # (a sensor no calibration can serve)
            raise InputError(f"calibrating noise sensor {base}: {exc}") from None
    return words, calibrations[key]


def _timed(reconstruct, words, config, method, window, device, calibration, kwargs, repeats):
    """-> (the reconstruction, the median of ``repeats`` run times in seconds: :mod:`.walltime`, as
    every report of the project times a reconstruction)."""
    from .walltime import median_seconds
    seconds, images = median_seconds(lambda: reconstruct(words, config, method, window=window, device=device,
                                                         calibration=calibration, **kwargs), repeats)
    return images, float(seconds)


def _measurement(name, sensor, method, images, light, frames, peak, seconds, further, vdp_frames,
                 device) -> Measurement:
    """One row of the table: ``images`` scored against ``light`` on the readouts ``frames``."""
    from .metrics import psnr_mu, ssim_mu
    from .score import score
    pred, truth = images[frames], light[frames]
    values, counted = {}, 0
    for key in further:
        subset = metric_subset(pred.shape[0], vdp_frames if key == "fovvideovdp" else None)
        scores = score(pred[subset], np.asarray(truth[subset]), metrics=(key,), device=device)
        values[key] = scores.sequence.get(key, scores.mean[key])
        if key == "fovvideovdp":
            counted = subset.stop - subset.start
    return Measurement(name, sensor, method, float(np.mean(psnr_mu(pred, truth, peak=peak))),
                       float(np.mean(ssim_mu(pred, truth, peak=peak))), 1e3 * seconds / light.shape[0],
                       int(pred.shape[0]), frames_vdp=counted, **values)


class ProgressLines:
    """Progress for a log file (stderr not a terminal): one line per finished step, with
    the time so far, where a bar would print nothing readable (the tqdm interface used here)."""

    def __init__(self, total: int):
        self.total, self.done, self.what, self.start = total, 0, "", time.perf_counter()

    def set_postfix_str(self, what: str) -> None:
        self.what = what

    def update(self) -> None:
        import sys
        self.done += 1
        print(f"evaluate: {self.done}/{self.total} {self.what} done, {time.perf_counter() - self.start:.0f} s",
              file=sys.stderr, flush=True)

    def close(self) -> None:
        pass


def metric_subset(scored: int, count: int | None) -> slice:
    """The middle ``count`` of ``scored`` frames (all when None or more), indices into the scored frames."""
    if not is_count(scored) or not (count is None or is_count(count, 1)):     # (2.5 had given a float slice)
        raise InputError(f"metric_subset({scored!r}, {count!r}): frames must be an integer >= 0, "
                         "the subset None or an integer >= 1")
    if count is None or count >= scored:
        return slice(0, scored)
    start = (scored - count) // 2
    return slice(start, start + count)


def _checked_sequence(name: str, light) -> tuple[np.ndarray, float]:
    """Check a (K, H, W) light sequence slice by slice (memory maps stay on disk); return it and its peak."""
    light = light if isinstance(light, np.ndarray) else np.asarray(light)
    check_scene(light, scan_values=False)
    if light.shape[0] == 0:
        raise InputError(f"sequence {name!r} has no frames (K = 0)")
    step = max(1, (1 << 22) // light[0].size)
    peak = 0.0
    for start in range(0, light.shape[0], step):
        peak = max(peak, float(check_scene(np.asarray(light[start:start + step])).max()))
    return light, peak
