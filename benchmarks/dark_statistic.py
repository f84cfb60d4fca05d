"""Which per-pixel dark statistic calibrated TFP and TFI should subtract, and whether an outlier
rule helps, against eq. 13's heavy-tailed dark charge.

On the held-out scenes (recon.scenes.heldout), the TE camera with each dark model (``eq13``,
or eq. 12 at a level), calibrated from its own dark and flat streams as ``tespike evaluate``
does (recon.evaluate.calibrate_sensor), TFP and TFI are scored (PSNR-mu, mean of the scenes)
with the calibration's gain and each dark map:

- ``mean``: the product's, the mean decoded light of the dark stream (recon.calibration);
- ``exact``: the sensor's true mean dark rate (golden.noise, what no camera team has): the
  best a per-pixel constant can do;
- ``trim5``, ``trim10``, ``trim20``: the mean of each pixel's dark readouts with 5, 10, 20 %
  cut from each end (a robust statistic a calibration file could carry);

the calibration's dark law (``law``, recon.darklaw: the product's calibrated TFP and TFI,
timed: the last two columns, seconds per sequence on one torch thread), and TFP once more with
an outlier rule applied where the correction is applied,
``winsorised``: each readout's decoded spikes clipped at the window's median plus the
pixel's dark spread (99th percentile less median of its dark readouts) plus three times the
square root of the median's own light, less the mean of the dark readouts clipped at their
99th percentile. That rule is also scored on the shot-noise-only stream (``clean``, where it
has no dark to remove): what it gains there is a different estimator, not a calibration.

    nice -n 10 python3 benchmarks/dark_statistic.py [--dark eq13,1,0.25,0.5,2,4] [--sequences N]
        [--sensor-noise N.json]
"""

from __future__ import annotations

import argparse
import time
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig  # noqa: E402
from tespike.golden.decode import decode_spikes  # noqa: E402
from tespike.golden.fastsim import simulate_sequence as simulate  # noqa: E402
from tespike.golden.noise import Sensor, SensorNoise, load_noise  # noqa: E402
from tespike.recon.evaluate import CALIBRATION_READOUTS, calibrate_sensor, scored_frames  # noqa: E402
from tespike.recon.settings import DEFAULT_WINDOW  # noqa: E402
from tespike.recon.methods import reconstruct  # noqa: E402
from tespike.recon.metrics import psnr_mu  # noqa: E402
from tespike.recon.scenes.heldout import sequence_set  # noqa: E402

TRIMS = (0.05, 0.10, 0.20)
WINDOW = DEFAULT_WINDOW


def dark_maps(dark_spikes: np.ndarray, calibration, sensor: Sensor, config: SensorConfig) -> dict:
    """Dark statistic name -> (H, W) dark rate, light units per readout."""
    shape = dark_spikes.shape[1:]
    maps = {"mean": calibration.dark,
            "exact": sensor.maps(shape).mean_dark_electrons(sensor.noise) / DESIGN_ELECTRONS}
    ordered = np.sort(dark_spikes, axis=0)
    K = ordered.shape[0]
    for trim in TRIMS:
        cut = int(round(trim * K))
        maps[f"trim{round(100 * trim)}"] = ordered[cut:K - cut].mean(axis=0) * config.spike_light
    return maps


def winsorised_tfp(spikes: np.ndarray, dark_spikes: np.ndarray, gain: np.ndarray, config: SensorConfig,
                   frames: slice) -> np.ndarray:
    """TFP of readouts clipped at the window's median + the dark spread + 3 sqrt(own light), less the
    clipped dark mean (frames whose whole window lies in the stream only; others 0)."""
    ceiling, middle = np.quantile(dark_spikes, 0.99, axis=0), np.median(dark_spikes, axis=0)
    dark = np.minimum(dark_spikes, ceiling).mean(axis=0)
    out = np.zeros(spikes.shape, np.float32)
    half = WINDOW // 2
    for k in range(frames.start, frames.stop):
        window = spikes[k - half:k + half + 1]
        median = np.median(window, axis=0)
        own = np.maximum(median - middle, 0)
        clipped = np.minimum(window, median - middle + ceiling + 3 * np.sqrt(own + 1))
        out[k] = np.maximum(clipped.mean(axis=0) - dark, 0) * config.spike_light / gain
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dark", default="eq13,1,0.25,0.5,2,4",
                        help="dark models: eq13, or an eq. 12 level (x the paper's eq. 12)")
    parser.add_argument("--sequences", type=int, default=None)
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--width", type=int, default=80)
    parser.add_argument("--sensor-seed", type=int, default=0)
    parser.add_argument("--sensor-noise", default=None, metavar="N.json",
                        help="take the non-uniformity (DSNU, hot pixels, PRNU, offset) from this golden.noise JSON")
    args = parser.parse_args()
    import torch
    torch.set_num_threads(1)
    config = SensorConfig.preset("te")
    sequences = sequence_set("heldout", args.frames, args.height, args.width)[:args.sequences]
    frames = scored_frames(args.frames, WINDOW)
    if frames.stop - frames.start < 1 or frames.start < WINDOW // 2:
        print(f"--frames {args.frames}: needs at least {WINDOW} readouts", file=sys.stderr)
        return 2
    print(f"{len(sequences)} held-out sequences of {args.frames} x {args.height} x {args.width}, TE, "
          f"sensor seed {args.sensor_seed}; PSNR-mu (dB), mean of the sequences\n")
    header = None
    base = load_noise(args.sensor_noise) if args.sensor_noise else SensorNoise()
    for model in args.dark.split(","):
        noise = dataclasses.replace(base, dark_current="eq13" if model == "eq13" else "eq12",
                                    dark_level=1.0 if model == "eq13" else float(model))
        sensor = Sensor(noise, args.sensor_seed)
        scores: dict[str, list[float]] = {}
        times: dict[str, list[float]] = {}
        for index, (name, light) in enumerate(sequences):
            light = np.asarray(light, np.float32)
            shape = light.shape[1:]
            calibration = calibrate_sensor(simulate, config, sensor, shape, np.random.default_rng([index, 2]))
            dark_words = simulate(config, np.zeros((CALIBRATION_READOUTS, *shape), np.float32),
                                  np.random.default_rng([index, 3]), sensor)
            dark_spikes = decode_spikes(dark_words, config)
            noisy = simulate(config, light, np.random.default_rng([index, 1]), sensor)
            clean = simulate(config, light, np.random.default_rng([index, 0]))

            def score(key, images):
                scores.setdefault(key, []).append(float(np.mean(psnr_mu(images[frames], light[frames]))))
            for statistic, dark in dark_maps(dark_spikes, calibration, sensor, config).items():
                fixed = dataclasses.replace(calibration, dark=np.asarray(dark, np.float64), dark_law=None)
                for method in ("tfp", "tfi"):
                    score(f"{method} {statistic}", reconstruct(noisy, config, method, calibration=fixed))
            for method in ("tfp", "tfi"):
                start = time.perf_counter()
                score(f"{method} law", reconstruct(noisy, config, method, calibration=calibration))
                times.setdefault(method, []).append(time.perf_counter() - start)
            score("tfp winsorised", winsorised_tfp(decode_spikes(noisy, config), dark_spikes, calibration.gain,
                                                   config, frames))
            score("tfp clean", reconstruct(clean, config, "tfp"))
            score("tfp clean winsorised", winsorised_tfp(decode_spikes(clean, config), np.zeros_like(dark_spikes),
                                                         np.ones(shape), config, frames))
        if header is None:
            header = list(scores)
            print("| dark | " + " | ".join(header) + " | tfp law s | tfi law s |")
            print("| :--- |" + " ---: |" * (len(header) + 2))
        label = "eq. 13" if model == "eq13" else f"eq. 12 x {float(model):g}"
        print(f"| {label} | " + " | ".join(f"{np.mean(scores[key]):.2f}" for key in header) + " | "
              + " | ".join(f"{np.mean(times[m]):.2f}" for m in ("tfp", "tfi")) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
