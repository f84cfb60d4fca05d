"""A command's fixed cost: ``tespike simulate`` with and without compiled bytecode, and with numpy's
OpenBLAS on one thread (the command's choice) or on every core (numpy's default).

Usage (from the worktree root):

    python3 benchmarks/bench_startup.py [--runs 15] [--scene I.npy]

Copies this tree's packages (sources only) to a temporary folder and times the
whole process there, interleaved: with no bytecode under
``PYTHONDONTWRITEBYTECODE=1`` (an editable install in such an environment
compiles every module on every run); after ``python3 -m compileall`` (what
``install.sh`` does, and what a wheel install does); and compiled with
``OPENBLAS_NUM_THREADS`` set to the core count, as a user may (the command
keeps a user's count; unset, it starts OpenBLAS on one thread, whose others
spin on the other cores after numpy's import). The scene is a 1 x 32 x 32 one
(the fixed cost alone) unless ``--scene`` names another, e.g. a dim pan from
``tespike scene``. Prints the fastest and the median wall time of each and
their ratios in this run; figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.arguments import existing_file  # noqa: E402

PACKAGES = ("golden", "rtl", "recon", "cosim", "tespike")


def _copy_tree(dest: Path) -> None:
    for name in PACKAGES:
        shutil.copytree(ROOT / name, dest / name, ignore=shutil.ignore_patterns("__pycache__", "*.pt", "data"))
    shutil.copy(ROOT / "pyproject.toml", dest / "pyproject.toml")


def _time(tree: Path, scene: Path, out: Path, blas_threads: int | None) -> float:
    """Wall seconds of one ``tespike simulate`` from ``tree``; ``blas_threads``: the user's
    ``OPENBLAS_NUM_THREADS`` (None: unset, the command's own choice)."""
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONDONTWRITEBYTECODE="1")
    env.pop("OPENBLAS_NUM_THREADS", None)
    if blas_threads is not None:
        env["OPENBLAS_NUM_THREADS"] = str(blas_threads)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tespike", "simulate", "--config", "te", "--scene", str(scene),
                    "--out", str(out), "--seed", "1", "--quiet"], env=env, cwd=tree, check=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15, help="runs of each kind (interleaved)")
    parser.add_argument("--scene", type=existing_file, help="I.npy to simulate (default: 1 x 32 x 32 at 0.1)")
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bare, compiled = tmp / "bare", tmp / "compiled"
        for tree in (bare, compiled):
            _copy_tree(tree)
        subprocess.run([sys.executable, "-m", "compileall", "-q", *PACKAGES], cwd=compiled, check=True)
        scene = args.scene.resolve() if args.scene else tmp / "I.npy"
        if not args.scene:
            np.save(scene, np.full((1, 32, 32), 0.1, np.float32))
        kinds = {"no bytecode": (bare, None), "compiled": (compiled, None),
                 f"compiled, {cores} BLAS threads": (compiled, cores)}
        times = {name: [] for name in kinds}
        for run in range(args.runs):
            print(f"\rrun {run + 1}/{args.runs}", end="", file=sys.stderr, flush=True)
            for name, (tree, threads) in kinds.items():
                times[name].append(_time(tree, scene, tmp / "S.npz", threads))
        print(file=sys.stderr)
    shape = " x ".join(map(str, np.load(scene, mmap_mode="r").shape)) if args.scene else "1 x 32 x 32"
    width = max(map(len, times))
    for name, values in times.items():
        print(f"tespike simulate, {shape} scene, {name:{width}s}: fastest {min(values):.3f} s, "
              f"median {statistics.median(values):.3f} s ({args.runs} runs)")
    bare_s, compiled_s, threaded_s = (statistics.median(v) for v in times.values())
    print(f"compiled bytecode saves {bare_s - compiled_s:.3f} s a command (median), {bare_s / compiled_s:.2f}x")
    print(f"one BLAS thread (the command's default) against {cores}: saves {threaded_s - compiled_s:.3f} s "
          f"a command (median), {threaded_s / compiled_s:.2f}x")


if __name__ == "__main__":
    main()
