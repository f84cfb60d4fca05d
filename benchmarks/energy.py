"""Energy per pixel per readout against light: TE, ML count and ML msb, whole streaming chip.

For each camera (the groups of ``benchmarks/hw_cost.py``: the paper's setting, TE
b1 = b2 = 4 against 8-bit ML count and msb and the 9-bit msb camera of TE's dynamic
range, and the equal-dynamic-range groups at b1 = b2 = 2 and 6), the script

* synthesises the camera's streaming top (Yosys, hierarchy kept,
  :func:`tespike.cosim.synthesis.synthesize_hierarchy`) for the flip-flops and gates of one
  pixel site (input register, state, rule), one readout cell, the timing block and the
  top's control;
* counts the toggles of every register and output port of the streaming top
  (:func:`tespike.golden.activity.top_activity`, equal to an Icarus VCD of the generated
  Verilog in tests/test_golden_activity.py) on one lane chain per light level: a
  B x levels array with one lane per column, so each lane is B sites of one light, B
  the beats of a 400 x 250 sensor (the paper's spike camera) with the fewest lanes
  whose beats fit in a readout interval, at most 240 (the paper TE camera's B);
  constant light with Poisson electrons (SPEC section 6), counted over ``--readouts``
  intervals after one interval of warm-up;
* prices them with the named CV^2 model :data:`tespike.cosim.energy.SKY130_HD`
  (docs/energy.md): register data toggles, gates at their block's register activity,
  the clock of every flip-flop on every clock, output bits; the timing block, the reset
  sample and the beat counter shared by the sensor's 100,000 pixels; the output bus
  per lane shared by its B pixels.

It prints a table (pJ per pixel per readout) and writes a PNG with the IMX636 event
sensor's budget (166 mW over 4 x 10^9 pixel-readouts a second: 41 pJ) for reference.

Run from the repository root:
``python3 benchmarks/energy.py [--readouts 3] [--out out/bench/energy.png | --docs]``
(``--docs`` writes docs/figures/energy.png). About a minute on one core.

Last, the energy model's one assumption about logic (gates toggle at their block's
register activity) is checked at gate level on a 2 x 3 top for the paper's cameras
(:func:`tespike.cosim.gate_activity.logic_check`): measured / estimated gate toggles per block.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))                       # measure this checkout's code

from benchmarks.hw_cost import ml_camera  # noqa: E402
from benchmarks.plotfile import add_png_arguments, png_path  # noqa: E402
from tespike.cosim.energy import SKY130_HD, block_cells, block_energy  # noqa: E402
from tespike.cosim.gate_activity import logic_check  # noqa: E402
from tespike.cosim.synthesis import synthesize_hierarchy  # noqa: E402
from tespike.cosim.tops import Top  # noqa: E402
from tespike.golden.activity import top_activity  # noqa: E402
from tespike.golden.beats import beat_count  # noqa: E402
from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig  # noqa: E402
from tespike.recon.pictures import save_figure  # noqa: E402

#: The sensor the figures are for: the paper's spike camera, 400 x 250 pixels.
SENSOR = (250, 400)
#: Most beats per interval: the paper TE camera's (L = 240 clocks, 417 lanes).
MAX_BEATS = 240
#: Sony IMX636 (1280 x 720 event sensor), 166 mW; a 400 x 250 camera read out at 40 kHz
#: makes 4e9 pixel-readouts a second, so the same power is 41.5 pJ per pixel-readout.
IMX636_PJ = 166e-3 / (400 * 250 * 40e3) * 1e12


#: (group, {label: config}): the hw_cost.py groups, without the b = 8 one (L = 65280 clocks
#: per readout: too long to count edge by edge here).
GROUPS = [
    ("paper setting (b1 = b2 = 4, 8-bit ML)", {
        "TE b1=b2=4": SensorConfig(mode="te", b1=4, b2=4), "ML count 8 bit": ml_camera(4, 8),
        "ML msb 8 bit": ml_camera(4, 8, "msb"), "ML msb 9 bit (TE's range)": ml_camera(4, 9, "msb")}),
    ("low range (b1 = b2 = 2, 4-bit ML)", {
        "TE b1=b2=2": SensorConfig(mode="te", b1=2, b2=2), "ML count 4 bit": ml_camera(2, 4),
        "ML msb 5 bit": ml_camera(2, 5, "msb")}),
    ("higher range (b1 = b2 = 6, 12-bit ML)", {
        "TE b1=b2=6": SensorConfig(mode="te", b1=6, b2=6), "ML count 12 bit": ml_camera(6, 12),
        "ML msb 13 bit": ml_camera(6, 13, "msb")}),
]

#: Light levels of the table (1 = 42000 electrons per readout), and of the plot: every half
#: decade, or every decade for cameras whose readout interval is longer than LONG_INTERVAL
#: clocks (counted over one readout: memory and time grow with L x B x levels).
TABLE_LIGHT = (1e-3, 1e-2, 1e-1, 1.0, 10.0)
LIGHT = np.array([10.0 ** (k / 2) for k in range(-8, 5)])
LIGHT_DECADES = np.array([10.0 ** k for k in range(-4, 3)])
LONG_INTERVAL = 1000


def sensor_beats(config: SensorConfig) -> tuple[int, int]:
    """(lanes, beats) of the 400 x 250 sensor: the fewest lanes with B <= min(L, MAX_BEATS)."""
    pixels = SENSOR[0] * SENSOR[1]
    lanes = -(-pixels // min(config.clocks_per_readout, MAX_BEATS))
    return lanes, beat_count(pixels, lanes)


def cells_per_site(config: SensorConfig) -> dict:
    """Flip-flops and gates of one pixel site, one readout cell, the timing block and the top's
    own logic, from Yosys on a 2 x 3 streaming top with 2 lanes (hierarchy kept: each module
    is synthesised once, so per-site figures do not depend on the array size)."""
    top = Top(config, 2, 3, 2)
    result = synthesize_hierarchy(top.verilog(), top.module)
    cells = block_cells(result["modules"], result["top"], config, True)
    for block in ("pixel", "readout"):
        cells[block] = {key: value // 6 for key, value in cells[block].items()}
    return cells


def camera_energy(config: SensorConfig, light: np.ndarray, readouts: int, seed: int = 0) -> dict:
    """Energy parts (J per pixel per readout, float64, one entry per light level) of the
    400 x 250 streaming chip, from one lane chain of B sites per light level."""
    L = config.clocks_per_readout
    lanes, beats = sensor_beats(config)
    pixels = SENSOR[0] * SENSOR[1]
    cells = cells_per_site(config)
    n = light.size
    lam = DESIGN_ELECTRONS * light / L
    rng = np.random.default_rng(seed)
    clocks = (readouts + 1) * L
    electrons = np.minimum(rng.poisson(np.broadcast_to(lam, (clocks, beats, n))), config.input_max)
    activity = top_activity(config, electrons, n, edges=clocks, start=L)
    K = activity.readouts
    bits = activity.register_bits()

    def per_site(block):
        total = sum(counts for (b, _), counts in activity.toggles.items() if b == block)
        return total.reshape(beats, n).mean(axis=0) / K        # toggles per site per readout, per light

    parts, split = {}, {}
    for block in ("pixel", "readout"):
        energy = block_energy(per_site(block), bits[block] // (beats * n), cells[block]["flops"],
                              cells[block]["gates"], L)
        parts[block] = sum(energy.values())
        split.update({f"{block} {part}": value for part, value in energy.items()})
    shared = 0.0                                              # timing and control, per readout, whole chip
    control_bits = bits["control"]
    for block, flops in (("timing", cells["timing"]["flops"]), ("control", control_bits)):
        energy = block_energy(activity.per_block()[block], bits[block], flops, cells[block]["gates"], K * L)
        shared += float(sum(energy.values())) / K
    parts["timing + control"] = np.full(n, shared / pixels)
    lane_toggles = activity.toggles[("output", "out_words")] / K          # per lane = per light
    flags = (activity.toggles[("output", "out_valid")].sum() + activity.toggles[("output", "out_first")].sum()) / K
    parts["output bus"] = (lane_toggles / beats + flags * lanes / pixels) * SKY130_HD.gate_toggle
    parts["total"] = sum(parts.values())
    parts["lanes"], parts["beats"], parts["cells"], parts["split"] = lanes, beats, cells, split
    return parts


def plot(path: Path, lights: dict, results: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(6 * len(results), 4.8))
    for ax, (group, cameras) in zip(axes, results.items()):
        light = lights[group]
        for label, parts in cameras.items():
            line, = ax.plot(light, parts["total"] * 1e12, label=f"{label}: whole chip")
            ax.plot(light, parts["pixel"] * 1e12, linestyle=":", color=line.get_color(),
                    label=f"{label}: pixel sites only")
        ax.axhline(IMX636_PJ, color="black", linestyle="--", label=f"IMX636 budget ({IMX636_PJ:.1f} pJ)")
        ax.set_xscale("log")
        ax.set_ylim(0, None)
        ax.set_xlabel("light I (1 = 42000 electrons per readout)")
        ax.set_ylabel("pJ per pixel per readout")
        ax.set_title(group, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6.5)
    fig.suptitle(f"Energy per pixel-readout, 400 x 250 streaming chip, model {SKY130_HD.name} "
                 "(dynamic, digital only)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readouts", type=int, default=3, help="readout intervals counted (default 3)")
    add_png_arguments(parser, "energy.png", "--out")
    args = parser.parse_args(argv)
    if args.readouts < 1:
        print(f"energy.py: --readouts {args.readouts}: must be >= 1", file=sys.stderr)
        return 2
    png_path(args, "energy.png", "--out")
    start = time.perf_counter()
    results, lights = {}, {}
    for group, cameras in GROUPS:
        results[group] = {}
        for label, config in cameras.items():
            long = config.clocks_per_readout > LONG_INTERVAL
            light = LIGHT_DECADES if long else LIGHT
            results[group][label] = camera_energy(config, light, 1 if long else args.readouts)
            lights[group] = light
    seconds = time.perf_counter() - start
    print(f"energy per pixel per readout (pJ), 400 x 250 streaming chip, model {SKY130_HD.name}; "
          f"{args.readouts} readouts after one of warm-up, seed 0")
    print("| group | camera | lanes x beats | flops / gates per site | " +
          " | ".join(f"I = {i:g}" for i in TABLE_LIGHT) + " | pixel sites at I = 1 |")
    print("| --- | --- | --- | --- |" + " ---: |" * (len(TABLE_LIGHT) + 1))
    for group, cameras in results.items():
        light = lights[group]
        for label, parts in cameras.items():
            pick = [int(np.flatnonzero(np.isclose(light, i))[0]) for i in TABLE_LIGHT]
            site = parts["cells"]["pixel"]
            cells = (f"{site['flops'] + parts['cells']['readout']['flops']} / "
                     f"{site['gates'] + parts['cells']['readout']['gates']}")
            print(f"| {group} | {label} | {parts['lanes']} x {parts['beats']} | {cells} | "
                  + " | ".join(f"{parts['total'][k] * 1e12:.1f}" for k in pick)
                  + f" | {parts['pixel'][pick[3]] * 1e12:.1f} |")
    print("\nwhere it goes, paper setting (pJ per pixel per readout): pixel sites' clock / data toggles / "
          "gates; readout cells' clock / data + gates; timing + control; output bus")
    print("| camera | I | pixel clock | pixel data | pixel gates | readout clock | readout data + gates | "
          "timing + control | output bus | total |")
    print("| --- | ---: |" + " ---: |" * 8)
    for label, parts in results[GROUPS[0][0]].items():
        for level in (1e-3, 1.0):
            k = int(np.flatnonzero(np.isclose(LIGHT, level))[0])
            sp = {key: value[k] * 1e12 for key, value in parts["split"].items()}
            print(f"| {label} | {level:g} | {sp['pixel clock']:.1f} | {sp['pixel data']:.1f} | "
                  f"{sp['pixel logic']:.1f} | {sp['readout clock']:.1f} | "
                  f"{sp['readout data'] + sp['readout logic']:.1f} | {parts['timing + control'][k] * 1e12:.3f} | "
                  f"{parts['output bus'][k] * 1e12:.3f} | {parts['total'][k] * 1e12:.1f} |")
    print("\nthe logic assumption, checked at gate level (2 x 3 streaming top, 3 lanes, 3 readouts; "
          "gate output toggles measured on the synthesised netlist in Icarus / estimated from the registers)")
    print("| camera | I | pixel sites | readout cells | timing | control |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    check_start = time.perf_counter()
    for label, config in GROUPS[0][1].items():
        for level in (1e-2, 1.0):
            L = config.clocks_per_readout
            rng = np.random.default_rng(1)
            lam = DESIGN_ELECTRONS * level / L * np.linspace(0.5, 1.5, 6)
            e = np.minimum(rng.poisson(lam, (3 * L, 6)), config.input_max).reshape(3 * L, 2, 3)
            check = logic_check(config, e, 3)
            print(f"| {label} | {level:g} | " + " | ".join(
                f"{check[b]['measured']} / {check[b]['estimated']:.0f} = {check[b]['ratio']:.2f}"
                for b in ("pixel", "readout", "timing", "control")) + " |")
    print(f"({time.perf_counter() - check_start:.1f} s gate-level check)")
    paper = results[GROUPS[0][0]]
    te = paper["TE b1=b2=4"]["total"][int(np.flatnonzero(np.isclose(LIGHT, 1.0))[0])] * 1e12
    print(f"IMX636 budget: {IMX636_PJ:.1f} pJ per pixel-readout; paper TE at I = 1: {te:.1f} pJ "
          f"({te / IMX636_PJ:.1f} x)")
    plot(Path(args.out), lights, results)
    print(f"wrote {args.out} ({seconds:.1f} s counting and synthesis)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
