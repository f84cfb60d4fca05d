"""``tespike synthesize``: Yosys generic synthesis of a generated top, hierarchy kept, per block.

Prints, per module (pixel, its rule, readout cell, beat group, timing, top), its instances in
the design, its own cells and flip-flops, the transistor estimate of docs/hardware-cost.md, and
the cells by type; then the design's totals (and per pixel), and Yosys's wall time, CPU time and
peak memory. ``synth`` flattens nothing, so each block is synthesised once whatever H x W is.
"""

from .common import add_config_argument

HELP = ("Yosys generic synthesis (hierarchy kept) of a generated top or a Verilog file: cells, "
        "flip-flops and transistors per block, time and peak memory")


def add_arguments(parser):
    add_config_argument(parser, required=False)
    parser.add_argument("--height", type=int, default=None, help="pixel rows H >= 1 (with --config)")
    parser.add_argument("--width", type=int, default=None, help="pixel columns W >= 1 (with --config)")
    parser.add_argument("--lanes", type=int, default=None,
                        help="the streaming top with N lanes (as tespike verilog --lanes); "
                             "without it the parallel top")
    parser.add_argument("--verilog", default=None, help="A.v: synthesise this file instead of a generated top")
    parser.add_argument("--top", default=None, help="top module of --verilog (default: the one not instantiated)")


def _design(args):
    """(Verilog text, top name or None, pixels or None, a one-line description) from the arguments."""
    from pathlib import Path

    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.rtl.array import check_array_size

    generated = [flag for flag, value in (("--config", args.config), ("--height", args.height),
                                          ("--width", args.width), ("--lanes", args.lanes)) if value is not None]
    if args.verilog is not None:
        if generated:
            raise InputError(f"--verilog and {' '.join(generated)}: give a Verilog file or a generated top, not both")
        path = Path(args.verilog)
        if not path.is_file():
            raise InputError(f"--verilog {args.verilog}: no such file")
        return path.read_text(errors="replace"), args.top, None, f"{args.verilog}"
    if args.top is not None:
        raise InputError("--top names a module of --verilog; a generated top is named by its configuration")
    missing = [flag for flag, value in (("--config", args.config), ("--height", args.height),
                                        ("--width", args.width)) if value is None]
    if missing:
        raise InputError(f"missing {' '.join(missing)}: give --config, --height and --width, or --verilog")
    config = load_config(args.config)
    try:
        height, width = check_array_size(args.height, args.width)
    except ValueError as exc:
        raise InputError(f"--{exc}") from None
    from .verilog_cmd import MAX_PIXELS, MAX_STREAM_PIXELS
    pixels = height * width
    limit = MAX_PIXELS if args.lanes is None else MAX_STREAM_PIXELS
    if pixels > limit:
        raise InputError(f"--height {height} x --width {width} = {pixels} pixels: at most {limit} are supported"
                         + ("" if args.lanes is None else " with --lanes"))
    if args.lanes is None:
        from tespike.rtl.verilog import array_verilog, module_names
        return (array_verilog(config, height, width), module_names(config)["top"], pixels,
                f"{module_names(config)['top']}, {height} x {width} pixels")
    from tespike.golden.beats import check_lanes
    try:
        check_lanes(config, height, width, args.lanes)
    except ValueError as exc:
        raise InputError(f"--{exc}") from None
    from tespike.rtl.verilog_stream import stream_array_verilog, stream_module_names
    top = stream_module_names(config)["top"]
    return (stream_array_verilog(config, height, width, args.lanes), top, pixels,
            f"{top}, {height} x {width} pixels, {args.lanes} lanes")


def instance_counts(modules: dict, top: str) -> dict[str, int]:
    """How many times each module occurs in the design under ``top``."""
    counts = {name: 0 for name in modules}

    def walk(name, times):
        counts[name] += times
        for sub, n in modules[name]["instances"].items():
            walk(sub, times * n)
    walk(top, 1)
    return counts


def report_lines(result: dict, pixels: int | None) -> list[str]:
    """The printed report of :func:`tespike.cosim.synthesis.synthesize_hierarchy`'s result."""
    from tespike.cosim.synthesis import hierarchy_total
    modules, top = result["modules"], result["top"]
    counts = instance_counts(modules, top)
    lines = [f"{'module':<28} {'instances':>9} {'cells':>7} {'flops':>6} {'transistors':>12}   "
             f"(own logic of one instance; submodules listed apart)"]
    for name in sorted(modules, key=lambda n: (-counts[n], n)):
        if counts[name] == 0:
            continue
        stat = modules[name]
        lo, hi = stat["transistors"], stat["transistors_max"]
        subs = ", ".join(f"{n} x {s}" for s, n in stat["instances"].items())
        lines.append(f"{name:<28} {counts[name]:>9} {stat['cells']:>7} {stat['flops']:>6} "
                     f"{(str(lo) if lo == hi else f'{lo}-{hi}'):>12}" + (f"   + {subs}" if subs else ""))
    lines.append("cells by type (own, one instance):")
    for name in sorted(modules, key=lambda n: (-counts[n], n)):
        if counts[name] and modules[name]["by_type"]:
            kinds = ", ".join(f"{k.strip('$_')} {n}" for k, n in sorted(modules[name]["by_type"].items()))
            lines.append(f"  {name}: {kinds}")
    total = hierarchy_total(modules, top)
    lo, hi = total["transistors"], total["transistors_max"]
    lines.append(f"total {top}: {total['cells']} cells, {total['flops']} flip-flops, "
                 f"{lo if lo == hi else f'{lo}-{hi}'} transistors (estimate)")
    if pixels:
        lines.append(f"per pixel: {total['cells'] / pixels:.1f} cells, {total['flops'] / pixels:.2f} flip-flops, "
                     f"{lo / pixels:.0f}-{hi / pixels:.0f} transistors")
    run = result["run"]
    lines.append(f"yosys: {run['seconds']:.1f} s wall, {run['cpu_seconds']:.1f} s CPU, "
                 f"peak {run['peak_mb']:.0f} MB")
    return lines


def run(args) -> int:
    from tespike.cosim.synthesis import SynthesisError, synthesize_hierarchy
    from tespike.golden.errors import InputError

    text, top, pixels, what = _design(args)
    print(f"synthesize: {what} (yosys synth, hierarchy kept)", flush=True)
    try:
        result = synthesize_hierarchy(text, top)
    except SynthesisError as exc:
        raise InputError(str(exc)) from None
    print("\n".join(report_lines(result, pixels)))
    return 0
