"""Dynamic range of the paper's TE (b1 = b2 = 4) and ML (8-bit, count and msb readout) settings: formula and measured.

Prints two tables and draws a PNG of decoded vs true light over 1e-6..1e3
(out/bench/dynamic-range.png); ``--docs`` writes the tables into
docs/dynamic-range.md (between the marker comments) and the PNG into docs/figures/:

1. dynamic range: SPEC/paper formula and the measurement of golden.dynamic_range
   (constant light through the cycle-exact engine, noise-free and Poisson);
2. TE estimators: bias and spread of single-readout decoded light under
   constant Poisson light over the overflow range, each named estimator of
   golden.decode.ESTIMATORS against the default "ratio".

    python3 benchmarks/dynamic_range.py [--n-s 16] [--windows 20] [--no-write | --docs]
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))    # measure this checkout's golden/

from benchmarks.plotfile import DOCS_FIGURES
from tespike.golden.config import SensorConfig
from tespike.golden.decode import ESTIMATORS, decode_light
from tespike.golden.dynamic_range import constant_light_words, estimator_error, formula_db, light_grid, measure
from tespike.golden.io import atomic_output
from tespike.recon.pictures import save_figure

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "dynamic-range.md"
PNG = DOCS_FIGURES / "dynamic-range.png"
TOLERANCES = (0.05, 0.20)


def replace_section(text: str, name: str, table: str) -> str:
    pattern = re.compile(rf"(<!-- {name}:start -->\n).*?(<!-- {name}:end -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"{DOC}: markers <!-- {name}:start/end --> not found")
    return pattern.sub(lambda m: m.group(1) + table + m.group(2), text)


def fmt_light(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3g}"


def range_table(n_s: int, windows: int, seed: int):
    """Rows of the dynamic-range table, and the mean decoded light per setting for the plot."""
    light = light_grid()
    header = ("| setting | estimator | electrons | formula, paper (dB) | formula, configured alpha (dB) | "
              + " | ".join(f"measured {int(t * 100)} %: darkest .. brightest light (dB)" for t in TOLERANCES)
              + " |\n|" + " --- |" * (5 + len(TOLERANCES)) + "\n")
    rows, curves = [], {}
    for name in ("te", "ml", "ml-msb"):
        config = SensorConfig.preset(name)
        label = {"te": "TE b1 = b2 = 4", "ml": "ML 8-bit count", "ml-msb": "ML 8-bit msb (eq. 10)"}[name]
        for noise, seed_or_none in (("noise-free", None), ("Poisson", seed)):
            start = time.perf_counter()
            words = constant_light_words(config, light, n_s * (windows + 1), seed=seed_or_none)
            elapsed = time.perf_counter() - start
            for estimator in (ESTIMATORS if config.is_te else ["ratio"]):
                cells = []
                for tolerance in TOLERANCES:
                    r = measure(config, n_s, estimator=estimator, tolerance=tolerance, windows=windows,
                                light=light, words=words)
                    cells.append(f"{fmt_light(r.low)} .. {fmt_light(r.high)} ({r.db:.1f})")
                rows.append(f"| {label} | {estimator} | {noise} | {formula_db(config, n_s, paper_alpha=True):.1f} | "
                            f"{formula_db(config, n_s):.1f} | " + " | ".join(cells) + " |")
                curves[(name, noise, estimator)] = decode_light(words[n_s:], config, estimator)
            print(f"  simulated {label}, {noise}: {words.size * config.clocks_per_readout:.3g} "
                  f"pixel clocks in {elapsed:.1f} s", flush=True)
    return header + "\n".join(rows) + "\n", light, curves


def estimator_table(seed: int, readouts: int):
    config = SensorConfig()
    low = config.p_max * config.spike_light                           # 2^b1 spikes per readout
    light = np.logspace(np.log10(low), 0, 25)
    header = ("| estimator | mean abs bias | max abs bias | mean spread (std) | RMS error |\n"
              "| --- | --- | --- | --- | --- |\n")
    rows = []
    for estimator in ESTIMATORS:
        bias, spread = estimator_error(config, estimator, light, readouts=readouts, replicas=4, seed=seed)
        rms = np.sqrt(np.mean(bias ** 2 + spread ** 2))
        rows.append(f"| {estimator}{' (default)' if estimator == 'ratio' else ''} | {np.abs(bias).mean():.2%} | "
                    f"{np.abs(bias).max():.2%} | {spread.mean():.2%} | {rms:.2%} |")
    note = (f"\nTE b1 = b2 = 4, {light.size} constant lights log-spaced over {low:.4g} .. 1 (2^b1 .. "
            f"2^b1 alpha spikes per readout), Poisson electrons, {readouts} readouts x 4 pixels each, seed {seed}; "
            "errors relative to the true light, single readouts.\n")
    return header + "\n".join(rows) + "\n" + note


def plot(light, curves, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    for ax, noise in zip(axes, ("noise-free", "Poisson")):
        ax.loglog(light, light, "k:", lw=1, label="true")
        for (name, kind, estimator), decoded in curves.items():
            if kind != noise or estimator == "midpoint":
                continue
            mean = decoded.mean(axis=0)
            lo, hi = np.percentile(decoded, [10, 90], axis=0)
            tag = f"{name.upper()} {estimator}"
            line, = ax.loglog(light, np.maximum(mean, 1e-7), label=tag + " (mean)")
            ax.fill_between(light, np.maximum(lo, 1e-7), np.maximum(hi, 1e-7), color=line.get_color(), alpha=0.15)
        ax.set_title(f"{noise} electrons")
        ax.set_xlabel("true light (1 = 42000 electrons per readout)")
        ax.set_ylim(1e-7, 1e3)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_ylabel("decoded light")
    axes[0].legend(fontsize=8)
    fig.suptitle("Decoded vs true constant light: mean (line) and 10-90 % of single readouts (band)")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-s", type=int, default=16, help="N_s: readouts per window (longest spike interval)")
    parser.add_argument("--windows", type=int, default=20, help="scored windows of N_s readouts per light")
    parser.add_argument("--estimator-readouts", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-write", action="store_true", help="print only; write no file")
    parser.add_argument("--docs", action="store_true",
                        help="write the tables into docs/dynamic-range.md and its PNG (regenerate them on purpose); "
                             "default: the PNG goes to out/bench/dynamic-range.png (git-ignored)")
    args = parser.parse_args()
    print(f"Dynamic range, N_s = {args.n_s}, {args.windows} windows; a light passes when the mean decoded "
          f"light of >= 90 % of its windows is within the tolerance")
    table, light, curves = range_table(args.n_s, args.windows, args.seed)
    print(table)
    est = estimator_table(args.seed, args.estimator_readouts)
    print(est)
    if not args.no_write and not args.docs:
        png = ROOT / "out" / "bench" / "dynamic-range.png"
        png.parent.mkdir(parents=True, exist_ok=True)
        plot(light, curves, png)
        print(f"wrote {png} (docs unchanged: --docs rewrites them)")
    elif args.docs and not args.no_write:
        text = DOC.read_text()
        text = replace_section(text, "dr-table", table)
        text = replace_section(text, "estimator-table", est)
        text = replace_section(text, "dr-settings",
                               f"N_s = {args.n_s}, {args.windows} scored windows after one warm-up window, "
                               f"seed {args.seed}; command: `python3 benchmarks/dynamic_range.py`\n")
        with atomic_output(DOC) as tmp:
            Path(tmp).write_text(text)
        plot(light, curves, PNG)
        print(f"wrote {DOC.relative_to(ROOT)} and {PNG.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
