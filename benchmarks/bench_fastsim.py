"""Fast simulator vs the naive loop: error and throughput per light level, and whole-process speed.

Usage (from the worktree root):

    python3 benchmarks/bench_fastsim.py [--pixels 2000] [--readouts 4] [--out PNG | --docs]
                                        [--skip-whole] [--skip-levels] [--whole-shape 64 384 512]
                                        [--scene I.npy ...] [--crops 6] [--repeats 3]
                                        [--workers N [N ...]] [--skip-synthetic] [--skip-redrawn] [--baseline DIR]
                                        [--interior PANORAMA.hdr ...] [--dim-median 0.015]
                                        [--dim-range 3e-4 0.36]

Part 1, per light level from 1e-4 to 10 x design light, paper TE, ML (count
readout) and ML msb (eq. 10) configurations: ``simulate_scene`` (fast) against the naive loop (Poisson
electrons drawn per pixel clock by ``tespike.golden.stimulus.poisson_stimulus``, stepped
by the cycle-exact ``tespike.golden.sensor.simulate``) on the same light: bias of the
mean decoded value (spikes per readout, with its standard error), total
variation distance (TVD) of the code histograms, and both throughputs
(pixel-readouts per second). A second, independent naive run gives the TVD
that sampling noise alone produces (the floor the fast simulator should sit
on). Part 2: ``tespike simulate`` as a whole process on two K x H x W HDR
scenes (light log-uniform over 1e-4..10 per pixel, drifting slowly in time,
and drawn anew every readout; ``--skip-synthetic`` leaves them out) and on
any ``--scene`` files, against the naive loop timed on several random crops of
the same scene (each crop's fastest of ``--repeats`` runs) and scaled per pixel-readout, for each of the three cameras,
with the msb camera's time over the ML-count camera's in the same run (wall
and child-process CPU time; the issue's target is within 10 %), and with
``--workers 1 2`` each camera at each worker count (interleaved) and the
wall-time ratio of the first count over the others. ``--baseline DIR`` times
another checkout's ``tespike simulate`` (e.g. ``git archive <commit> | tar -x -C
DIR``) interleaved with this one's, against the same naive rate: before/after
ratios from one run, under one load. ``--interior`` adds a dim interior pan of
each panorama given (e.g. the Poly Haven interiors of the shared data folder):
the panorama panned (``tespike.recon.scenes.panorama``), its light mapped monotonically
(a power law in log light on each side of the median) to median ``--dim-median``
and 1st..99th percentiles ``--dim-range`` of the design light, the dim,
wide-range scenes of issue 28.
Prints tables, writes a PNG. Figures depend on the machine and its load; the
ratios are measured in the same run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.arguments import existing_file  # noqa: E402
from benchmarks.usage import children_cpu  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.decode import decode_spikes  # noqa: E402
from tespike.golden.fastsim import SceneSimulator  # noqa: E402
from tespike.golden.resources import keep_freed_memory  # noqa: E402
from tespike.golden.stimulus import poisson_stimulus  # noqa: E402
from tespike.golden.sensor import simulate  # noqa: E402
from benchmarks.plotfile import add_png_arguments, png_path  # noqa: E402
from tespike.recon.pictures import save_figure  # noqa: E402

LEVELS = np.logspace(-4, 1, 16)

#: The cameras timed: configuration preset -> label.
CAMERAS = {"te": "TE", "ml": "ML", "ml-msb": "ML-MSB"}


def _histogram(words, config):
    return np.bincount(words.ravel().astype(np.int64), minlength=1 << config.word_bits) / words.size


def _naive(config, scene, seed):
    return simulate(config, poisson_stimulus(config, scene, seed))


def error_table(config, pixels, readouts, seed=0, fast_factor=20):
    """The fast simulator runs on ``fast_factor`` times more pixels than the naive
    loop: its throughput is then not dominated by per-call overhead, and its
    sampling error is negligible next to the naive run's."""
    rows = []
    for i, level in enumerate(LEVELS):
        scene = np.full((readouts, 1, pixels), level)
        big = np.full((readouts, 1, pixels * fast_factor), level)
        # hand-written timing: numpy simulators (no torch), timed once per light level (seconds each)
        t0 = time.perf_counter()
        sim = SceneSimulator(config, (1, big.shape[2]), rng=seed + i, total_pixel_readouts=big.size)
        fast = np.stack([sim.readout(big[k]) for k in range(readouts)])
        t1 = time.perf_counter()
        naive = _naive(config, scene, seed + 1000 + i)
        t2 = time.perf_counter()
        naive2 = _naive(config, scene, seed + 2000 + i)
        a = decode_spikes(fast, config).mean(axis=0)[0]
        b = decode_spikes(naive, config).mean(axis=0)[0]
        se = float(np.sqrt(a.var() / a.size + b.var() / b.size))
        tvd = 0.5 * np.abs(_histogram(fast, config) - _histogram(naive, config)).sum()
        floor = 0.5 * np.abs(_histogram(naive2, config) - _histogram(naive, config)).sum()
        main = max(sim.path_counts, key=sim.path_counts.get)
        rows.append(dict(level=level, mean=float(b.mean()), bias=float(a.mean() - b.mean()), se=se,
                         tvd=tvd, floor=floor, fast_rate=big.size / (t1 - t0),
                         naive_rate=scene.size / (t2 - t1), path=main))
    return rows


def print_table(config, rows, label):
    print(f"\n{label} {config}: fast vs naive (cycle-exact model on per-clock Poisson electrons)")
    print(f"{'light':>9} {'mean':>9} {'bias':>9} {'(se)':>8} {'TVD':>7} {'floor':>7} "
          f"{'fast px-ro/s':>13} {'naive px-ro/s':>14} {'ratio':>7}  main path")
    for r in rows:
        print(f"{r['level']:9.2e} {r['mean']:9.3f} {r['bias']:+9.4f} {r['se']:8.4f} {r['tvd']:7.4f} "
              f"{r['floor']:7.4f} {r['fast_rate']:13.3g} {r['naive_rate']:14.3g} "
              f"{r['fast_rate'] / r['naive_rate']:7.1f}  {r['path']}")


def hdr_scene(shape, seed=0):
    """Light log-uniform over 1e-4..10 per pixel, drifting by +-10 % over the readouts."""
    K, H, W = shape
    rng = np.random.default_rng(seed)
    base = 10.0 ** rng.uniform(-4, 1, (H, W))
    drift = np.exp(0.1 * np.sin(np.arange(K) / 5.0))
    return (base[None] * drift[:, None, None]).astype(np.float32)


def redrawn_scene(shape, seed=0):
    """Light log-uniform over 1e-4..10 drawn anew for every pixel and readout: bright
    and dark alternate, so charge carried from the last readout (backlogs, full
    or empty accumulators) meets other light everywhere."""
    return (10.0 ** np.random.default_rng(seed).uniform(-4, 1, shape)).astype(np.float32)


def dim_interior_scene(panorama, shape, median=0.015, low=3e-4, high=0.36, seed=0):
    """A pan over the panorama file ``panorama`` (K, H, W), its light mapped to median
    ``median`` and 1st / 99th percentiles ``low`` / ``high`` of the design light: log
    light scaled about the log median, by one factor below it and another above (a
    monotone map: the scene's texture and ordering are kept, its spread is set)."""
    from tespike.recon.scenes.panorama import panorama_sequence
    light = panorama_sequence(np.random.default_rng(seed), *shape, source=panorama)
    mid = np.median(light)
    p1, p99 = np.percentile(light, [1, 99])
    if not 0 < p1 < mid < p99:
        raise SystemExit(f"{panorama}: its pan has no spread to map (percentiles {p1}, {mid}, {p99})")
    x = np.log(np.maximum(light, p1 * 1e-6) / mid)
    x *= np.where(x < 0, np.log(low / median) / np.log(p1 / mid), np.log(high / median) / np.log(p99 / mid))
    return (median * np.exp(x)).astype(np.float32)


def naive_rate(config, scene, crops=6, crop=(2, 32, 48), seed=0, repeats=3):
    """Naive-loop throughput (pixel-readouts/s) over ``crops`` random crops of
    ``scene`` (readouts x rows x cols each): a corner alone can be all dark or
    all bright and would misstate the cost of a scene that mixes both. Each crop
    is timed ``repeats`` times and its fastest run counts, as the fast process's
    does: on a shared machine a slower run measures the other processes, and
    a loaded naive loop alone would flatter the ratio. ``main`` gives this process the
    allocator settings the simulator's process runs with (``keep_freed_memory``) first."""
    rng = np.random.default_rng(seed)
    K, H, W = scene.shape
    k, h, w = min(crop[0], K), min(crop[1], H), min(crop[2], W)
    elapsed = size = 0
    for i in range(crops):
        k0, y0, x0 = rng.integers(0, K - k + 1), rng.integers(0, H - h + 1), rng.integers(0, W - w + 1)
        part = np.array(scene[k0:k0 + k, y0:y0 + h, x0:x0 + w], np.float64)
        best = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            _naive(config, part, seed + i)
            best = min(best, time.perf_counter() - t0)
        elapsed += best
        size += part.size
    return size / elapsed


def whole_process(name, path, crops=6, repeats=3, workers=(None,), baseline=None):
    """``tespike simulate`` as a whole process (start, read, simulate, write) on
    the scene file ``path`` against the naive loop on random crops of it.

    Each camera's process runs ``repeats`` times at each of ``workers``
    (``--workers``; ``None``: the command's default), cameras and worker counts
    interleaved, and the fastest run counts (wall and CPU time separately): on a
    shared machine the slower runs measure the other processes. ``baseline``:
    another checkout's command, run after each of this one's."""
    scene = np.load(path, mmap_mode="r")
    K, H, W = scene.shape
    trees = {"": ROOT} if baseline is None else {"": ROOT, "baseline": Path(baseline).resolve()}
    times = {(tree, preset, t): [] for tree in trees for preset in CAMERAS for t in workers}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            for preset in CAMERAS:
                for t in workers:
                    for tree, root in trees.items():
                        cpu0 = children_cpu()
                        t0 = time.perf_counter()
                        run = subprocess.run([sys.executable, "-m", "tespike", "simulate", "--config", preset,
                                              "--scene", str(Path(path).resolve()), "--out",
                                              str(Path(tmp) / "S.npz"), "--seed", "1",
                                              *(() if t is None else ("--workers", str(t)))],
                                             env=dict(os.environ, PYTHONPATH=str(root)), cwd=root,
                                             capture_output=True, text=True)
                        wall = time.perf_counter() - t0
                        if run.returncode:
                            raise SystemExit(run.stderr)
                        times[tree, preset, t].append((wall, children_cpu() - cpu0))
    naive = {preset: naive_rate(SensorConfig.preset(preset), scene, crops, repeats=repeats) for preset in CAMERAS}
    if baseline is None:
        return _report(name, scene, {key[1:]: value for key, value in times.items()}, naive, repeats, workers)
    for preset in CAMERAS:
        for t in workers:
            new, old = (min(wall for wall, _ in times[tree, preset, t]) for tree in trees)
            cpu_new, cpu_old = (min(cpu for _, cpu in times[tree, preset, t]) for tree in trees)
            tag = "" if t is None else f" --workers {t}"
            print(f"{name} {CAMERAS[preset]}{tag}: baseline {old:.2f} s (CPU {cpu_old:.2f} s), this tree "
                  f"{new:.2f} s (CPU {cpu_new:.2f} s): wall {old / new:.2f}x, CPU {cpu_old / cpu_new:.2f}x "
                  f"(best of {repeats}, interleaved)", flush=True)
    print(f"{name}: the baseline ({baseline}) against the naive loop:", flush=True)
    _report(name, scene, {key[1:]: value for key, value in times.items() if key[0] == "baseline"},
            naive, repeats, workers)
    print(f"{name}: this tree against the same naive rates:", flush=True)
    return _report(name, scene, {key[1:]: value for key, value in times.items() if key[0] == ""},
                   naive, repeats, workers)


def _report(name, scene, times, naive_rates, repeats, workers):
    """Print each camera's whole-process ratio against the naive loop's rate ``naive_rates[preset]``."""
    K, H, W = scene.shape
    results = {}
    for preset in CAMERAS:
        naive = naive_rates[preset]
        for t in workers:
            fast = min(wall for wall, _ in times[preset, t])
            cpu = min(cpu for _, cpu in times[preset, t])
            results[preset, t] = dict(fast=fast, cpu=cpu, rate=scene.size / fast, naive_rate=naive,
                                    ratio=scene.size / fast / naive)
            tag = "" if t is None else f" --workers {t}"
            print(f"{name} {CAMERAS[preset]}{tag}: tespike simulate on {K} x {H} x {W} (readouts x rows x cols): "
                  f"{fast:.1f} s = {scene.size / fast:.3g} pixel-readouts/s (best of {repeats}; CPU {cpu:.1f} s); "
                  f"naive loop {naive:.3g} pixel-readouts/s (random 2 x 32 x 48 crops, best of {repeats}) -> "
                  f"{scene.size / naive:.0f} s scaled; speed ratio {scene.size / fast / naive:.1f}x", flush=True)
        first = results[preset, workers[0]]
        for t in workers[1:]:
            other = results[preset, t]
            print(f"{name} {CAMERAS[preset]}: --workers {workers[0]} / --workers {t} in this run: wall "
                  f"{first['fast'] / other['fast']:.2f}x, CPU {first['cpu'] / other['cpu']:.2f}x", flush=True)
    for t in workers:
        msb, count = results["ml-msb", t], results["ml", t]
        tag = "" if t is None else f" (--workers {t})"
        print(f"{name}: ML-MSB / ML-count whole-process time in this run{tag}: wall "
              f"{msb['fast'] / count['fast']:.3f}, CPU {msb['cpu'] / count['cpu']:.3f} (target: within 1.10)",
              flush=True)
    return results


def plot(tables, out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for preset, rows in tables.items():
        levels = [r["level"] for r in rows]
        tag = CAMERAS[preset]
        axes[0].errorbar(levels, [r["bias"] for r in rows], yerr=[2 * r["se"] for r in rows],
                         marker="o", capsize=3, label=f"{tag} fast - naive (2 se)")
        axes[1].plot(levels, [r["tvd"] for r in rows], "o-", label=f"{tag} fast vs naive")
        axes[1].plot(levels, [r["floor"] for r in rows], "x--", label=f"{tag} naive vs naive")
        axes[2].plot(levels, [r["fast_rate"] for r in rows], "o-", label=f"{tag} fast")
        axes[2].plot(levels, [r["naive_rate"] for r in rows], "x--", label=f"{tag} naive")
    axes[0].axhline(0, color="k", lw=0.5)
    axes[0].set(xscale="log", xlabel="light (1 = design)", ylabel="bias of mean decoded spikes",
                title="bias of the mean")
    axes[1].set(xscale="log", xlabel="light (1 = design)", ylabel="TVD of code histograms",
                title="code histogram distance")
    axes[2].set(xscale="log", yscale="log", xlabel="light (1 = design)", ylabel="pixel-readouts / s",
                title="throughput")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, out, dpi=110)
    print(f"wrote {out}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pixels", type=int, default=2000)
    parser.add_argument("--readouts", type=int, default=4)
    add_png_arguments(parser, "fastsim.png", "--out")
    parser.add_argument("--skip-whole", action="store_true")
    parser.add_argument("--skip-levels", action="store_true", help="only the whole-process part")
    parser.add_argument("--whole-shape", type=int, nargs=3, default=(64, 384, 512))
    parser.add_argument("--scene", action="append", default=[], type=existing_file,
                        help="I.npy to time the whole process on as well (repeatable), e.g. from "
                             "'TESPIKE_HDRI_DIR=../shared/data/hdri python3 -m tespike scene --name city --frames 64 "
                             "--height 384 --width 512' (the full-size panorama: the shipped copy is 128 x 256)")
    parser.add_argument("--crops", type=int, default=6, help="random crops the naive loop is timed on")
    parser.add_argument("--repeats", type=int, default=3,
                        help="whole-process runs per camera (interleaved) and naive-loop runs per crop; "
                             "the fastest counts")
    parser.add_argument("--skip-synthetic", action="store_true",
                        help="whole process: only the --scene files, not the two log-uniform scenes")
    parser.add_argument("--skip-redrawn", action="store_true",
                        help="whole process: of the two log-uniform scenes, only the drifting one")
    parser.add_argument("--workers", type=int, nargs="+", default=[None],
                        help="whole process: tespike simulate --workers values to time, interleaved "
                             "(e.g. 1 2; default: the command's default)")
    parser.add_argument("--interior", action="append", default=[], metavar="PANORAMA", type=existing_file,
                        help="whole process: a dim pan over this .hdr/.exr panorama as well (repeatable; "
                             "e.g. /work/shared/data/hdri-polyhaven/vestibule_1k.hdr)")
    parser.add_argument("--dim-median", type=float, default=0.015,
                        help="median light of the --interior pans, in design light")
    parser.add_argument("--dim-range", type=float, nargs=2, default=(3e-4, 0.36), metavar=("P1", "P99"),
                        help="1st and 99th percentile light of the --interior pans")
    parser.add_argument("--baseline", metavar="DIR",
                        help="whole process: another checkout whose tespike simulate is timed interleaved "
                             "with this one's (before/after in one run)")
    args = parser.parse_args(argv)
    png_path(args, "fastsim.png", "--out")
    # The naive loop runs with the allocator settings `tespike simulate` gives its own process:
    # without them each call's per-clock arrays (6 MB a crop) were fresh mappings faulted in again,
    # and its rate hung on what this process had allocated before (the courtyard pan's naive loop:
    # 1.8e5 pixel-readouts/s measured first in a process, 3.2e5 after other scenes or with them).
    keep_freed_memory()
    if not args.skip_levels:
        tables = {}
        for preset in CAMERAS:
            config = SensorConfig.preset(preset)
            tables[preset] = error_table(config, args.pixels, args.readouts)
            print_table(config, tables[preset], CAMERAS[preset])
        plot(tables, args.out)
    if not args.skip_whole:
        print(f"\nwhole process (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
        with tempfile.TemporaryDirectory() as tmp:
            for name, make in (("log-uniform 1e-4..10", hdr_scene),
                               ("log-uniform 1e-4..10 redrawn every readout", redrawn_scene)):
                if args.skip_synthetic or (args.skip_redrawn and make is redrawn_scene):
                    break
                path = Path(tmp) / "I.npy"
                np.save(path, make(tuple(args.whole_shape)))
                whole_process(name, path, args.crops, args.repeats, tuple(args.workers), args.baseline)
            for panorama in args.interior:
                path = Path(tmp) / "I.npy"
                np.save(path, dim_interior_scene(panorama, tuple(args.whole_shape), args.dim_median,
                                                 *args.dim_range))
                name = f"dim {Path(panorama).stem} (median {args.dim_median:g})"
                whole_process(name, path, args.crops, args.repeats, tuple(args.workers), args.baseline)
        for scene in args.scene:
            whole_process(Path(scene).name, scene, args.crops, args.repeats, tuple(args.workers),
                          args.baseline)


if __name__ == "__main__":
    main()
