"""Table (golden.poisson) and vectorised PTRS (golden.poisson_rejection) Poisson samplers vs numpy's ``Generator.poisson``: ns per draw.

Usage (from the worktree root; the machine is shared, so run it niced):

    nice -n 19 python3 benchmarks/bench_poisson.py [--repeats 3] [--log-tail -75]

(a) per-clock electrons: shape (240, 20000), one mean per column: lam 88, 175,
350, 700; 88 and 700 plus a random fraction per column (the fractional part's
cost); per column log-uniform in [50, 1000] (about 950 tables: cache misses).
The table build is shown apart (first call, cache empty);
(b) one draw per element, n = 196608: lam log-uniform in [1e-3, 1e3], and
constant 0.7 and 190;
(c) the vectorised transformed rejection (:func:`tespike.golden.poisson_rejection.poisson_draws`),
one draw per element, n = 58000 (an event path's pixels in a stripe of a 384 x 512
pan): lam log-uniform in [350, 15000] (the event path's means on a dim interior),
uniform in [1000, 1200], log-uniform in [10, 350], and the first with 41 % zeros
(the path run under a frame mask). Best of ``--repeats`` timings for each; the ratio is
numpy over the sampler in the same run. Times are process CPU time (the
machine is shared and loaded: wall time there counts other processes' turns);
the wall-clock ratio of the same runs is printed beside it. Figures depend on
the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.golden.poisson import PoissonSampler  # noqa: E402
from tespike.golden.poisson_rejection import poisson_draws  # noqa: E402
from tespike.golden.resources import keep_freed_memory  # noqa: E402


def best_ns(fn, draws: int, repeats: int) -> tuple[float, float]:
    """Best CPU and best wall time of ``repeats`` calls, in ns per draw."""
    cpu = wall = float("inf")
    for _ in range(repeats):
        # hand-written timing: numpy code (no torch) and CPU seconds beside wall time (torch.utils.benchmark gives wall only)
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        cpu = min(cpu, time.process_time() - c0)
        wall = min(wall, time.perf_counter() - t0)
    return cpu / draws * 1e9, wall / draws * 1e9


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--log-tail", type=float, default=-75.0)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(2026)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}, "
          f"numpy {np.__version__}, log_tail {args.log_tail}")
    print(f"{'case':36s} {'numpy ns':>9s} {'table ns':>9s} {'ratio':>6s} {'wall ratio':>10s} "
          f"{'build ms':>9s}")
    L, n = 240, 20000
    cases = [(f"lam {b}", np.full(n, float(b))) for b in (88, 175, 350, 700)]
    cases += [(f"lam {b}+U(0,1)", b + rng.random(n)) for b in (88, 700)]
    cases += [("lam log-unif 50..1000", np.exp(rng.uniform(np.log(50), np.log(1000), n)))]
    for name, lam in cases:
        sampler = PoissonSampler(args.log_tail)
        t0 = time.perf_counter()
        sampler.draw(rng, lam, clocks=L)
        first = time.perf_counter() - t0
        ns_np = best_ns(lambda: rng.poisson(lam[None, :], size=(L, n)), L * n, args.repeats)
        ns_tab = best_ns(lambda: sampler.draw(rng, lam, clocks=L), L * n, args.repeats)
        print(f"{f'(a) {L}x{n} {name}':36s} {ns_np[0]:9.1f} {ns_tab[0]:9.1f} "
              f"{ns_np[0] / ns_tab[0]:6.2f} {ns_np[1] / ns_tab[1]:10.2f} {sampler.build_seconds * 1e3:9.1f}"
              f"  (first call, build included: {first / (L * n) * 1e9:.1f} ns/draw wall)")
    m = 196608
    cases = [("log-uniform 1e-3..1e3", np.exp(rng.uniform(np.log(1e-3), np.log(1e3), m))),
             ("0.7", np.full(m, 0.7)), ("190", np.full(m, 190.0))]
    for name, lam in cases:
        sampler = PoissonSampler(args.log_tail)
        sampler.draw(rng, lam)
        ns_np = best_ns(lambda: rng.poisson(lam), m, args.repeats)
        ns_tab = best_ns(lambda: sampler.draw(rng, lam), m, args.repeats)
        print(f"{f'(b) n={m} lam {name}':36s} {ns_np[0]:9.1f} {ns_tab[0]:9.1f} "
              f"{ns_np[0] / ns_tab[0]:6.2f} {ns_np[1] / ns_tab[1]:10.2f} {sampler.build_seconds * 1e3:9.1f}"
              f"  ({sampler.cache_bytes / 2**20:.1f} MiB of tables)")
    keep_freed_memory()                                 # as the simulator has it: no fresh pages a call
    m = 58000
    event = np.exp(rng.uniform(np.log(350), np.log(15000), m))
    cases = [("log-uniform 350..15000", event), ("uniform 1000..1200", rng.uniform(1000, 1200, m)),
             ("log-uniform 10..350", np.exp(rng.uniform(np.log(10), np.log(350), m))),
             ("log-unif 350..15000, 41% 0", np.where(rng.random(m) < 0.41, 0.0, event))]
    print(f"{'case':36s} {'numpy ns':>9s} {'PTRS ns':>9s} {'ratio':>6s} {'wall ratio':>10s}")
    for name, lam in cases:
        ns_np = best_ns(lambda: rng.poisson(lam), m, args.repeats)
        ns_pt = best_ns(lambda: poisson_draws(rng, lam), m, args.repeats)
        print(f"{f'(c) n={m} lam {name}':36s} {ns_np[0]:9.1f} {ns_pt[0]:9.1f} "
              f"{ns_np[0] / ns_pt[0]:6.2f} {ns_np[1] / ns_pt[1]:10.2f}")


if __name__ == "__main__":
    main()
