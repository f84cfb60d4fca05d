"""Speed of the cycle-exact engine (golden.sensor) against the literal per-clock rule.

Prints pixel-clock updates per second for the paper's TE, ML (count readout)
and ML msb (eq. 10) settings on
Poisson stimuli around the design light, plus the stiff stimuli (maximum input
every clock, sparse huge values, zero). Both are run in this process on the
same stimulus; the engine's words are checked equal to the reference's.

    python3 benchmarks/bench_golden.py [--size 128] [--readouts 20]
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))    # measure this checkout's golden/

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig
from tespike.golden.io import atomic_output
from tespike.golden.reference import step_reference
from tespike.golden.sensor import simulate


def poisson_stimulus(config, rng, size, readouts, low, high):
    """Electrons per clock for light log-uniform in [low, high] x design light, constant per pixel."""
    light = 10 ** rng.uniform(np.log10(low), np.log10(high), size=(1, size, size))
    mean = DESIGN_ELECTRONS * light / config.clocks_per_readout
    stim = rng.poisson(mean, size=(config.clocks_per_readout * readouts, size, size))
    return np.minimum(stim, config.input_max).astype(np.uint16 if config.input_bits <= 16 else np.uint32)


def stimuli(config, rng, size, readouts):
    T = config.clocks_per_readout * readouts
    shape = (T, size, size)
    dtype = np.uint16 if config.input_bits <= 16 else np.uint32
    yield "Poisson, light 1 (design)", poisson_stimulus(config, rng, size, readouts, 1, 1)
    yield "Poisson, light 0.5..2", poisson_stimulus(config, rng, size, readouts, 0.5, 2)
    yield "Poisson, light 1e-3..1e3", poisson_stimulus(config, rng, size, readouts, 1e-3, 1e3)
    yield "max input every clock", np.full(shape, config.input_max, dtype)
    yield "sparse huge values (1 %)", np.where(rng.random(shape) < 0.01, config.input_max, 0).astype(dtype)
    yield "zero", np.zeros(shape, dtype)


def rate(fn, stimulus, repeat=1):
    """Pixel-clock updates per second of CPU time of this process (best of ``repeat``).

    CPU time rather than wall time: on a shared machine the wall clock also
    counts the time other processes hold the core.
    """
    best = float("inf")
    for _ in range(repeat):
        # hand-written timing: numpy code (no torch) and CPU seconds, which torch.utils.benchmark does not report
        start = time.process_time()
        out = fn(stimulus)
        best = min(best, time.process_time() - start)
    return stimulus.size / max(best, 1e-9), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128, help="array is size x size pixels")
    parser.add_argument("--readouts", type=int, default=20, help="readout intervals per run")
    parser.add_argument("--reference-readouts", type=int, default=2, help="readouts timed for the reference")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--write-doc", action="store_true",
                        help="also put the table into docs/golden-model.md (between the bench markers)")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    load = os.getloadavg()
    print(f"golden from {Path(sys.modules['golden'].__file__).parent}; load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    print(f"{args.size}x{args.size} pixels, {args.readouts} readouts per run (reference: "
          f"{args.reference_readouts}); pixel-clock updates per CPU second, best of 3 for both")
    lines = [f"{args.size} x {args.size} pixels, {args.readouts} readouts; pixel-clock updates per CPU second; "
             f"load average {load[0]:.1f} on {os.cpu_count()} cores",
             "", "| config | stimulus | engine | reference | ratio | words equal |", "| --- | --- | --- | --- | --- | --- |"]
    print(f"{'config':<7} {'stimulus':<28} {'engine':>10} {'reference':>10} {'ratio':>7}  words equal")
    for name in ("te", "ml", "ml-msb"):
        config = SensorConfig.preset(name)
        L = config.clocks_per_readout
        for label, stim in stimuli(config, rng, args.size, args.readouts):
            fast, words = rate(lambda s: simulate(config, s), stim, repeat=3)
            short = stim[:L * args.reference_readouts]
            slow, ref = rate(lambda s: step_reference(config, s)[0], short, repeat=3)
            equal = np.array_equal(words[:args.reference_readouts], ref)
            print(f"{name:<7} {label:<28} {fast:10.3g} {slow:10.3g} {fast / slow:7.1f}  {equal}")
            lines.append(f"| {name} | {label} | {fast:.3g} | {slow:.3g} | {fast / slow:.1f} | {equal} |")
    if args.write_doc:
        doc = Path(__file__).resolve().parent.parent / "docs" / "golden-model.md"
        text = doc.read_text()
        pattern = re.compile(r"(<!-- bench:start -->\n).*?(<!-- bench:end -->)", re.S)
        text = pattern.sub(lambda m: m.group(1) + "\n".join(lines) + "\n" + m.group(2), text)
        with atomic_output(doc) as tmp:
            Path(tmp).write_text(text)
        print(f"wrote {doc}")


if __name__ == "__main__":
    main()
