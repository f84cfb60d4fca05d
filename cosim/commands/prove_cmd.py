"""``tespike prove``: the pixel against SPEC sections 3-4 (k-induction), the streaming Verilog top's
pixel rule against that pixel, and every generated Verilog top against a SPEC reference (ABC)."""

HELP = ("prove the pixel equal to SPEC section 3's rule (yosys-smtbmc k-induction), the streaming "
        "Verilog top's pixel rule equivalent to it (Yosys sat), and every generated Verilog top "
        "(timing block, parallel and streaming tops, read from the text `tespike verilog` writes) "
        "equal to a SPEC reference with reset free on every clock (ABC dprove, else BMC)")

PARTS = ("pixel", "tops")


def add_arguments(parser):
    parser.add_argument("--config", metavar="C", action="append", default=[],
                        help="sensor: te, ml, ml-msb or a JSON file (repeatable; default: all three presets)")
    parser.add_argument("--only", choices=PARTS, default=None,
                        help="prove only the pixel properties or only the generated tops (default: both)")
    parser.add_argument("--corners", action="store_true",
                        help="also prove the pixel at the extreme corners of SPEC section 2 for each "
                             "configuration's mode (min, max and saturating widths; see docs/rtl.md)")
    parser.add_argument("--depth", type=int, default=3,
                        help="k of the pixel's k-induction (base case and induction step; default 3)")
    parser.add_argument("--solver", default="z3", help="SMT solver for yosys-smtbmc (default z3)")
    parser.add_argument("--sizes", default="1x1,2x3,3x4", metavar="HxW,...",
                        help="array sizes of the tops at small clocks (b1 = b2 = 2, L = 12; default 1x1,2x3,3x4)")
    parser.add_argument("--config-sizes", default="none", metavar="HxW,...",
                        help="array sizes of the tops at each configuration's own clocks (default none: "
                             "only its timing block; the presets' L = 240 makes even 1x1 take minutes)")
    parser.add_argument("--top-timeout", type=float, default=300.0, metavar="S",
                        help="seconds each top property may take (default 300)")
    parser.add_argument("--traces", metavar="DIR", default="tespike-prove-traces",
                        help="folder for counterexample VCDs of failed pixel properties "
                             "(default ./tespike-prove-traces; made only on a failure)")


def targets(specs, with_corners: bool):
    """``--config`` values (and their corners) -> {name: SensorConfig}, in order."""
    from pathlib import Path

    from tespike.cosim.formal import corners
    from tespike.golden.config import PRESETS, load_config

    configs = {}
    for spec in specs or list(PRESETS):
        name = spec if spec in PRESETS else Path(spec).stem
        config = load_config(spec)
        configs[name] = config
        if with_corners:
            for corner, c in corners(config.mode, config.ml_readout).items():
                configs[f"{name}:{corner}"] = c
    return configs


def parse_sizes(flag: str, text: str) -> list[tuple[int, int]]:
    """``"1x1,2x3"`` -> [(1, 1), (2, 3)]; ``"none"`` -> []; anything else is refused in one line."""
    from tespike.golden.errors import InputError

    if text.strip() == "none":
        return []
    sizes = []
    for part in text.split(","):
        rows, sep, cols = part.strip().partition("x")
        if not (sep and rows.isdigit() and cols.isdigit() and int(rows) >= 1 and int(cols) >= 1
                and int(rows) * int(cols) <= 64):
            raise InputError(f"{flag} {text!r}: each size must be HxW with H, W >= 1 and H x W <= 64 "
                             f"(e.g. 2x3), or 'none'")
        sizes.append((int(rows), int(cols)))
    return sizes


def _prove_pixel(name, config, args, traces, emit) -> tuple[int, int]:
    from tespike.cosim.formal import properties, prove

    count = failed = 0
    for prop, build in properties(config).items():
        result = prove(f"{name.replace(':', '-')}-{prop}", build(), depth=args.depth,
                       solver=args.solver, trace_dir=traces)
        method = "SAT (combinational)" if prop == "stream-pixel-rule" else f"k-induction depth {args.depth}"
        count += 1
        if result.proved:
            emit(f"{name} {prop}: proved, {method} ({result.seconds:.1f} s)")
        else:
            failed += 1
            where = f"; counterexample {result.trace}" if result.trace else ""
            emit(f"{name} {prop}: FAILED, {method}, in the {result.detail}{where}", always=True)
    return count, failed


def _prove_tops(name, config, sizes, args, emit) -> tuple[int, int]:
    from tespike.cosim.formal.abc import prove_harness
    from tespike.cosim.formal.tops import top_properties

    count = failed = 0
    for prop, build in top_properties(config, sizes).items():
        result = prove_harness(f"{name} {prop}", build(), timeout=args.top_timeout)
        count += 1
        if result.proved:
            emit(f"{name} {prop}: proved, {result.method} ({result.seconds:.1f} s)")
        else:
            failed += 1
            emit(f"{name} {prop}: FAILED, {result.method}, {result.detail} ({result.seconds:.1f} s)", always=True)
    return count, failed


def run(args) -> int:
    import time
    from pathlib import Path

    from tespike.cosim.formal import require_tools
    from tespike.cosim.formal.tops import small_clocks
    from tespike.golden.errors import InputError

    if args.depth < 1:
        raise InputError(f"--depth {args.depth} must be >= 1")
    if not args.top_timeout > 0:
        raise InputError(f"--top-timeout {args.top_timeout} must be > 0")
    sizes = parse_sizes("--sizes", args.sizes)
    config_sizes = parse_sizes("--config-sizes", args.config_sizes)
    require_tools(args.solver)
    configs = targets(args.config, args.corners)
    traces = Path(args.traces)
    start = time.perf_counter()

    def emit(line: str, always: bool = False) -> None:
        if always or not args.quiet:
            print(line, flush=True)

    count = failed = 0
    for name, config in configs.items():
        if args.only != "tops":
            done = _prove_pixel(name, config, args, traces, emit)
            count, failed = count + done[0], failed + done[1]
        if args.only != "pixel" and ":" not in name:      # the corners are pixel-only
            for label, c, at in ((name, config, config_sizes), (f"{name}-small", small_clocks(config), sizes)):
                done = _prove_tops(label, c, at, args, emit)      # the timing block at least
                count, failed = count + done[0], failed + done[1]
    if failed or not args.quiet:
        print(f"prove: {count - failed} of {count} properties proved, {len(configs)} configuration(s), "
              f"{time.perf_counter() - start:.1f} s", flush=True)
    return 1 if failed else 0
