"""The report of an evaluation: the paper's Table 1 (Markdown, CSV), every result, the plots and strips.

:func:`tespike.recon.evaluate.evaluate` (or :func:`tespike.recon.dataset.evaluate.evaluate_store`) measures;
this module only lays out what an :class:`tespike.recon.evaluate.Evaluation` holds, so a table
can be re-laid without re-running anything.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from pathlib import Path

import numpy as np

from tespike.golden.errors import InputError, check_flag
from tespike.golden.paths import path_text

from .evaluate import BASIC_METRICS, CALIBRATED, NOISE_SENSORS, Evaluation, Measurement
from .names import label, name
from .mulaw import MU, tone_map
from .pictures import ERROR_RANGE, save_figure, write_text

#: Sensors that get a column of Table 1; any other evaluated sensor gets extra rows.
COLUMNS = ("ml-msb", "te")
#: Files :func:`write_outputs` writes into its folder (``strips/*.png``: one strip per sequence;
#: :func:`tespike.golden.paths.check_results_dir` reads the folder pattern).
OUTPUT_FILES = ("table.md", "table.csv", "results.csv", "quality_vs_time.png", "strips/", "strips/*.png")
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


def _cells(evaluation: Evaluation, summary: dict, method: str, sensor: str) -> list[str]:
    """Name, every metric, ms per frame of one method on one sensor (blank if not run,
    ``no weights`` where a learned method had none for the sensor)."""
    keys = _keys(evaluation)
    s = summary.get((method, sensor))
    if s:
        return [label(method, sensor)] + [_fmt(s[k], DIGITS[k]) for k in keys]
    if (method, sensor) in evaluation.missing:
        return [label(method, sensor), NO_WEIGHTS] + [""] * (len(keys) - 1)
    return [label(method, sensor)] + [""] * len(keys)


def table_layout(evaluation: Evaluation) -> tuple[list[str], list[str]]:
    """(column sensors, extra-row sensors), in evaluation order: the full-count ML camera
    (``ml``) gets rows beneath the ML (msb) column when that is the first column (the
    paper's Table 1 with its extra rows, both ML cameras under one title); otherwise, and
    for every other sensor, a column of its own, so no row sits under another camera's
    title. The noise sensors (:data:`NOISE_SENSORS`, ``Evaluation.noise_sensors``) and
    their calibrated ``+cal`` sensors have a table of their own (:func:`noise_markdown`)."""
    plain = [sensor for sensor in evaluation.sensors
             if sensor not in NOISE_SENSORS and sensor not in evaluation.noise_sensors]
    first = [sensor for sensor in plain if sensor in COLUMNS][:1]
    extra = [sensor for sensor in plain if sensor == "ml"] if first == ["ml-msb"] else []
    return [sensor for sensor in plain if sensor not in extra], extra


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
    rows = [[cell for sensor in columns for cell in _cells(evaluation, summary, method, sensor)]
            + (complexity_cells(evaluation, method) if cost else []) for method in evaluation.methods]
    blank = [""] * (width * (len(columns) - 1) + (len(complexity_header()) if cost else 0))
    rows += [_cells(evaluation, summary, method, sensor) + blank for sensor in extra for method in evaluation.methods]
    return rows


def run_time_label(evaluation: Evaluation) -> str:
    """Run-time column title: median of how many runs, with how many torch threads."""
    return (f"ms / frame ↓ (median of {evaluation.repeats}, {evaluation.threads} "
            f"thread{'s' if evaluation.threads != 1 else ''})")


def _markdown(header: list[str], align: list[str], rows: list[list[str]]) -> list[str]:
    return (["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
            + ["| " + " | ".join(row) + " |" for row in rows])


def check_evaluation(evaluation, what: str) -> Evaluation:
    """``evaluation``, an :class:`tespike.recon.evaluate.Evaluation`, refused in one line naming ``what``
    otherwise (a dict or a path had been an AttributeError deep in the table)."""
    if not isinstance(evaluation, Evaluation):
        raise InputError(f"{what}: the evaluation must be an Evaluation, not {type(evaluation).__name__}")
    return evaluation


def table_markdown(evaluation: Evaluation) -> str:
    """The paper's Table 1 layout in Markdown (the metrics and ms per frame per sensor):
    ML (msb) and TE columns, the full-count ML camera's rows beneath; then the noise
    table, the metrics' notes and the methods without weights, where there are any."""
    check_evaluation(evaluation, "table_markdown")
    header, align = [], []
    for sensor in table_layout(evaluation)[0]:
        header += [f"{name(sensor)} reconstruction", *(HEADERS[k] for k in evaluation.metrics),
                   run_time_label(evaluation)]
        align += [":---"] + ["---:"] * (len(evaluation.metrics) + 1)
    if evaluation.complexity:
        header += complexity_header()
        align += ["---:"] * len(complexity_header())
    lines = _markdown(header, align, table_rows(evaluation))
    if any(sensor in NOISE_SENSORS or sensor in evaluation.noise_sensors for sensor in evaluation.sensors):
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
    for (method, sensor), reason in evaluation.missing.items():
        by_reason.setdefault(reason, []).append(label(method, sensor))
    return [f"- {', '.join(labels)}: {reason}" for reason, labels in by_reason.items()]


def noise_what(evaluation: Evaluation, sensor: str) -> str:
    """Column title of a noise sensor: the paper's dark current, else the options its
    :class:`tespike.golden.noise.SensorNoise` sets (``shot noise only`` for an ideal sensor)."""
    if sensor in NOISE_SENSORS:
        return f"dark current eq. {NOISE_SENSORS[sensor][1][2:]}"
    if sensor not in evaluation.noise_sensors:
        return "shot noise only"
    noise = evaluation.noise_sensors[sensor].noise
    ideal = type(noise)().to_dict()
    changed = {k: v for k, v in noise.to_dict().items() if v != ideal[k]}
    return ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}" for k, v in changed.items())


def noise_markdown(evaluation: Evaluation) -> list[str]:
    """The paper's Tables 6 to 9: the TE methods with shot noise only and with each noise
    sensor, a row as the method reconstructs and, where a ``+cal`` sensor was run, a row
    with the sensor's calibration."""
    summary = evaluation.summary()
    noisy = [s for s in evaluation.sensors if s in evaluation.noise_sensors and not s.endswith(CALIBRATED)]
    noisy += [s[:-len(CALIBRATED)] for s in evaluation.sensors if s.endswith(CALIBRATED)
              and s in evaluation.noise_sensors and s[:-len(CALIBRATED)] not in noisy]
    noisy += [s for s in evaluation.sensors if s in NOISE_SENSORS and s not in noisy]  # a store's, no Sensor kept
    sensors = [s for s in ("te",) if s in evaluation.sensors] + noisy
    calibrated = any(s.endswith(CALIBRATED) for s in evaluation.sensors)
    header, align = ["TE reconstruction"], [":---"]
    for sensor in sensors:
        what = noise_what(evaluation, sensor)
        header += [f"PSNR-μ ↑ ({what})", f"SSIM-μ ↑ ({what})"]
        align += ["---:", "---:"]
    rows = []
    for method in evaluation.methods:
        for suffix in (("", CALIBRATED) if calibrated else ("",)):
            row = [label(method, "te") + (" (calibrated)" if suffix else "")]
            for sensor in sensors:
                if suffix and sensor not in evaluation.noise_sensors:      # nothing to calibrate
                    row += ["-", "-"]
                    continue
                key = sensor + suffix
                s = summary.get((method, key))
                row += ([_fmt(s["psnr_mu"], 2), _fmt(s["ssim_mu"], 3)] if s else
                        [NO_WEIGHTS if (method, key) in evaluation.missing else "", ""])
            rows.append(row)
    return _markdown(header, align, rows)


def table_csv(evaluation: Evaluation) -> str:
    """Table 1 as CSV, one row per method: method, then per sensor (key as in
    :data:`tespike.recon.evaluate.SENSORS`: ``ml-msb``, ``te``, ``ml``, and the noise sensors) name, every
    metric, ms_per_frame; then, with the complexity measured, its columns."""
    check_evaluation(evaluation, "table_csv")
    summary = evaluation.summary()
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    header = ["method"]
    for sensor in evaluation.sensors:
        header += [f"{sensor}_name"] + [f"{sensor}_{k}" for k in _keys(evaluation)]
    if evaluation.complexity:
        header += ["parameters", "gflops_384x512", "paper_parameters", "paper_flops", "paper_seconds_gpu"]
    writer.writerow(header)
    for method in evaluation.methods:
        row = [method] + ["" if cell == NO_WEIGHTS else cell for sensor in evaluation.sensors
                          for cell in _cells(evaluation, summary, method, sensor)]
        if evaluation.complexity:
            measured = evaluation.complexity.get(method, {})
            from .complexity import paper_table10
            paper = paper_table10().get(method)
            row += [measured.get("parameters", ""), measured.get("flops", ""),
                    *((paper.parameters, paper.flops, paper.seconds) if paper else ("", "", ""))]
        writer.writerow(row)
    return buffer.getvalue()


def results_csv(evaluation: Evaluation) -> str:
    """Every sequence x sensor x method, one row each (full precision)."""
    check_evaluation(evaluation, "results_csv")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    fields = [f.name for f in dataclasses.fields(Measurement)]
    writer.writerow(fields)
    for result in evaluation.results:
        writer.writerow([getattr(result, f) for f in fields])
    return buffer.getvalue()


def plot_quality_vs_time(evaluation: Evaluation, path: str | Path) -> None:
    """PNG: every metric computed against run time per frame, every method and sensor, with a legend."""
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
    for (method, sensor), s in summary.items():     # marker: method, colour: sensor (the legend names both)
        marker = markers[evaluation.methods.index(method) % len(markers)]
        for axis, key in zip(axes, keys):
            if math.isfinite(s[key]) and math.isfinite(s["ms_per_frame"]):
                axis.scatter(s["ms_per_frame"], s[key], marker=marker, s=60,
                             color=colours.get(sensor, "tab:gray"), label=label(method, sensor))
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
    with the error maps |T(method) - T(GT)| beneath, one pair of rows per sensor."""
    check_evaluation(evaluation, "plot_strip")
    if sequence not in evaluation.strips:                # (a KeyError)
        raise InputError(f"plot_strip: no sequence {sequence!r} in this evaluation "
                         f"(its sequences: {', '.join(evaluation.strips) or 'none'})")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    strip = evaluation.strips[sequence]
    peak = strip["peak"]
    truth = tone_map(strip["gt"], peak)
    methods, sensors = evaluation.methods, evaluation.sensors
    columns = 1 + len(methods)
    height, width = truth.shape
    scale = 2.4 / max(height, width) * max(width, height * 0.75)
    fig, axes = plt.subplots(2 * len(sensors), columns, squeeze=False,
                             figsize=(columns * scale * width / max(height, width) + 0.6,
                                      2 * len(sensors) * scale * height / max(height, width) + 0.6))
    error_image = None
    for m, sensor in enumerate(sensors):
        top, bottom = axes[2 * m], axes[2 * m + 1]
        top[0].imshow(truth, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        top[0].set_title("ground truth", fontsize=8)
        bottom[0].axis("off")
        for c, method in enumerate(methods, start=1):
            if (sensor, method) not in strip:              # a learned method without weights here
                for axis in (top[c], bottom[c]):
                    axis.set_facecolor("0.85")
                top[c].set_title(f"{label(method, sensor)} ({NO_WEIGHTS})", fontsize=8)
                continue
            mapped = tone_map(strip[sensor, method], peak)
            psnr = next(r.psnr_mu for r in evaluation.results
                        if r.sequence == sequence and r.sensor == sensor and r.method == method)
            top[c].imshow(mapped, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            top[c].set_title(f"{label(method, sensor)} ({psnr:.1f} dB)", fontsize=8)
            error_image = bottom[c].imshow(np.abs(mapped - truth), cmap="magma", vmin=0,
                                           vmax=ERROR_RANGE, interpolation="nearest")
            bottom[c].set_title(f"|error| {label(method, sensor)}", fontsize=8)
        for axis in list(top) + list(bottom):
            axis.set_xticks([])
            axis.set_yticks([])
    fig.suptitle(f"{sequence}, frame {strip['frame']}: μ-law (μ = {MU:g}) of light / GT peak", fontsize=9)
    fig.tight_layout()
    if error_image is not None:          # the colour scale sits in the empty cell left of the errors
        for m in range(len(sensors)):
            holder = axes[2 * m + 1, 0]
            bar = fig.colorbar(error_image, cax=holder.inset_axes([0.42, 0.05, 0.12, 0.9]))
            bar.ax.tick_params(labelsize=7)
            bar.set_label("|error|", fontsize=7)
    save_figure(fig, path)


def safe_name(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name) or "sequence"


def write_outputs(evaluation: Evaluation, out: str | Path, *, plot: bool = True) -> dict[str, Path]:
    """Write table.md, table.csv, results.csv, quality_vs_time.png and strips/<seq>.png into ``out``
    -> the paths written (key ``plot`` for the plot, ``strip:<sequence>`` for the strips).
    ``plot=False`` leaves the quality-against-run-time plot out (an evaluation over a dataset
    store, whose scores come from many workers, has no comparable run times)."""
    check_flag(plot, "plot")                             # ('no' had written the plot)
    check_evaluation(evaluation, "write_outputs")
    out = Path(path_text(out, "results folder"))
    if out.exists() and not out.is_dir():                # (mkdir's FileExistsError)
        raise InputError(f"results folder {str(out)!r} is a file, not a folder")
    if not out.parent.is_dir():                          # (never made: a folder removed during a run, and the
        raise InputError(f"results folder {str(out)!r}: its folder {str(out.parent)!r} does not exist "
                         "(removed during the run?)")     # one holding it, had been made again, half-filled)
    out.mkdir(exist_ok=True)
    (out / "strips").mkdir(exist_ok=True)
    paths = {"table.md": out / "table.md", "table.csv": out / "table.csv", "results.csv": out / "results.csv"}
    write_text(paths["table.md"], table_markdown(evaluation))
    write_text(paths["table.csv"], table_csv(evaluation))
    write_text(paths["results.csv"], results_csv(evaluation))
    if plot:
        paths["plot"] = out / "quality_vs_time.png"
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
