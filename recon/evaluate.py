"""Evaluation harness: sequences -> TE and ML streams -> every method -> the paper's Table 1.

For each light sequence ``I`` (K, H, W) and each sensor mode (the paper's
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
words``) because :mod:`recon` does not import the simulator; the command
line and the benchmarks pass :func:`golden.fastsim.simulate_scene`.

Sensors (keys are ``--config`` presets): ``"ml-msb"`` is the ML camera the
paper's Tables 1 and 2 compare against, the dual-buffer camera that reads
only the counter's most significant bit (its appendix A.2.1, eq. 10), so it
is the table's ML column (``TFP_ML``, ``TFI_ML``); ``"te"`` the TE column;
``"ml"``, the full-count ML camera (a stronger, wider-output sensor than the
paper's), is added below the table as extra rows (``TFP_ML-count``, ...).
The noise sensors of :data:`NOISE_MODES` (``"te+eq12"``, ``"te+eq13"``: the TE
camera with the dark current of the paper's eq. 12 or 13, its Tables 6 to 9)
get a table of their own (:mod:`recon.paper_tables`).

Metrics: PSNR-mu and SSIM-mu always; ``metrics=`` adds any further column of
:data:`recon.score.KEYS` (PU21-PSNR, HDR-VQM, FovVideoVDP, conventions in
docs/metrics.md), computed by :func:`recon.score.score` on the scored frames;
FovVideoVDP, which costs about half a second per frame at any frame size here
(100 times PSNR-mu at 96 x 128), on the middle ``vdp_frames`` of them where
asked. HDR-VQM is its sequence value (15-frame tubes), the others frame means.

A learned method without shipped weights for a sensor is refused up front
when it was asked for by name; when the methods were left to the default
(every method), its cells say why they are empty (``Evaluation.missing``).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import time
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from golden.config import SensorConfig
from golden.errors import InputError
from golden.io import check_scene
from golden.resources import require_memory

from .pictures import ERROR_RANGE, save_figure, tone_map, write_text

#: Sensors evaluated by default: the paper's Table 1 columns (ML = the msb camera
#: of its eq. 10 on the left, TE on the right), then the full-count ML camera.
MODES = ("ml-msb", "te", "ml")
#: Noise sensors (the paper's Tables 6 to 9): key -> (sensor preset, dark-current model of golden.light).
NOISE_MODES = {"te+eq12": ("te", "eq12"), "te+eq13": ("te", "eq13")}
#: Sensors that get a column of Table 1; any other evaluated sensor gets extra rows.
COLUMNS = ("ml-msb", "te")
#: Names in tables and plots: the paper's names for its two cameras.
NAMES = {"ml-msb": "ML", "te": "TE", "ml": "ML-count", "te+eq12": "TE+dark12", "te+eq13": "TE+dark13"}
#: Methods as the paper names them (``label``); other methods in capitals.
METHOD_NAMES = {"tfp": "TFP", "tfi": "TFI", "spk2imgnet": "Spk2ImgNet", "bsf": "BSF", "mambaspike": "MambaSpike",
                "net": "Net"}
#: Metrics every evaluation computes; the others of recon.score.KEYS are asked for.
BASIC_METRICS = ("psnr_mu", "ssim_mu")
#: Memory of one sequence's work besides its words and images (reconstruction
#: blocks, metric bands, torch), for the up-front check of :func:`evaluate`.
WORKING_BYTES = 512 << 20

#: Files :func:`write_outputs` writes into its folder (besides strips/<sequence>.png).
OUTPUT_FILES = ("table.md", "table.csv", "results.csv", "quality_vs_time.png", "strips/")

#: ``simulate(config, light, rng) -> words``; for a noise sensor also ``dark_current="eq12"`` (a keyword).
Simulate = Callable[..., np.ndarray]


def paper_configs() -> dict[str, SensorConfig]:
    """The paper's section 6.1 sensors at default thresholds: ML 8 bits with the msb
    readout (eq. 10), TE b1 = b2 = 4, the full-count ML camera (extra rows), and the
    TE camera of the noise sensors."""
    return {mode: SensorConfig.preset(NOISE_MODES.get(mode, (mode,))[0]) for mode in (*MODES, *NOISE_MODES)}


def name(mode: str) -> str:
    """Table name of a sensor: ``ML`` (msb, the paper's), ``TE``, ``ML-count``; else the key in capitals."""
    return NAMES.get(mode, mode.upper())


def label(method: str, mode: str) -> str:
    """Paper-style name, e.g. ``TFP_TE``, ``TFI_ML`` (msb camera), ``BSF_ML-count``, ``Net_TE``."""
    return f"{METHOD_NAMES.get(method, method.upper())}_{name(mode)}"


def scored_frames(frames: int, window: int, span: int | None = None) -> slice:
    """Frames whose whole window of readouts lies inside the sequence (all if too short);
    with ``span`` (the readouts a learned method sees), frames whose span lies inside it
    too, where the sequence is longer than the span (else the window's frames)."""
    reach = window if span is None or frames <= 2 * (span // 2) else max(window, span)
    half = reach // 2
    return slice(half, frames - half) if frames > 2 * half else slice(0, frames)


def learned_span(methods: Sequence[str]) -> int | None:
    """The longest span of readouts the learned ones of ``methods`` see (None: none is learned)."""
    from .learned import LEARNED, method_span
    spans = [method_span(m) for m in methods if m in LEARNED]
    return max(spans) if spans else None


@dataclasses.dataclass(frozen=True)
class Result:
    """One sequence x mode x method."""

    sequence: str
    mode: str
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
    """Every :class:`Result`, plus one tone-mapping-ready frame per sequence for the strips."""

    results: list[Result]
    methods: tuple[str, ...]
    modes: tuple[str, ...]
    window: int
    strips: dict[str, dict] = dataclasses.field(default_factory=dict)
    #: timing: median of this many runs, with this many torch threads
    repeats: int = 1
    threads: int = 1
    #: with ``keep=True``: (sequence, mode) -> words and (sequence, mode, method) -> images
    streams: dict[tuple[str, str], np.ndarray] = dataclasses.field(default_factory=dict)
    images: dict[tuple[str, str, str], np.ndarray] = dataclasses.field(default_factory=dict)
    #: metric keys computed (recon.score.KEYS order) and the frames FovVideoVDP was limited to
    metrics: tuple[str, ...] = BASIC_METRICS
    vdp_frames: int | None = None
    #: (method, mode) -> why it was not run (a learned method's missing weights)
    missing: dict[tuple[str, str], str] = dataclasses.field(default_factory=dict)
    #: method -> {"parameters", "flops"} of the learned methods (recon.paper_tables.measure_complexity)
    complexity: dict[str, dict] = dataclasses.field(default_factory=dict)
    #: frame size of the sequences (rows, columns), when all share one
    frame_size: tuple[int, int] | None = None
    #: readouts the learned methods see (None: none was run); sequences longer than it are
    #: scored only where every method's readouts lie inside them (:func:`scored_frames`)
    span: int | None = None

    def summary(self) -> dict[tuple[str, str], dict[str, float]]:
        """(method, mode) -> mean over sequences of the per-sequence means."""
        out = {}
        for method in self.methods:
            for mode in self.modes:
                rows = [r for r in self.results if r.method == method and r.mode == mode]
                if rows:
                    out[method, mode] = {key: float(np.mean([getattr(r, key) for r in rows]))
                                         for key in (*self.metrics, "ms_per_frame")}
                    out[method, mode]["sequences"] = len(rows)
        return out


def evaluate(sequences: Iterable[tuple[str, np.ndarray]], simulate: Simulate, *,
             methods: Sequence[str] | None = None, modes: Sequence[str] = MODES,
             configs: dict[str, SensorConfig] | None = None, window: int = 9, seed: int = 0,
             device: str = "cpu", progress: bool = True, keep: bool = False,
             options: dict[str, dict] | None = None, weights: dict[tuple[str, str], str] | None = None,
             repeats: int = 3,
             metrics: Sequence[str] = BASIC_METRICS, vdp_frames: int | None = None,
             missing: str | None = None) -> Evaluation:
    """Simulate every sequence in every mode, reconstruct with every method, score.

    ``sequences``: (label, light (K, H, W)) pairs; ``methods``: keys of
    :data:`recon.methods.RECON_METHODS` (default all); ``seed`` makes the shot
    noise reproducible (one independent stream per sequence and mode);
    ``keep`` keeps every stream and reconstruction in the result (memory!);
    ``options`` maps a method to extra keywords of :func:`recon.methods.reconstruct`
    (e.g. ``{"tfi": {"search": "window"}}``); ``weights``: (method, mode) -> the
    learned method's weights file there (:func:`recon.learned.weights_by_sensor`; else
    the shipped ones); ``repeats``: runs timed per method (the median is reported). ``metrics``: keys of :data:`recon.score.KEYS` (PSNR-mu
    and SSIM-mu are always computed); ``vdp_frames``: compute FovVideoVDP on the
    middle this many scored frames only (None: all). A mode of
    :data:`NOISE_MODES` is simulated with ``simulate(..., dark_current=model)``.
    ``missing``: ``"refuse"`` a learned method without weights for a sensor (the
    default when ``methods`` are named), or ``"note"`` it in
    ``Evaluation.missing`` and go on (the default for every method).
    """
    import torch
    from tqdm import tqdm

    from .methods import RECON_METHODS, missing_weights, reconstruct
    from .metrics import psnr_mu, ssim_mu
    from .score import KEYS, score

    if missing is None:
        missing = "note" if methods is None else "refuse"
    if missing not in ("note", "refuse"):
        raise InputError(f"missing = {missing!r}: must be 'note' or 'refuse'")
    methods = tuple(RECON_METHODS) if methods is None else tuple(methods)
    for method in methods:
        if method not in RECON_METHODS:
            raise InputError(f"unknown reconstruction method {method!r} (known: {', '.join(RECON_METHODS)})")
    if not methods:
        raise InputError("no reconstruction method to evaluate")
    unknown = [key for key in metrics if key not in KEYS]
    if unknown:
        raise InputError(f"unknown metric {unknown[0]!r} (known: {', '.join(KEYS)})")
    metrics = tuple(key for key in KEYS if key in (*BASIC_METRICS, *metrics))
    further = [key for key in metrics if key not in BASIC_METRICS]
    if vdp_frames is not None and (type(vdp_frames) is not int or vdp_frames < 1):
        raise InputError(f"vdp_frames = {vdp_frames!r}: must be an integer >= 1")
    configs = dict(paper_configs() if configs is None else configs)
    for mode in modes:
        if mode not in configs:
            raise InputError(f"no sensor configuration for mode {mode!r}")
    absent = {}
    for mode in modes:
        for method in methods:
            reason = missing_weights(method, configs[mode], (weights or {}).get((method, mode)))
            if reason is not None and missing == "refuse":
                raise InputError(reason)
            if reason is not None:
                absent[method, mode] = reason
    if type(seed) is not int or seed < 0:
        raise InputError(f"seed = {seed!r} must be an integer >= 0")
    if type(repeats) is not int or repeats < 1:
        raise InputError(f"repeats = {repeats!r} must be an integer >= 1")
    sequences = list(sequences)
    if not sequences:
        raise InputError("no sequences to evaluate")
    labels = [name for name, _ in sequences]
    if len(set(labels)) != len(labels):
        raise InputError(f"sequence labels must be unique, got {labels}")

    evaluation = Evaluation([], methods, tuple(modes), window, repeats=repeats,
                            threads=torch.get_num_threads(), metrics=metrics, vdp_frames=vdp_frames,
                            missing=absent)
    span = evaluation.span = learned_span([m for m in methods if any((m, mode) not in absent for mode in modes)])
    sizes = {tuple(light.shape[1:]) for _, light in sequences}
    evaluation.frame_size = sizes.pop() if len(sizes) == 1 else None
    warmed: set[tuple[str, str]] = set()
    bar = tqdm(total=len(sequences) * (len(modes) * (1 + len(methods)) - len(absent)), desc="evaluate",
               unit="step", disable=not progress)
    for index, (name, light) in enumerate(sequences):
        light, peak = _checked_sequence(name, light)   # checked slice by slice, never copied whole
        if peak <= 0:
            raise InputError(f"sequence {name!r} is all zero: its peak cannot normalise the metrics")
        K, H, W = light.shape
        word_bytes = max(np.dtype(np.uint16 if configs[m].word_bits > 8 else np.uint8).itemsize
                         for m in modes)
        kept = len(modes) * (word_bytes + 4 * len(methods)) if keep else 0
        require_memory(K * H * W * (word_bytes + 4 + kept) + WORKING_BYTES,
                       f"evaluating sequence {name!r} ({K} x {H} x {W})")
        frames = scored_frames(light.shape[0], window, span)
        middle = (frames.start + frames.stop - 1) // 2
        strip = {"gt": np.array(light[middle], np.float64), "peak": peak, "frame": middle}
        for mode_index, mode in enumerate(modes):
            config = configs[mode]
            bar.set_postfix_str(f"{name} {mode} simulate")
            rng = np.random.default_rng([seed, index, mode_index])
            if mode in NOISE_MODES:
                words = simulate(config, light, rng, dark_current=NOISE_MODES[mode][1])
            else:
                words = simulate(config, light, rng)
            if keep:
                evaluation.streams[name, mode] = words
            bar.update()
            for method in methods:
                if (method, mode) in absent:
                    continue
                bar.set_postfix_str(f"{name} {label(method, mode)}")
                kwargs = {**(options or {}).get(method, {}),
                          **({"weights": weights[method, mode]} if (method, mode) in (weights or {}) else {})}
                if (mode, method) not in warmed:      # one-time costs (tables, torch) are not timed
                    reconstruct(words[:window, :4, :4], config, method, window=window, device=device, **kwargs)
                    warmed.add((mode, method))
                times = []
                for _ in range(repeats):
                    start = time.perf_counter()
                    images = reconstruct(words, config, method, window=window, device=device, **kwargs)
                    times.append(time.perf_counter() - start)
                seconds = float(np.median(times))
                pred, truth = images[frames], light[frames]
                values, counted = {}, 0
                for key in further:
                    subset = metric_subset(pred.shape[0], vdp_frames if key == "fovvideovdp" else None)
                    scores = score(pred[subset], np.asarray(truth[subset]), metrics=(key,), device=device)
                    values[key] = scores.sequence.get(key, scores.mean[key])
                    if key == "fovvideovdp":
                        counted = subset.stop - subset.start
                evaluation.results.append(Result(
                    name, mode, method,
                    float(np.mean(psnr_mu(pred, truth, peak=peak))),
                    float(np.mean(ssim_mu(pred, truth, peak=peak))),
                    1e3 * seconds / light.shape[0], int(pred.shape[0]), frames_vdp=counted, **values))
                strip[mode, method] = np.array(images[middle])     # a copy: the images can go
                if keep:
                    evaluation.images[name, mode, method] = images
                bar.update()
        evaluation.strips[name] = strip
    bar.close()
    return evaluation


def metric_subset(scored: int, count: int | None) -> slice:
    """The middle ``count`` of ``scored`` frames (all when None or more), indices into the scored frames."""
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


# ----------------------------------------------------------------- writers
#: Short column titles of the metrics (the full labels, units and display: :func:`metric_notes`).
HEADERS = {"psnr_mu": "PSNR-μ ↑", "ssim_mu": "SSIM-μ ↑", "psnr_pu21": "PU21-PSNR (dB) ↑",
           "hdr_vqm": "HDR-VQM ↓", "fovvideovdp": "FovVideoVDP (JOD) ↑"}
DIGITS = {"psnr_mu": 2, "ssim_mu": 3, "psnr_pu21": 2, "hdr_vqm": 3, "fovvideovdp": 3, "ms_per_frame": 2}
#: What an empty row of a method without weights says.
NO_WEIGHTS = "no weights"


def _fmt(value: float, digits: int) -> str:
    """``inf`` for a perfect PSNR, empty for a figure not measured (nan: run time over a store)."""
    return "" if math.isnan(value) else "inf" if math.isinf(value) else f"{value:.{digits}f}"


def _keys(evaluation: Evaluation) -> tuple[str, ...]:
    return (*evaluation.metrics, "ms_per_frame")


def _cells(evaluation: Evaluation, summary: dict, method: str, mode: str) -> list[str]:
    """Name, every metric, ms per frame of one method on one sensor (blank if not run,
    ``no weights`` where a learned method had none for the sensor)."""
    keys = _keys(evaluation)
    s = summary.get((method, mode))
    if s:
        return [label(method, mode)] + [_fmt(s[k], DIGITS[k]) for k in keys]
    if (method, mode) in evaluation.missing:
        return [label(method, mode), NO_WEIGHTS] + [""] * (len(keys) - 1)
    return [label(method, mode)] + [""] * len(keys)


def table_layout(evaluation: Evaluation) -> tuple[list[str], list[str]]:
    """(column sensors, extra-row sensors): the evaluated sensors of :data:`COLUMNS`
    get columns, in evaluation order; the others get rows under the first column.
    An evaluation without any of them gives every sensor a column. The noise
    sensors (:data:`NOISE_MODES`) have a table of their own (:func:`noise_markdown`)."""
    plain = [mode for mode in evaluation.modes if mode not in NOISE_MODES]
    columns = [mode for mode in plain if mode in COLUMNS] or plain
    return columns, [mode for mode in plain if mode not in columns]


def complexity_header() -> list[str]:
    return ["parameters", "GFLOPs / 384 x 512", "paper: parameters", "paper: FLOPs", "paper: s / frame (GPU)"]


def complexity_cells(evaluation: Evaluation, method: str) -> list[str]:
    """Measured parameters and FLOPs of a learned method (its TE weights), the paper's Table 10 beside."""
    from .complexity import paper_table10
    measured = evaluation.complexity.get(method)
    paper = paper_table10().get(method)
    cells = ([f"{measured['parameters']:,}", f"{measured['flops'] / 1e9:.1f}"] if measured
             else ["-", "-"] if method in ("tfp", "tfi") else ["", ""])
    cells += ([f"{paper.parameters / 1e6:.3f} M", f"{paper.flops / 1e12:.3f} T", f"{paper.seconds:.3f}"] if paper
              else ["-", "-", "-"])
    return cells


def table_rows(evaluation: Evaluation) -> list[list[str]]:
    """Table 1 layout: one row per method with the column sensors (ML msb, then TE),
    then one row per method of each extra sensor (ML-count) in the first column;
    with the complexity measured, its columns after the sensors' (rows of methods only)."""
    summary = evaluation.summary()
    columns, extra = table_layout(evaluation)
    width = 1 + len(_keys(evaluation))
    cost = bool(evaluation.complexity)
    rows = [[cell for mode in columns for cell in _cells(evaluation, summary, method, mode)]
            + (complexity_cells(evaluation, method) if cost else []) for method in evaluation.methods]
    blank = [""] * (width * (len(columns) - 1) + (len(complexity_header()) if cost else 0))
    rows += [_cells(evaluation, summary, method, mode) + blank for mode in extra for method in evaluation.methods]
    return rows


def timing_label(evaluation: Evaluation) -> str:
    """Run-time column title: median of how many runs, with how many torch threads."""
    return (f"ms / frame ↓ (median of {evaluation.repeats}, {evaluation.threads} "
            f"thread{'s' if evaluation.threads != 1 else ''})")


def _markdown(header: list[str], align: list[str], rows: list[list[str]]) -> list[str]:
    return (["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
            + ["| " + " | ".join(row) + " |" for row in rows])


def table_markdown(evaluation: Evaluation) -> str:
    """The paper's Table 1 layout in Markdown (the metrics and ms per frame per sensor):
    ML (msb) and TE columns, the full-count ML camera's rows beneath; then the noise
    table, the metrics' notes and the methods without weights, where there are any."""
    header, align = [], []
    for mode in table_layout(evaluation)[0]:
        header += [f"{name(mode)} reconstruction", *(HEADERS[k] for k in evaluation.metrics),
                   timing_label(evaluation)]
        align += [":---"] + ["---:"] * (len(evaluation.metrics) + 1)
    if evaluation.complexity:
        header += complexity_header()
        align += ["---:"] * len(complexity_header())
    lines = _markdown(header, align, table_rows(evaluation))
    if any(mode in NOISE_MODES for mode in evaluation.modes):
        lines += ["", *noise_markdown(evaluation)]
    notes = scoring_notes(evaluation) + metric_notes(evaluation) + missing_notes(evaluation)
    if notes:
        lines += ["", *notes]
    return "\n".join(lines) + "\n"


def metric_notes(evaluation: Evaluation) -> list[str]:
    """One line per further metric: its full label (units, display), and the frames it saw."""
    if evaluation.metrics == BASIC_METRICS:
        return []
    from .score import columns
    lines = [f"- {c.label}" + ("" if "better" in c.label else
                               f", {'higher' if c.higher_is_better else 'lower'} is better")
             for c in columns() if c.key in evaluation.metrics and c.key not in BASIC_METRICS]
    if "fovvideovdp" in evaluation.metrics:
        counts = sorted({r.frames_vdp for r in evaluation.results if r.frames_vdp})
        which = ("every scored frame" if evaluation.vdp_frames is None else
                 f"the middle {evaluation.vdp_frames} scored frames of each sequence")
        lines.append(f"- FovVideoVDP on {which} ({'/'.join(map(str, counts)) or 0}); every other metric on every "
                     "scored frame; HDR-VQM is the sequence value (15-frame tubes, fewer frames one tube), "
                     "the others frame means")
    return lines


def scoring_notes(evaluation: Evaluation) -> list[str]:
    """With a learned method in the run: which frames were scored, and why."""
    if evaluation.span is None:
        return []
    counts = sorted({r.frames_scored for r in evaluation.results})
    return [f"- frames scored per sequence: {'/'.join(map(str, counts))}, those whose {evaluation.window}-readout "
            f"window and, in sequences longer than {evaluation.span} readouts, whose {evaluation.span}-readout "
            "span of the learned methods lie inside the sequence (in shorter ones the learned methods see the "
            "end readouts repeated)"]


def missing_notes(evaluation: Evaluation) -> list[str]:
    """One line per missing weights file, with the cells it left empty."""
    by_reason: dict[str, list[str]] = {}
    for (method, mode), reason in evaluation.missing.items():
        by_reason.setdefault(reason, []).append(label(method, mode))
    return [f"- {', '.join(labels)}: {reason}" for reason, labels in by_reason.items()]


def noise_markdown(evaluation: Evaluation) -> list[str]:
    """The paper's Tables 6 to 9: the TE methods with shot noise only and with each dark current."""
    summary = evaluation.summary()
    modes = [m for m in ("te", *NOISE_MODES) if m in evaluation.modes]
    header, align = ["TE reconstruction"], [":---"]
    for mode in modes:
        what = f"dark current eq. {NOISE_MODES[mode][1][2:]}" if mode in NOISE_MODES else "shot noise only"
        header += [f"PSNR-μ ↑ ({what})", f"SSIM-μ ↑ ({what})"]
        align += ["---:", "---:"]
    rows = []
    for method in evaluation.methods:
        row = [label(method, "te")]
        for mode in modes:
            s = summary.get((method, mode))
            row += ([_fmt(s["psnr_mu"], 2), _fmt(s["ssim_mu"], 3)] if s else
                    [NO_WEIGHTS if (method, mode) in evaluation.missing else "", ""])
        rows.append(row)
    return _markdown(header, align, rows)


def table_csv(evaluation: Evaluation) -> str:
    """Table 1 as CSV, one row per method: method, then per sensor (key as in
    :data:`MODES`: ``ml-msb``, ``te``, ``ml``, and the noise sensors) name, every
    metric, ms_per_frame; then, with the complexity measured, its columns."""
    summary = evaluation.summary()
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    header = ["method"]
    for mode in evaluation.modes:
        header += [f"{mode}_name"] + [f"{mode}_{k}" for k in _keys(evaluation)]
    if evaluation.complexity:
        header += ["parameters", "gflops_384x512", "paper_parameters", "paper_flops", "paper_seconds_gpu"]
    writer.writerow(header)
    for method in evaluation.methods:
        row = [method] + ["" if cell == NO_WEIGHTS else cell for mode in evaluation.modes
                          for cell in _cells(evaluation, summary, method, mode)]
        if evaluation.complexity:
            measured = evaluation.complexity.get(method, {})
            from .complexity import paper_table10
            paper = paper_table10().get(method)
            row += [measured.get("parameters", ""), measured.get("flops", ""),
                    *((paper.parameters, paper.flops, paper.seconds) if paper else ("", "", ""))]
        writer.writerow(row)
    return buffer.getvalue()


def results_csv(evaluation: Evaluation) -> str:
    """Every sequence x mode x method, one row each (full precision)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    fields = [f.name for f in dataclasses.fields(Result)]
    writer.writerow(fields)
    for result in evaluation.results:
        writer.writerow([getattr(result, f) for f in fields])
    return buffer.getvalue()


def plot_quality_vs_time(evaluation: Evaluation, path: str | Path) -> None:
    """PNG: every metric computed against run time per frame, every method and mode, with a legend."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = evaluation.summary()
    keys = evaluation.metrics
    across = min(3, len(keys))
    down = -(-len(keys) // across)
    fig, axes = plt.subplots(down, across, figsize=(4.2 * across + 1.8, 3.6 * down + 0.4), squeeze=False)
    for axis in axes.flat[len(keys):]:
        axis.axis("off")
    axes = axes.flat[:len(keys)]
    markers = "osD^vP*X"
    colours = {"ml-msb": "tab:blue", "te": "tab:red", "ml": "tab:cyan", "te+eq12": "tab:orange",
               "te+eq13": "tab:brown"}
    for (method, mode), s in summary.items():     # marker: method, colour: sensor (the legend names both)
        marker = markers[evaluation.methods.index(method) % len(markers)]
        for axis, key in zip(axes, keys):
            if math.isfinite(s[key]) and math.isfinite(s["ms_per_frame"]):
                axis.scatter(s["ms_per_frame"], s[key], marker=marker, s=60,
                             color=colours.get(mode, "tab:gray"), label=label(method, mode))
    for axis, key in zip(axes, keys):
        axis.set_xscale("log")
        axis.set_xlabel("run time per frame (ms, log)")
        axis.set_ylabel(HEADERS[key])
        axis.grid(True, alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="center right", title="method_sensor", title_fontsize=7)
    count = len({r.sequence for r in evaluation.results})
    fig.suptitle(f"quality against run time, mean of {count} sequence(s), window {evaluation.window}; "
                 f"run time: median of {evaluation.repeats} runs, {evaluation.threads} torch "
                 f"thread{'s' if evaluation.threads != 1 else ''}", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1 - 1.6 / (4.2 * across + 1.8), 1))
    save_figure(fig, path)


def plot_strip(evaluation: Evaluation, sequence: str, path: str | Path) -> None:
    """PNG strip of one frame: ground truth and every method (mu-law, GT-peak normalised),
    with the error maps |T(method) - T(GT)| beneath, one pair of rows per mode."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    strip = evaluation.strips[sequence]
    peak = strip["peak"]
    truth = tone_map(strip["gt"], peak)
    methods, modes = evaluation.methods, evaluation.modes
    columns = 1 + len(methods)
    height, width = truth.shape
    scale = 2.4 / max(height, width) * max(width, height * 0.75)
    fig, axes = plt.subplots(2 * len(modes), columns, squeeze=False,
                             figsize=(columns * scale * width / max(height, width) + 0.6,
                                      2 * len(modes) * scale * height / max(height, width) + 0.6))
    error_image = None
    for m, mode in enumerate(modes):
        top, bottom = axes[2 * m], axes[2 * m + 1]
        top[0].imshow(truth, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        top[0].set_title("ground truth", fontsize=8)
        bottom[0].axis("off")
        for c, method in enumerate(methods, start=1):
            if (mode, method) not in strip:              # a learned method without weights here
                for axis in (top[c], bottom[c]):
                    axis.set_facecolor("0.85")
                top[c].set_title(f"{label(method, mode)} ({NO_WEIGHTS})", fontsize=8)
                continue
            mapped = tone_map(strip[mode, method], peak)
            psnr = next(r.psnr_mu for r in evaluation.results
                        if r.sequence == sequence and r.mode == mode and r.method == method)
            top[c].imshow(mapped, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            top[c].set_title(f"{label(method, mode)} ({psnr:.1f} dB)", fontsize=8)
            error_image = bottom[c].imshow(np.abs(mapped - truth), cmap="magma", vmin=0,
                                           vmax=ERROR_RANGE, interpolation="nearest")
            bottom[c].set_title(f"|error| {label(method, mode)}", fontsize=8)
        for axis in list(top) + list(bottom):
            axis.set_xticks([])
            axis.set_yticks([])
    fig.suptitle(f"{sequence}, frame {strip['frame']}: μ-law (μ = 5000) of light / GT peak", fontsize=9)
    fig.tight_layout()
    if error_image is not None:          # the colour scale sits in the empty cell left of the errors
        for m in range(len(modes)):
            holder = axes[2 * m + 1, 0]
            bar = fig.colorbar(error_image, cax=holder.inset_axes([0.42, 0.05, 0.12, 0.9]))
            bar.ax.tick_params(labelsize=7)
            bar.set_label("|error|", fontsize=7)
    save_figure(fig, path)


def safe_name(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name) or "sequence"


def write_outputs(evaluation: Evaluation, out: str | Path) -> dict[str, Path]:
    """Write table.md, table.csv, results.csv, quality_vs_time.png and strips/<seq>.png into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "strips").mkdir(exist_ok=True)
    paths = {"table.md": out / "table.md", "table.csv": out / "table.csv",
             "results.csv": out / "results.csv", "plot": out / "quality_vs_time.png"}
    write_text(paths["table.md"], table_markdown(evaluation))
    write_text(paths["table.csv"], table_csv(evaluation))
    write_text(paths["results.csv"], results_csv(evaluation))
    plot_quality_vs_time(evaluation, paths["plot"])
    used: set[str] = set()
    for sequence in evaluation.strips:
        stem = safe_name(sequence)
        while stem in used:                       # "a b" and "a_b" must not share a file
            stem += "_"
        used.add(stem)
        paths[f"strip:{sequence}"] = out / "strips" / f"{stem}.png"
        plot_strip(evaluation, sequence, paths[f"strip:{sequence}"])
    return paths
