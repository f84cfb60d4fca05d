"""Whole-process time of ``tespike verilog`` for small and large arrays, and the Verilog size.

Each size runs the command as a user would (a fresh ``python3 -m tespike verilog``
process: interpreter start, imports, Amaranth elaboration, Yosys conversion,
atomic write), ``--repeats`` times; the median is reported, and the ratio of
128 x 128 to 8 x 8 (the brief's bound: about 16x at most). Writes
``out/bench/bench_verilog.png`` (``--docs``: ``docs/figures/bench_verilog.png``).

Run from the repository root: ``python3 benchmarks/bench_verilog.py [--config te] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.plotfile import add_png_arguments, png_path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SIZES = [8, 32, 128]


def time_command(config: str, size: int, out: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "tespike", "verilog", "--config", config,
                             "--height", str(size), "--width", str(size), "--out", str(out)],
                            capture_output=True, text=True, env=env, cwd=ROOT)
    elapsed = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"tespike verilog failed for {size} x {size}: {result.stderr.strip()}")
    return elapsed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="te", help="config file or 'te' / 'ml'")
    parser.add_argument("--repeats", type=int, default=3)
    add_png_arguments(parser, "bench_verilog.png")
    args = parser.parse_args(argv)
    png_path(args, "bench_verilog.png")
    from tqdm import tqdm

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        runs = [(size, r) for r in range(args.repeats) for size in SIZES]   # interleaved: fair under load
        times = {size: [] for size in SIZES}
        for size, _ in tqdm(runs, desc="tespike verilog", file=sys.stderr):
            out = Path(tmp) / f"a{size}.v"
            times[size].append(time_command(args.config, size, out))
        for size in SIZES:
            out = Path(tmp) / f"a{size}.v"
            results[size] = (statistics.median(times[size]), out.stat().st_size)
    print(f"tespike verilog --config {args.config}: whole process, median of {args.repeats}")
    print(f"{'array':>10} {'seconds':>8} {'bytes':>9}")
    for size, (seconds, size_bytes) in results.items():
        print(f"{f'{size}x{size}':>10} {seconds:8.2f} {size_bytes:9d}")
    ratio = results[128][0] / results[8][0]
    print(f"time ratio 128x128 / 8x8 = {ratio:.2f} (pixels ratio 256; bound about 16)")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from tespike.recon.pictures import save_figure

        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.bar([f"{s}x{s}" for s in SIZES], [results[s][0] for s in SIZES], color="#4a7ab5")
        ax.set_ylabel("seconds (whole process)")
        ax.set_title(f"tespike verilog --config {args.config}")
        fig.tight_layout()
        save_figure(fig, args.png)
        print(f"wrote {args.png}")
    except ImportError:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
