"""Training of the reconstruction network (paper section 6.3), resumable, on any torch device.

The paper's recipe is the default: Adam (beta 0.9 / 0.999), learning rate
1e-4 halved every 10 epochs, the L1 loss of eq. 7, 96 x 96 random crops with
random horizontal and vertical flips, batch 4. An epoch here is
``steps_per_epoch`` steps of random (sequence, key moment, crop) draws. The
other loss, ``mu-l1``, is the L1 distance after the mu-law tone map the
metrics use (mu = 5000). A run stops at a step or wall-time budget, writes a
CSV log, a loss-curve PNG and a checkpoint every ``checkpoint_seconds`` (and at
the end), and resumes from its checkpoint bit for bit in what it draws.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from golden.config import SensorConfig
from golden.errors import InputError
from golden.io import atomic_output

from ..stream import decode_light
from .data import DataRecipe, training_set
from .model import TESpikeNet, compress, parameter_count
from .sizes import NetSizes

LOSSES = ("l1", "mu-l1")
#: Quantum efficiency of the paper's eq. 7 (its output is divided by it).
ETA = 0.7


@dataclasses.dataclass(frozen=True)
class TrainOptions:
    """One training run. ``minutes`` and ``steps`` are budgets (the first reached ends it)."""

    sensor: str = "te"                  # preset name or the JSON text of a configuration
    size: str = "cpu"
    ablation: int | None = None         # the paper's Table 3 case 1..6 (None: the whole network)
    loss: str = "l1"
    lr: float = 1e-4
    halve_every: int = 10               # epochs
    steps_per_epoch: int = 200
    batch: int = 4
    crop: int = 96
    steps: int | None = None
    minutes: float | None = None
    seed: int = 0
    device: str = "cpu"
    threads: int | None = None
    checkpoint_seconds: float = 120.0
    recipe: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:
            raise InputError(f"loss = {self.loss!r}: must be one of {', '.join(LOSSES)}")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise InputError(f"learning rate {self.lr!r} must be a finite number > 0")
        for key in ("halve_every", "steps_per_epoch", "batch", "crop"):
            if type(getattr(self, key)) is not int or getattr(self, key) < 1:
                raise InputError(f"{key} = {getattr(self, key)!r}: must be an integer >= 1")
        if self.steps is None and self.minutes is None:
            raise InputError("give a budget: steps or minutes")
        self.sizes()                    # an unknown size or ablation case is refused here
        if self.steps is not None and (type(self.steps) is not int or self.steps < 1):
            raise InputError(f"steps = {self.steps!r}: must be an integer >= 1")
        if self.minutes is not None and not (self.minutes > 0 and math.isfinite(self.minutes)):
            raise InputError(f"minutes = {self.minutes!r}: must be a finite number > 0")

    def config(self) -> SensorConfig:
        from golden.config import PRESETS
        if self.sensor in PRESETS:
            return SensorConfig.preset(self.sensor)
        return SensorConfig.from_json(self.sensor)

    def sizes(self) -> NetSizes:
        sizes = NetSizes.preset(self.size)
        return sizes if self.ablation is None else sizes.ablation(self.ablation)

    def data_recipe(self) -> DataRecipe:
        return DataRecipe(**self.recipe)


def training_loss(pred: torch.Tensor, truth: torch.Tensor, loss: str, mu: float = 5000.0) -> torch.Tensor:
    """Eq. 7 (``l1``: |I^ / eta - I_gt|, the network's output already being I^ / eta) or
    ``mu-l1``: the same after the mu-law tone map of the metrics."""
    if loss == "l1":
        return (pred - truth).abs().mean()
    return (compress(pred, mu) - compress(truth, mu)).abs().mean()


class Batches:
    """Random training batches: (decoded light (B, span, c, c), truth (B, 1, c, c))."""

    def __init__(self, light: np.ndarray, words: np.ndarray, config: SensorConfig, sizes: NetSizes,
                 crop: int, batch: int, generator: np.random.Generator, device: str = "cpu"):
        n, k, h, w = light.shape
        if k < sizes.span or h < crop or w < crop:
            raise InputError(f"training sequences {k} x {h} x {w} are too small for span {sizes.span} "
                             f"and crop {crop}")
        self.light, self.words, self.config = light, words, config
        self.sizes, self.crop, self.batch, self.rng, self.device = sizes, crop, batch, generator, device

    def __next__(self) -> tuple[torch.Tensor, torch.Tensor]:
        n, k, h, w = self.light.shape
        half, c = self.sizes.span // 2, self.crop
        inputs, truths = [], []
        for _ in range(self.batch):
            i = int(self.rng.integers(n))
            t = int(self.rng.integers(half, k - half))
            y, x = int(self.rng.integers(h - c + 1)), int(self.rng.integers(w - c + 1))
            words = np.asarray(self.words[i, t - half:t + half + 1, y:y + c, x:x + c])
            truth = np.asarray(self.light[i, t, y:y + c, x:x + c], np.float32)[None]
            flips = [axis for axis, flip in ((-1, self.rng.integers(2)), (-2, self.rng.integers(2))) if flip]
            if flips:
                words, truth = np.flip(words, flips), np.flip(truth, flips)
            inputs.append(np.ascontiguousarray(words))
            truths.append(np.ascontiguousarray(truth))
        light = decode_light(np.stack(inputs), self.config, device=self.device, dtype=torch.float32)
        return light, torch.from_numpy(np.stack(truths)).to(self.device)


def _lr(options: TrainOptions, step: int) -> float:
    return options.lr * 0.5 ** (step // (options.steps_per_epoch * options.halve_every))


def save_weights(path: str | Path, model: TESpikeNet, config: SensorConfig, meta: dict[str, Any]) -> None:
    """The shipped form: state dict + sizes + sensor configuration + how they were made,
    loadable with ``torch.load(weights_only=True)`` (no pickled code)."""
    payload = {"state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
               "sizes": model.sizes.to_dict(), "config": config.to_dict(), "meta": meta}
    with atomic_output(path) as tmp:
        torch.save(payload, tmp)


def _save_checkpoint(path: Path, model, optimizer, step, elapsed, generator, options) -> None:
    payload = {"model": model.state_dict(), "optimizer": optimizer.state_dict(), "step": step,
               "elapsed": elapsed, "generator": json_state(generator), "options": dataclasses.asdict(options),
               "torch_rng": torch.get_rng_state()}
    with atomic_output(path) as tmp:
        torch.save(payload, tmp)


def json_state(generator: np.random.Generator) -> dict:
    state = generator.bit_generator.state
    return {"bit_generator": state["bit_generator"], "state": {k: int(v) for k, v in state["state"].items()},
            "has_uint32": int(state["has_uint32"]), "uinteger": int(state["uinteger"])}


def plot_losses(log_path: Path, png_path: Path, title: str) -> None:
    """Loss against step (and the learning rate) from the CSV log, as a PNG with a legend."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with open(log_path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        return
    step = np.array([int(r["step"]) for r in rows])
    loss = np.array([float(r["loss"]) for r in rows])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(step, loss, lw=0.6, alpha=0.4, label="loss per logged step")
    if len(loss) >= 20:
        width = max(5, len(loss) // 20)
        smooth = np.convolve(loss, np.ones(width) / width, mode="valid")
        ax.plot(step[width - 1:], smooth, lw=1.5, label=f"running mean of {width}")
    ax.set_xlabel("step")
    ax.set_ylabel("training loss")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    with atomic_output(png_path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def train(options: TrainOptions, out: str | Path, *, work_dir: str | Path | None = None,
          resume: bool = False, cache: str | Path | None = None, progress: bool | None = None,
          command: str = "") -> Path:
    """Run (or resume) one training; write the weights to ``out``; return its path.

    ``work_dir`` (default: ``out`` with suffix ``.run``) holds the checkpoint, the
    CSV log and the loss-curve PNG.
    """
    out = Path(out)
    work = Path(work_dir) if work_dir is not None else out.with_suffix(".run")
    work.mkdir(parents=True, exist_ok=True)
    checkpoint, log_path = work / "checkpoint.pt", work / "log.csv"
    if options.threads is not None:
        torch.set_num_threads(options.threads)
    config, sizes = options.config(), options.sizes()
    torch.manual_seed(options.seed)
    generator = np.random.default_rng(options.seed)
    model = TESpikeNet(sizes).to(options.device).to(memory_format=torch.channels_last)
    optimizer = torch.optim.Adam(model.parameters(), lr=options.lr, betas=(0.9, 0.999))
    step, elapsed_before = 0, 0.0
    if resume:
        if not checkpoint.is_file():
            raise InputError(f"nothing to resume: no checkpoint at {str(checkpoint)!r}")
        state = torch.load(checkpoint, map_location=options.device, weights_only=True)
        saved = TrainOptions(**{**state["options"], "steps": options.steps, "minutes": options.minutes,
                                "device": options.device, "threads": options.threads})
        def same(o: TrainOptions) -> TrainOptions:    # the recipe compared as resolved, not as typed
            return dataclasses.replace(o, checkpoint_seconds=0, recipe=o.data_recipe().to_dict())
        if same(saved) != same(options):
            raise InputError(f"checkpoint {str(checkpoint)!r} was made with other options; "
                             "resume with the same sensor, size, loss, recipe and seed")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        step, elapsed_before = int(state["step"]), float(state["elapsed"])
        generator.bit_generator.state = state["generator"]
        torch.set_rng_state(state["torch_rng"])
    elif log_path.exists():
        log_path.unlink()
    light, words = training_set(config, options.data_recipe(), cache=cache, progress=bool(progress))
    batches = Batches(light, words, config, sizes, options.crop, options.batch, generator, options.device)
    show = sys.stderr.isatty() if progress is None else progress
    bar = None
    if show:
        from tqdm import tqdm
        bar = tqdm(total=options.steps, initial=step, desc=f"train {options.sensor}", unit="step")
    start = time.monotonic()
    last_save = start
    new_log = not log_path.exists()
    with open(log_path, "a", newline="") as handle:
        log = csv.writer(handle)
        if new_log:
            log.writerow(["step", "epoch", "lr", "loss", "seconds"])
        model.train()
        while True:
            elapsed = elapsed_before + time.monotonic() - start
            if options.steps is not None and step >= options.steps:
                break
            if options.minutes is not None and elapsed >= 60 * options.minutes:
                break
            lr = _lr(options, step)
            for group in optimizer.param_groups:
                group["lr"] = lr
            inputs, truth = next(batches)
            loss = training_loss(model(inputs), truth, options.loss, sizes.mu)
            value = loss.detach().item()
            if not math.isfinite(value):
                raise InputError(f"training diverged at step {step} (loss {value}); lower the learning rate")
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            step += 1
            log.writerow([step, step // options.steps_per_epoch, f"{lr:.3g}", f"{value:.6g}", f"{elapsed:.1f}"])
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{value:.4g}")
            if time.monotonic() - last_save >= options.checkpoint_seconds:
                handle.flush()
                _save_checkpoint(checkpoint, model, optimizer, step, elapsed_before + time.monotonic() - start,
                                 generator, options)
                plot_losses(log_path, work / "loss.png", f"{options.sensor}: {options.loss} loss")
                last_save = time.monotonic()
    if bar is not None:
        bar.close()
    elapsed = elapsed_before + time.monotonic() - start
    _save_checkpoint(checkpoint, model, optimizer, step, elapsed, generator, options)
    plot_losses(log_path, work / "loss.png", f"{options.sensor}: {options.loss} loss")
    meta = {"steps": step, "wall_seconds": round(elapsed, 1), "threads": torch.get_num_threads(),
            "options": dataclasses.asdict(options), "recipe": options.data_recipe().to_dict(),
            "parameters": parameter_count(model), "command": command}
    save_weights(out, model.eval(), config, meta)
    return out
