"""Outside simulators on the generated array Verilog: Verilator build time and cycles/s, Icarus cycles/s.

For each array size (paper TE configuration, square arrays) the benchmark
generates the Verilog (``tespike.rtl.verilog.array_verilog``), builds the Verilator
model in a fresh cache directory (wall and CPU seconds of the build, and the
peak resident memory of its largest process; the runtime objects of the user's
cache are reused, as in normal use) and runs ``--readouts`` readout intervals
of Poisson light through the harness alone (cycles per second of the
simulation, stimulus packing excluded), then checks the words against the
golden model. Icarus runs the small sizes. For comparison the same harness runs a
hand-written model of the same ports written as one procedural ``for`` loop
over register arrays (tests/verilog_spec_model.py, ``style="loop"``): it shows
what the generated array's one-instance-per-pixel structure costs in
Verilator. The baseline
measured in the same run is the literal golden model
(``tespike.golden.reference.step_reference``) on the same stimulus; the table prints
each simulator's speed as a ratio to it. Writes ``out/bench/bench_verilator.png`` (``--docs``: ``docs/figures/bench_verilator.png``).

Run from the repository root:
``python3 benchmarks/bench_verilator.py [--sizes 32 64] [--loop-sizes 32 64] [--icarus-sizes 4 8]
[--readouts 20] [--inline] [--variants O1 O0 O2 O1:-fno-dfg]``

``--variants`` builds and runs the generated array once per variant in the same
run: ``O<n>`` is the C++ optimisation (``cxx_opt``) of the backend's default
view (``tespike.cosim.verilator.shared_pixel_view``), ``plain-O<n>`` the Verilog
exactly as generated, anything after ``:`` more Verilator options (space
separated), e.g. ``O1:-fno-dfg``, ``O1:--threads 2`` or ``O1:-MAKEFLAGS OPT_SLOW=-O0``;
``default`` is the Verilog exactly as generated built with Verilator's default
options only (``--cc --exe --build``) and the same plain C++ harness. The loop
model runs on the same stimulus, built like the backend (and, with ``default``
among the variants, with default options too); the last lines print each build's
cycles/s as a ratio to the loop model's in the same run.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.usage import children_cpu  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.reference import step_reference  # noqa: E402
from benchmarks.plotfile import add_png_arguments, png_path  # noqa: E402


def _build_and_peak(build, args, kwargs) -> tuple[Path, float]:
    """Run ``build(*args, **kwargs)`` in this (forked) process; return its result and the
    peak resident memory in MB of the largest process it waited for."""
    exe = build(*args, **kwargs)
    return exe, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0


def measured_build(build, *args, **kwargs) -> tuple[Path, float]:
    """Build in a forked child so the kernel's peak-memory record covers this build alone
    (``ru_maxrss`` of waited-for processes only ever grows within one process): returns
    the executable and the peak resident MB of the build's largest process (Verilator or
    one C++ compiler; parallel jobs add up beyond it). The child's CPU time reaches this
    process's ``children_cpu()`` when it is waited for."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        return pool.submit(_build_and_peak, build, args, kwargs).result()


def stimulus(config: SensorConfig, side: int, readouts: int, rng) -> np.ndarray:
    light = rng.uniform(0.0, 1.5, size=(side, side))
    mean = 42000.0 * light / config.clocks_per_readout
    return rng.poisson(mean, size=(readouts * config.clocks_per_readout, side, side)).astype(np.int64)


def golden_rate(config, stim) -> tuple[float, np.ndarray]:
    start = time.perf_counter()
    words = step_reference(config, stim)[0]
    return stim.shape[0] / (time.perf_counter() - start), words


def parse_variant(text: str) -> tuple[bool, str, tuple[str, ...]]:
    opt, _, extra = text.partition(":")
    plain = opt.startswith("plain-")
    return not plain, "-" + opt.removeprefix("plain-"), tuple(extra.split())


def build_default_options(verilog: str, top: str, charge_bits: int, frame_bits: int, tmp) -> Path:
    """Build with Verilator's default options only (``--cc --exe --build``: its default inlining,
    no ``-O3``, make's default ``OPT_FAST``) and the same plain C++ harness: what a user who
    takes the Verilog into their own Verilator flow gets. Returns the executable."""
    import tespike.cosim.verilator as cv

    work = Path(tmp) / "default-options"
    work.mkdir()
    (work / "array.v").write_text(verilog)
    (work / "harness.cpp").write_text(cv.harness_cpp(top, charge_bits, frame_bits))
    subprocess.run(["verilator", "--cc", "--exe", "--build", "-j", str(cv.build_jobs()),
                    "--top-module", top, "--prefix", "Varray", "-o", "sim", "-Mdir", "obj",
                    "array.v", "harness.cpp"], cwd=work, check=True, capture_output=True)
    return work / "obj" / "sim"


def bench_verilator(config, side, stim, inline: bool, loop_model: bool = False,
                    variant: str = "O1"):
    import tespike.cosim.verilator as cv
    from tespike.cosim.outside import check_captures, unpack_rows, words_per_row
    from tespike.rtl.verilog import array_verilog
    from tests.verilog_spec_model import spec_model_verilog

    start = time.perf_counter()
    if loop_model:
        verilog = spec_model_verilog(config, side, side, style="loop")
    else:
        verilog = array_verilog(config, side, side)
    default = variant == "default"
    shared, cxx_opt, extra = parse_variant("plain-O1" if default else variant)
    if shared and not loop_model:
        verilog = cv.shared_pixel_view(verilog, "te_pixel")
    gen = time.perf_counter() - start
    N = side * side
    with tempfile.TemporaryDirectory(prefix="bench-verilator-") as tmp:
        # hand-written timing: builds and runs of child processes, wall and their CPU (not torch code)
        cpu0, start = children_cpu(), time.perf_counter()
        if default:
            exe, build_mb = measured_build(build_default_options, verilog, "te_pixel_array",
                                           N * config.input_bits, N * config.word_bits, tmp)
        else:
            exe, build_mb = measured_build(cv.build, verilog, "te_pixel_array",
                                           N * config.input_bits, N * config.word_bits,
                                           build_dir=tmp, progress=True, inline=inline,
                                           cxx_opt=cxx_opt, extra_flags=extra)
        build_wall, build_cpu = time.perf_counter() - start, children_cpu() - cpu0
        T, L = stim.shape[0], config.clocks_per_readout
        stim_path, cap_path = Path(tmp) / "stim.bin", Path(tmp) / "cap.bin"
        cv.write_stimulus_file(stim_path, stim, config.input_bits)
        cpu0, start = children_cpu(), time.perf_counter()
        subprocess.run([str(exe), str(stim_path), str(T), str(T // L), str(L + 1), str(cap_path), "0"],
                       check=True)
        run_wall, run_cpu = time.perf_counter() - start, children_cpu() - cpu0
        clocks, frames = cv.read_captures(cap_path, words_per_row(N, config.word_bits))
        check_captures(clocks, config, T // L, "bench")
        words = unpack_rows(frames, N, config.word_bits).reshape(-1, side, side)
    return dict(gen=gen, build_wall=build_wall, build_cpu=build_cpu, build_mb=build_mb,
                rate=T / run_wall, rate_cpu=T / max(run_cpu, 1e-9), words=words)


def bench_icarus(config, side, stim):
    from tespike.cosim.icarus import run_icarus
    from tespike.rtl.verilog import array_verilog

    verilog = array_verilog(config, side, side)
    start = time.perf_counter()
    words = run_icarus(config, stim, verilog=verilog)
    return dict(rate=stim.shape[0] / (time.perf_counter() - start), words=words)


def ratio_lines(rows) -> list[str]:
    """Cycles/s of each generated-array build over the loop model's at the same size
    (the "default" build against the loop model's "default" build, every other against "loop model")."""
    loops = {(name, side): r for name, side, r, _, _ in rows if name.startswith("loop model")}
    out = []
    for name, side, r, _, _ in rows:
        if name.startswith(("loop model", "icarus")):
            continue
        loop = loops.get(("loop model default" if name == "default" else "loop model", side))
        if loop is not None:
            out.append(f"{name:>24} {side * side:7d} pixels: {r['rate'] / loop['rate']:.2f} of the loop "
                       f"model's cycles/s ({r['rate_cpu'] / loop['rate_cpu']:.2f} per CPU-second), "
                       f"build {r['build_wall']:.1f} s wall / {r['build_cpu']:.1f} CPU-s / "
                       f"{r['build_mb']:.0f} MB peak")
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[32, 64], help="Verilator array sides")
    parser.add_argument("--icarus-sizes", type=int, nargs="*", default=[4, 8], help="Icarus array sides")
    parser.add_argument("--readouts", type=int, default=20, help="readout intervals of L = 240 clocks")
    parser.add_argument("--icarus-readouts", type=int, default=2)
    parser.add_argument("--inline", action="store_true",
                        help="Verilator's default module inlining instead of -fno-inline")
    parser.add_argument("--loop-sizes", type=int, nargs="*", default=[32, 64],
                        help="sides for the hand-written procedural-loop model of the same ports "
                             "(tests/verilog_spec_model.py): what the array's structure costs")
    parser.add_argument("--variants", nargs="*", default=["O1"],
                        help="builds of the generated array to compare: O<n>[:verilator options]")
    add_png_arguments(parser, "bench_verilator.png")
    args = parser.parse_args(argv)
    png_path(args, "bench_verilator.png")
    config = SensorConfig()
    load_start = os.getloadavg()[0]
    rng = np.random.default_rng(2024)
    rows = []
    stimuli = {}
    for side in sorted(set(args.sizes) | set(args.loop_sizes)):
        stimuli[side] = stimulus(config, side, args.readouts, rng)
    for side in args.sizes:
        stim = stimuli[side]
        base, golden_words = golden_rate(config, stim)
        for variant in args.variants:
            r = bench_verilator(config, side, stim, inline=args.inline, variant=variant)
            name = "verilator" if variant == "O1" else variant
            rows.append((name, side, r, base, np.array_equal(r["words"], golden_words)))
    loop_variants = sorted({"default" if v == "default" else "O1" for v in args.variants})
    for side in args.loop_sizes:
        stim = stimuli[side]
        base, golden_words = golden_rate(config, stim)
        for variant in loop_variants:
            r = bench_verilator(config, side, stim, inline=args.inline, loop_model=True, variant=variant)
            name = "loop model" if variant == "O1" else f"loop model {variant}"
            rows.append((name, side, r, base, np.array_equal(r["words"], golden_words)))
    for side in args.icarus_sizes:
        stim = stimulus(config, side, args.icarus_readouts, rng)
        base, golden_words = golden_rate(config, stim)
        r = bench_icarus(config, side, stim)
        rows.append(("icarus", side, r, base, np.array_equal(r["words"], golden_words)))

    load = os.getloadavg()[0]
    print(f"paper TE (L = 240), load average {load:.1f} on {os.cpu_count()} cores "
          f"({load_start:.1f} at the start); "
          f"Verilator {'default inlining' if args.inline else '-fno-inline'}")
    print(f"{'simulator':>24} {'pixels':>7} {'gen s':>6} {'build s':>8} {'build cpu':>9} "
          f"{'cycles/s':>9} {'cyc/cpu-s':>9} {'golden c/s':>10} {'x golden':>8} {'equal':>5}")
    for name, side, r, base, equal in rows:
        gen = f"{r['gen']:6.1f}" if "gen" in r else f"{'':>6}"
        build = f"{r['build_wall']:8.1f} {r['build_cpu']:9.1f}" if "build_wall" in r else f"{'':>8} {'':>9}"
        cpu_rate = f"{r['rate_cpu']:9.0f}" if "rate_cpu" in r else f"{'':>9}"
        print(f"{name:>24} {side * side:7d} {gen} {build} {r['rate']:9.0f} {cpu_rate} {base:10.0f} "
              f"{r['rate'] / base:8.1f} {str(equal):>5}")
    ratios = ratio_lines(rows)
    if ratios:
        print("\ngenerated array against the loop model of the same ports, same stimulus and options:")
        print("\n".join(ratios))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from tespike.recon.pictures import save_figure

        fig, ax = plt.subplots(figsize=(5.5, 3.5))
        names = list(dict.fromkeys(n for n, *_ in rows))
        for name in names:
            marker = "^" if name.startswith("loop model") else {"icarus": "s"}.get(name, "o")
            pts = [(side * side, r["rate"]) for n, side, r, _, _ in rows if n == name]
            if pts:
                ax.loglog(*zip(*pts), marker=marker, label=name)
        by_size = {}
        for _, side, _, base, _ in rows:          # one point per size: the median of its runs
            by_size.setdefault(side * side, []).append(base)
        pts = sorted((n, float(np.median(v))) for n, v in by_size.items())
        ax.loglog(*zip(*pts), "k--", marker="x", label="golden step_reference")
        ax.set_xlabel("pixels")
        ax.set_ylabel("pixel clocks per second")
        ax.set_title("generated Verilog in outside simulators (paper TE)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, args.png)
        print(f"wrote {args.png}")
    except ImportError:
        pass
    return 0 if all(equal for *_, equal in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
