"""``tespike evaluate``: every sequence x {ML (msb), TE, ML-count} x method -> the paper's Table 1, plots, strips.

The ML column is the paper's ML camera, the msb readout of its eq. 10; the
full-count ML camera is reported as extra rows beneath (``--ml-count-config none``
leaves it out).
"""

HELP = ("simulate sequences with the paper's TE and ML (msb readout) sensors and the full-count ML "
        "camera, reconstruct with every method, write Table 1 (Markdown, CSV), a quality-against-run-time "
        "plot and image strips")


def add_arguments(parser):
    parser.add_argument("--out", required=True, help="folder for table.md, table.csv, results.csv, "
                                                     "quality_vs_time.png and strips/")
    parser.add_argument("--set", default="heldout",
                        help="built-in sequences: heldout (default: the project's evaluation set), "
                             "moderate (its moderately HDR part), panoramas (tuning/examples), default, "
                             "or none (only --scene / --folder)")
    parser.add_argument("--scene", action="append", default=[], metavar="I.npy",
                        help="also evaluate this light sequence (repeatable)")
    parser.add_argument("--folder", action="append", default=[], metavar="DIR",
                        help="also evaluate a folder of .exr/.hdr frames (repeatable)")
    parser.add_argument("--frames", type=int, default=24, help="frames of built-in sequences (default 24)")
    parser.add_argument("--height", type=int, default=96, help="rows of built-in sequences (default 96)")
    parser.add_argument("--width", type=int, default=128, help="columns of built-in sequences (default 128)")
    parser.add_argument("--methods", default=None,
                        help="comma-separated reconstruction methods (default: every method)")
    parser.add_argument("--window", type=int, default=9, help="readouts per window (default 9, paper 6.4)")
    parser.add_argument("--te-config", default="te", help="TE sensor: JSON file or 'te' (paper b1 = b2 = 4)")
    parser.add_argument("--ml-config", default="ml-msb",
                        help="ML sensor of the table's ML column, msb readout: JSON file or 'ml-msb' "
                             "(paper 8 bits, eq. 10)")
    parser.add_argument("--ml-count-config", default="ml",
                        help="full-count ML sensor of the extra rows: JSON file, 'ml' (8 bits) or 'none'")
    parser.add_argument("--seed", type=int, default=0, help="shot-noise seed (default 0)")
    parser.add_argument("--device", default="cpu", help="torch device for reconstruction (default cpu)")
    parser.add_argument("--store", metavar="STORE",
                        help="instead of simulating: score the streams of a dataset store (tespike synth), "
                             "one task per sequence x sensor x method (docs/distributed.md)")
    parser.add_argument("--workers", type=int, default=None,
                        help="with --store: worker processes on this machine (default 1, in this process)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="with --store: a running Dask scheduler")


def run(args) -> int:
    from pathlib import Path

    from cosim.console import progress_wanted
    from golden.config import load_config
    from golden.errors import ConfigError, InputError
    from golden.fastsim import simulate_scene
    from golden.io import load_scene
    from golden.paths import check_output_dir
    from recon.evaluate import OUTPUT_FILES, evaluate, table_markdown, write_outputs
    from recon.scenes import load_hdr_sequence
    from recon.scenes.heldout import sequence_set

    if args.store or args.workers is not None or args.scheduler:
        from cosim.dataset.evaluate import run_store
        return run_store(args)
    methods = None
    if args.methods is not None:
        methods = [m.strip() for m in args.methods.split(",") if m.strip()]
        if not methods:
            raise InputError(f"--methods {args.methods!r} names no method (give e.g. tfp,tfi)")
    check_output_dir(args.out, "--out", OUTPUT_FILES)
    # option, value, sensor key, (mode, ml_readout) it must have
    wanted = [("--ml-config", args.ml_config, "ml-msb", ("ml", "msb")),
              ("--te-config", args.te_config, "te", ("te", "count"))]
    if args.ml_count_config != "none":
        wanted.append(("--ml-count-config", args.ml_count_config, "ml", ("ml", "count")))
    configs = {}
    for option, value, mode, (kind, readout) in wanted:
        config = configs[mode] = load_config(value)
        if (config.mode, config.ml_readout) != (kind, readout):
            raise ConfigError(f"{option} {value!r} has mode {config.mode!r}, ml_readout {config.ml_readout!r}; "
                              f"expected mode {kind!r}" + (f", ml_readout {readout!r}" if kind == "ml" else ""))
    sequences = [] if args.set == "none" else sequence_set(args.set, args.frames, args.height, args.width)
    for path in args.scene:          # memory-mapped: read one slice at a time
        sequences.append((Path(path).stem, load_scene(path, memory_map=True)))
    for folder in args.folder:
        sequences.append((Path(folder).name or str(folder),
                          load_hdr_sequence(folder, progress=progress_wanted(args))))
    if not sequences:
        raise InputError("nothing to evaluate: --set none and no --scene or --folder")
    evaluation = evaluate(sequences, lambda config, light, rng: simulate_scene(config, light, seed=rng),
                          methods=methods, modes=tuple(configs), configs=configs, window=args.window, seed=args.seed,
                          device=args.device, progress=progress_wanted(args))
    paths = write_outputs(evaluation, args.out)
    if args.quiet:
        return 0
    print(table_markdown(evaluation), end="")
    print(f"wrote {paths['table.md']}, {paths['table.csv']}, {paths['results.csv']}, {paths['plot']} "
          f"and {len(evaluation.strips)} strip(s) in {Path(args.out) / 'strips'}")
    return 0
