"""``tespike prove``: the pixel against SPEC sections 3-4 (k-induction), the streaming Verilog top's
pixel rule against that pixel, and every generated Verilog top against a SPEC reference (ABC)."""

from .common import CONFIG_HELP

HELP = ("prove the pixel equal to SPEC section 3's rule (yosys-smtbmc k-induction), the streaming "
        "Verilog top's pixel rule equivalent to it (Yosys sat), and every generated Verilog top "
        "(timing block, parallel and streaming tops of a few small arrays, read from the text "
        "`tespike verilog` writes for them) "
        "equal to a SPEC reference with reset free on every clock (ABC scorr + pdr or dprove, else BMC); "
        "independent proofs run in --workers processes")

PARTS = ("pixel", "tops")
#: Largest k of the pixel's k-induction: each step unrolls k clocks of the harness, and the solver's
#: time grows fast with k (100000 ran for minutes with nothing printed); the properties are 1- or
#: 2-inductive (docs/rtl.md), the default 3.
MAX_DEPTH = 32
#: Options only the pixel's proofs use, and only the tops' (``--only`` refuses the other part's).
PIXEL_OPTIONS = ("corners", "depth", "solver", "traces")
TOP_OPTIONS = ("sizes", "config_sizes", "top_timeout")


def add_arguments(parser):
    parser.add_argument("--config", metavar="C", action="append", default=[],
                        help=f"sensor: {CONFIG_HELP} (repeatable; default: every preset)")
    parser.add_argument("--only", choices=PARTS, default=None,
                        help="prove only the pixel properties or only the generated tops (default: both)")
    parser.add_argument("--corners", action="store_true",
                        help="also prove the pixel at the extreme corners of SPEC section 2 for each "
                             "configuration's mode (min, max and saturating widths; see docs/rtl.md)")
    parser.add_argument("--depth", type=int, default=3,
                        help=f"k of the pixel's k-induction (base case and induction step), 1..{MAX_DEPTH} "
                             "(default 3)")
    parser.add_argument("--solver", default="z3", help="SMT solver for yosys-smtbmc (default z3)")
    from tespike.cosim.formal.tops import SIZES
    default_sizes = ",".join(f"{rows}x{cols}" for rows, cols in SIZES)
    parser.add_argument("--sizes", default=default_sizes, metavar="HxW,...",
                        help=f"array sizes of the tops at small clocks (b1 = b2 = 2, L = 12; default {default_sizes})")
    parser.add_argument("--config-sizes", default="1x1", metavar="HxW,...",
                        help="array sizes of the tops at each configuration's own clocks and widths, beside "
                             "its timing block (default 1x1; 'none': the timing block only)")
    parser.add_argument("--top-timeout", type=float, default=300.0, metavar="S",
                        help="seconds each top property may take (default 300; at least 10)")
    parser.add_argument("--workers", type=int, default=2,
                        help="proofs run at once, each in its own process (default 2; 1: one after another)")
    parser.add_argument("--traces", metavar="DIR", default="tespike-prove-traces",
                        help="folder for counterexample VCDs of failed pixel properties "
                             "(default ./tespike-prove-traces; made only on a failure)")


def targets(specs, with_corners: bool):
    """``--config`` values (and their corners) -> {name: SensorConfig}, in order."""
    from tespike.cosim.formal import corners
    from tespike.golden.config import PRESETS, load_config

    from .common import config_name

    configs = {}
    for spec in specs or list(PRESETS):
        name = config_name(spec, configs)
        config = load_config(spec)
        configs[name] = config
        if with_corners:
            for corner, c in corners(config.mode, config.ml_readout).items():
                configs[f"{name}:{corner}"] = c
    return configs


def parse_sizes(flag: str, text: str) -> list[tuple[int, int]]:
    """``"1x1,2x3"`` -> [(1, 1), (2, 3)]; ``"none"`` -> []; anything else is refused in one line."""
    from tespike.cosim.formal.tops import MAX_PROOF_PIXELS
    from tespike.golden.errors import InputError

    if text.strip() == "none":
        return []
    from .common import decimal

    sizes = []
    for part in text.split(","):
        rows, sep, cols = part.strip().partition("x")
        try:
            size = (decimal(rows), decimal(cols)) if sep else (0, 0)
        except ValueError:
            size = (0, 0)
        if not (min(size) >= 1 and size[0] * size[1] <= MAX_PROOF_PIXELS):
            raise InputError(f"{flag} {text!r}: each size must be HxW with H, W >= 1 and H x W <= {MAX_PROOF_PIXELS} "
                             f"(e.g. 2x3), or 'none'")
        if size in sizes:               # (it was proven once, without a word)
            raise InputError(f"{flag} {text!r}: {size[0]}x{size[1]} is named more than once")
        sizes.append(size)
    return sizes


def _tasks(configs, args, sizes, config_sizes):
    """Every proof of the run, in the order its lines are printed: ``("pixel", name, config, prop)``
    and ``("top", label, config, prop, sizes)``; each is rebuilt from these values where it runs."""
    from tespike.cosim.formal import properties
    from tespike.cosim.formal.tops import small_clocks, top_properties

    for name, config in configs.items():
        if args.only != "tops":
            for prop in properties(config):
                yield ("pixel", name, config, prop)
        if args.only != "pixel" and ":" not in name:      # the corners are pixel-only
            for label, c, at in ((name, config, config_sizes), (f"{name}-small", small_clocks(config), sizes)):
                for prop in top_properties(c, at):          # the timing block at least
                    yield ("top", label, c, prop, at)


def trace_name(name: str, prop: str) -> str:
    """A pixel property's name in the proof, and its counterexample's file name in ``--traces``
    (``NAME.vcd``)."""
    return f"{name.replace(':', '-')}-{prop}"


def run_task(task, depth: int, solver: str, traces, top_timeout: float) -> tuple[bool, str]:
    """Prove one task of :func:`_tasks`: ``(proved, the line that reports it)``."""
    from tespike.cosim.formal import properties, prove

    if task[0] == "pixel":
        _, name, config, prop = task
        result = prove(trace_name(name, prop), properties(config)[prop](), depth=depth,
                       solver=solver, trace_dir=traces)
        method = "SAT (combinational)" if prop == "stream-pixel-rule" else f"k-induction depth {depth}"
        if result.proved:
            return True, f"{name} {prop}: proved, {method} ({result.seconds:.1f} s)"
        if result.detail.startswith("induction step"):   # (from a state the base case may never reach)
            where = f"; the induction step's trace {result.trace}" if result.trace else ""
            return False, (f"{name} {prop}: NOT PROVED, {method}: the {result.detail} (inconclusive: that "
                           f"state may be unreachable; try a larger --depth){where}")
        where = f"; counterexample {result.trace}" if result.trace else ""
        return False, f"{name} {prop}: FAILED, {method}, in the {result.detail}{where}"
    from tespike.cosim.formal.abc import prove_harness
    from tespike.cosim.formal.tops import top_properties

    _, label, config, prop, sizes = task
    result = prove_harness(f"{label} {prop}", top_properties(config, sizes)[prop](), timeout=top_timeout)
    if result.proved:
        return True, f"{label} {prop}: proved, {result.method} ({result.seconds:.1f} s)"
    return False, f"{label} {prop}: FAILED, {result.method}, {result.detail} ({result.seconds:.1f} s)"


def _results(tasks, workers: int, settings: tuple):
    """``run_task`` of each task, in order; up to ``workers`` at once, each in a forked process
    (every proof is its own Yosys/ABC/z3 run, independent of the others; fork keeps the
    parent's modules as they are, patched ones included)."""
    if workers == 1:
        for task in tasks:
            yield run_task(task, *settings)
        return
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=proof_worker_start, initargs=(os.getpid(),))
    try:
        futures = [pool.submit(run_task, task, *settings) for task in tasks]
        for future in futures:
            yield future.result()
    except BaseException:
        # Ctrl-C, a signal or a failure: the workers go at once (a worker that the terminal's
        # Ctrl-C had interrupted inside the pool's queue lock left shutdown waiting forever)
        manager = getattr(pool, "_executor_manager_thread", None)
        for child in multiprocessing.active_children():
            child.kill()
        pool.shutdown(wait=False, cancel_futures=True)
        if manager is not None:
            # the pool's manager thread sees its workers gone and closes its wakeup pipe, which
            # CPython 3.11's exit hook (concurrent.futures.process._python_exit) writes to without
            # the lock it is closed under: a command ending at once printed "Exception ignored ...
            # Bad file descriptor" after its line. Bounded: the exit hook joins it in any case.
            manager.join(MANAGER_EXIT_SECONDS)
        raise
    pool.shutdown(wait=True)


#: Seconds a failed proof run waits for its pool's manager thread to close (milliseconds, measured).
MANAGER_EXIT_SECONDS = 10.0


def proof_worker_start(parent: int) -> None:
    """A proof worker: ends with the command, even one killed outright (and through it its
    tools), and leaves the terminal's Ctrl-C and the signals sent to the whole process group
    to the command, which ends it (a handler, not SIG_IGN: the tools it starts keep the
    default action, which exec restores for handlers only). A signal the command runs with
    ignored (``nohup``, a background job's Ctrl-C) stays ignored, in the tools too."""
    import signal

    from tespike.cosim.children import end_with_parent
    end_with_parent(parent)
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(number) is not signal.SIG_IGN:
            signal.signal(number, _ignore_here)


def _ignore_here(signum, frame) -> None:
    """The worker's handler of the group's signals: nothing (the command ends the worker)."""


def run(args) -> int:
    import time
    from pathlib import Path

    from tespike.cosim.formal import TOP_TOOLS, require_tools
    from tespike.golden.errors import InputError

    from tespike.golden.resources import check_workers_argument

    if args.only is not None:           # the other part's options would be dropped without a word
        from .common import options_given
        other = PIXEL_OPTIONS if args.only == "tops" else TOP_OPTIONS
        given = [flag for flag, dest in options_given(args.command_parser, args) if dest in other]
        if given:
            part = "the pixel's proofs" if args.only == "tops" else "the tops' proofs"
            raise InputError(f"{given[0]} belongs to {part}, which --only {args.only} leaves out")
    if not 1 <= args.depth <= MAX_DEPTH:
        raise InputError(f"--depth {args.depth} must be in 1..{MAX_DEPTH}")
    from tespike.cosim.formal.abc import MIN_BMC_SECONDS
    if not args.top_timeout >= MIN_BMC_SECONDS:        # (BMC gets that much whatever is left: "undecided
        raise InputError(f"--top-timeout {args.top_timeout:g} must be at least {MIN_BMC_SECONDS:g} seconds "   # in 0.001 s"
                         "(the bounded check of a top property gets that much in any case)")
    check_workers_argument(args.workers)
    from tespike.golden.paths import check_output_dir
    if args.only != "tops":             # (written only on a failure: a bad one was found after the proofs)
        check_output_dir(args.traces, "--traces")
    sizes = parse_sizes("--sizes", args.sizes)
    config_sizes = parse_sizes("--config-sizes", args.config_sizes)
    if args.only == "tops":                # ABC alone: no SMT solver, no yosys-smtbmc
        require_tools(None, TOP_TOOLS)
    else:
        require_tools(args.solver)
    configs = targets(args.config, args.corners)
    start = time.perf_counter()
    tasks = list(_tasks(configs, args, sizes, config_sizes))
    if args.only != "tops":             # every trace a failure may write, checked before any proof runs:
        from tespike.golden.config import PRESETS      # never a folder, never a --config file (a link)
        from tespike.golden.paths import check_distinct
        traces = [f"{trace_name(task[1], task[3])}.vcd" for task in tasks if task[0] == "pixel"]
        check_output_dir(args.traces, "--traces", tuple(traces))
        config_files = [("--config", spec) for spec in args.config if spec not in PRESETS]
        for name in traces:             # (one at a time: each is named "a counterexample of --traces")
            check_distinct(config_files, {"a counterexample of --traces": Path(args.traces) / name})
    count = failed = 0
    for proved, line in _results(tasks, args.workers, (args.depth, args.solver, Path(args.traces),
                                                        args.top_timeout)):
        count += 1
        failed += not proved
        if not proved or not args.quiet:
            print(line, flush=True)
    if failed or not args.quiet:
        print(f"prove: {count - failed} of {count} properties proved, {len(configs)} configuration(s), "
              f"{args.workers} worker(s), {time.perf_counter() - start:.1f} s", flush=True)
    return 1 if failed else 0
