"""``tespike evaluate --store STORE``: the command-line side of :mod:`tespike.recon.dataset.evaluate`."""

from __future__ import annotations

#: Options of ``tespike evaluate`` that pick or simulate sequences, with their defaults:
#: a store already holds its sequences and streams, so any other value is refused.
SIMULATION_OPTIONS = {"set": "heldout", "scene": [], "folder": [], "frames": None, "height": None,
                      "width": None, "te_config": "te", "ml_config": "ml-msb", "ml_count_config": None,
                      "seed": 0}


def run_store(args) -> int:

    from tespike.cosim.commands.results import publish_results
    from tespike.cosim.console import report
    from tespike.golden.errors import InputError
    from tespike.golden.paths import check_results_dir
    from tespike.recon.dataset.evaluate import evaluate_store
    from tespike.recon.report import OUTPUT_FILES

    from .cluster import Runner, check_cluster_options

    if not args.store:
        raise InputError("--workers and --scheduler need --store (the serial evaluation simulates "
                         "in this process)")
    for key, default in SIMULATION_OPTIONS.items():
        if getattr(args, key) != default:
            raise InputError(f"--{key.replace('_', '-')} cannot be combined with --store "
                             "(the store holds the sequences and their streams)")
    check_cluster_options(args.workers, args.scheduler)
    check_results_dir(args.out, OUTPUT_FILES, args.force)
    methods = None if args.methods is None else [m.strip() for m in args.methods.split(",") if m.strip()]
    from tespike.recon.dataset.store import DatasetStore
    DatasetStore.open(args.store)                       # a missing or foreign store refused before any line
    with Runner(args.workers, args.scheduler) as runner:
        evaluation = evaluate_store(args.store, runner, methods=methods, window=args.window, device=args.device,
                                    starting=lambda: report(args, f"evaluate: {args.store} on {runner.where}"))
    return publish_results(args, evaluation, plot=False)
