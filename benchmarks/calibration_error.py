"""Calibration error against the readouts it uses (and its run time): how many are enough.

For two sensors (the paper's eq. 12 and eq. 13 dark current, each with DSNU,
hot pixels, PRNU and comparator offset; one sensor seed), the TE camera records
K dark readouts and K flat readouts at the flat light of recon.evaluate
(CALIBRATION_FLAT, below the TE overflow level), ``tespike.recon.calibration.estimate``
turns them into maps, and the maps are compared with the sensor's true ones
(golden.noise.Sensor.maps):

- gain: RMS relative error ``rms(gain_est / gain - 1)`` over the ordinary pixels
  (and, apart, the hot ones, whose flat overflows: TE decoding of an overflow
  word is biased), beside the true gain spread it corrects (``std(gain)``);
- dark rate: RMS error in electrons per readout over the ordinary pixels (and,
  apart, over the hot ones), beside the true mean dark rate.

Run time is the simulation of both streams plus the estimate (what a camera
team pays in recording and computing). "Enough" is the fewest readouts whose
gain error is below a third of the gain spread and whose dark error is below
10 % of the mean dark rate. Prints one row per K; writes a PNG (error against run
time, one line per sensor and map, legend).

    nice -n 10 python3 benchmarks/calibration_error.py [--size 64] [--readouts 16,32,...] [--png P] [--docs]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.plotfile import add_png_arguments, write_plot  # noqa: E402
from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig  # noqa: E402
from tespike.golden.fastsim import simulate_scene  # noqa: E402
from tespike.golden.noise import Sensor, SensorNoise  # noqa: E402
from tespike.recon.calibration import estimate  # noqa: E402
from tespike.recon.evaluate import CALIBRATION_FLAT  # noqa: E402

NAME = "calibration_error.png"
SENSORS = {
    "eq12": SensorNoise(dark_current="eq12", dsnu=0.2, hot_pixels=0.005, hot_factor=20.0, prnu=0.01,
                        comparator_offset=0.02),
    "eq13": SensorNoise(dark_current="eq13", dsnu=0.2, hot_pixels=0.005, hot_factor=20.0, prnu=0.01,
                        comparator_offset=0.02),
}


def measure(noise: SensorNoise, size: int, readouts: int, seed: int) -> dict:
    config = SensorConfig()
    sensor = Sensor(noise, seed)
    start = time.perf_counter()
    dark = simulate_scene(config, np.zeros((readouts, size, size), np.float32), seed=[seed, 1, readouts],
                          sensor=sensor)
    flat = simulate_scene(config, np.full((readouts, size, size), CALIBRATION_FLAT, np.float32),
                          seed=[seed, 2, readouts], sensor=sensor)
    c = estimate(dark, flat, config, CALIBRATION_FLAT)
    seconds = time.perf_counter() - start
    maps = sensor.maps((size, size))
    true_dark = maps.mean_dark_electrons(noise)
    hot = maps.dark_scale > 5 * np.median(maps.dark_scale)
    dark_error = DESIGN_ELECTRONS * c.dark - true_dark
    return {"seconds": seconds, "gain": float(np.sqrt(np.mean((c.gain / maps.gain - 1)[~hot] ** 2))),
            "gain_hot": float(np.sqrt(np.mean((c.gain / maps.gain - 1)[hot] ** 2))) if hot.any() else float("nan"),
            "spread": float(maps.gain.std()), "dark": float(np.sqrt(np.mean(dark_error[~hot] ** 2))),
            "dark_hot": float(np.sqrt(np.mean(dark_error[hot] ** 2))) if hot.any() else float("nan"),
            "dark_mean": float(true_dark[~hot].mean()), "overflow": c.overflow_share}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64, help="frame side, pixels (default 64)")
    parser.add_argument("--readouts", default="16,32,64,128,256,512,1024,2048")
    parser.add_argument("--seed", type=int, default=0, help="sensor seed (default 0)")
    add_png_arguments(parser, NAME)
    args = parser.parse_args()
    counts = [int(k) for k in args.readouts.split(",")]
    print(f"TE camera, {args.size} x {args.size} pixels, flat light {CALIBRATION_FLAT}, sensor seed {args.seed}")
    print("| sensor | readouts | run time s | gain RMS rel. error | (hot) | gain spread | dark RMS error e- "
          "| (hot) | mean dark e- | flat overflow words |")
    print("| :--- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    results = {}
    for name, noise in SENSORS.items():
        for k in counts:
            r = results[name, k] = measure(noise, args.size, k, args.seed)
            print(f"| {name} | {k} | {r['seconds']:.2f} | {r['gain']:.4f} | {r['gain_hot']:.3f} | {r['spread']:.4f} | {r['dark']:.1f} | "
                  f"{r['dark_hot']:.0f} | {r['dark_mean']:.0f} | {100 * r['overflow']:.1f} % |", flush=True)
    for name in SENSORS:
        enough = [k for k in counts if results[name, k]["gain"] < results[name, k]["spread"] / 3
                  and results[name, k]["dark"] < 0.1 * results[name, k]["dark_mean"]]
        print(f"{name}: enough readouts (gain error < spread / 3, dark error < 10 % of the mean): "
              + (f"{enough[0]}" if enough else f"more than {counts[-1]}"))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for name in SENSORS:
        seconds = [results[name, k]["seconds"] for k in counts]
        axes[0].loglog(seconds, [results[name, k]["gain"] for k in counts], "o-", label=f"{name}: gain")
        axes[0].axhline(results[name, counts[0]]["spread"] / 3, ls=":", color="grey")
        axes[1].loglog(seconds, [results[name, k]["dark"] for k in counts], "o-", label=f"{name}: dark (ordinary)")
        for k, s in zip(counts, seconds):
            axes[0].annotate(str(k), (s, results[name, k]["gain"]), fontsize=7)
    axes[0].set(xlabel="run time, s (both streams simulated + estimate)", ylabel="RMS relative gain error",
                title="gain (dotted: a third of the true spread)")
    axes[1].set(xlabel="run time, s", ylabel="RMS dark error, e- per readout", title="dark rate")
    for ax in axes:
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"calibration error against run time (readouts annotated), {args.size} x {args.size} TE")
    write_plot(fig, args, NAME)
    return 0


if __name__ == "__main__":
    sys.exit(main())
