"""``tespike demo``: circuit to image in one command, on the built-in moving HDR scene.

Stages (each timed, each written, each with the individual command that redoes it):

1. scene: the shipped CC0 panorama, panned (``I.npy``);
2. golden, full frame: TE from the per-clock electrons of
   :func:`tespike.golden.fastsim.iter_scene_stimulus` through the cycle-exact
   :class:`tespike.golden.sensor.PixelArrayModel` (so the RTL crop below gets literally the
   electrons the golden model got), ML count and ML msb with the fast
   simulator :func:`tespike.golden.fastsim.simulate_scene` (same law); ``S_<sensor>.npz``;
3. RTL: the TE pixel array (Amaranth by default, pixels inlined, no build) on a
   crop of those electrons (``E_crop.npy``), with a VCD and a GTKWave save file
   opening on one readout interval; the stream is rebuilt from the VCD with
   vcdvcd (:func:`tespike.cosim.vcd.waveform_words`) and compared with the golden
   stream of the same pixels and readouts: "bit-identical", or the first
   differing readout, pixel and both words (``verdict.txt``, exit 1);
4. reconstruction: every method of :data:`tespike.recon.methods.RECON_METHODS` with weights for the sensors on every
   golden stream (:func:`tespike.recon.evaluate.evaluate`: PSNR-mu / SSIM-mu, run time
   the median of repeats) and on the RTL's own stream;
5. dynamic range (formula and measured, :mod:`tespike.golden.dynamic_range`) and a
   small hardware cost table (Yosys, when installed);
6. pictures and ``report.md``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count
from tespike.recon.evaluate import SENSORS  # the golden full frame's: presets, the paper's msb ML camera, TE, ML count
from tespike.recon.settings import DEFAULT_WINDOW, check_window

#: The sensor the RTL runs (the paper's subject).
RTL_SENSOR = "te"
#: Crop and readouts the README's demo uses; unless given, each is at most the frame's
#: side and the scene's frames (a smaller demo shrinks them; an explicit larger value is refused).
DEFAULT_CROP, DEFAULT_RTL_READOUTS = 16, 16
#: Smallest crop: SSIM's 11 x 11 Gaussian window must fit.
MIN_CROP = 11
#: Most timed runs per method (each reconstructs the whole sequence).
MAX_REPEATS = 100
#: Memory besides the arrays (torch, the network, metric bands): a lower bound for the room check.
WORKING_BYTES = 256 << 20
#: Files the demo writes into its folder (checked before any work).
OUTPUT_FILES = ("report.md", "verdict.txt", "I.npy", "E_crop.npy", "S_rtl.npz", "W.vcd", "W.gtkw",
                "frame.png", "rtl_crop.png", "strips/")
#: The demo's scene (:func:`tespike.recon.scenes.make_scene`), and the name of its sequence and strip.
DEMO_SCENE = "default"
#: Names a demo's folder holds besides OUTPUT_FILES and the evaluation's: per-sensor streams, images.
PER_SENSOR_FILES = ("S_*.npz", "R_*.npy")


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
    from tespike.golden.io import atomic_output
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, array)


def choose_crop(light: np.ndarray, size: int) -> tuple[int, int]:
    """Top-left corner of the ``size`` x ``size`` crop holding the brightest pixel of the
    sequence's mean frame (centred on it, kept inside the frame): dark and bright pixels
    side by side, the part of the scene an HDR sensor is about."""
    light = np.asarray(light)
    if light.ndim != 3 or not light.size:
        raise InputError(f"choose_crop: the light must be a non-empty (K, H, W) sequence, not of shape {light.shape}")
    H, W = light.shape[1:]
    if not is_count(size, 1) or size > min(H, W):      # (a crop past the frame had a negative corner)
        raise InputError(f"choose_crop: crop {size!r} must be an integer from 1 to the frame's {min(H, W)}")
    mean = light.mean(axis=0)
    r, c = np.unravel_index(int(np.argmax(mean)), mean.shape)
    return (int(min(max(0, r - size // 2), H - size)), int(min(max(0, c - size // 2), W - size)))


# ---------------------------------------------------------------- hardware cost
def hardware_cost(configs: dict[str, SensorConfig], yosys: str = "yosys") -> list[dict] | str:
    """Per sensor: Yosys cells, flip-flops and transistor estimates (:func:`tespike.cosim.synthesis.synthesize_module`)
    of one pixel and of the shared timing block. A string says why there is no table (Yosys
    missing, failing, or reporting no usable estimate): the report says so instead of crashing."""
    if not isinstance(configs, dict) or not all(isinstance(c, SensorConfig) for c in configs.values()):
        raise InputError("hardware_cost: the sensors must be a dict of name -> SensorConfig, "
                         f"not {type(configs).__name__} {configs!r}"[:200])
    from tespike.rtl.names import module_names
    from tespike.rtl.verilog import pixel_verilog, timing_verilog

    from .synthesis import SynthesisError, synthesize_module, yosys_missing
    missing = yosys_missing(yosys)
    if missing:
        return missing
    rows = []
    for label, config in configs.items():
        names = module_names(config)
        try:
            rows.append({"sensor": label, "config": config,
                         "pixel": synthesize_module(pixel_verilog(config), names["pixel"], yosys),
                         "timing": synthesize_module(timing_verilog(config), names["timing"], yosys)})
        except SynthesisError as exc:
            return f"{label}: {exc}"
    return rows


# ---------------------------------------------------------------- up-front checks
def check_options(out, *, frames, height, width, seed, crop, rtl_readouts, backend, repeats, window,
                  sensors) -> tuple[int, int]:
    """Refuse a bad option in one line; return (crop, RTL readouts) with their defaults resolved."""
    from tespike.cosim.backends import NAMES
    from tespike.recon.scenes import check_scene_request

    check_scene_request(DEMO_SCENE, frames, height, width, flags=True)
    for key, value, low in (("--crop", crop, 1), ("--rtl-readouts", rtl_readouts, 1),
                            ("--repeats", repeats, 1), ("--seed", seed, 0)):
        if (value is not None or key in ("--repeats", "--seed")) and not is_count(value, low):
            raise InputError(f"{key} {value!r}: must be an integer >= {low}")   # (11.5 had failed inside)
    if repeats > MAX_REPEATS:
        raise InputError(f"--repeats {repeats}: must be in 1..{MAX_REPEATS}")
    if crop is None:
        crop = min(DEFAULT_CROP, height, width)
        if crop < MIN_CROP:
            raise InputError(f"--height {height} --width {width}: the RTL crop needs a frame of at least "
                             f"{MIN_CROP} x {MIN_CROP} (SSIM-mu's window)")
    elif crop < MIN_CROP:
        raise InputError(f"--crop {crop}: must be >= {MIN_CROP} (SSIM-mu of the crop needs {MIN_CROP} x {MIN_CROP})")
    elif crop > min(height, width):
        raise InputError(f"--crop {crop}: larger than the {height} x {width} frame")
    if rtl_readouts is None:
        rtl_readouts = min(DEFAULT_RTL_READOUTS, frames)
    elif rtl_readouts > frames:
        raise InputError(f"--rtl-readouts {rtl_readouts}: more than the {frames} frames of the scene")
    if backend not in NAMES:
        raise InputError(f"--backend {backend!r}: one of {', '.join(NAMES)}")
    check_window(window, "--window")
    unknown = [name for name in sensors if name not in SENSORS]
    if unknown or not sensors or RTL_SENSOR not in sensors or len(set(sensors)) != len(sensors):
        raise InputError(f"--sensors {','.join(sensors)!r}: a list of distinct sensors among "
                         f"{', '.join(SENSORS)}, with {RTL_SENSOR!r} (the RTL's)")
    check_demo_folder(out)
    return crop, rtl_readouts


def check_demo_folder(out) -> None:
    """``--out``: new, empty, or a previous demo's folder, which the run replaces whole when it is
    done (:func:`tespike.golden.atomic.atomic_folder`: killed or failing, the previous demo stays
    untouched); never a folder holding anything else, which replacing it would delete: a file no demo
    writes, at the top or among the strips (an evaluation's strips are named after its sequences)."""
    import os

    from tespike.golden.paths import check_output_dir, foreign_names
    from tespike.recon.report import OUTPUT_FILES as EVALUATION_FILES
    check_output_dir(out, "--out")
    foreign = foreign_names(out, OUTPUT_FILES + EVALUATION_FILES + PER_SENSOR_FILES)
    if foreign:
        raise InputError(f"--out {str(out)!r} holds {foreign[0]!r}, which no demo writes: choose a new or "
                         "empty folder (a demo replaces its folder whole)")
    # an evaluation's strips are named after its sequences; the demo's after its scene
    foreign = foreign_names(os.path.join(out, "strips"), (f"{DEMO_SCENE}.png",))
    if foreign:
        raise InputError(f"--out {str(out)!r} holds 'strips/{foreign[0]}', which no demo writes (an "
                         "evaluation's results?): choose a new or empty folder (a demo replaces its "
                         "folder whole)")


def check_room(out, configs: dict[str, SensorConfig], *, frames, height, width, crop, rtl_readouts,
               vcd: bool, methods=(), verilog: str | None = None) -> None:
    """Refuse up front (one line) a demo whose arrays do not fit in memory or whose files do not
    fit on the disk of ``out``: a lower bound of each, from the sizes the options give (``methods``:
    those the demo runs, each reconstructing every sensor's stream); with ``verilog`` (what writes
    Verilog and how to leave it out: the hardware cost, or the RTL on the generated Verilog), an
    address-space limit below what Amaranth's Yosys reserves (the demo had done all its other work,
    a minute or more, before that failed)."""
    if verilog:
        from tespike.golden.resources import address_space_limit, mapped_bytes
        from tespike.rtl.verilog import YOSYS_ADDRESS_SPACE
        limit = address_space_limit()
        if limit is not None and limit - mapped_bytes() < YOSYS_ADDRESS_SPACE:
            raise MemoryError(f"Amaranth's Yosys (WebAssembly) reserves {YOSYS_ADDRESS_SPACE / 2 ** 30:.1f} GiB "
                              f"of address space for {verilog}")
    from tespike.cosim.headroom import require_room as require
    from tespike.golden.io import word_dtype
    from tespike.golden.light import stimulus_dtype
    from .vcd import VCD_BYTES_PER_PIXEL_CLOCK
    te = configs[RTL_SENSOR]
    values = frames * height * width
    word_bytes = sum(word_dtype(config).itemsize for config in configs.values())
    images = 4 * len(methods) * len(configs) * values            # R_*.npy, float32, kept for the report
    crop_clocks = rtl_readouts * te.clocks_per_readout * crop * crop
    disk = (4 * values + word_bytes * values + images + stimulus_dtype(te).itemsize * crop_clocks
            + (VCD_BYTES_PER_PIXEL_CLOCK * crop_clocks if vcd else 0))
    memory = WORKING_BYTES + (4 + 8) * values + word_bytes * values + images   # light, TE words, streams
    require(f"the demo of {frames} x {height} x {width} pixel-readouts", memory=memory,
            disk={Path(out) / "report.md": disk})


# ---------------------------------------------------------------- the stages
def demo_methods(weights, configs: dict[str, SensorConfig]):
    """-> (``chosen``: (method, sensor) -> weights file, the methods the demo runs): the learned ones
    only where there are weights for every sensor; a given file the demo would leave unused is refused."""
    from tespike.recon.learned import weights_by_sensor
    from tespike.recon.methods import available_methods, missing_weights
    chosen = weights_by_sensor(weights, configs)                        # (method, sensor) -> file
    ready = {(method, configs[sensor]): path for (method, sensor), path in chosen.items()}
    methods = available_methods(configs.values(), ready)
    unused = sorted({(method, str(path)) for (method, _), path in chosen.items() if method not in methods})
    if unused:
        method, path = unused[0]
        missing = [sensor for sensor, config in configs.items()
                   if missing_weights(method, config, ready.get((method, config))) is not None]
        raise InputError(f"--weights {path!r}: the demo runs {method} only with weights for every sensor, "
                         f"and there are none for {', '.join(missing)} (give those too, or leave --sensors "
                         "to the sensors it has; the file would be ignored)")
    return chosen, methods


@dataclasses.dataclass
class RTLCrop:
    """The pixels and readouts the RTL runs: rows ``y..y + size``, columns ``x..x + size``,
    the first ``readouts`` readouts."""
    y: int
    x: int
    size: int
    readouts: int

    def of(self, array: np.ndarray) -> np.ndarray:
        """The crop of a ``(K, H, W)`` array (its readouts and pixels)."""
        return array[:self.readouts, self.y:self.y + self.size, self.x:self.x + self.size]


def golden_stage(out: Path, light, configs, crop: RTLCrop, seed: int, bars: bool):
    """Stage 2: every sensor's stream of ``light`` (``S_<sensor>.npz``), TE through the per-clock
    electrons of the cycle-exact model, and the crop's electrons (``E_crop.npy``) -> (streams,
    crop electrons, the commands that redo it)."""
    from tespike.golden.fastsim import iter_scene_stimulus, simulate_scene
    from tespike.golden.io import save_stream
    from tespike.golden.sensor import PixelArrayModel
    te = configs[RTL_SENSOR]
    frames, height, width = light.shape
    L = te.clocks_per_readout
    array = PixelArrayModel(te, (height, width))
    words_te = np.empty((frames, height, width), np.int64)
    crop_stimulus = np.empty((crop.readouts * L, crop.size, crop.size), np.uint16)
    electrons = iter_scene_stimulus(te, light, seed=seed)
    if bars:
        from tqdm import tqdm
        electrons = tqdm(electrons, total=frames, desc="golden te", unit="readout", leave=False)
    for k, e in enumerate(electrons):
        words_te[k] = array.feed(e)[0]
        if k < crop.readouts:
            crop_stimulus[k * L:(k + 1) * L] = e[:, crop.y:crop.y + crop.size, crop.x:crop.x + crop.size]
    streams = {}
    for label, config in configs.items():
        streams[label] = words_te if label == RTL_SENSOR else simulate_scene(config, light, seed=seed)
        save_stream(out / f"S_{label}.npz", streams[label], config)
    _save_npy(out / "E_crop.npy", crop_stimulus)
    commands = [f"tespike stimulus --config te --scene I.npy --seed {seed} --out E_te.npy   "
                f"# {frames * L * height * width * 2 / 2**20:.0f} MiB",
                "tespike golden --config te --stimulus E_te.npy --out S_te.npz",
                f"tespike simulate --config te --scene I.npy --seed {seed} --method per-clock --out S_te.npz"
                "   # the same words, without the file"]
    commands += [f"tespike simulate --config {label} --scene I.npy --seed {seed} --out S_{label}.npz"
                 for label in configs if label != RTL_SENSOR]
    return streams, crop_stimulus, commands


@dataclasses.dataclass
class RTLResult:
    """Stage 3's outcome: the RTL's words, the first difference from golden (None: bit-identical),
    its verdict line, what the report says of the run, and the commands that redo it."""
    words: np.ndarray
    difference: object
    verdict: str
    info: dict
    commands: list[str]


def rtl_stage(out: Path, te: SensorConfig, crop_stimulus, golden_crop, crop: RTLCrop, backend: str,
              seed: int, bars: bool) -> RTLResult:
    """Stage 3: the TE array in ``backend`` on the crop's electrons (with a VCD read back under
    Amaranth), ``S_rtl.npz`` and ``verdict.txt`` against the golden model's words."""
    from tespike.golden.io import save_stream
    from tespike.golden.sensor import simulate
    from tespike.recon.pictures import write_text

    from .backends import backend as run_backend, checked_words
    from .compare import first_difference
    from .demo_report import verdict_text
    expected = simulate(te, crop_stimulus)
    if not np.array_equal(expected, golden_crop):   # the generator and the engine disagree: a bug, not a verdict
        raise RuntimeError("golden on the crop stimulus differs from the full frame's crop")
    info = {"backend": backend, "vcd": None}
    if backend == "amaranth":
        from tespike.cosim.rtlsim import rtl_run
        from tespike.cosim.vcd import waveform_words
        run = rtl_run(te, crop_stimulus, vcd_path=out / "W.vcd", gtkw_path=out / "W.gtkw", flat=True,
                      progress=bars)
        read_started = time.perf_counter()
        wave = waveform_words(out / "W.vcd", te, (crop.size, crop.size))
        info.update(vcd="W.vcd", gtkw="W.gtkw", latency=run.latency, cycles=run.cycles,
                    sim_seconds=run.seconds, read_seconds=time.perf_counter() - read_started,
                    live_equals_vcd=bool(np.array_equal(run.words, wave.words)),
                    vcd_bytes=(out / "W.vcd").stat().st_size)
        words = wave.words
    else:
        words = checked_words(run_backend(backend)(te, crop_stimulus), te, crop_stimulus, backend)
    save_stream(out / "S_rtl.npz", words, te)
    difference = first_difference(words, expected)
    verdict = verdict_text(difference, backend, crop.readouts, crop.size, (crop.y, crop.x))
    write_text(out / "verdict.txt", verdict + "\n")
    commands = [f"tespike stimulus --config te --scene I.npy --seed {seed} "
                f"--crop {crop.y},{crop.x},{crop.size},{crop.size} --readouts {crop.readouts} --out E_crop.npy",
                "tespike rtl-sim --config te --stimulus E_crop.npy --out S_rtl.npz --check"
                + (" --vcd W.vcd" if backend == "amaranth" else f" --backend {backend}")]
    return RTLResult(words, difference, verdict, info, commands)


def rtl_reconstruction(out: Path, rtl_words, te: SensorConfig, light, crop: RTLCrop, evaluation, methods,
                       chosen, window: int, repeats: int, scored: slice, middle: int):
    """Stage 4's second half: every method on the RTL's own stream (``R_<method>_rtl.npy``), scored
    on the crop's readouts ``scored`` beside the same method on the golden full frame's stream ->
    (rows of the report, readout ``middle``'s RTL and golden images per method)."""
    from tespike.golden.io import save_images
    from tespike.recon.methods import reconstruct
    from tespike.recon.metrics import psnr_mu, ssim_mu

    from tespike.recon.walltime import median_seconds
    peak = float(light.max())
    truth = crop.of(light)
    rows, rtl_images, golden_images = [], {}, {}
    for method in methods:
        seconds, images = median_seconds(
            lambda: reconstruct(rtl_words, te, method, window=window, weights=chosen.get((method, RTL_SENSOR))),
            repeats)
        save_images(out / f"R_{method}_rtl.npy", images)
        full = crop.of(evaluation.images[DEMO_SCENE, RTL_SENSOR, method])
        rtl_images[method], golden_images[method] = images[middle], full[middle]
        rows.append({
            "method": method,
            "rtl_psnr": float(np.mean(psnr_mu(images[scored], truth[scored], peak=peak))),
            "rtl_ssim": float(np.mean(ssim_mu(images[scored], truth[scored], peak=peak))),
            "golden_psnr": float(np.mean(psnr_mu(full[scored], truth[scored], peak=peak))),
            "golden_ssim": float(np.mean(ssim_mu(full[scored], truth[scored], peak=peak))),
            "max_diff": float(np.max(np.abs(images[scored] - full[scored]))),
            "ms_per_frame": 1e3 * seconds / crop.readouts})
    return rows, rtl_images, golden_images


def reconstruction_commands(configs, methods, window: int, frames: int, height: int, width: int,
                            seed: int) -> list[str]:
    """The commands that redo stage 4."""
    from tespike.recon.settings import uses_window
    return ([f"tespike reconstruct --stream S_{sensor}.npz --method {method} "
             + (f"--window {window} " if uses_window(method) else "")
             + f"--out R_{method}_{sensor}.npy" for sensor in list(configs) + ["rtl"] for method in methods]
            + [f"tespike evaluate --set default --frames {frames} --height {height} --width {width} "
               f"--seed {seed} --out eval   # Table 1 layout, TE, ML msb and ML count, other noise draws"])


# ---------------------------------------------------------------- the demo
def run_demo(out, *, frames: int = 32, height: int = 96, width: int = 128, seed: int = 0,
             crop: int | None = None, rtl_readouts: int | None = None,
             backend: str = "amaranth", repeats: int = 3, window: int = DEFAULT_WINDOW, hw_cost: bool = True,
             sensors=SENSORS, quiet: bool = False, bars: bool | None = None, weights=()) -> int:
    """Run every stage into folder ``out``; 0 if the RTL stream is bit-identical to golden, else 1.

    ``crop`` / ``rtl_readouts``: None for :data:`DEFAULT_CROP` / :data:`DEFAULT_RTL_READOUTS`
    within the frame and the scene. Every option and the room the outputs need are checked
    before anything is printed or written. ``quiet``: no stage lines and no table; ``bars``:
    progress bars within the stages (default: when not quiet and stderr is a terminal); ``weights``:
    learned methods' weights files to use instead of the shipped ones for the sensor each was trained for.
    """
    from tespike.golden.atomic import atomic_folder
    from tespike.golden.config import load_config
    from tespike.golden.io import save_images
    from tespike.recon.evaluate import evaluate, scored_frames
    from tespike.recon.names import label
    from tespike.recon.pictures import write_text
    from tespike.recon.report import write_outputs
    from tespike.recon.scenes import make_scene

    from .demo_plots import plot_frame, plot_rtl_crop
    from .demo_report import report_markdown
    sensors = tuple(sensors)
    size, rtl_readouts = check_options(out, frames=frames, height=height, width=width, seed=seed, crop=crop,
                                       rtl_readouts=rtl_readouts, backend=backend, repeats=repeats,
                                       window=window, sensors=sensors)
    configs = {name: load_config(name) for name in sensors}
    chosen, methods = demo_methods(weights, configs)
    te = configs[RTL_SENSOR]
    check_room(out, configs, frames=frames, height=height, width=width, crop=size,
               rtl_readouts=rtl_readouts, vcd=backend == "amaranth", methods=methods,
               verilog=("the hardware cost (--no-hw-cost leaves it out)" if hw_cost else
                        f"the {backend} backend's Verilog" if backend != "amaranth" else None))
    given = out
    with atomic_folder(given) as out:          # the folder is this run's whole, or the previous run's
        progress = Progress(6, quiet)
        if bars is None:
            bars = not quiet and sys.stderr.isatty()

        started = progress.begin(f"scene: pan over the shipped CC0 panorama, {frames} x {height} x {width}")
        light = make_scene(DEMO_SCENE, frames, height, width, seed=seed)
        _save_npy(out / "I.npy", light)
        progress.end("scene", started, [f"tespike scene --name {DEMO_SCENE} --frames {frames} --height {height} "
                                        f"--width {width} --seed {seed} --out I.npy"])

        started = progress.begin("golden model, full frame: TE (per-clock electrons, cycle-exact), "
                                 "ML count and ML msb (fast simulator)")
        rtl_crop = RTLCrop(*choose_crop(light, size), size, rtl_readouts)
        streams, crop_stimulus, commands = golden_stage(out, light, configs, rtl_crop, seed, bars)
        progress.end("golden, full frame", started, commands)

        started = progress.begin(f"RTL ({backend}): TE array of {size} x {size} pixels, {rtl_readouts} readouts "
                                 f"({rtl_readouts * te.clocks_per_readout} clocks) at rows {rtl_crop.y}.., "
                                 f"columns {rtl_crop.x}..")
        rtl = rtl_stage(out, te, crop_stimulus, rtl_crop.of(streams[RTL_SENSOR]), rtl_crop, backend, seed, bars)
        progress.end(f"RTL ({backend})", started, rtl.commands)
        if not quiet:
            print(f"      RTL verdict: {rtl.verdict}", file=sys.stderr, flush=True)

        started = progress.begin(f"reconstruction: {', '.join(methods)} on every stream (run time: median of "
                                 f"{repeats}) and on the RTL stream")
        by_config = {configs[name]: streams[name] for name in configs}
        evaluation = evaluate([(DEMO_SCENE, light)], lambda config, scene, rng: by_config[config],
                              methods=methods, sensors=tuple(configs), configs=configs, window=window, seed=seed,
                              progress=bars, keep=True, repeats=repeats, weights=chosen)
        paths = write_outputs(evaluation, out)
        for (_, sensor, method), images in evaluation.images.items():
            save_images(out / f"R_{method}_{sensor}.npy", images)
        scored = scored_frames(rtl_readouts, window, evaluation.span)    # (the golden rows' rule)
        middle = (scored.start + scored.stop - 1) // 2                  # (the pictures' readout)
        rtl_rows, rtl_images, golden_images = rtl_reconstruction(
            out, rtl.words, te, light, rtl_crop, evaluation, methods, chosen, window, repeats, scored, middle)
        progress.end("reconstruction", started,
                     reconstruction_commands(configs, methods, window, frames, height, width, seed))

        started = progress.begin("dynamic range (formula and measured)" + (" and hardware cost (Yosys)"
                                                                           if hw_cost else ""))
        ranges = dynamic_ranges(configs)
        hardware = (hardware_cost({k: c for k, c in configs.items() if k in ("te", "ml")}) if hw_cost
                    else "not computed (--no-hw-cost)")
        progress.end("dynamic range and hardware cost", started,
                     ["python3 benchmarks/dynamic_range.py   # the full table, from the clone's root",
                      "python3 benchmarks/hw_cost.py          # the full cost table, from the clone's root"])

        started = progress.begin("pictures and report.md")
        plot_frame(light, middle, (rtl_crop.y, rtl_crop.x, size), out / "frame.png")
        plot_rtl_crop(rtl_crop.of(light)[middle], rtl_images, golden_images, float(light.max()), middle,
                      out / "rtl_crop.png")
        progress.end("pictures and report", started, [
            "tespike view --input I.npy --out I.png",
            "tespike view --input S_te.npz --out S_te.png",
            "tespike view --input R_tfi_te.npy --out R_tfi_te.png --peak 1",
            "gtkwave W.gtkw" if backend == "amaranth" else "# no waveform: only the amaranth backend writes one"])
        report = report_markdown(
            configs=configs, rtl_config=te, frames=frames, height=height, width=width, seed=seed,
            crop=(rtl_crop.y, rtl_crop.x, size), rtl_readouts=rtl_readouts, rtl_info=rtl.info,
            verdict=rtl.verdict, evaluation=evaluation, rtl_rows=rtl_rows, scored=scored, ranges=ranges,
            hardware=hardware, stages=progress.stages, total=time.perf_counter() - progress.start,
            window=window, methods=list(methods), label=label)
        write_text(out / "report.md", report)

    if quiet:                         # nothing on stdout; a verdict that fails the run on stderr
        if rtl.difference is not None:
            print(f"RTL: {rtl.verdict}", file=sys.stderr)
        return 0 if rtl.difference is None else 1
    from tespike.recon.report import table_markdown
    print(table_markdown(evaluation), end="")
    print(f"RTL: {rtl.verdict}")
    print(f"wrote {given}/: report.md, verdict.txt, I.npy, S_*.npz, R_*.npy, E_crop.npy, "
          + ("W.vcd, W.gtkw, " if backend == "amaranth" else "")
          + f"frame.png, rtl_crop.png, {paths['plot'].name}, strips/{DEMO_SCENE}.png, table.md, "
            f"table.csv, results.csv ({time.perf_counter() - progress.start:.0f} s)")
    return 0 if rtl.difference is None else 1


def dynamic_ranges(configs: dict[str, SensorConfig], n_s: int = 16) -> list[dict]:
    """Formula (N_s = 1 and ``n_s``) and measured range (noise-free electrons, 5 % and 20 %)."""
    from tespike.golden.dynamic_range import constant_light_words, formula_db, light_grid, measure
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
