"""The paper's Tables 6 to 9 with calibrated rows, and PSNR-mu against the dark level.

On the held-out scenes (recon.scenes.heldout), the TE camera with shot noise
only, with the paper's eq. 12 and eq. 13 dark current, and with eq. 12 scaled
by each ``--levels`` factor; each noise sensor is scored as every method
reconstructs it and again with the sensor's calibration (recon.evaluate's
``+cal`` sensors: its own dark and flat streams, recon.calibration). Methods: TFP,
TFI and every learned method with shipped TE weights (today's weights). Prints
the noise table (the Tables 6-9 layout, a calibrated row under each method),
what each method loses against shot noise alone and what the calibration wins
back, and writes a PNG of PSNR-mu against the dark level (x eq. 12) per method,
uncalibrated (solid) and calibrated (dashed), shot noise alone dotted.

    nice -n 10 python3 benchmarks/noise_tables.py [--sequences N] [--frames 12 --height 64 --width 80]
        [--levels 0.25,0.5,1,2,4] [--sensor-noise N.json] [--methods tfp,tfi,net] [--png P] [--docs]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.plotfile import add_png_arguments, write_plot  # noqa: E402
from tespike.golden.fastsim import simulate_sequence as simulate  # noqa: E402
from tespike.golden.noise import Sensor, SensorNoise, load_noise  # noqa: E402
from tespike.recon.evaluate import CALIBRATED, default_noise_sensors, evaluate, paper_configs  # noqa: E402
from tespike.recon.names import METHOD_NAMES  # noqa: E402
from tespike.recon.methods import available_methods  # noqa: E402
from tespike.recon.report import noise_markdown  # noqa: E402
from tespike.recon.scenes.heldout import sequence_set  # noqa: E402

NAME = "noise_tables.png"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", default="heldout")
    parser.add_argument("--sequences", type=int, default=None, help="score only the first N sequences of the set")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--width", type=int, default=80)
    parser.add_argument("--levels", default="0.25,0.5,2,4", help="dark levels x eq. 12 besides 1 (default 0.25,0.5,2,4)")
    parser.add_argument("--sensor-noise", action="append", default=[], metavar="N.json",
                        help="a further noise sensor (golden.noise JSON), scored and calibrated too")
    parser.add_argument("--sensor-seed", type=int, default=0)
    parser.add_argument("--methods", default=None, help="default: tfp, tfi and every learned method with TE weights")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1: on a shared 2-core machine more threads ran 10x slower)")
    add_png_arguments(parser, NAME)
    args = parser.parse_args()
    import torch
    torch.set_num_threads(args.threads)
    configs = paper_configs()
    te = configs["te"]
    methods = (tuple(m.strip() for m in args.methods.split(",")) if args.methods
               else available_methods([te]))
    levels = [float(x) for x in args.levels.split(",") if x.strip()]
    noise_sensors = default_noise_sensors(args.sensor_seed)
    for level in levels:
        noise_sensors[f"te+eq12x{level:g}"] = Sensor(SensorNoise(dark_current="eq12", dark_level=level),
                                                     args.sensor_seed)
    for path in args.sensor_noise:
        noise_sensors[f"te+{Path(path).stem}"] = Sensor(load_noise(path), args.sensor_seed)
    sensors = ["te"] + [s + suffix for s in noise_sensors for suffix in ("", CALIBRATED)]
    configs.update({sensor: te for sensor in sensors})
    sequences = sequence_set(args.set, args.frames, args.height, args.width)[:args.sequences]
    print(f"{len(sequences)} {args.set} sequences of {args.frames} x {args.height} x {args.width}; "
          f"methods {', '.join(methods)}; sensor seed {args.sensor_seed}", flush=True)
    evaluation = evaluate(sequences, simulate, methods=methods, sensors=tuple(sensors), configs=configs,
                          seed=args.seed, progress=False, repeats=1, noise_sensors=noise_sensors)
    summary = evaluation.summary()
    print("\n".join(noise_markdown(evaluation)))

    print("\nPSNR-mu lost against shot noise alone, uncalibrated -> calibrated (won back):")
    for method in methods:
        clean = summary[method, "te"]["psnr_mu"]
        cells = []
        for sensor in noise_sensors:
            raw, cal = summary[method, sensor]["psnr_mu"], summary[method, sensor + CALIBRATED]["psnr_mu"]
            back = (cal - raw) / (clean - raw) if clean > raw else float("nan")
            cells.append(f"{sensor[3:]} {clean - raw:.2f} -> {clean - cal:.2f} dB ({100 * back:.0f} % back)")
        print(f"  {METHOD_NAMES.get(method, method)}_TE (clean {clean:.2f}): " + "; ".join(cells))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sweep = sorted([(1.0, "te+eq12")] + [(level, f"te+eq12x{level:g}") for level in levels])
    x = [level for level, _ in sweep]
    fig, ax = plt.subplots(figsize=(8, 5))
    for i, method in enumerate(methods):
        color = f"C{i}"
        name = f"{METHOD_NAMES.get(method, method)}_TE"
        ax.plot(x, [summary[method, m]["psnr_mu"] for _, m in sweep], "o-", color=color, label=name)
        ax.plot(x, [summary[method, m + CALIBRATED]["psnr_mu"] for _, m in sweep], "s--", color=color,
                label=f"{name} calibrated")
        ax.axhline(summary[method, "te"]["psnr_mu"], color=color, ls=":", lw=1)
    ax.set_xscale("log")
    ax.set(xlabel="dark current, x the paper's eq. 12 (N(400, 50) e- per readout)", ylabel="PSNR-μ, dB",
           title=f"held-out scenes ({args.frames} x {args.height} x {args.width}): dotted = shot noise only")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    write_plot(fig, args, NAME)
    return 0


if __name__ == "__main__":
    sys.exit(main())
