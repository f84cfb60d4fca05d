"""Where a learned method should be corrected by the calibration: at its output or at its input.

On held-out scenes recorded by a noisy TE sensor (the paper's eq. 12 or eq. 13 dark
current, or a golden.noise JSON), calibrated from its own dark and flat streams as
`tespike evaluate` does, TFI and every learned method with TE weights is scored (PSNR-mu)
three ways: with shot noise alone; its output corrected, ``max(0, (x - dark) / gain)``
on the image; and (the product's rule) its input corrected: a learned method sees every
readout's decoded light as ``(x - dark) / gain``, TFI the pixel's own charge, its decoded
spikes less the dark rate re-coded as a pixel without dark current codes them
(recon.calibration.dark_free_light), divided by the gain. TFP, corrected at its output
(exact for a windowed mean), is printed beside. Each row gives its run time.

    nice -n 10 python3 benchmarks/calibration_route.py [--sequences 2] [--dark eq12] [--level 1]
        [--methods net] [--weights net=W.pt]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.fastsim import simulate_sequence as simulate  # noqa: E402
from tespike.golden.noise import Sensor, SensorNoise, load_noise  # noqa: E402
from tespike.recon.calibration import correct  # noqa: E402
from tespike.recon.evaluate import calibrate_sensor, learned_span, scored_frames  # noqa: E402
from tespike.recon.settings import DEFAULT_WINDOW  # noqa: E402
from tespike.recon.learned import LEARNED  # noqa: E402
from tespike.recon.methods import available_methods, reconstruct  # noqa: E402
from tespike.recon.metrics import psnr_mu  # noqa: E402
from tespike.recon.scenes.heldout import sequence_set  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=2)
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--width", type=int, default=80)
    parser.add_argument("--dark", default="eq12", help="eq12, eq13 or a golden.noise JSON file")
    parser.add_argument("--level", type=float, default=1.0, help="dark level x the model's (eq12 / eq13)")
    parser.add_argument("--sensor-seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--weights", action="append", default=[], metavar="METHOD=W.pt",
                        help="score a learned method with this weights file instead of the shipped one")
    parser.add_argument("--methods", default=None, help="comma-separated (default: tfp, tfi, every learned one)")
    args = parser.parse_args()
    import torch
    torch.set_num_threads(args.threads)
    config = SensorConfig.preset("te")
    noise = (SensorNoise(dark_current=args.dark, dark_level=args.level) if args.dark in ("eq12", "eq13")
             else load_noise(args.dark))
    sensor = Sensor(noise, args.sensor_seed)
    methods = (args.methods.split(",") if args.methods
               else ["tfp", "tfi"] + [m for m in available_methods([config]) if m in LEARNED])
    weights = dict(item.split("=", 1) for item in args.weights)
    rows = {m: {"clean": [], "output": [], "input": [], "seconds": 0.0} for m in methods}
    sequences = sequence_set("heldout", args.frames, args.height, args.width)[:args.sequences]
    for index, (name, light) in enumerate(sequences):
        light = np.asarray(light, np.float32)
        frames = scored_frames(light.shape[0], DEFAULT_WINDOW, learned_span(methods))
        clean = simulate(config, light, np.random.default_rng([index, 0]))
        noisy = simulate(config, light, np.random.default_rng([index, 1]), sensor)
        calibration = calibrate_sensor(simulate, config, sensor, light.shape[1:], np.random.default_rng([index, 2]))

        def score(images):
            return float(np.mean(psnr_mu(images[frames], light[frames])))
        for method in methods:
            start = time.perf_counter()
            row = rows[method]
            own = {"weights": weights[method]} if method in weights else {}
            row["clean"].append(score(reconstruct(clean, config, method, **own)))
            row["output"].append(score(correct(reconstruct(noisy, config, method, **own), calibration)))
            row["input"].append(score(reconstruct(noisy, config, method, calibration=calibration, **own)))
            row["seconds"] += time.perf_counter() - start
            print(f"{name} {method}: clean {row['clean'][-1]:.2f}, output corrected {row['output'][-1]:.2f}, "
                  f"input corrected {row['input'][-1]:.2f}", file=sys.stderr, flush=True)
    print(f"{len(sequences)} held-out sequences of {args.frames} x {args.height} x {args.width}, TE, dark "
          f"{args.dark} x {args.level:g}, sensor seed {args.sensor_seed}; PSNR-mu (dB), mean of the sequences\n")
    print("| method | shot noise only | corrected at the output | corrected at the input | run time s (3 runs) |")
    print("| :--- | ---: | ---: | ---: | ---: |")
    for method, row in rows.items():
        note = " (the same: TFP is linear)" if method == "tfp" else ""
        print(f"| {method} | {np.mean(row['clean']):.2f} | {np.mean(row['output']):.2f} | "
              f"{np.mean(row['input']):.2f}{note} | {row['seconds']:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
