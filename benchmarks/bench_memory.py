"""Peak memory of ``tespike reconstruct`` and ``tespike simulate`` against the input size.

Each command runs as a user would (a fresh ``python3 -m cosim`` process) on
inputs of growing size; the peak resident memory of the child (``ru_maxrss``,
which also counts the pages of memory-mapped files it touched) is printed with
the input size and the growth between sizes. Bounded memory shows as a peak
that grows much more slowly than the input (the words and images stay on
disk, memory-mapped; the work is done in blocks).

Run from the repository root: ``python3 benchmarks/bench_memory.py [--sizes 8,32,128] [--out DIR]``
(sizes in millions of readout words; DIR defaults to a temporary folder).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def peak_rss_mb(args: list[str]) -> float:
    """Run ``python3 -m cosim ARGS`` and return its peak resident memory in MB."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    code = ("import resource, subprocess, sys; "
            "r = subprocess.run([sys.executable, '-m', 'cosim', *sys.argv[1:]], capture_output=True); "
            "sys.stderr.write(r.stderr.decode()); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(r.returncode)")
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"tespike {' '.join(args)} failed: {done.stderr.strip()}")
    return int(done.stdout.split()[-1]) / 1024


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="8,32,128", help="millions of readout words, comma-separated")
    parser.add_argument("--out", default=None, help="folder for the inputs (default: a temporary folder)")
    args = parser.parse_args(argv)
    from golden.config import SensorConfig
    from golden.io import save_stream

    config = SensorConfig(mode="te")
    sizes = [int(s) for s in args.sizes.split(",")]
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.out or scratch)
        folder.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng(0)
        print("| words (M) | stream (MB) | reconstruct tfp peak (MB) | reconstruct tfi peak (MB) | "
              "simulate peak (MB) |")
        print("| ---: | ---: | ---: | ---: | ---: |")
        for millions in sizes:
            K = 16
            H, W = 1024, max(1, millions * (1 << 20) // (K * 1024))
            stream, scene = folder / f"s{millions}.npz", folder / f"i{millions}.npy"
            save_stream(stream, rng.integers(0, 16, size=(K, H, W)).astype(np.uint8), config)
            light = np.lib.format.open_memmap(scene, mode="w+", dtype=np.float32, shape=(K, H, W))
            light[:] = 0.5
            light.flush()
            del light
            tfp = peak_rss_mb(["reconstruct", "--stream", str(stream), "--method", "tfp",
                               "--out", str(folder / "r.npy"), "--quiet"])
            tfi = peak_rss_mb(["reconstruct", "--stream", str(stream), "--method", "tfi",
                               "--out", str(folder / "r.npy"), "--quiet"])
            sim = peak_rss_mb(["simulate", "--config", "te", "--scene", str(scene), "--seed", "1",
                               "--out", str(folder / "s.npz"), "--quiet"])
            size = stream.stat().st_size / 2 ** 20
            print(f"| {K * H * W / 2 ** 20:.0f} | {size:.0f} | {tfp:.0f} | {tfi:.0f} | {sim:.0f} |", flush=True)
            for path in (stream, scene):
                path.unlink()
    print(f"(peak resident memory of the child; the images of the largest size are "
          f"{4 * K * H * W / 2 ** 20:.0f} MB of float32 on disk)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
