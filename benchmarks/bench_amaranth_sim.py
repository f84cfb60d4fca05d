"""Amaranth simulator speed of the co-simulation testbench (cosim.rtlsim), in pixel clocks per second.

For 1, 16 and 64 pixels (TE, the paper's b1 = b2 = 4), with and without a VCD,
for the hierarchical array (one submodule per pixel, the default) and the flat
one (pixels inlined). Each figure is the simulated clocks over their wall time as
the testbench measures it (``RtlRun.cycles / RtlRun.seconds``: elaboration and
reset are not counted), best of ``--repeat`` runs. Ratios are
against 1 pixel without VCD measured in the same run. Prints a table, writes a
PNG plot.

    python3 benchmarks/bench_amaranth_sim.py [--readouts N] [--png PATH]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.cosim.rtlsim import rtl_run                     # noqa: E402
from tespike.golden.config import SensorConfig               # noqa: E402
from tespike.recon.pictures import save_figure                # noqa: E402
from tests.cosim_helpers import light_stimulus       # noqa: E402

SHAPES = {1: (1, 1), 16: (4, 4), 64: (8, 8)}


def clocks_per_second(config, stim, *, vcd: bool, flat: bool, repeat: int) -> tuple[float, int]:
    """Best of ``repeat`` runs (the machine is shared: the best is the least disturbed)."""
    best, size = 0.0, 0
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as scratch:
            path = os.path.join(scratch, "w.vcd") if vcd else None
            run = rtl_run(config, stim, vcd_path=path, flat=flat)
            best = max(best, run.cycles / run.seconds)
            size = os.path.getsize(path) if vcd else 0
    return best, size


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readouts", type=int, default=4, help="readout intervals (L = 240 clocks) per 1-pixel run; "
                        "larger arrays run proportionally fewer (at least 1)")
    parser.add_argument("--repeat", type=int, default=2, help="runs per figure; the best is reported")
    parser.add_argument("--png", default=str(Path(__file__).resolve().parent.parent / "out" / "bench" / "amaranth_sim.png"),
                        help="plot to write (default: out/bench/amaranth_sim.png, git-ignored)")
    args = parser.parse_args(argv)

    config = SensorConfig()
    rng = np.random.default_rng(0)
    L = config.clocks_per_readout
    rows = []
    print(f"TE b1 = b2 = 4, L = {L} clocks per readout; {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    print(f"{'pixels':>6} {'array':>6} {'vcd':>4} {'clocks':>7} {'clocks/s':>9} {'pixel-clk/s':>11} "
          f"{'vs 1px':>7} {'VCD MB':>7}")
    base = None
    for n, (h, w) in SHAPES.items():
        readouts = max(1, args.readouts * 16 // (16 + n))
        stim = light_stimulus(config, rng, readouts, h, w, dtype=np.uint16)
        for flat in (False, True):
            for vcd in (False, True):
                rate, size = clocks_per_second(config, stim, vcd=vcd, flat=flat, repeat=args.repeat)
                base = base or rate
                rows.append((n, flat, vcd, rate))
                print(f"{n:>6} {'flat' if flat else 'hier':>6} {'yes' if vcd else 'no':>4} {stim.shape[0]:>7} "
                      f"{rate:>9.0f} {rate * n:>11.0f} {rate / base:>7.3f} {size / 1e6:>7.2f}", flush=True)
    for n in SHAPES:
        plain = [r for p, f, v, r in rows if p == n and not f and not v][0]
        dumped = [r for p, f, v, r in rows if p == n and not f and v][0]
        print(f"VCD slowdown at {n} pixels (hierarchical): {plain / dumped:.1f}x")
    _plot(rows, args.png)
    print(f"plot: {args.png}")
    return 0


def _plot(rows, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for flat in (False, True):
        for vcd in (False, True):
            xs = [n for n, f, v, _ in rows if f == flat and v == vcd]
            ys = [r for n, f, v, r in rows if f == flat and v == vcd]
            ax.plot(xs, ys, "o-" if not vcd else "s--", label=f"{'flat' if flat else 'hierarchical'}"
                    f"{', VCD' if vcd else ''}")
    ax.set(xscale="log", yscale="log", xlabel="pixels", ylabel="clock cycles per second (whole array)",
           title="Amaranth pysim speed of cosim.rtlsim (TE, b1 = b2 = 4)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, png, dpi=120, bbox_inches="tight")


if __name__ == "__main__":
    sys.exit(main())
