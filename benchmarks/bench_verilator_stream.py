"""The streaming top (``tespike verilog --lanes N``) in Verilator against pixel count, up to the paper's sensor.

For each array (paper TE configuration, L = 240; default 32 x 32, 64 x 64,
128 x 128 and the paper's 400 x 250) the benchmark generates the streaming
Verilog (``tespike.rtl.verilog_stream.stream_array_verilog``, N = ceil(H W / L) lanes,
the fewest that fit; ``--view loop``, the default, is the simulation view made for
Verilator at sensor size, ``--view instances`` the design with one instance per site), builds the Verilator model in a fresh cache directory
(``tespike.cosim.verilator.build_stream``: wall and CPU seconds of Verilator and
g++, and the peak resident memory of the build's largest process; Verilator's
runtime objects of the user's cache are reused, as in normal use), runs
``--readouts`` readout intervals of Poisson light through the harness alone
(stimulus packing excluded) and checks every beat against the golden model
(``tespike.golden.beats.beats`` of ``tespike.golden.sensor.simulate``).

Printed per size: build wall / CPU seconds and peak MB, cycles per second
(wall) and per CPU-second of the harness process, pixel clocks per CPU-second
(cycles x pixels) and that figure as a ratio to the first (smallest) size's in
the same run: the issue's target is a ratio of at least 0.5 at 400 x 250 and a
build under 10 minutes and 8 GB on 2 cores.

Run from the repository root (the big sizes take a minute or two, mostly
stimulus and golden model):
``python3 benchmarks/bench_verilator_stream.py [--sizes 32x32 64x64 128x128 400x250] [--readouts 4]``
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.usage import children_cpu  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402


def _build_and_peak(config, verilog, height, width, lanes, build_dir):
    from tespike.cosim.verilator import build_stream
    exe = build_stream(config, verilog, height, width, lanes, build_dir=build_dir)
    return exe, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0


def measured_build(*args):
    """Build in a forked child so the peak-memory record (``ru_maxrss``) covers this build alone."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        return pool.submit(_build_and_peak, *args).result()


def parse_size(text: str) -> tuple[int, int]:
    rows, _, cols = text.partition("x")
    return int(rows), int(cols)


def stimulus(config: SensorConfig, height: int, width: int, readouts: int, rng) -> np.ndarray:
    """Poisson electrons of a scene from dark to 1.5x design light, one level per pixel (uint16)."""
    L = config.clocks_per_readout
    light = rng.uniform(0.0, 1.5, size=(height, width))
    mean = 42000.0 * light / L
    return rng.poisson(mean, size=(readouts * L, height, width)).astype(np.uint16)


def bench(config, height, width, readouts, rng, view="loop") -> dict:
    import tespike.cosim.verilator as vs
    from tespike.cosim.outside import words_per_row
    from tespike.cosim.stream_ports import check_beats, flush_clocks
    from tespike.golden.sensor import simulate
    from tespike.golden.beats import beat_count, beats, min_lanes
    from tespike.rtl.verilog_stream import stream_array_verilog

    lanes = min_lanes(config, height, width)
    start = time.perf_counter()
    verilog = stream_array_verilog(config, height, width, lanes, view=view)
    gen = time.perf_counter() - start
    stim = stimulus(config, height, width, readouts, rng)
    T, L = stim.shape[0], config.clocks_per_readout
    K, B = T // L, beat_count(height * width, lanes)
    with tempfile.TemporaryDirectory(prefix="bench-stream-") as tmp:
        cpu0, start = children_cpu(), time.perf_counter()
        exe, build_mb = measured_build(config, verilog, height, width, lanes, tmp)
        build_wall, build_cpu = time.perf_counter() - start, children_cpu() - cpu0
        stim_path, cap_path = Path(tmp) / "stim.bin", Path(tmp) / "cap.bin"
        vs.write_stimulus_file(stim_path, stim, config.input_bits)
        cpu0, start = children_cpu(), time.perf_counter()
        vs.run_executable(exe, stim_path, cap_path, T, K * B, flush_clocks(config))
        run_wall, run_cpu = time.perf_counter() - start, children_cpu() - cpu0
        clocks, firsts, rows = vs.read_beat_captures(cap_path, words_per_row(lanes, config.word_bits))
    got, latency = check_beats(clocks, firsts, rows, config, height, width, lanes, K, "bench")
    equal = bool(np.array_equal(got, beats(simulate(config, stim), lanes)))
    return dict(pixels=height * width, lanes=lanes, beats=B, latency=latency, gen=gen,
                build_wall=build_wall, build_cpu=build_cpu, build_mb=build_mb, clocks=T,
                rate=T / run_wall, rate_cpu=T / max(run_cpu, 1e-9), equal=equal)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["32x32", "64x64", "128x128", "400x250"],
                        help="arrays as HxW (the first is the per-pixel baseline)")
    parser.add_argument("--readouts", type=int, default=4,
                        help="readout intervals of L = 240 clocks of the largest array; smaller arrays run "
                             "as many more as give the same pixel clocks (so start-up weighs alike)")
    parser.add_argument("--view", choices=("loop", "instances"), default="loop",
                        help="the simulation view (default; one clocked loop over memories) or the design "
                             "itself (one pixel and readout cell instance per site: Verilator 5.006 copies "
                             "every instance, so keep it to small sizes)")
    args = parser.parse_args(argv)
    config = SensorConfig()
    rng = np.random.default_rng(2024)
    load_start = os.getloadavg()[0]
    rows = []
    largest = max(h * w for h, w in map(parse_size, args.sizes))
    for size in args.sizes:
        height, width = parse_size(size)
        readouts = max(args.readouts, round(args.readouts * largest / (height * width)))
        rows.append((size, bench(config, height, width, readouts, rng, args.view)))
        print(f"  done {size}", file=sys.stderr, flush=True)
    load = os.getloadavg()[0]
    print(f"streaming top ({args.view} view), paper TE (L = 240), {args.readouts} readouts of the largest array and the same "
          f"pixel clocks for the others, N = ceil(H W / L) lanes; "
          f"load average {load_start:.1f} at the start, {load:.1f} at the end, {os.cpu_count()} cores")
    print(f"{'array':>8} {'pixels':>7} {'lanes':>5} {'clocks':>7} {'gen s':>6} {'build s':>8} {'build cpu':>9} "
          f"{'build MB':>8} {'cycles/s':>9} {'cyc/cpu-s':>9} {'Mpix-clk/cpu-s':>14} {'x first':>7} "
          f"{'latency':>7} {'equal':>5}")
    base = None
    for size, r in rows:
        per_pixel = r["rate_cpu"] * r["pixels"]
        base = base or per_pixel
        print(f"{size:>8} {r['pixels']:7d} {r['lanes']:5d} {r['clocks']:7d} {r['gen']:6.1f} {r['build_wall']:8.1f} "
              f"{r['build_cpu']:9.1f} {r['build_mb']:8.0f} {r['rate']:9.0f} {r['rate_cpu']:9.0f} "
              f"{per_pixel / 1e6:14.1f} {per_pixel / base:7.2f} {r['latency']:7d} {str(r['equal']):>5}")
    return 0 if all(r["equal"] for _, r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
