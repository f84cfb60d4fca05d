"""The text of the demo's ``report.md`` and of its RTL verdict: words only, no work.

:func:`tespike.cosim.demo.run_demo` measures; this module turns its measurements into
Markdown (configuration, RTL against golden, quality tables, dynamic range,
hardware cost, stage times and the commands that redo each stage).
"""

from __future__ import annotations

import math

from tespike.golden.config import DESIGN_ELECTRONS

from .synthesis import ABC_GATE_SETS, transistor_range

def verdict_text(difference, backend: str, readouts: int, crop: int, corner) -> str:
    """The RTL's verdict in one line: bit-identical, or the first difference
    (:class:`tespike.cosim.compare.Difference`) with its place in the frame."""
    if difference is None:
        return (f"bit-identical: {backend} RTL == golden model, {readouts} readouts x {crop} x {crop} pixels "
                f"({readouts * crop * crop} words)")
    return "DIFFERENT: " + difference.text(corner)



def _fmt_range(m) -> str:
    if math.isnan(m.low):
        return "none"
    return f"{m.low:.3g} .. {m.high:.3g} ({m.db:.1f} dB)"


def report_markdown(*, configs, rtl_config, frames, height, width, seed, crop, rtl_readouts, rtl_info, verdict,
                    evaluation, rtl_rows, scored, ranges, hardware, stages, total, window, methods,
                    label) -> str:
    import platform

    import torch

    from tespike.recon.evaluate import scored_frames
    from tespike.recon.methods import RECON_METHODS
    from tespike.recon.mulaw import MU
    from tespike.recon.report import table_markdown
    y, x, size = crop
    te = rtl_config
    golden_scored = scored_frames(frames, evaluation.window, evaluation.span)
    left = [method for method in RECON_METHODS if method not in methods]
    lines = ["# tespike demo report", "",
             f"Scene: the shipped CC0 panorama (Greg Zaal, HDRI Haven; `recon/data/README.md`), panned: "
             f"{frames} readout intervals of {height} x {width} pixels, brightest pixel = design light "
             f"(I = 1: {DESIGN_ELECTRONS} electrons per readout interval), seed {seed}. Photon shot noise: Poisson "
             f"electrons per pixel clock. Machine: {platform.machine()}, {torch.get_num_threads()} torch "
             f"thread(s), Python {platform.python_version()}. Total {total:.0f} s.", "",
             "## Configuration", "",
             "| sensor | config (JSON, every key) | L clocks / readout | word bits |",
             "| --- | --- | ---: | ---: |"]
    for name, config in configs.items():
        lines.append(f"| {name} | `{config.to_json()}` | {config.clocks_per_readout} | {config.word_bits} |")
    lines += ["", "`ml-msb` is the paper's ML camera (its eq. 10; Table 1's ML column, `TFP_ML`, `TFI_ML`), "
              "`ml` the full-count ML camera (rows `TFP_ML-count`, ...), `te` the TE camera.",
              "", "## RTL against the golden model", "",
              f"**{verdict}**", "",
              f"- crop: rows {y}..{y + size - 1}, columns {x}..{x + size - 1} of the frame (marked in "
              f"`frame.png`), readouts 0..{rtl_readouts - 1} ({rtl_readouts * te.clocks_per_readout} pixel "
              f"clocks), TE sensor;",
              "- stimulus `E_crop.npy`: the very per-clock electrons the golden full-frame TE run got for "
              "these pixels (the golden stream of the crop equals the full-frame stream's crop);",
              f"- backend: {rtl_info['backend']}" + (" (Amaranth simulator, pixels inlined; no build step)"
                                                     if rtl_info["backend"] == "amaranth" else "") + ";"]
    if rtl_info.get("vcd"):
        lines += [f"- waveform `W.vcd` ({rtl_info['vcd_bytes'] / 2**20:.1f} MiB) and GTKWave save file "
                  f"`W.gtkw` (opens on readout interval 0, marker on its last clock): `gtkwave W.gtkw`;",
                  f"- the stream was rebuilt from the VCD alone with vcdvcd (`cosim/vcd.py`) in "
                  f"{rtl_info['read_seconds']:.1f} s; it equals the stream the testbench captured live: "
                  f"{'yes' if rtl_info['live_equals_vcd'] else 'NO'}; frame_valid latency "
                  f"{rtl_info['latency']} clock(s); {rtl_info['cycles']} clocks simulated in "
                  f"{rtl_info['sim_seconds']:.1f} s ({rtl_info['cycles'] / max(rtl_info['sim_seconds'], 1e-9):.0f} "
                  f"clocks/s)."]
    else:
        lines += ["- no waveform: only the amaranth backend writes a VCD."]
    lines += ["", "### Reconstruction of the RTL's own stream", "",
              f"Frames {scored.start}..{scored.stop - 1} of the {rtl_readouts} RTL readouts scored (window "
              f"{window}), against the ground truth of the crop, normalised by the sequence's peak. "
              "'golden full frame' is the same method on the full-frame TE stream, cut to the crop. TFP and "
              "TFI work pixel by pixel along time, so they agree wherever the window does not reach past "
              "the RTL's readouts (TFI searches the whole stream for a spike interval, so it may differ "
              "near the ends); the learned methods are spatial (they see a neighbourhood of each pixel), so "
              "near the crop's borders it sees other pixels than on the full frame and may differ there. "
              "A learned method's light is floored at zero, so a dim pixel its output drives below zero is "
              "black in either panel (the network's head, docs/fair-training.md). "
              "Run time: median of repeats (`recon/walltime.py`). Pictures: `rtl_crop.png`.", "",
              "| method | RTL: PSNR-μ | SSIM-μ | golden full frame: PSNR-μ | SSIM-μ | max abs difference (light) "
              "| RTL stream ms / frame |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in rtl_rows:
        lines.append(f"| {label(row['method'], 'te')} | {row['rtl_psnr']:.2f} | {row['rtl_ssim']:.3f} | "
                     f"{row['golden_psnr']:.2f} | {row['golden_ssim']:.3f} | {row['max_diff']:.3g} | "
                     f"{row['ms_per_frame']:.3f} |")
    lines += ["", "## Quality per method and sensor (golden full frame)", "",
              f"PSNR-μ / SSIM-μ (μ = {MU:g}, after division by the ground truth's peak), frames "
              f"{golden_scored.start}..{golden_scored.stop - 1} scored; run time per frame "
              f"is the median of {evaluation.repeats} runs with {evaluation.threads} torch thread(s) (single "
              "runs vary several-fold on a shared machine). Methods: those of the registry "
              f"(`recon/methods.py`) with weights for every sensor here: {', '.join(methods)}"
              + (f" (not {', '.join(left)}: no shipped weights for one of the sensors; `--weights` "
                 "gives yours)" if left else "") + ".", "",
              table_markdown(evaluation).rstrip(), "",
              "Pictures: `strips/default.png` (ground truth, each method, |error| maps with colour bar, one "
              "pair of rows per sensor), `quality_vs_time.png` (quality against run time, with legend), "
              "`frame.png` (the frame with the RTL crop marked).", "",
              "## Dynamic range", "",
              "Formula (paper section 4.3): D_TE = 20 log10(2^b1 (2^b2 - 1) N_s), D_ML = 20 log10((2^B - 1) "
              "N_s), N_s the longest accepted spike interval in readouts. Measured "
              "(`golden/dynamic_range.py`): constant light on a grid of 20 levels per decade through the "
              f"cycle-exact model, noise-free electrons, N_s = {ranges[0]['n_s']}; a light passes when the "
              "mean decoded light over N_s readouts is within the tolerance in 90 % of 20 windows; the range "
              "is the longest run of passing lights (light in units of the design light).", "",
              f"| sensor | formula, N_s = 1 (dB) | formula, N_s = {ranges[0]['n_s']} (dB) | measured, 5 % | "
              "measured, 20 % |", "| --- | ---: | ---: | --- | --- |"]
    for row in ranges:
        lines.append(f"| {row['sensor']} | {row['formula_1']:.1f} | {row['formula_ns']:.1f} | "
                     f"{_fmt_range(row['strict'])} | {_fmt_range(row['loose'])} |")
    lines += ["", "## Hardware cost (one pixel, Yosys)", ""]
    if isinstance(hardware, str):
        lines += [f"Not computed here: {hardware}. The full table is `docs/hardware-cost.md` "
                  "(`python3 benchmarks/hw_cost.py`)."]
    else:
        lines += ["`synth -top <module>; stat` of the project's Verilog (`rtl/verilog.py`, synthesised by "
                  "`cosim/synthesis.py`, the flow of `docs/hardware-cost.md`): cells of Yosys's gate library "
                  "and flip-flops; transistors: flip-flops legalised to plain D flip-flops, mapped by ABC to "
                  f"each of {', '.join(ABC_GATE_SETS)} and counted with `stat -tech cmos` (a rough static-CMOS "
                  "estimate, shown as min-max over the mappings: ABC is heuristic; see "
                  "`docs/hardware-cost.md` for the counting-logic comparison).", "",
                  "| sensor | pixel cells | pixel flip-flops | pixel transistors | timing block cells | "
                  "timing flip-flops | timing transistors (one per array) |",
                  "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for row in hardware:
            p, t = row["pixel"], row["timing"]
            lines.append(f"| {row['sensor']} | {p['cells']} | {p['flops']} | {transistor_range(p)} | "
                         f"{t['cells']} | {t['flops']} | {transistor_range(t)} |")
    lines += ["", "## Run time of every stage", "", "| stage | seconds |", "| --- | ---: |"]
    lines += [f"| {stage.name} | {stage.seconds:.1f} |" for stage in stages]
    lines += [f"| total | {total:.1f} |", "", "## Rerun each step with the individual commands", "",
              "In a new, empty folder, in order (each step makes the files the next reads; run here they "
              "would leave files no demo writes, and the next `tespike demo` into this folder would refuse it):",
              "", "```sh", "mkdir ../demo-rerun && cd ../demo-rerun"]
    for stage in stages:
        lines.append(f"# {stage.name}")
        lines += stage.commands
    lines += ["```", ""]
    return "\n".join(lines)
