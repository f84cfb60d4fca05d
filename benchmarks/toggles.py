"""Switching activity against light: toggles per pixel per readout interval (an energy proxy).

For TE (b1 = b2 = 4), ML count (8 bit: the paper's ML counter and about TE's
dynamic range, 48.1 against 47.6 dB) and ML msb (8 bit: the paper's Table 1
camera; 9 bit: about TE's dynamic range, 48.2 dB), each with its SPEC default
threshold, counts the exact bit changes of the pixel's state flip-flops and of
its readout word register (the word bus) under constant light with Poisson
shot noise (:func:`tespike.golden.toggles.constant_light_toggles`), and prints a table
and writes a PNG (log axes; a zero count is not drawn on a log axis).

Run from the repository root:
``python3 benchmarks/toggles.py [--readouts 16] [--pixels 8] [--out out/bench/toggles.png | --docs]``
(``--docs`` writes docs/figures/toggles.png). About 10 s on one core.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))                       # measure this checkout's golden/

from benchmarks.plotfile import add_png_arguments, png_path  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.toggles import constant_light_toggles  # noqa: E402
from tespike.recon.pictures import save_figure  # noqa: E402

#: label -> configuration (the paper's settings and the equal-dynamic-range msb camera)
CAMERAS = {
    "TE b1=b2=4": SensorConfig(mode="te", b1=4, b2=4),
    "ML count 8 bit": SensorConfig(mode="ml", ml_bits=8),
    "ML msb 8 bit (paper Table 1)": SensorConfig(mode="ml", ml_bits=8, ml_readout="msb"),
    "ML msb 9 bit (TE's range)": SensorConfig(mode="ml", ml_bits=9, ml_readout="msb"),
}

#: light levels of the table (1 = brightest designed light, 42000 electrons per readout)
TABLE_LIGHT = (1e-3, 1e-2, 1e-1, 1.0, 10.0)


def sweep(config: SensorConfig, light: np.ndarray, readouts: int, pixels: int, seed: int = 0):
    """Mean (flip-flop, counter, word bus) toggles per pixel per interval at each light level."""
    toggles = constant_light_toggles(config, np.repeat(light, pixels), readouts, seed=seed)
    return tuple(x.reshape(light.size, pixels).mean(1) for x in toggles.per_interval())


def plot(path: Path, light: np.ndarray, curves: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    for label, values in curves.items():
        for ax, value in zip(axes, values):
            ax.plot(light, np.where(value > 0, value, np.nan), label=label)
    for ax, title in zip(axes, ("all state flip-flops (acc + counters)", "counters only (no acc)",
                                "readout word register (word bus)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("light I (1 = 42000 electrons per readout)")
        ax.set_ylabel("bit toggles per pixel per readout interval")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Switching activity (energy proxy), Poisson light, SPEC default thresholds")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readouts", type=int, default=16, help="readout intervals per pixel (default 16)")
    parser.add_argument("--pixels", type=int, default=8, help="pixels per light level (default 8)")
    add_png_arguments(parser, "toggles.png", "--out")
    args = parser.parse_args(argv)
    png_path(args, "toggles.png", "--out")
    light = np.logspace(-4, 2, 25)
    light = np.unique(np.concatenate([light, TABLE_LIGHT]))
    curves = {}
    start = time.perf_counter()
    for label, config in CAMERAS.items():
        curves[label] = sweep(config, light, args.readouts, args.pixels)
    seconds = time.perf_counter() - start
    print(f"toggles per pixel per readout interval: all state flip-flops / counters only / word bus "
          f"({args.readouts} readouts x {args.pixels} pixels per light, seed 0)")
    print("| camera | " + " | ".join(f"I = {i:g}" for i in TABLE_LIGHT) + " |")
    print("| --- |" + " ---: |" * len(TABLE_LIGHT))
    for label, (flops, counters, word) in curves.items():
        cells = [f"{flops[light == i][0]:.0f} / {counters[light == i][0]:.1f} / {word[light == i][0]:.2f}"
                 for i in TABLE_LIGHT]
        print(f"| {label} | " + " | ".join(cells) + " |")
    plot(Path(args.out), light, curves)
    print(f"wrote {args.out} ({seconds:.1f} s counting)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
