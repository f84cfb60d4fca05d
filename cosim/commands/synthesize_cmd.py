"""``tespike synthesize``: Yosys generic synthesis of a generated top, hierarchy kept, per block.

Prints, per module (pixel, its rule, readout cell, beat group, timing, top), its instances in
the design, its own cells and flip-flops, the transistor estimate of docs/hardware-cost.md, and
the cells by type; then the design's totals (and per pixel), and Yosys's wall time, CPU time and
peak memory. ``synth`` flattens nothing, so each block is synthesised once whatever H x W is.

``--stimulus E.npy`` (a generated top only) also counts the toggles of every register and
output port of a run of that stimulus, per block (:mod:`tespike.golden.activity`), and prices
them with the energy model of docs/energy.md (:mod:`tespike.cosim.energy`); ``--icarus``
counts the same toggles in an Icarus VCD of the generated text and refuses the run if any
block differs.
"""

from .common import add_array_arguments, add_config_argument

HELP = ("Yosys generic synthesis (hierarchy kept) of a generated top or a Verilog file: cells, "
        "flip-flops and transistors per block, time and peak memory")


def add_arguments(parser):
    add_config_argument(parser, required=False)
    add_array_arguments(parser, required=False, what=" (with --config)")
    parser.add_argument("--verilog", default=None, help="A.v: synthesise this file instead of a generated top")
    parser.add_argument("--top", default=None, help="top module of --verilog (default: the one not instantiated)")
    parser.add_argument("--stimulus", default=None,
                        help="E.npy (T, H, W): also the toggles of every register and output port of a run "
                             "of it, per block, and the energy per readout (docs/energy.md)")
    parser.add_argument("--icarus", action="store_true",
                        help="with --stimulus: count the same toggles in an Icarus VCD of the generated "
                             "Verilog and refuse if a block differs")


#: Most stimulus values (T x H x W) --stimulus counts (the count holds a few int64 copies).
MAX_STIMULUS_VALUES = 1 << 25
#: Most pixels --icarus simulates (Icarus runs tens of clocks per second at 1024 pixels).
MAX_ICARUS_PIXELS = 1024


def _design(args):
    """(Verilog text, top name or None, pixels or None, a one-line description) from the arguments."""
    import re

    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.golden.paths import check_input_file

    from .common import check_array_arguments

    generated = [flag for flag, value in (("--config", args.config), ("--height", args.height),
                                          ("--width", args.width), ("--lanes", args.lanes)) if value is not None]
    if args.icarus and args.stimulus is None:
        raise InputError("--icarus checks the toggles of --stimulus: give --stimulus E.npy")
    if args.verilog is not None:
        if args.stimulus is not None:
            raise InputError("--stimulus counts a generated top's registers: give --config, --height and "
                             "--width, not --verilog")
        if generated:
            raise InputError(f"--verilog and {' '.join(generated)}: give a Verilog file or a generated top, not both")
        path = check_input_file(args.verilog, "--verilog")
        if args.top is not None and not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_$]*", args.top):
            # (a Verilog identifier: the name goes into Yosys's script, where ';' would start a command)
            raise InputError(f"--top {args.top!r}: not a Verilog module name (letters, digits, _ and $, "
                             "starting with a letter or _)")
        return path.read_text(errors="replace"), args.top, None, f"{args.verilog}"
    if args.top is not None:
        raise InputError("--top names a module of --verilog; a generated top is named by its configuration")
    missing = [flag for flag, value in (("--config", args.config), ("--height", args.height),
                                        ("--width", args.width)) if value is None]
    if missing:
        raise InputError(f"missing {' '.join(missing)}: give --config, --height and --width, or --verilog")
    config = load_config(args.config)
    height, width = check_array_arguments(config, args.height, args.width, args.lanes)
    pixels = height * width
    if args.lanes is None:
        from tespike.rtl.names import module_names
        from tespike.rtl.verilog import array_verilog
        return (array_verilog(config, height, width), module_names(config)["top"], pixels,
                f"{module_names(config)['top']}, {height} x {width} pixels")
    from tespike.rtl.names import stream_module_names
    from tespike.rtl.verilog_stream import stream_array_verilog
    top = stream_module_names(config)["top"]
    return (stream_array_verilog(config, height, width, args.lanes), top, pixels,
            f"{top}, {height} x {width} pixels, {args.lanes} lanes")


def report_lines(result: dict, pixels: int | None) -> list[str]:
    """The printed report of :func:`tespike.cosim.synthesis.synthesize_hierarchy`'s result."""
    from tespike.cosim.synthesis import hierarchy_total, instance_counts, transistor_range
    modules, top = result["modules"], result["top"]
    counts = instance_counts(modules, top)
    lines = [f"{'module':<28} {'instances':>9} {'cells':>7} {'flops':>6} {'transistors':>12}   "
             f"(own logic of one instance; submodules listed apart)"]
    for name in sorted(modules, key=lambda n: (-counts[n], n)):
        if counts[name] == 0:
            continue
        stat = modules[name]
        subs = ", ".join(f"{n} x {s}" for s, n in stat["instances"].items())
        lines.append(f"{name:<28} {counts[name]:>9} {stat['cells']:>7} {stat['flops']:>6} "
                     f"{transistor_range(stat):>12}" + (f"   + {subs}" if subs else ""))
    lines.append("cells by type (own, one instance):")
    for name in sorted(modules, key=lambda n: (-counts[n], n)):
        if counts[name] and modules[name]["by_type"]:
            kinds = ", ".join(f"{k.strip('$_')} {n}" for k, n in sorted(modules[name]["by_type"].items()))
            lines.append(f"  {name}: {kinds}")
    total = hierarchy_total(modules, top)
    lines.append(f"total {top}: {total['cells']} cells, {total['flops']} flip-flops, "
                 f"{transistor_range(total)} transistors (estimate)")
    if pixels:
        lines.append(f"per pixel: {total['cells'] / pixels:.1f} cells, {total['flops'] / pixels:.2f} flip-flops, "
                     f"{total['transistors'] / pixels:.0f}-{total['transistors_max'] / pixels:.0f} transistors")
    run = result["run"]
    lines.append(f"yosys: {run['seconds']:.1f} s wall, {run['cpu_seconds']:.1f} s CPU, "
                 f"peak {run['peak_mb']:.0f} MB")
    return lines


def _stimulus(args):
    """The checked stimulus of ``--stimulus`` for the generated top, or None."""
    if args.stimulus is None:
        return None
    import numpy as np

    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_stimulus

    stimulus = load_stimulus(args.stimulus, load_config(args.config))
    T, H, W = stimulus.shape
    if (H, W) != (args.height, args.width):
        raise InputError(f"--stimulus {args.stimulus}: {H} x {W} pixels, not --height {args.height} x "
                         f"--width {args.width}")
    if T * H * W > MAX_STIMULUS_VALUES:
        raise InputError(f"--stimulus {args.stimulus}: {T} x {H} x {W} values; at most {MAX_STIMULUS_VALUES} "
                         "are counted (use fewer clocks or pixels)")
    if args.icarus and H * W > MAX_ICARUS_PIXELS:
        raise InputError(f"--icarus: {H * W} pixels; Icarus runs at most {MAX_ICARUS_PIXELS} here")
    return np.asarray(stimulus, np.int64)


def energy_lines(config, stimulus, lanes, result: dict, text: str, icarus: bool) -> list[str]:
    """Toggles per block of a run of ``stimulus`` (and, with ``icarus``, the VCD's), the synthesised
    cells per block and the energy of :data:`tespike.cosim.energy.SKY130_HD`."""
    from tespike.cosim.energy import SKY130_HD, block_cells, run_energy
    from tespike.golden.activity import BLOCKS, top_activity
    from tespike.golden.errors import InputError

    activity = top_activity(config, stimulus, lanes)
    found = None
    if icarus:
        from pathlib import Path

        from tespike.cosim.activity import edges_after_reset, vcd_activity
        from tespike.cosim.icarus import DUT_SCOPE, run_icarus, run_icarus_stream
        from tespike.golden.atomic import work_folder

        with work_folder("tespike-energy-") as tmp:
            vcd = Path(tmp) / "run.vcd"
            if lanes is None:
                run_icarus(config, stimulus, verilog=text, vcd_path=vcd)
            else:
                run_icarus_stream(config, stimulus, lanes, verilog=text, vcd_path=vcd)
            activity = top_activity(config, stimulus, lanes, edges=edges_after_reset(vcd, DUT_SCOPE))
            counts = vcd_activity(vcd, config, text, result["top"], lanes is not None, DUT_SCOPE)
        found = {block: sum(n for (b, _), n in counts.items() if b == block) for block in BLOCKS}
    toggles, bits = activity.per_block(), activity.register_bits()
    if found is not None and found != toggles:
        wrong = [b for b in BLOCKS if found[b] != toggles[b]]
        raise InputError(f"--icarus: the VCD's toggles differ from the model's in block {wrong[0]} "
                         f"({found[wrong[0]]} against {toggles[wrong[0]]})")
    cells = block_cells(result["modules"], result["top"], config, lanes is not None)
    energy = run_energy(activity, cells)
    K, P = max(activity.readouts, 1), stimulus.shape[1] * stimulus.shape[2]
    lines = [f"switching and energy of the run ({activity.edges} clocks after reset, {activity.readouts} "
             f"readouts; model {SKY130_HD.name}, docs/energy.md):",
             f"{'block':<8} {'toggles':>9} {'vcd':>9} {'reg bits':>8} {'flops':>6} {'gates':>6} "
             f"{'data pJ':>9} {'logic pJ':>9} {'clock pJ':>9} {'total pJ':>9}"]
    for block in BLOCKS:
        e = energy[block]
        vcd = "" if found is None else found[block]
        lines.append(f"{block:<8} {toggles[block]:>9} {vcd:>9} {bits[block]:>8} {cells[block]['flops']:>6} "
                     f"{cells[block]['gates']:>6} {e['data'] * 1e12:>9.2f} {e['logic'] * 1e12:>9.2f} "
                     f"{e['clock'] * 1e12:>9.2f} {e['total'] * 1e12:>9.2f}")
    total = sum(e["total"] for e in energy.values())
    lines.append(f"energy: {total * 1e12:.2f} pJ in the run, {total / K * 1e12:.2f} pJ per readout, "
                 f"{total / K / P * 1e12:.2f} pJ per pixel-readout"
                 + ("" if found is None else "; toggles equal to the Icarus VCD's in every block"))
    return lines


def run(args) -> int:
    from tespike.cosim.console import report
    from tespike.cosim.synthesis import DESIGN_FILE, SynthesisError, synthesize_hierarchy
    from tespike.golden.errors import InputError

    text, top, pixels, what = _design(args)
    stimulus = _stimulus(args)
    try:
        result = synthesize_hierarchy(text, top)
    except SynthesisError as exc:     # about --verilog: named as given, never as Yosys's copy
        if args.verilog is None:
            raise InputError(str(exc)) from None
        raise InputError(f"--verilog {args.verilog!r}: {str(exc).replace(DESIGN_FILE, args.verilog)}") from None
    lines = [f"synthesize: {what} (yosys synth, hierarchy kept)", *report_lines(result, pixels)]
    if stimulus is not None:
        from tespike.golden.config import load_config
        lines += energy_lines(load_config(args.config), stimulus, args.lanes, result, text, args.icarus)
    report(args, "\n".join(lines))               # (all at the end: a refusal leaves stdout empty)
    return 0
