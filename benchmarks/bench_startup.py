"""A command's fixed cost: ``tespike simulate`` on a 1 x 32 x 32 scene, with and without compiled bytecode.

Usage (from the worktree root):

    python3 benchmarks/bench_startup.py [--runs 15]

Copies this tree's packages (sources only) to a temporary folder and times the
whole process there, interleaved: with no bytecode under
``PYTHONDONTWRITEBYTECODE=1`` (an editable install in such an environment
compiles every module on every run), and after ``python3 -m compileall`` (what
``install.sh`` does, and what a wheel install does). Prints the fastest and
the median wall time of each and their ratio in this run; figures depend on
the machine and its load.
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
PACKAGES = ("golden", "rtl", "recon", "cosim", "tespike")


def _copy_tree(dest: Path) -> None:
    for name in PACKAGES:
        shutil.copytree(ROOT / name, dest / name, ignore=shutil.ignore_patterns("__pycache__", "*.pt", "data"))
    shutil.copy(ROOT / "pyproject.toml", dest / "pyproject.toml")


def _time(tree: Path, scene: Path, out: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONDONTWRITEBYTECODE="1")
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tespike", "simulate", "--config", "te", "--scene", str(scene),
                    "--out", str(out), "--seed", "1", "--quiet"], env=env, cwd=tree, check=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15, help="runs of each kind (interleaved)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bare, compiled = tmp / "bare", tmp / "compiled"
        for tree in (bare, compiled):
            _copy_tree(tree)
        subprocess.run([sys.executable, "-m", "compileall", "-q", *PACKAGES], cwd=compiled, check=True)
        scene = tmp / "I.npy"
        np.save(scene, np.full((1, 32, 32), 0.1, np.float32))
        times = {"no bytecode": [], "compiled": []}
        for run in range(args.runs):
            print(f"\rrun {run + 1}/{args.runs}", end="", file=sys.stderr, flush=True)
            times["no bytecode"].append(_time(bare, scene, tmp / "S.npz"))
            times["compiled"].append(_time(compiled, scene, tmp / "S.npz"))
        print(file=sys.stderr)
    for name, values in times.items():
        print(f"tespike simulate, 1 x 32 x 32 scene, {name:11s}: fastest {min(values):.3f} s, "
              f"median {statistics.median(values):.3f} s ({args.runs} runs)")
    slow, fast = (statistics.median(v) for v in times.values())
    print(f"compiled bytecode saves {slow - fast:.3f} s a command (median), {slow / fast:.2f}x")


if __name__ == "__main__":
    main()
