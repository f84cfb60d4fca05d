"""Training of every learned reconstruction method (paper section 6.3), resumable, on any torch device.

Data come from the training-data engine (:mod:`tespike.recon.engine`): clips made on
worker processes, never the same twice, deterministic from the seed; each step
draws ``batch`` (clip, key moment, crop, flip) samples. The optimiser is Adam
(beta 0.9 / 0.999); the learning rate halves every ``halve_every`` epochs of
``steps_per_epoch`` steps, after an optional linear warm-up (:func:`lr_factor`). Losses: ``l1``
(the paper's eq. 7) or ``mu-l1``, the L1 distance after the mu-law tone map of
the metrics. Every ``validate_every`` steps the model is scored on the held-out
validation set (:mod:`tespike.recon.engine.validation`); the weights kept are the best
on it. A run stops at a step or wall-time budget, writes a CSV log, a PNG of
the loss and validation curves and a checkpoint every ``checkpoint_seconds``,
and resumes exactly (the same draws as an uninterrupted run; its logs are cut back
to the checkpoint's step). Faults end in one line naming the file: files are
written whole or not at all (a full disk named, not torch's internal error), a
truncated ``--init`` or checkpoint is named with its cause, the weights go to
``out`` before anything else at the end (a run folder removed meanwhile loses
none), and an interrupted run keeps its steps in a checkpoint (:func:`train`).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import functools
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import torch

from tespike.golden.atomic import NO_ROOM, finished_outputs, folder_held, stops_held
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, check_flag, is_count, is_positive_number, one_line
from tespike.golden.io import atomic_output, word_dtype
from tespike.golden.paths import path_text
from tespike.golden.resources import MAX_WORKERS, require_memory

from .engine.batches import ClipPool, draw_batch
from .engine.clips import EngineRecipe
from .learned import load_weights, method_classes
from .learning.head import FLOORS, set_floor
from .learning.layers import parameter_count
from .settings import check_device
from .mulaw import MU, compress
from .learning.weights import cpu_state, read_torch_file, read_weights, save_weights, write_torch_file

LOSSES = ("l1", "mu-l1")
#: Largest learning rate a run takes (Adam's step per weight is about the rate: 1e30 trained weights
#: to 1e30 with a loss that never moved, and exit 0).
MAX_LR = 1.0
#: Smallest learning rate a run takes: Adam's step, about the rate, rounds away below float32's
#: spacing, 1.2e-10 at a weight of 1e-3 (``--lr 1e-40`` wrote the --init weights back unchanged, exit 0).
MIN_LR = 1e-10


@dataclasses.dataclass(frozen=True)
class TrainOptions:
    """One training run. ``minutes`` and ``steps`` are budgets (the first reached ends it)."""

    config: str = "te"                  # preset name or the JSON text of a configuration (--config)
    method: str = "net"                 # a learned method of recon.learned
    size: str = "cpu"
    ablation: int | None = None         # the paper's Table 3 case 1..6 (None: the whole network)
    loss: str = "l1"
    lr: float = 1e-4
    halve_every: int = 10               # epochs
    steps_per_epoch: int = 250
    batch: int = 4
    crop: int = 96
    steps: int | None = None
    minutes: float | None = None
    seed: int = 0
    device: str = "cpu"
    threads: int | None = None
    workers: int = 1                    # data-engine processes (0: in this process)
    pool: int = 48                      # clips a step draws from
    refresh: int = 4                    # steps between two new clips entering the pool
    validate_every: int = 1000          # steps between two validations (0: never)
    checkpoint_seconds: float = 120.0
    recipe: dict = dataclasses.field(default_factory=dict)
    init: str | None = None             # weights file to start from (its tensors of matching name and shape)
    warmup: int = 0                     # steps of linear learning-rate warm-up (0: none)
    floor: str = "clamp"                # the head's floor in training (recon.learning.head.FLOORS)

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:
            raise InputError(f"loss = {self.loss!r}: must be one of {', '.join(LOSSES)}")
        if self.floor not in FLOORS:
            raise InputError(f"floor = {self.floor!r}: must be one of {', '.join(FLOORS)}")
        if not isinstance(self.config, str):
            raise InputError(f"config = {self.config!r}: must be a preset's name or a configuration's JSON text "
                             f"(SensorConfig.to_json()), not {type(self.config).__name__}")
        if not isinstance(self.recipe, dict):
            raise InputError(f"recipe = {self.recipe!r}: must be a dict of the data engine's settings")
        if self.recipe.get("seed", self.seed) != self.seed:   # (it had been replaced by the run's seed silently)
            raise InputError(f"recipe seed {self.recipe['seed']!r}: the data engine's seed is the run's own "
                             f"(TrainOptions.seed = {self.seed!r}), not a recipe key")
        if self.init is not None:
            path_text(self.init, "init")
        if self.threads is not None and not is_count(self.threads, 1):
            raise InputError(f"threads = {self.threads!r}: must be an integer >= 1 (torch CPU threads) or None")
        if not (is_positive_number(self.checkpoint_seconds) or type(self.checkpoint_seconds) in (int, float)
                and self.checkpoint_seconds == 0):        # (0: a checkpoint after every step)
            raise InputError(f"checkpoint_seconds = {self.checkpoint_seconds!r}: must be a finite number >= 0")
        if not (is_positive_number(self.lr) and MIN_LR <= self.lr <= MAX_LR):
            raise InputError(f"learning rate {self.lr!r} must be in [{MIN_LR:g}, {MAX_LR:g}] (Adam moves every weight "
                             "by about the learning rate each step: above 1 the weights only grow, below 1e-10 the "
                             "step rounds away on float32 weights)")
        for key in ("halve_every", "steps_per_epoch", "batch", "crop", "pool", "refresh"):
            if type(getattr(self, key)) is not int or getattr(self, key) < 1:
                raise InputError(f"{key} = {getattr(self, key)!r}: must be an integer >= 1")
        if type(self.seed) is not int or not 0 <= self.seed < 1 << 63:
            raise InputError(f"seed = {self.seed!r}: must be an integer in 0..2^63 - 1")
        for key in ("workers", "validate_every", "warmup"):
            if type(getattr(self, key)) is not int or getattr(self, key) < 0:
                raise InputError(f"{key} = {getattr(self, key)!r}: must be an integer >= 0")
        if self.workers > MAX_WORKERS:
            raise InputError(f"workers = {self.workers}: must be in 0..{MAX_WORKERS} (data-engine processes)")
        if self.warmup > self.lr / MIN_LR:
            raise InputError(f"warmup = {self.warmup}: its first step's rate, lr / warmup = {self.lr / self.warmup:.3g}, "
                             f"is below {MIN_LR:g}, where a step rounds away (at most lr / {MIN_LR:g} = "
                             f"{int(self.lr / MIN_LR)} steps)")
        if self.steps is None and self.minutes is None:
            raise InputError("give a budget: steps or minutes")
        self.sizes()                    # an unknown method, size or ablation case is refused here
        self.data_recipe()
        if self.crop > min(self.data_recipe().height, self.data_recipe().width):
            raise InputError(f"crop = {self.crop}: larger than the engine's clips "
                             f"({self.data_recipe().height} x {self.data_recipe().width})")
        if self.crop % self.sizes().pyramid_factor:
            raise InputError(f"crop = {self.crop}: must be a multiple of the method's pyramid factor "
                             f"{self.sizes().pyramid_factor}")
        if self.steps is not None and (type(self.steps) is not int or self.steps < 1):
            raise InputError(f"steps = {self.steps!r}: must be an integer >= 1")
        if self.minutes is not None and not is_positive_number(self.minutes):
            raise InputError(f"minutes = {self.minutes!r}: must be a finite number > 0")

    def sensor_config(self) -> SensorConfig:
        """The :class:`SensorConfig` of ``config``."""
        from tespike.golden.config import PRESETS
        if self.config in PRESETS:
            return SensorConfig.preset(self.config)
        if not self.config.lstrip().startswith("{"):     # ('tee' had been "not valid JSON")
            raise InputError(f"config = {self.config!r}: neither a preset ({', '.join(PRESETS)}) nor a "
                             "configuration's JSON text")
        return SensorConfig.from_json(self.config)

    def sizes(self):
        module, sizes_class = method_classes(self.method)
        sizes = sizes_class.for_camera(self.size, self.sensor_config())
        if self.ablation is None:
            return sizes
        if self.method != "net":
            raise InputError(f"--ablation is the paper's Table 3 of the network, not of {self.method!r}")
        return sizes.ablation(self.ablation)

    def model(self) -> torch.nn.Module:
        return set_floor(method_classes(self.method)[0](self.sizes()), self.floor)

    def data_recipe(self) -> EngineRecipe:
        return EngineRecipe.from_dict({**self.recipe, "seed": self.seed})


def training_loss(pred: torch.Tensor, truth: torch.Tensor, loss: str, mu: float = MU) -> torch.Tensor:
    """Eq. 7 (``l1``: |I^ / eta - I_gt|, the network's output already being I^ / eta) or
    ``mu-l1``: the same after the mu-law tone map of the metrics."""
    if loss == "l1":
        return (pred - truth).abs().mean()
    if loss != "mu-l1":                                  # ('l2' or None had been mu-l1, silently)
        raise InputError(f"loss = {loss!r}: must be one of {', '.join(LOSSES)}")
    return (compress(pred, mu) - compress(truth, mu)).abs().mean()


#: What a checkpoint holds (:func:`_save_checkpoint`).
CHECKPOINT_KEYS = ("model", "optimizer", "scheduler", "step", "elapsed", "generator", "options", "torch_rng")


def _save_checkpoint(path: Path, model, optimizer, scheduler, step, elapsed, generator, options,
                     best, init=None) -> None:
    payload = {"model": model.state_dict(), "optimizer": optimizer.state_dict(),
               "scheduler": scheduler.state_dict(), "step": step, "elapsed": elapsed,
               "generator": json_state(generator), "options": dataclasses.asdict(options),
               "torch_rng": torch.get_rng_state(), "best": best, "init": init}
    write_torch_file(path, payload)


def read_checkpoint(path: Path) -> tuple[dict, "TrainOptions"]:
    """(the checkpoint's payload, the options it was made with); a one-line refusal naming ``path``
    where it is missing, truncated or not a checkpoint of this trainer."""
    if not (path.exists() or path.is_symlink()):
        raise InputError(f"nothing to resume: no checkpoint at {str(path)!r} (a run killed before its first "
                         "checkpoint left none: start it anew with --force)")
    state = read_torch_file(path, "checkpoint", "training checkpoint")
    if not isinstance(state, dict) or any(key not in state for key in CHECKPOINT_KEYS):
        raise InputError(f"checkpoint {str(path)!r} is not a checkpoint of tespike train")
    try:
        options = dict(state["options"])
        if "sensor" in options and "config" not in options:     # (a checkpoint written before the rename)
            options["config"] = options.pop("sensor")
        return state, TrainOptions(**options)
    except (TypeError, ValueError, InputError) as exc:
        raise InputError(f"checkpoint {str(path)!r} holds options this trainer cannot take "
                         f"({one_line(exc, 300)})") from None


#: The header of a run's ``log.csv`` (a row a step).
LOG_HEADER = ["step", "epoch", "lr", "loss", "seconds"]


def _is_validation_header(row: list[str]) -> bool:
    """A ``validation.csv`` header: step, the validation cases' PSNR-mu (their labels), mean, seconds."""
    return len(row) >= 3 and row[0] == "step" and row[-2:] == ["mean", "seconds"] and all(row)


def trim_log(path: Path, step: int, every_step: bool = False) -> None:
    """Drop the rows of CSV log ``path`` after ``step`` (written by a run killed after its last
    checkpoint, which a resumed run writes again); a missing log is left missing, a log whose
    header is not the run's (``every_step``: :data:`LOG_HEADER`, else a validation header), with a
    row cut short or a value that is not a number is refused (the rows appended
    next would be unreadable, the curves drawn at the run's end would fail), and so is one whose
    rows, ``every_step`` (a row a step, from wherever the log began), stop short of ``step`` or
    skip one (cut at a row's end)."""
    if not path.is_file():
        return
    try:
        with open(path, newline="") as handle:
            text = handle.read()
        rows = list(csv.reader(text.splitlines()))
        header_cut = len(rows) == 1 and not text.endswith("\n")
        header_ok = bool(rows) and (rows[0] == LOG_HEADER if every_step else _is_validation_header(rows[0]))
        if not header_ok or header_cut or any(len(row) != len(rows[0]) for row in rows):
            raise ValueError("no header, or a row cut short")    # new rows would follow none, or a stub
        for row in rows[1:]:
            int(row[0]), [float(value) for value in row[1:]]     # (a flipped byte: not a number)
        kept = rows[:1] + [row for row in rows[1:] if int(row[0]) <= step]
    except (ValueError, IndexError, csv.Error, UnicodeDecodeError):
        raise InputError(f"run log {str(path)!r} is damaged: move it away to resume") from None
    steps = [int(row[0]) for row in kept[1:]]
    if every_step and steps and steps != list(range(steps[0], step + 1)):
        raise InputError(f"run log {str(path)!r} is damaged (its rows {'stop at step ' + str(steps[-1]) if steps[-1] < step else 'skip steps'}, "
                         f"the checkpoint is at step {step}): move it away to resume")
    if len(kept) < len(rows) or not text.endswith("\n"):      # a row cut at its end: the next would join it
        with atomic_output(path) as tmp, open(tmp, "w", newline="") as handle:
            csv.writer(handle).writerows(kept)


def last_logged_step(path: Path) -> int | None:
    """The step of a CSV log's last row (:func:`trim_log` has checked it), None where it has none."""
    if not path.is_file():
        return None
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    return int(rows[-1][0]) if len(rows) > 1 else None


@contextlib.contextmanager
def appending(path: Path):
    """A CSV log appended to ``path`` (not replaced: it grows with the run): a write that runs out of
    room fails at a buffered flush or at the close, as an OSError naming no file; it names ``path``."""
    try:
        with open(path, "a", newline="") as handle:
            yield handle
    except OSError as exc:
        if exc.filename is None and exc.errno in NO_ROOM:
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise


def _random_states(generator: np.random.Generator) -> tuple:
    """The training's random states (the batch generator's, torch's) at a step boundary."""
    return generator.bit_generator.state, torch.get_rng_state()


def _restore_random_states(generator: np.random.Generator, states: tuple) -> None:
    """Back to the states of :func:`_random_states`: an interrupted step's checkpoint resumes exactly
    (its batch, drawn again by the resumed run, is the one the uninterrupted run draws)."""
    generator.bit_generator.state, torch_state = states
    torch.set_rng_state(torch_state)


def json_state(generator: np.random.Generator) -> dict:
    state = generator.bit_generator.state
    return {"bit_generator": state["bit_generator"], "state": {k: int(v) for k, v in state["state"].items()},
            "has_uint32": int(state["has_uint32"]), "uinteger": int(state["uinteger"])}


def plot_curves(log_path: Path, validation_path: Path, png_path: Path, title: str) -> None:
    """Training loss and validation PSNR-mu against step, one PNG with legends."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .pictures import save_figure
    with open(log_path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        return
    step = np.array([int(r["step"]) for r in rows])
    loss = np.array([float(r["loss"]) for r in rows])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4))
    ax.plot(step, loss, lw=0.6, alpha=0.4, label="loss per logged step")
    if len(loss) >= 20:
        width = max(5, len(loss) // 20)
        smooth = np.convolve(loss, np.ones(width) / width, mode="valid")
        ax.plot(step[width - 1:], smooth, lw=1.5, label=f"running mean of {width}")
    ax.set_xlabel("step")
    ax.set_ylabel("training loss")
    ax.set_yscale("log")
    ax.set_title(f"{title}: training loss")
    ax.legend()
    if validation_path.is_file():
        with open(validation_path, newline="") as handle:
            vrows = list(csv.DictReader(handle))
        if vrows:
            vstep = [int(r["step"]) for r in vrows]
            for key in vrows[0]:
                if key in ("step", "seconds"):
                    continue
                values = [float(r[key]) for r in vrows]
                bx.plot(vstep, values, marker="o" if key == "mean" else None, lw=2.0 if key == "mean" else 0.8,
                        label=key)
    bx.set_xlabel("step")
    bx.set_ylabel("validation PSNR-mu (dB)")
    bx.set_title("held-out validation")
    if bx.lines:
        bx.legend(fontsize=7)
    else:
        bx.text(0.5, 0.5, "no validation in this run", ha="center", transform=bx.transAxes)
    fig.tight_layout()
    save_figure(fig, png_path)
    plt.close(fig)


def lr_factor(options: TrainOptions, step: int) -> float:
    """The learning rate at ``step`` over ``options.lr``: halved every ``halve_every`` epochs
    (the paper's schedule) and, over the first ``warmup`` steps, ramped up linearly: a warm
    start (``--init``) meets a fresh Adam state, whose first steps move every weight by about
    the learning rate whatever its gradient. (Measured: it did not remove the 1.5 to 2 dB
    validation dip of the shipped ML networks warm-started on noisy clips, which is the data's,
    not the optimiser's: docs/fair-training.md.)"""
    ramp = min(1.0, (step + 1) / options.warmup) if options.warmup else 1.0   # (warmup <= lr / MIN_LR)
    halved = 0.5 ** (step // (options.steps_per_epoch * options.halve_every))
    return ramp * max(halved, MIN_LR / options.lr)      # halving stops at MIN_LR, below which a step rounds away


def validate(model: torch.nn.Module, cases, config: SensorConfig, device: str) -> dict[str, float]:
    """PSNR-mu of ``model`` on the validation cases (whole frames, every readout)."""
    from .engine.validation import validation_psnr
    from .learning.infer import reconstruct_model
    was_training = model.training
    model.eval()
    try:
        with torch.inference_mode():
            return validation_psnr(lambda case: reconstruct_model(model, case.words, config, tile=None,
                                                                  device=device, calibration=case.calibration,
                                                                  inputs=case.law_inputs(device)),
                                   cases)
    finally:
        model.train(was_training)


def warm_start(model: torch.nn.Module, path: str, method: str) -> tuple[list[str], SensorConfig]:
    """Copy into ``model`` every tensor of weights file ``path`` whose name and shape match;
    return the names and the configuration the file was trained for.

    A network whose head changed keeps what it learned elsewhere (features,
    alignment, refinement) and trains its new parts from their initial values; one
    trained for another sensor is a start too (the run says so, and records it).
    """
    source, trained_for, _ = load_weights(path, "--init", method)
    saved, own = source.state_dict(), model.state_dict()
    copied = [name for name, value in saved.items() if name in own and own[name].shape == value.shape]
    if not copied:
        raise InputError(f"--init {path!r}: no tensor matches the model's names and shapes")
    model.load_state_dict({**own, **{name: saved[name] for name in copied}})
    return copied, trained_for


def step_memory(options: TrainOptions) -> int:
    """A lower bound on the bytes of one training step on the CPU, measured rather than guessed:
    the tensors autograd keeps for the backward pass (each storage once), counted by
    ``saved_tensors_hooks`` in forward passes of one sample at two small crops, grow with the
    crop's area (fitted on the two, which leaves out what does not grow: the weights) and with
    the batch; the parameters' four copies (weights, gradients, Adam's two moments) beside
    them. All of it is alive when the forward pass ends, so a run needing more memory than is
    free cannot fit (peaks measured 2-3x this bound at batch 4, crop 96, and batch 16, crop 128)."""
    config, sizes = options.sensor_config(), options.sizes()
    model = options.model()
    factor = sizes.pyramid_factor
    small = factor * max(1, 16 // factor)

    def saved(crop: int) -> int:
        storages: dict[int, int] = {}

        def keep(tensor):
            storage = tensor.untyped_storage()
            storages[storage.data_ptr()] = max(storages.get(storage.data_ptr(), 0), storage.nbytes())
            return tensor
        light = torch.rand(1, sizes.span, crop, crop)
        inside = torch.ones(1, sizes.span, dtype=torch.bool)
        with torch.autograd.graph.saved_tensors_hooks(keep, lambda tensor: tensor):
            model(light, inside, config.spike_light)
        return sum(storages.values())

    per_pixel = max(0.0, (saved(4 * small) - saved(2 * small)) / (12 * small ** 2))
    parameters = sum(p.numel() * p.element_size() for p in model.parameters())
    return int(per_pixel * options.batch * options.crop ** 2) + 4 * parameters


class RunFolderGone(InputError):
    """The run folder vanished during training (the weights were saved to the output first)."""


def train(options: TrainOptions, out: str | Path, *, work_dir: str | Path | None = None,
          resume: bool = False, progress: bool | None = None, command: str = "") -> Path:
    """Run (or resume) one training; write the best-on-validation weights to ``out``; return its path.

    ``work_dir`` (default: ``out`` with suffix ``.run``) holds the checkpoint, the
    CSV logs and the curves' PNG. Interrupted (Ctrl-C, a termination signal)
    after a step, the run saves its checkpoint first and says so in a note on
    the exception; one that made nothing removes the run folder it created.
    """
    if not isinstance(options, TrainOptions):
        raise InputError(f"train: the options must be TrainOptions, not {type(options).__name__}")
    check_flag(resume, "resume")                         # ('no' had resumed)
    out = path_text(out, "weights file")
    check_device(options.device)       # (here, not in the options: a checkpoint's saved device may be absent)
    recipe = options.data_recipe()     # the clip pool's words and light, before anything is built
    clip_bytes = max(recipe.long[1], recipe.short[1]) * recipe.height * recipe.width * (
        4 + word_dtype(options.sensor_config()).itemsize)
    pool_bytes = options.pool * clip_bytes
    require_memory(pool_bytes, f"a pool of {options.pool} clips of up to "
                               f"{max(recipe.long[1], recipe.short[1])} x {recipe.height} x {recipe.width}")
    if options.device == "cpu":        # (a GPU's memory is its own: torch names what does not fit there)
        require_memory(pool_bytes + step_memory(options), f"training {options.method} at batch {options.batch}, "
                                                          f"crop {options.crop} (and its clip pool)")
    out = Path(out)
    work = Path(work_dir) if work_dir is not None else out.with_suffix(".run")
    created = not (work.exists() or work.is_symlink())
    if resume and created:             # (no run ever started: --force would not help)
        raise InputError(f"nothing to resume: no run folder {str(work)!r} (no run of these weights started: "
                         "leave out --resume)")
    work.mkdir(parents=True, exist_ok=True)
    start = len(finished_outputs())
    try:
        # one run writes a run folder at a time: two into one --out had both exited 0 on a folder whose
        # log, checkpoint and best weights mixed the two runs
        with folder_held(work, f"run folder {str(work)!r}"):
            return _train(options, out, work, resume, progress, command)
    except BaseException:
        made_weights = any(Path(written) == out for written in finished_outputs(start))
        if created and work.is_dir() and not (work / CHECKPOINT).exists() and not made_weights:
            shutil.rmtree(work, ignore_errors=True)        # nothing to resume or to explain: no empty folder
            with contextlib.suppress(OSError):             # (out of file handles rmtree removes nothing:
                os.rmdir(work)                             # it opens the folder it walks; rmdir opens none)
        raise                                              # (weights written: their logs and curves stay)


#: The run folder's checkpoint (``OUT.run/``), what ``--resume`` continues from.
CHECKPOINT = "checkpoint.pt"
#: What a run writes into its run folder: checkpoint, logs, best weights, curves.
RUN_FILES = (CHECKPOINT, "log.csv", "validation.csv", "best.pt", "curves.png")


def _train(options: TrainOptions, out: Path, work: Path, resume: bool, progress: bool | None,
           command: str) -> Path:
    run = TrainingRun(options, out, work, command)
    if resume:
        run.resume()
    else:
        run.start_anew()
    run.steps(sys.stderr.isatty() if progress is None else progress)
    if run.step == 0:                  # (--minutes 1e-300 wrote the untrained weights as a result)
        raise InputError(f"--minutes {options.minutes:g} ran out before the first step: nothing trained, "
                         "nothing written")
    run.write_weights()                # the result first: a run folder lost now loses no weights
    run.save_checkpoint()
    return out


class TrainingRun:
    """One training in progress: the model, its optimiser and schedule, the batch generator, the step
    reached, the best validation so far, and the files of its run folder ``work`` (:data:`RUN_FILES`)
    and of its weights ``out``."""

    def __init__(self, options: TrainOptions, out: Path, work: Path, command: str):
        self.checkpoint, self.log_path, self.validation_path, self.best_path, self.curves_path = (
            work / name for name in RUN_FILES)
        self.options, self.out, self.work, self.command = options, out, work, command
        if options.threads is not None:
            torch.set_num_threads(options.threads)
        self.config, self.sizes = options.sensor_config(), options.sizes()
        torch.manual_seed(options.seed)
        self.generator = np.random.default_rng(options.seed)
        self.model = options.model().to(options.device).to(memory_format=torch.channels_last)
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=options.lr, betas=(0.9, 0.999))
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(self.optimizer, functools.partial(lr_factor, options))
        self.step, self.elapsed_before, self.best, self.best_weights, self.init = 0, 0.0, None, None, None
        self.validated, self.pool, self.cases, self.meta = None, None, None, {}
        self.started = time.monotonic()

    # ---------------------------------------------------------------- the run's start
    def resume(self) -> None:
        """Continue from the run folder's checkpoint (made with the same options but the budgets);
        the logs are cut back to its step."""
        options, checkpoint = self.options, self.checkpoint
        state, saved = read_checkpoint(checkpoint)
        kept = {"steps": options.steps, "minutes": options.minutes, "device": options.device,
                "threads": options.threads, "workers": options.workers,
                "init": saved.init}      # the warm start is in the checkpoint: --resume needs no --init

        def same(o: TrainOptions) -> TrainOptions:    # the recipe compared as resolved, not as typed
            return dataclasses.replace(o, **kept, checkpoint_seconds=0, recipe=o.data_recipe().to_dict())
        if same(saved) != same(options):
            was, now = dataclasses.asdict(same(saved)), dataclasses.asdict(same(options))
            differ = [key for key in was if was[key] != now[key]]
            shown = "; ".join(f"{key} {was[key]!r}, not {now[key]!r}" for key in differ[:2]
                              if key != "recipe") or "its recipe differs"
            raise InputError(f"checkpoint {str(checkpoint)!r} was made with other options ({shown}); resume with "
                             "the options it was made with (every one but the budget, device, threads and workers)")
        self.options = dataclasses.replace(options, init=saved.init)     # the record names the run's warm start
        try:
            self.model.load_state_dict(state["model"])
            self.optimizer.load_state_dict(state["optimizer"])
            self.scheduler.load_state_dict(state["scheduler"])
            self.step, self.elapsed_before, self.best = int(state["step"]), float(state["elapsed"]), state.get("best")
            self.init = state.get("init")        # (what the warm start copied; absent from older checkpoints)
            self.generator.bit_generator.state = state["generator"]
            torch.set_rng_state(state["torch_rng"])
        except (RuntimeError, KeyError, TypeError, ValueError) as exc:
            raise InputError(f"checkpoint {str(checkpoint)!r} does not fit this run ({one_line(exc, 300)})") from None
        if self.best is not None:
            self.best_weights = read_weights(self.best_path, "the run's best weights")
        trim_log(self.log_path, self.step, every_step=True)
        trim_log(self.validation_path, self.step)
        if last_logged_step(self.validation_path) == self.step:   # (validated again, a second row of it)
            self.validated = self.step

    def start_anew(self) -> None:
        """A new run: no file of an earlier one stays in the run folder; ``--init`` copied in."""
        options = self.options
        if options.init is not None:    # (first: an --init refused removes nothing of an earlier run)
            copied, trained_for = warm_start(self.model, options.init, options.method)
            self.init = {"tensors_copied": len(copied), "tensors": len(self.model.state_dict()),
                         "trained_for": trained_for.to_dict()}
        removed = []
        for stale in (self.checkpoint, self.log_path, self.validation_path, self.best_path, self.curves_path):
            if stale.exists():
                stale.unlink()
                removed.append(stale.name)
        # --force over an earlier run: said at once (a run stopped before its checkpoint leaves none of them)
        if {self.checkpoint.name, self.best_path.name} & set(removed):
            print(f"train: a new run in {str(self.work)!r}: removed the earlier run's {', '.join(removed)}",
                  file=sys.stderr)
        partial = options.init is not None and len(copied) < self.init["tensors"]
        if options.init is not None and (trained_for != self.config or partial):
            why = (f"was trained for {trained_for.describe()}, this run is for {self.config.describe()}"
                   if trained_for != self.config else "holds another size or ablation of the method")
            rest = ", the others afresh" if partial else ""
            print(f"train: --init {options.init!r} {why}: {len(copied)} of this run's {self.init['tensors']} "
                  f"tensors (matching name and shape) start from it{rest}", file=sys.stderr)

    # ---------------------------------------------------------------- what it writes
    def elapsed(self) -> float:
        """Wall seconds of the run, its earlier sessions included."""
        return self.elapsed_before + time.monotonic() - self.started

    def write_weights(self) -> None:
        """``out``: the best weights on validation so far, else the present ones."""
        if self.best_weights is None:
            save_weights(self.out, self.model, self.config,
                         {**self.meta, "steps": self.step, "wall_seconds": round(self.elapsed(), 1),
                          "threads": torch.get_num_threads()}, self.options.method)
            return
        final = {**self.best_weights["meta"], "final_step": self.step,
                 "final_wall_seconds": round(self.elapsed(), 1), "threads": torch.get_num_threads(),
                 "waited_for_data_seconds": round(self.pool.source.waited, 1)}
        save_weights(self.out, self.model, self.config, final, self.options.method,
                     self.best_weights["state_dict"])

    def run_folder_kept(self) -> None:
        """Before every write into the run folder: one removed meanwhile ends the run, its weights saved."""
        if not self.work.is_dir():
            self.write_weights()
            raise RunFolderGone(f"run folder {str(self.work)!r} was removed during training (step {self.step}): "
                                f"its checkpoint and logs are lost; wrote the weights to {str(self.out)!r}")

    def save_checkpoint(self) -> None:
        """The checkpoint and the curves' PNG."""
        self.run_folder_kept()
        self._write_checkpoint()
        plot_curves(self.log_path, self.validation_path, self.curves_path,
                    f"{self.options.method} {self.options.config}")

    def _write_checkpoint(self) -> None:
        _save_checkpoint(self.checkpoint, self.model, self.optimizer, self.scheduler, self.step, self.elapsed(),
                         self.generator, self.options, self.best, self.init)

    def keep_if_best(self) -> None:
        """Score the model on the validation set, log it, and keep it if it is the best so far. The
        log's row, the best and its file ``best.pt`` change as one, a stop held until all three are
        done: a Ctrl-C between them had left a checkpoint recording a best whose file was never
        written, which ``--resume`` refused."""
        scores = validate(self.model, self.cases, self.config, self.options.device)
        self.run_folder_kept()
        with stops_held():
            new_file = not self.validation_path.exists()
            with appending(self.validation_path) as handle:
                writer = csv.writer(handle)
                if new_file:
                    writer.writerow(["step", *scores, "seconds"])
                writer.writerow([self.step, *(f"{v:.3f}" for v in scores.values()), f"{self.elapsed():.1f}"])
            if self.best is None or scores["mean"] > self.best["mean"]:
                best_weights = {"state_dict": cpu_state(self.model),
                                "meta": {**self.meta, "steps": self.step, "validation": scores,
                                         "wall_seconds": round(self.elapsed(), 1)}}
                save_weights(self.best_path, self.model, self.config, best_weights["meta"], self.options.method,
                             best_weights["state_dict"])
                self.best, self.best_weights = {"step": self.step, **scores}, best_weights
            self.validated = self.step

    # ---------------------------------------------------------------- the steps
    def steps(self, show: bool) -> None:
        """Train until a budget is reached (``show``: a progress bar); an interrupt after a step
        saves the checkpoint of the last step boundary first."""
        options, config = self.options, self.config
        if options.validate_every:
            from .engine.validation import validation_set
            self.cases = validation_set(config)
        self.meta = {"options": dataclasses.asdict(options), "recipe": options.data_recipe().to_dict(),
                     "parameters": parameter_count(self.model), "command": self.command}
        if self.init is not None:
            self.meta["init"] = self.init
        self.started, first_step = time.monotonic(), self.step
        self.pool = ClipPool(options.data_recipe(), config, capacity=options.pool, refresh=options.refresh,
                             step=self.step, workers=options.workers, progress=show)
        bar = None
        if show:
            from tqdm import tqdm
            bar = tqdm(total=options.steps, initial=self.step, desc=f"train {options.method} {options.config}",
                       unit="step")
        last_save = time.monotonic()
        new_log = not self.log_path.exists()
        try:
            with appending(self.log_path) as handle:
                log = csv.writer(handle)
                if new_log:
                    log.writerow(LOG_HEADER)
                self.model.train()
                boundary = _random_states(self.generator)      # the random states where the last step ended
                while not self.budget_spent():
                    value, lr = self.one_step(first_step)
                    with stops_held():                  # the step's updates whole, or none of them
                        self.optimizer.step()
                        self.scheduler.step()
                        self.step += 1
                        log.writerow([self.step, self.step // options.steps_per_epoch, f"{lr:.3g}", f"{value:.6g}",
                                      f"{self.elapsed():.1f}"])
                        boundary = _random_states(self.generator)
                    if bar is not None:
                        bar.update(1)
                        bar.set_postfix(loss=f"{value:.4g}", best=f"{self.best['mean']:.2f}" if self.best else "-")
                    if self.cases is not None and self.step % options.validate_every == 0:
                        handle.flush()
                        self.keep_if_best()
                    if time.monotonic() - last_save >= options.checkpoint_seconds:
                        handle.flush()
                        self.save_checkpoint()
                        last_save = time.monotonic()
            if self.cases is not None and self.validated != self.step:
                self.keep_if_best()
        except BaseException as exc:
            if not isinstance(exc, Exception) and self.step > first_step and self.work.is_dir():   # interrupted
                with contextlib.suppress(Exception), stops_held(again=False):   # (a second Ctrl-C waits)
                    _restore_random_states(self.generator, boundary)   # (a step cut short drew the next batch)
                    self._write_checkpoint()
                    exc.add_note(f"at step {self.step}: checkpoint {str(self.checkpoint)!r} saved "
                                 "(continue with --resume)")
            raise
        finally:
            self.pool.close()
            if bar is not None:
                bar.close()

    def budget_spent(self) -> bool:
        """The step or wall-time budget reached (the first of the two that is set)."""
        options = self.options
        return ((options.steps is not None and self.step >= options.steps)
                or (options.minutes is not None and self.elapsed() >= 60 * options.minutes))

    def one_step(self, first_step: int) -> tuple[float, float]:
        """A batch's loss and gradients (the updates are the caller's, held against stops) ->
        (the loss, the learning rate it was taken at); a loss that is not finite ends the run."""
        options, config = self.options, self.config
        self.pool.advance_to(self.step)
        lr = self.optimizer.param_groups[0]["lr"]
        inputs, truth, inside = draw_batch(self.pool, config, self.sizes.span, options.crop, options.batch,
                                           self.generator, options.device)
        loss = training_loss(self.model(inputs, inside, config.spike_light), truth, options.loss)
        value = loss.detach().item()
        if not math.isfinite(value):
            cause = ("" if self.step > first_step or options.init is None
                     else f" (or the --init weights {options.init!r} are not a trained network's)")
            raise InputError(f"training diverged at step {self.step} (loss {value}); lower the learning rate"
                             + cause)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        return value, lr
