"""CPU cost of every metric of ``tespike score`` per 384 x 512 frame.

Usage (from the worktree root; the machine is shared, so run it niced):

    nice -n 19 python3 benchmarks/bench_metrics.py [--frames 8] [--repeats 2] [--threads 1]

Scores a reconstruction-like estimate (the 'city' scene with 10 % noise) of
``--frames`` 384 x 512 frames against the scene with each metric, one call per
metric over all the frames (HDR-VQM's sequence value comes with its per-frame
values). Prints, per metric, the best of ``--repeats`` runs: process CPU time
and wall time per frame, and the CPU time over PSNR-mu's of the same run.
``--threads``: torch intra-op threads (default 1: on a shared, loaded machine
two threads contend; CPU time is the honest figure there).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

HEIGHT, WIDTH = 384, 512


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()

    import torch

    from tespike.recon.scenes import make_scene
    from tespike.recon.score import METRIC_KEYS, columns, score

    torch.set_num_threads(args.threads)
    reference = make_scene("city", frames=args.frames, height=HEIGHT, width=WIDTH).astype(np.float64)
    rng = np.random.default_rng(0)
    estimate = reference * (1 + 0.1 * rng.standard_normal(reference.shape))
    score(estimate[:1, :64, :64], reference[:1, :64, :64])          # imports and pyfvvdp's set-up
    print(f"{args.frames} frames of {HEIGHT} x {WIDTH}, torch threads {args.threads}, best of {args.repeats}")
    labels = {c.key: c.label for c in columns()}
    cpu_of = {}
    for key in METRIC_KEYS:
        cpu = wall = float("inf")
        for _ in range(args.repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            result = score(estimate, reference, metrics=(key,))
            cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - t0)
        cpu_of[key] = cpu
        print(f"{labels[key]:<52} CPU {1000 * cpu / args.frames:8.1f} ms/frame   "
              f"wall {1000 * wall / args.frames:8.1f} ms/frame   x{cpu / cpu_of['psnr_mu']:6.1f} PSNR-mu   "
              f"mean {result.mean[key]:.4f}")


if __name__ == "__main__":
    main()
