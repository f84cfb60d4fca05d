"""``tespike cocotb``: the cocotb testbench of the array Verilog under one or more simulators.

Drives only the SPEC section 6 ports and compares every word with the golden
model (:mod:`tespike.cosim.cocotb_bench`); one line per simulator, exit 1 if any fails.
"""

from .common import add_array_arguments, add_config_argument

HELP = "check the array Verilog with the cocotb testbench (golden model as scoreboard) in Icarus / Verilator / ..."


#: Readout intervals of the default stimulus.
DEFAULT_READOUTS = 3


def add_arguments(parser):
    add_config_argument(parser)
    add_array_arguments(parser, lanes_use=" (its beats checked against the golden model's words in beat order)")
    parser.add_argument("--simulator", nargs="+", default=["icarus", "verilator"],
                        help="cocotb simulator names (default: icarus verilator; any cocotb knows, "
                             "e.g. questa, xcelium, vcs)")
    parser.add_argument("--verilog", help="Verilog to test instead of the generated array "
                                          "(must have the SPEC section 6 ports)")
    parser.add_argument("--stimulus", help="E.npy (T, H, W) electrons per pixel clock "
                                           "(default: --readouts intervals of a mixed Poisson stimulus)")
    parser.add_argument("--readouts", type=int, default=None,
                        help=f"readout intervals of the default stimulus (default {DEFAULT_READOUTS}; not with --stimulus)")
    parser.add_argument("--seed", type=int, default=None,
                        help="seed of the default stimulus (default 0; not with --stimulus)")
    parser.add_argument("--resets", help="also reset mid-run: 'sweep' (rst at every phase of an interval "
                                         "and of its beats, charge flowing throughout) or R.npy (one 0/1 per "
                                         "stimulus clock); each segment is checked from zero state")
    parser.add_argument("--work-dir", help="keep each simulator's log and results here (new, empty, or an "
                                           "earlier run's, which the run replaces whole when it ends)")


def run(args) -> int:
    import contextlib
    import dataclasses
    from pathlib import Path

    from tespike.cosim.console import report
    from tespike.golden.atomic import atomic_folder
    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError

    from tespike.cosim.cocotb_bench import Settings
    from tespike.cosim.cocotb_run import check_simulator, run_cocotb

    from .common import check_array_arguments, check_inputs_outside

    twice = next((s for i, s in enumerate(args.simulator) if s in args.simulator[:i]), None)
    if twice is not None:
        raise InputError(f"--simulator {twice} is given twice: name each simulator once")
    for simulator in args.simulator:      # every name checked before the first run (it ran, then refused)
        check_simulator(simulator)
    config = load_config(args.config)
    check_array_arguments(config, args.height, args.width, args.lanes)   # the tops tespike verilog writes
    if args.work_dir is not None:         # (a file there was "File exists", naming no option)
        check_work_dir(args.work_dir)
        check_inputs_outside(args, "work_dir", ("config", "verilog", "stimulus"))
    for flag, value in (("--readouts", args.readouts), ("--seed", args.seed)):
        if value is not None and args.stimulus is not None:
            raise InputError(f"{flag} shapes the default stimulus; --stimulus gives its own (it would be ignored)")
    readouts = DEFAULT_READOUTS if args.readouts is None else args.readouts
    seed = 0 if args.seed is None else args.seed
    if readouts < 1:
        raise InputError(f"--readouts {readouts}: must be >= 1")
    if seed < 0:
        raise InputError(f"--seed {seed}: must be >= 0")
    if args.stimulus is None:           # the default stimulus, int64 electrons per pixel clock
        from tespike.cosim.headroom import require_room
        L = config.clocks_per_readout
        clocks = readouts * L
        if args.resets == "sweep":          # at most 2L + 3 segments cut up to 2L + 2 clocks in, held up
            clocks += (2 * L + 3) * (2 * L + 2) // 2 + 3 * (2 * L + 3) + L   # to 3 (reset_sweep)
        require_room(f"the stimulus of {clocks} clocks of {args.height} x {args.width} pixels",
                     memory=8 * clocks * args.height * args.width)
    settings = Settings(config, args.height, args.width, readouts, seed, args.stimulus, args.lanes,
                        args.resets)
    results = []
    with contextlib.ExitStack() as stack:
        # --work-dir is one run's logs and results, whole (a stop leaves the previous run's untouched)
        folder = None if args.work_dir is None else stack.enter_context(atomic_folder(args.work_dir))
        for simulator in args.simulator:
            result = run_cocotb(settings, simulator, verilog_path=args.verilog, work_dir=folder)
            if folder is not None:              # named where it will be once the folder is in place
                result = dataclasses.replace(result, log=Path(args.work_dir) / Path(result.log).name)
            results.append(result)
        if folder is not None:
            name_final_folder(Path(folder), Path(args.work_dir))
    failed = 0
    for result in results:
        verdict = "pass" if result.passed else "FAIL"
        line = f"tespike cocotb: {result.simulator}: {verdict}: {result.message} (log: {result.log})"
        if result.passed:
            report(args, line)
        else:
            print(line, flush=True)                 # a failure is printed, --quiet or not
        failed += not result.passed
    return 1 if failed else 0


#: The files a cocotb run writes into ``--work-dir`` (per simulator): what the folder may hold
#: when a run replaces it whole.
WORK_FILES = ("*.log", "*-results.xml", "*-commands.txt")


def name_final_folder(staging, final) -> None:
    """The tools' logs in the staging folder name it (``Results file: .../.wd.123.x.part/...``), which is
    gone once the folder is in place: they name the work folder instead."""
    old, new = str(staging.resolve()), str(final.resolve())
    for path in staging.iterdir():
        if path.is_file() and not path.is_symlink() and path.suffix in (".log", ".txt", ".xml"):
            text = path.read_text(errors="surrogateescape")
            if old in text:
                path.write_text(text.replace(old, new), errors="surrogateescape")


def check_work_dir(path) -> None:
    """``--work-dir``: new, empty, or an earlier run's (replaced whole when the run ends); never a
    folder holding anything else, which replacing it would delete."""
    from tespike.golden.errors import InputError
    from tespike.golden.paths import check_output_dir, foreign_names
    check_output_dir(path, "--work-dir")
    foreign = foreign_names(path, WORK_FILES)
    if foreign:
        raise InputError(f"--work-dir {str(path)!r} holds {foreign[0]!r}, which no cocotb run writes: choose a "
                         "new or empty folder (a run replaces its work folder whole)")
