"""``tespike demo``: circuit to image in one command, on the built-in moving HDR scene.

Stages (each timed, each written, each with the individual command that redoes it):

1. scene: the shipped CC0 panorama, panned (``I.npy``);
2. golden, full frame: TE from the per-clock electrons of
   :func:`golden.fastsim.iter_scene_stimulus` through the cycle-exact
   :class:`golden.sensor.PixelArray` (so the RTL crop below gets literally the
   electrons the golden model got), ML count and ML msb with the fast
   simulator :func:`golden.fastsim.simulate_scene` (same law); ``S_<sensor>.npz``;
3. RTL: the TE pixel array (Amaranth by default, pixels inlined, no build) on a
   crop of those electrons (``E_crop.npy``), with a VCD and a GTKWave save file
   opening on one readout interval; the stream is rebuilt from the VCD with
   vcdvcd (:func:`cosim.vcd.waveform_stream`) and compared with the golden
   stream of the same pixels and readouts: "bit-identical", or the first
   differing readout, pixel and both words (``verdict.txt``, exit 1);
4. reconstruction: every method of :data:`recon.methods.METHODS` on every
   golden stream (:func:`recon.evaluate.evaluate`: PSNR-mu / SSIM-mu, run time
   the median of repeats) and on the RTL's own stream;
5. dynamic range (formula and measured, :mod:`golden.dynamic_range`) and a
   small hardware cost table (Yosys, when installed);
6. pictures and ``report.md``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from golden.config import SensorConfig
from golden.errors import InputError

#: Sensors of the golden full frame: file label -> config preset (paper section 6.1 and eq. 10),
#: in :data:`recon.evaluate.MODES` order: the paper's ML (msb) camera, TE, the full-count ML camera.
SENSORS = {"ml-msb": "ml-msb", "te": "te", "ml": "ml"}
#: The sensor the RTL runs (the paper's subject).
RTL_SENSOR = "te"
BACKENDS = ("amaranth", "verilator", "icarus")
#: Smallest crop and readouts the README's demo uses (the options may ask for less, e.g. in tests).
DEFAULT_CROP, DEFAULT_RTL_READOUTS = 16, 16
#: Smallest crop: SSIM's 11 x 11 Gaussian window must fit.
MIN_CROP = 11


@dataclasses.dataclass
class Stage:
    name: str
    seconds: float
    commands: list[str]


class Progress:
    """One line per stage on stderr, with the time it took."""

    def __init__(self, total: int, quiet: bool = False):
        self.total, self.done, self.quiet = total, 0, quiet
        self.stages: list[Stage] = []
        self.start = time.perf_counter()

    def begin(self, what: str) -> float:
        self.done += 1
        if not self.quiet:
            print(f"[{self.done}/{self.total}] {what} ...", file=sys.stderr, flush=True)
        return time.perf_counter()

    def end(self, name: str, started: float, commands: list[str]) -> None:
        seconds = time.perf_counter() - started
        self.stages.append(Stage(name, seconds, commands))
        if not self.quiet:
            print(f"      {name}: {seconds:.1f} s", file=sys.stderr, flush=True)


def _save_npy(path: Path, array: np.ndarray) -> None:
    from golden.io import atomic_output
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, array)


def choose_crop(light: np.ndarray, size: int) -> tuple[int, int]:
    """Top-left corner of the ``size`` x ``size`` crop holding the brightest pixel of the
    sequence's mean frame (centred on it, kept inside the frame): dark and bright pixels
    side by side, the part of the scene an HDR sensor is about."""
    mean = light.mean(axis=0)
    r, c = np.unravel_index(int(np.argmax(mean)), mean.shape)
    H, W = mean.shape
    return (int(min(max(0, r - size // 2), H - size)), int(min(max(0, c - size // 2), W - size)))


def first_difference(rtl: np.ndarray, golden: np.ndarray) -> dict | None:
    """``None`` if identical, else readout, pixel and both words of the first difference."""
    differ = np.argwhere(rtl != golden)
    if len(differ) == 0:
        return None
    k, r, c = (int(i) for i in differ[0])
    return {"count": int(len(differ)), "readout": k, "row": r, "col": c,
            "rtl": int(rtl[k, r, c]), "golden": int(golden[k, r, c])}


def median_seconds(function, repeats: int) -> tuple[float, object]:
    """Median wall time of ``repeats`` calls, and the last call's result."""
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


# ---------------------------------------------------------------- hardware cost
def hardware_cost(configs: dict[str, SensorConfig], yosys: str = "yosys") -> list[dict] | str:
    """Per sensor: Yosys ``synth`` cells and flip-flops of one pixel and of the shared timing
    block, and a CMOS transistor estimate (``abc -g cmos3``, ``stat -tech cmos``). A string
    says why there is no table (Yosys missing or failing)."""
    if shutil.which(yosys) is None:
        return f"Yosys ({yosys!r}) is not installed"
    from rtl.verilog import module_names, pixel_verilog, timing_verilog

    rows = []
    for label, config in configs.items():
        try:
            row = {"sensor": label, "config": config}
            names = module_names(config)
            for part, text, top in (("pixel", pixel_verilog(config), names["pixel"]),
                                    ("timing", timing_verilog(config), names["timing"])):
                row[part] = _synthesize(text, top, yosys)
        except Exception as exc:       # the RTL or Yosys refused: say so in the report, not a crash
            return f"{label}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        rows.append(row)
    return rows


def _synthesize(verilog: str, top: str, yosys: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "design.v"
        src.write_text(verilog)
        script = (f"read_verilog {src}; synth -top {top}; tee -q -o {tmp}/generic.json stat -json; "
                  f"dfflegalize -cell $_DFF_P_ 01; abc -g cmos3; opt_clean; "
                  f"tee -q -o {tmp}/cmos.json stat -json -tech cmos")
        result = subprocess.run([yosys, "-q", "-p", script], capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError((result.stderr or result.stdout).strip().splitlines()[-1:] or ["yosys failed"])
        generic = _stat(json.loads((Path(tmp) / "generic.json").read_text()))
        cmos = _stat(json.loads((Path(tmp) / "cmos.json").read_text()))
    return {"cells": generic["cells"], "flops": generic["flops"], "transistors": cmos["transistors"]}


def _stat(data: dict) -> dict:
    design = data.get("design") or next(iter((data.get("modules") or {"": {}}).values()))
    by_type = design.get("num_cells_by_type", {})
    return {"cells": int(design.get("num_cells", 0)),
            "flops": sum(n for kind, n in by_type.items() if "DFF" in kind or "DLATCH" in kind),
            "transistors": str(design.get("estimated_num_transistors", "?"))}


# ---------------------------------------------------------------- pictures
def _figure_save(fig, path: Path) -> None:
    import matplotlib.pyplot as plt

    from golden.io import atomic_output
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def plot_frame(light: np.ndarray, frame: int, crop: tuple[int, int, int], path: Path) -> None:
    """Tone-mapped ground truth of one frame with the RTL crop marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from recon.evaluate import tone_map
    y, x, size = crop
    H, W = light.shape[1:]
    fig, axis = plt.subplots(figsize=(6.4, 6.4 * H / W + 0.5))
    axis.imshow(tone_map(light[frame], float(light.max())), cmap="gray", vmin=0, vmax=1,
                interpolation="nearest")
    axis.add_patch(Rectangle((x - 0.5, y - 0.5), size, size, fill=False, edgecolor="red", linewidth=1.5))
    axis.annotate("RTL crop", (x + size, y), color="red", fontsize=8, xytext=(3, -3),
                  textcoords="offset points", va="top")
    axis.set_xticks([])
    axis.set_yticks([])
    axis.set_title(f"ground truth, frame {frame}: μ-law (μ = 5000) of light / sequence peak; "
                   f"RTL crop rows {y}..{y + size - 1}, columns {x}..{x + size - 1}", fontsize=8)
    fig.tight_layout()
    _figure_save(fig, path)


def plot_rtl_crop(truth: np.ndarray, rtl_images: dict, golden_images: dict, peak: float,
                  frame: int, path: Path) -> None:
    """The crop at one frame: ground truth, each method on the RTL stream and on the golden
    full frame, and the |error| maps of the RTL's with a colour bar."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from recon.evaluate import ERROR_RANGE, tone_map
    methods = list(rtl_images)
    gt = tone_map(truth, peak)
    fig, axes = plt.subplots(3, 1 + len(methods), squeeze=False, figsize=(2.1 * (1 + len(methods)) + 0.6, 6.6))
    axes[0, 0].imshow(gt, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    axes[0, 0].set_title("ground truth", fontsize=8)
    axes[1, 0].axis("off")
    axes[2, 0].axis("off")
    shown = None
    for c, method in enumerate(methods, start=1):
        rtl = tone_map(rtl_images[method], peak)
        axes[0, c].imshow(rtl, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axes[0, c].set_title(f"{method.upper()} on the RTL stream", fontsize=8)
        axes[1, c].imshow(tone_map(golden_images[method], peak), cmap="gray", vmin=0, vmax=1,
                          interpolation="nearest")
        axes[1, c].set_title(f"{method.upper()}, golden full frame", fontsize=8)
        shown = axes[2, c].imshow(np.abs(rtl - gt), cmap="magma", vmin=0, vmax=ERROR_RANGE,
                                  interpolation="nearest")
        axes[2, c].set_title(f"|error| {method.upper()} (RTL)", fontsize=8)
    for axis in axes.flat:
        axis.set_xticks([])
        axis.set_yticks([])
    fig.suptitle(f"RTL crop, frame {frame}: μ-law (μ = 5000) of light / sequence peak", fontsize=9)
    fig.tight_layout()
    if shown is not None:
        bar = fig.colorbar(shown, cax=axes[2, 0].inset_axes([0.42, 0.05, 0.12, 0.9]))
        bar.set_label("|error| of μ-law images", fontsize=7)
        bar.ax.tick_params(labelsize=7)
    _figure_save(fig, path)


# ---------------------------------------------------------------- the demo
def run_demo(out, *, frames: int = 32, height: int = 96, width: int = 128, seed: int = 0,
             crop: int = DEFAULT_CROP, rtl_readouts: int = DEFAULT_RTL_READOUTS,
             backend: str = "amaranth", repeats: int = 3, window: int = 9, hw_cost: bool = True,
             sensors=tuple(SENSORS), quiet: bool = False, bars: bool | None = None) -> int:
    """Run every stage into folder ``out``; 0 if the RTL stream is bit-identical to golden, else 1.

    ``quiet``: no stage lines and no table; ``bars``: progress bars within the stages
    (default: when not quiet and stderr is a terminal).
    """
    from golden.config import load_config
    from golden.fastsim import iter_scene_stimulus, simulate_scene
    from golden.io import save_images, save_stream
    from golden.sensor import PixelArray, simulate
    from recon.scenes import make_scene

    for key, value, low in (("--frames", frames, 1), ("--height", height, 1), ("--width", width, 1),
                            ("--crop", crop, 1), ("--rtl-readouts", rtl_readouts, 1), ("--repeats", repeats, 1),
                            ("--seed", seed, 0)):
        if value < low:
            raise InputError(f"{key} {value}: must be >= {low}")
    if crop < MIN_CROP:
        raise InputError(f"--crop {crop}: must be >= {MIN_CROP} (SSIM-mu of the crop needs {MIN_CROP} x {MIN_CROP})")
    if crop > min(height, width):
        raise InputError(f"--crop {crop}: larger than the {height} x {width} frame")
    if rtl_readouts > frames:
        raise InputError(f"--rtl-readouts {rtl_readouts}: more than the {frames} frames of the scene")
    if backend not in BACKENDS:
        raise InputError(f"--backend {backend!r}: one of {', '.join(BACKENDS)}")
    if window < 1 or window % 2 == 0:
        raise InputError(f"--window {window}: must be an odd integer >= 1")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    progress = Progress(6, quiet)
    if bars is None:
        bars = not quiet and sys.stderr.isatty()
    sensors = tuple(sensors)
    unknown = [name for name in sensors if name not in SENSORS]
    if unknown or not sensors or RTL_SENSOR not in sensors or len(set(sensors)) != len(sensors):
        raise InputError(f"--sensors {','.join(sensors)!r}: a list of distinct sensors among "
                         f"{', '.join(SENSORS)}, with {RTL_SENSOR!r} (the RTL's)")
    configs = {label: load_config(SENSORS[label]) for label in sensors}
    te = configs[RTL_SENSOR]
    L = te.clocks_per_readout

    # 1. scene
    started = progress.begin(f"scene: pan over the shipped CC0 panorama, {frames} x {height} x {width}")
    light = make_scene("default", frames, height, width, seed=seed)
    _save_npy(out / "I.npy", light)
    progress.end("scene", started, [f"tespike scene --name default --frames {frames} --height {height} "
                                    f"--width {width} --seed {seed} --out I.npy"])

    # 2. golden full frame; TE through the per-clock electrons the RTL crop will get
    started = progress.begin("golden model, full frame: TE (per-clock electrons, cycle-exact), "
                             "ML count and ML msb (fast simulator)")
    y, x = choose_crop(light, crop)
    streams = {}
    array = PixelArray(te, (height, width))
    words_te = np.empty((frames, height, width), np.int64)
    crop_stimulus = np.empty((rtl_readouts * L, crop, crop), np.uint16)
    electrons = iter_scene_stimulus(te, light, seed=seed)
    if bars:
        from tqdm import tqdm
        electrons = tqdm(electrons, total=frames, desc="golden te", unit="readout", leave=False)
    for k, e in enumerate(electrons):
        words_te[k] = array.feed(e)[0]
        if k < rtl_readouts:
            crop_stimulus[k * L:(k + 1) * L] = e[:, y:y + crop, x:x + crop]
    for label, config in configs.items():
        streams[label] = words_te if label == RTL_SENSOR else simulate_scene(config, light, seed=seed)
        save_stream(out / f"S_{label}.npz", streams[label], config)
    _save_npy(out / "E_crop.npy", crop_stimulus)
    commands = [f"tespike stimulus --config te --scene I.npy --seed {seed} --out E_te.npy   "
                f"# {frames * L * height * width * 2 / 2**20:.0f} MiB",
                "tespike golden --config te --stimulus E_te.npy --out S_te.npz",
                f"tespike simulate --config te --scene I.npy --seed {seed} --method per-clock --out S_te.npz"
                "   # the same words, without the file"]
    commands += [f"tespike simulate --config {SENSORS[label]} --scene I.npy --seed {seed} --out S_{label}.npz"
                 for label in configs if label != RTL_SENSOR]
    progress.end("golden, full frame", started, commands)

    # 3. RTL on the crop
    started = progress.begin(f"RTL ({backend}): TE array of {crop} x {crop} pixels, {rtl_readouts} readouts "
                             f"({rtl_readouts * L} clocks) at rows {y}.., columns {x}..")
    expected = simulate(te, crop_stimulus)
    consistent = bool(np.array_equal(expected, words_te[:rtl_readouts, y:y + crop, x:x + crop]))
    if not consistent:           # the generator and the engine disagree: a bug, not a verdict
        raise RuntimeError("golden on the crop stimulus differs from the full frame's crop")
    rtl_info = {"backend": backend, "vcd": None}
    if backend == "amaranth":
        from cosim.rtlsim import rtl_run
        from cosim.vcd import waveform_stream
        run = rtl_run(te, crop_stimulus, vcd_path=out / "W.vcd", gtkw_path=out / "W.gtkw", flat=True,
                      progress=bars)
        read_started = time.perf_counter()
        wave = waveform_stream(out / "W.vcd", te, (crop, crop))
        rtl_info.update(vcd="W.vcd", gtkw="W.gtkw", latency=run.latency, cycles=run.cycles,
                        sim_seconds=run.seconds, read_seconds=time.perf_counter() - read_started,
                        live_equals_vcd=bool(np.array_equal(run.words, wave.words)),
                        vcd_bytes=(out / "W.vcd").stat().st_size)
        rtl_words = wave.words
    else:
        from cosim.commands.rtl_sim_cmd import _backend, _check_backend_words
        rtl_words = _check_backend_words(_backend(backend)(te, crop_stimulus), te, crop_stimulus, backend)
    save_stream(out / "S_rtl.npz", rtl_words, te)
    difference = first_difference(np.asarray(rtl_words), expected)
    verdict = verdict_text(difference, backend, rtl_readouts, crop, (y, x))
    from recon.evaluate import write_text
    write_text(out / "verdict.txt", verdict + "\n")
    rerun = (f"tespike stimulus --config te --scene I.npy --seed {seed} --crop {y},{x},{crop},{crop} "
             f"--readouts {rtl_readouts} --out E_crop.npy")
    rtl_cmd = (f"tespike rtl-sim --config te --stimulus E_crop.npy --out S_rtl.npz --check"
               + (" --vcd W.vcd" if backend == "amaranth" else f" --backend {backend}"))
    progress.end(f"RTL ({backend})", started, [rerun, rtl_cmd])
    if not quiet:
        print(f"      RTL verdict: {verdict}", file=sys.stderr, flush=True)

    # 4. reconstruction: every method on every golden stream, and on the RTL's own stream
    started = progress.begin("reconstruction: every method on every stream (run time: median of "
                             f"{repeats}) and on the RTL stream")
    from recon.evaluate import evaluate, label, scored_frames, write_outputs
    from recon.methods import METHODS, reconstruct
    from recon.metrics import psnr_mu, ssim_mu
    by_config = {configs[name]: streams[name] for name in configs}
    evaluation = evaluate([("default", light)], lambda config, scene, rng: by_config[config],
                          modes=tuple(configs), configs=configs, window=window, seed=seed,
                          progress=bars, keep=True, repeats=repeats)
    paths = write_outputs(evaluation, out)
    for (_, mode, method), images in evaluation.images.items():
        save_images(out / f"R_{method}_{mode}.npy", images)
    peak = float(light.max())
    truth = light[:rtl_readouts, y:y + crop, x:x + crop]
    scored = scored_frames(rtl_readouts, window)
    rtl_rows, rtl_images, golden_images = [], {}, {}
    middle = (scored.start + scored.stop - 1) // 2
    for method in METHODS:
        seconds, images = median_seconds(lambda: reconstruct(rtl_words, te, method, window=window), repeats)
        save_images(out / f"R_{method}_rtl.npy", images)
        full = evaluation.images["default", RTL_SENSOR, method][:rtl_readouts, y:y + crop, x:x + crop]
        rtl_images[method], golden_images[method] = images[middle], full[middle]
        rtl_rows.append({
            "method": method,
            "rtl_psnr": float(np.mean(psnr_mu(images[scored], truth[scored], peak=peak))),
            "rtl_ssim": float(np.mean(ssim_mu(images[scored], truth[scored], peak=peak))),
            "golden_psnr": float(np.mean(psnr_mu(full[scored], truth[scored], peak=peak))),
            "golden_ssim": float(np.mean(ssim_mu(full[scored], truth[scored], peak=peak))),
            "max_diff": float(np.max(np.abs(images[scored] - full[scored]))),
            "ms_per_frame": 1e3 * seconds / rtl_readouts})
    progress.end("reconstruction", started,
                 [f"tespike reconstruct --stream S_{mode}.npz --method {method} --window {window} "
                  f"--out R_{method}_{mode}.npy" for mode in list(configs) + ["rtl"] for method in METHODS]
                 + [f"tespike evaluate --set default --frames {frames} --height {height} --width {width} "
                    f"--seed {seed} --out eval   # Table 1 layout, TE and ML count, other noise draws"])

    # 5. dynamic range and hardware cost
    started = progress.begin("dynamic range (formula and measured)" + (" and hardware cost (Yosys)"
                                                                       if hw_cost else ""))
    ranges = dynamic_ranges(configs)
    hardware = hardware_cost({k: c for k, c in configs.items() if k in ("te", "ml")}) if hw_cost else "not computed (--no-hw-cost)"
    progress.end("dynamic range and hardware cost", started,
                 ["python3 benchmarks/dynamic_range.py   # the full table, from a clone",
                  "python3 benchmarks/hw_cost.py          # the full cost table, from a clone"])

    # 6. pictures and report
    started = progress.begin("pictures and report.md")
    plot_frame(light, middle, (y, x, crop), out / "frame.png")
    plot_rtl_crop(truth[middle], rtl_images, golden_images, peak, middle, out / "rtl_crop.png")
    progress.end("pictures and report", started, [
        "tespike view --input I.npy --out I.png",
        "tespike view --input S_te.npz --out S_te.png",
        "tespike view --input R_tfi_te.npy --out R_tfi_te.png --peak 1",
        "gtkwave W.gtkw" if backend == "amaranth" else "# no waveform: only the amaranth backend writes one"])
    report = report_markdown(
        configs=configs, frames=frames, height=height, width=width, seed=seed, crop=(y, x, crop),
        rtl_readouts=rtl_readouts, rtl_info=rtl_info, verdict=verdict, evaluation=evaluation,
        rtl_rows=rtl_rows, scored=scored, ranges=ranges, hardware=hardware, stages=progress.stages,
        total=time.perf_counter() - progress.start, window=window, methods=list(METHODS),
        label=label)
    write_text(out / "report.md", report)

    if not quiet:
        from recon.evaluate import table_markdown
        print(table_markdown(evaluation), end="")
    print(f"RTL: {verdict}")
    print(f"wrote {out}/: report.md, verdict.txt, I.npy, S_*.npz, R_*.npy, E_crop.npy, "
          + ("W.vcd, W.gtkw, " if backend == "amaranth" else "")
          + f"frame.png, rtl_crop.png, {paths['plot'].name}, strips/default.png, table.md "
            f"({time.perf_counter() - progress.start:.0f} s)")
    return 0 if difference is None else 1


def verdict_text(difference: dict | None, backend: str, readouts: int, crop: int, corner) -> str:
    if difference is None:
        return (f"bit-identical: {backend} RTL == golden model, {readouts} readouts x {crop} x {crop} pixels "
                f"({readouts * crop * crop} words)")
    d = difference
    return (f"DIFFERENT: {d['count']} of {readouts * crop * crop} words differ; first at readout {d['readout']}, "
            f"crop pixel ({d['row']}, {d['col']}) = frame pixel ({corner[0] + d['row']}, {corner[1] + d['col']}): "
            f"RTL word {d['rtl']}, golden word {d['golden']}")


def dynamic_ranges(configs: dict[str, SensorConfig], n_s: int = 16) -> list[dict]:
    """Formula (N_s = 1 and ``n_s``) and measured range (noise-free electrons, 5 % and 20 %)."""
    from golden.dynamic_range import constant_light_words, formula_db, light_grid, measure
    rows = []
    grid = light_grid()
    windows = 20
    for label, config in configs.items():
        words = constant_light_words(config, grid, n_s * (windows + 1))
        strict = measure(config, n_s, light=grid, words=words, windows=windows, tolerance=0.05)
        loose = measure(config, n_s, light=grid, words=words, windows=windows, tolerance=0.20)
        rows.append({"sensor": label, "formula_1": formula_db(config, 1), "formula_ns": formula_db(config, n_s),
                     "strict": strict, "loose": loose, "n_s": n_s})
    return rows


def _fmt_range(m) -> str:
    if math.isnan(m.low):
        return "none"
    return f"{m.low:.3g} .. {m.high:.3g} ({m.db:.1f} dB)"


def report_markdown(*, configs, frames, height, width, seed, crop, rtl_readouts, rtl_info, verdict,
                    evaluation, rtl_rows, scored, ranges, hardware, stages, total, window, methods,
                    label) -> str:
    import platform

    import torch

    from recon.evaluate import table_markdown
    y, x, size = crop
    te = configs[RTL_SENSOR]
    lines = ["# tespike demo report", "",
             f"Scene: the shipped CC0 panorama (Greg Zaal, HDRI Haven; `recon/data/README.md`), panned: "
             f"{frames} readout intervals of {height} x {width} pixels, brightest pixel = design light "
             f"(I = 1: 42000 electrons per readout interval), seed {seed}. Photon shot noise: Poisson "
             f"electrons per pixel clock. Machine: {platform.machine()}, {torch.get_num_threads()} torch "
             f"thread(s), Python {platform.python_version()}. Total {total:.0f} s.", "",
             "## Configuration", "",
             "| sensor | config (JSON, every key) | L clocks / readout | word bits |",
             "| --- | --- | ---: | ---: |"]
    for name, config in configs.items():
        lines.append(f"| {name} | `{config.to_json()}` | {config.clocks_per_readout} | {config.word_bits} |")
    lines += ["", "`ml-msb` is the paper's ML camera (its eq. 10; Table 1's ML column, `TFP_ML`, `TFI_ML`), "
              "`ml` the full-count ML camera (rows `TFP_ML-count`, ...), `te` the TE camera.",
              "", "## RTL against the golden model", "",
              f"**{verdict}**", "",
              f"- crop: rows {y}..{y + size - 1}, columns {x}..{x + size - 1} of the frame (marked in "
              f"`frame.png`), readouts 0..{rtl_readouts - 1} ({rtl_readouts * te.clocks_per_readout} pixel "
              f"clocks), TE sensor;",
              "- stimulus `E_crop.npy`: the very per-clock electrons the golden full-frame TE run got for "
              "these pixels (the golden stream of the crop equals the full-frame stream's crop);",
              f"- backend: {rtl_info['backend']}" + (" (Amaranth simulator, pixels inlined; no build step)"
                                                     if rtl_info["backend"] == "amaranth" else "") + ";"]
    if rtl_info.get("vcd"):
        lines += [f"- waveform `W.vcd` ({rtl_info['vcd_bytes'] / 2**20:.1f} MiB) and GTKWave save file "
                  f"`W.gtkw` (opens on readout interval 0, marker on its last clock): `gtkwave W.gtkw`;",
                  f"- the stream was rebuilt from the VCD alone with vcdvcd (`cosim/vcd.py`) in "
                  f"{rtl_info['read_seconds']:.1f} s; it equals the stream the testbench captured live: "
                  f"{'yes' if rtl_info['live_equals_vcd'] else 'NO'}; frame_valid latency "
                  f"{rtl_info['latency']} clock(s); {rtl_info['cycles']} clocks simulated in "
                  f"{rtl_info['sim_seconds']:.1f} s ({rtl_info['cycles'] / max(rtl_info['sim_seconds'], 1e-9):.0f} "
                  f"clocks/s)."]
    else:
        lines += ["- no waveform: only the amaranth backend writes a VCD."]
    lines += ["", "### Reconstruction of the RTL's own stream", "",
              f"Frames {scored.start}..{scored.stop - 1} of the {rtl_readouts} RTL readouts scored (window "
              f"{window}), against the ground truth of the crop, normalised by the sequence's peak. "
              "'golden full frame' is the same method on the full-frame TE stream, cut to the crop; the "
              "methods work pixel by pixel along time, so the two agree wherever the window does not reach "
              "past the RTL's readouts (TFI searches the whole stream for a spike interval, so it may "
              "differ near the ends). Run time: median of repeats. Pictures: `rtl_crop.png`.", "",
              "| method | RTL: PSNR-μ | SSIM-μ | golden full frame: PSNR-μ | SSIM-μ | max abs difference (light) "
              "| RTL stream ms / frame |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in rtl_rows:
        lines.append(f"| {label(row['method'], 'te')} | {row['rtl_psnr']:.2f} | {row['rtl_ssim']:.3f} | "
                     f"{row['golden_psnr']:.2f} | {row['golden_ssim']:.3f} | {row['max_diff']:.3g} | "
                     f"{row['ms_per_frame']:.3f} |")
    lines += ["", "## Quality per method and sensor (golden full frame)", "",
              f"PSNR-μ / SSIM-μ (μ = 5000, after division by the ground truth's peak), frames "
              f"{evaluation.window // 2}..{frames - 1 - evaluation.window // 2} scored; run time per frame "
              f"is the median of {evaluation.repeats} runs with {evaluation.threads} torch thread(s) (single "
              "runs vary several-fold on a shared machine). Methods: every one of the registry "
              f"(`recon/methods.py`): {', '.join(methods)}.", "",
              table_markdown(evaluation).rstrip(), "",
              "Pictures: `strips/default.png` (ground truth, each method, |error| maps with colour bar, one "
              "pair of rows per sensor), `quality_vs_time.png` (quality against run time, with legend), "
              "`frame.png` (the frame with the RTL crop marked).", "",
              "## Dynamic range", "",
              "Formula (paper section 4.3): D_TE = 20 log10(2^b1 (2^b2 - 1) N_s), D_ML = 20 log10((2^B - 1) "
              "N_s), N_s the longest accepted spike interval in readouts. Measured "
              "(`golden/dynamic_range.py`): constant light on a grid of 20 levels per decade through the "
              f"cycle-exact model, noise-free electrons, N_s = {ranges[0]['n_s']}; a light passes when the "
              "mean decoded light over N_s readouts is within the tolerance in 90 % of 20 windows; the range "
              "is the longest run of passing lights (light in units of the design light).", "",
              f"| sensor | formula, N_s = 1 (dB) | formula, N_s = {ranges[0]['n_s']} (dB) | measured, 5 % | "
              "measured, 20 % |", "| --- | ---: | ---: | --- | --- |"]
    for row in ranges:
        lines.append(f"| {row['sensor']} | {row['formula_1']:.1f} | {row['formula_ns']:.1f} | "
                     f"{_fmt_range(row['strict'])} | {_fmt_range(row['loose'])} |")
    lines += ["", "## Hardware cost (one pixel, Yosys)", ""]
    if isinstance(hardware, str):
        lines += [f"Not computed here: {hardware}. The full table is `docs/hardware-cost.md` "
                  "(`python3 benchmarks/hw_cost.py`)."]
    else:
        lines += ["`synth -top <module>; stat` of the project's Verilog (`rtl/verilog.py`): cells of Yosys's "
                  "gate library and flip-flops; transistors: flip-flops legalised to plain D flip-flops, "
                  "`abc -g cmos3`, `stat -tech cmos` (a rough static-CMOS estimate; one mapping, ABC is "
                  "heuristic: see `docs/hardware-cost.md` for the spread over mappings and the counting-logic "
                  "comparison).", "",
                  "| sensor | pixel cells | pixel flip-flops | pixel transistors | timing block cells | "
                  "timing flip-flops | timing transistors (one per array) |",
                  "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for row in hardware:
            p, t = row["pixel"], row["timing"]
            lines.append(f"| {row['sensor']} | {p['cells']} | {p['flops']} | {p['transistors']} | "
                         f"{t['cells']} | {t['flops']} | {t['transistors']} |")
    lines += ["", "## Run time of every stage", "", "| stage | seconds |", "| --- | ---: |"]
    lines += [f"| {stage.name} | {stage.seconds:.1f} |" for stage in stages]
    lines += [f"| total | {total:.1f} |", "", "## Rerun each step with the individual commands", "",
              "From this folder (`cd` into it), in order:", "", "```sh"]
    for stage in stages:
        lines.append(f"# {stage.name}")
        lines += stage.commands
    lines += ["```", ""]
    return "\n".join(lines)
