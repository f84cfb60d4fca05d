"""``tespike prove``: unbounded proofs (k-induction) of the pixel against SPEC sections 3-4, and the
streaming Verilog top's pixel rule proved equivalent to that pixel (``stream-pixel-rule``)."""

HELP = ("prove the pixel equal to SPEC section 3's rule and its counters and words legal, for every "
        "input (Yosys + yosys-smtbmc k-induction), and the streaming Verilog top's pixel rule equivalent "
        "to that pixel (Yosys miter + sat), for a configuration and optionally its extreme corners")


def add_arguments(parser):
    parser.add_argument("--config", metavar="C", action="append", default=[],
                        help="sensor: te, ml, ml-msb or a JSON file (repeatable; default: all three presets)")
    parser.add_argument("--corners", action="store_true",
                        help="also prove the extreme corners of SPEC section 2 for each configuration's "
                             "mode (min, max and saturating widths; see docs/rtl.md)")
    parser.add_argument("--depth", type=int, default=3,
                        help="k of the k-induction (base case and induction step; default 3)")
    parser.add_argument("--solver", default="z3", help="SMT solver for yosys-smtbmc (default z3)")
    parser.add_argument("--traces", metavar="DIR", default="tespike-prove-traces",
                        help="folder for counterexample VCDs of failed properties "
                             "(default ./tespike-prove-traces; made only on a failure)")


def targets(specs, with_corners: bool):
    """``--config`` values (and their corners) -> {name: SensorConfig}, in order."""
    from pathlib import Path

    from cosim.formal import corners
    from golden.config import PRESETS, load_config

    configs = {}
    for spec in specs or list(PRESETS):
        name = spec if spec in PRESETS else Path(spec).stem
        config = load_config(spec)
        configs[name] = config
        if with_corners:
            for corner, c in corners(config.mode, config.ml_readout).items():
                configs[f"{name}:{corner}"] = c
    return configs


def run(args) -> int:
    import time
    from pathlib import Path

    from cosim.formal import properties, prove, require_tools
    from golden.errors import InputError

    if args.depth < 1:
        raise InputError(f"--depth {args.depth} must be >= 1")
    require_tools(args.solver)
    configs = targets(args.config, args.corners)
    traces = Path(args.traces)
    start = time.perf_counter()
    failed = 0
    count = 0
    for name, config in configs.items():
        for prop, build in properties(config).items():
            result = prove(f"{name.replace(':', '-')}-{prop}", build(), depth=args.depth,
                           solver=args.solver, trace_dir=traces)
            count += 1
            if result.proved:
                if not args.quiet:
                    print(f"{name} {prop}: proved ({result.seconds:.1f} s)", flush=True)
            else:
                failed += 1
                where = f"; counterexample {result.trace}" if result.trace else ""
                print(f"{name} {prop}: FAILED in the {result.detail}{where}", flush=True)
    if failed or not args.quiet:
        print(f"prove: {count - failed} of {count} properties proved, {len(configs)} configuration(s), "
              f"k = {args.depth}, {args.solver}, {time.perf_counter() - start:.1f} s", flush=True)
    return 1 if failed else 0
