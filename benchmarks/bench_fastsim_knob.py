"""One fast-simulator constant at several values, timed readout by readout, interleaved in one process.

Usage (from the worktree root):

    python3 benchmarks/bench_fastsim_knob.py --scene I.npy --constant window.MERGE_DRAWS \\
        --values 16384 16384 4096 65536 [--config te] [--repeats 3]

Whole-process timings on a shared 2-core machine move by 10-20 % from run to run
(docs/simulator.md, ninth round), more than most single changes gain. Here one
simulator per value reads out the first stripe of the scene (the noisy fast
method, as ``tespike simulate`` runs it), and each readout interval is run by every
simulator in turn, alternating the order, with the constant set to that
simulator's value just before its call (a constant of ``tespike.golden.fastsim.M`` read
when a path runs, not when a level is found); process CPU time summed per value,
``--repeats`` times with fresh simulators and seeds. Giving the first value twice
shows the harness's own spread (an A/A pair: within 1 % here). Prints each
value's CPU time and its ratio to the first's.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.arguments import existing_file  # noqa: E402
from tespike.golden.config import SensorConfig, load_config  # noqa: E402
from tespike.golden.fastsim.scene import stripe_simulators  # noqa: E402
from tespike.golden.resources import keep_freed_memory  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", required=True, type=existing_file, help="I.npy (K, H, W) light")
    parser.add_argument("--constant", required=True,
                        help="MODULE.NAME under tespike.golden.fastsim, e.g. window.MERGE_DRAWS")
    parser.add_argument("--values", nargs="+", required=True, help="Python literals; the first is the reference")
    parser.add_argument("--config", default="te", help="preset or C.json (default te)")
    parser.add_argument("--repeats", type=int, default=3, help="passes over the scene (default 3)")
    args = parser.parse_args()
    module_name, _, name = args.constant.rpartition(".")
    module = importlib.import_module(f"tespike.golden.fastsim.{module_name}")
    if not hasattr(module, name):
        raise SystemExit(f"--constant {args.constant!r}: tespike.golden.fastsim.{module_name} has no {name}")
    values = [ast.literal_eval(v) for v in args.values]
    config = load_config(args.config) if args.config.endswith(".json") else SensorConfig.preset(args.config)
    scene = np.load(args.scene, mmap_mode="r")
    keep_freed_memory()
    cpu = np.zeros(len(values))
    original = getattr(module, name)
    try:
        for repeat in range(args.repeats):
            sims, rows = [], None
            for _ in values:
                rows, stripes = stripe_simulators(config, scene.shape[1:], seed=1 + repeat,
                                                  total_pixel_readouts=scene.size)
                sims.append(stripes[0])
            for k in range(scene.shape[0]):
                print(f"\rpass {repeat + 1}/{args.repeats}, readout {k + 1}/{scene.shape[0]}", end="",
                      file=sys.stderr, flush=True)
                light = np.asarray(scene[k])[rows[0]]
                order = range(len(values)) if k % 2 == 0 else reversed(range(len(values)))
                for i in order:
                    setattr(module, name, values[i])
                    start = time.process_time()
                    sims[i].readout(light)
                    cpu[i] += time.process_time() - start
    finally:
        setattr(module, name, original)
        print(file=sys.stderr)
    print(f"{Path(args.scene).name}, {config.mode.upper()}, stripe 0 of {len(rows)}, {args.repeats} passes "
          "(process CPU time, readouts interleaved):")
    for value, seconds in zip(values, cpu):
        print(f"  {name} = {value!r}: {seconds:.3f} s, {seconds / cpu[0]:.3f}x the first")


if __name__ == "__main__":
    main()
