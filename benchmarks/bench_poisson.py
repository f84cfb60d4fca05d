"""Table Poisson sampler (golden.poisson) vs numpy's ``Generator.poisson``: ns per draw.

Usage (from the worktree root; the machine is shared, so run it niced):

    nice -n 19 python3 benchmarks/bench_poisson.py [--repeats 3] [--log-tail -75]

(a) per-clock electrons: shape (240, 20000), one mean per column (lam 88, 175,
350, 700, each plus a random fraction per column so the fractional part is
exercised), the table build shown apart (first call, cache empty);
(b) one draw per element, n = 196608: lam log-uniform in [1e-3, 1e3], and
constant 0.7 and 190. Best of ``--repeats`` timings for each; the ratio is
numpy over the sampler in the same run. Figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from golden.poisson import PoissonSampler  # noqa: E402


def best_ns(fn, draws: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best / draws * 1e9


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--log-tail", type=float, default=-75.0)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(2026)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}, "
          f"numpy {np.__version__}, log_tail {args.log_tail}")
    print(f"{'case':34s} {'numpy ns':>9s} {'table ns':>9s} {'ratio':>6s} {'build ms':>9s}")
    L, n = 240, 20000
    for base in (88, 175, 350, 700):
        lam = base + rng.random(n)
        sampler = PoissonSampler(args.log_tail)
        t0 = time.perf_counter()
        sampler.draw(rng, lam, clocks=L)
        first = time.perf_counter() - t0
        ns_np = best_ns(lambda: rng.poisson(lam[None, :], size=(L, n)), L * n, args.repeats)
        ns_tab = best_ns(lambda: sampler.draw(rng, lam, clocks=L), L * n, args.repeats)
        print(f"{f'(a) {L}x{n} lam {base}+U(0,1)':34s} {ns_np:9.1f} {ns_tab:9.1f} {ns_np / ns_tab:6.2f} "
              f"{sampler.build_seconds * 1e3:9.1f}  (first call {first / (L * n) * 1e9:.1f} ns/draw)")
    m = 196608
    cases = [("log-uniform 1e-3..1e3", np.exp(rng.uniform(np.log(1e-3), np.log(1e3), m))),
             ("0.7", np.full(m, 0.7)), ("190", np.full(m, 190.0))]
    for name, lam in cases:
        sampler = PoissonSampler(args.log_tail)
        sampler.draw(rng, lam)
        ns_np = best_ns(lambda: rng.poisson(lam), m, args.repeats)
        ns_tab = best_ns(lambda: sampler.draw(rng, lam), m, args.repeats)
        print(f"{f'(b) n={m} lam {name}':34s} {ns_np:9.1f} {ns_tab:9.1f} {ns_np / ns_tab:6.2f} "
              f"{sampler.build_seconds * 1e3:9.1f}  ({sampler.cache_bytes / 2**20:.1f} MiB cached)")


if __name__ == "__main__":
    main()
