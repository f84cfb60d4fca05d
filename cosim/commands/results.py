"""The end of ``tespike evaluate``, simulated or over a dataset store: the results folder, whole."""


def publish_results(args, evaluation, *, plot: bool = True) -> int:
    """The end of ``tespike evaluate`` (simulated or over a store): write the results folder
    ``--out`` whole (:func:`tespike.recon.report.write_outputs` inside
    :func:`tespike.golden.atomic.atomic_folder`, after checking it again: the run may have taken an
    hour), then print the table and the files written."""
    from pathlib import Path

    from tespike.golden.atomic import atomic_folder
    from tespike.golden.paths import check_results_dir
    from tespike.recon.report import OUTPUT_FILES, table_markdown, write_outputs

    check_results_dir(args.out, OUTPUT_FILES, args.force)
    with atomic_folder(args.out, replace=args.force) as folder:   # (another run's, finished meanwhile: kept)
        written = write_outputs(evaluation, folder, plot=plot)
        files = [path.relative_to(folder) for key, path in written.items() if not key.startswith("strip:")]
    if args.quiet:
        return 0
    out = Path(args.out)
    print(table_markdown(evaluation), end="")
    print(f"wrote {', '.join(str(out / name) for name in files)} and {len(evaluation.strips)} strip(s) "
          f"in {out / 'strips'}")
    return 0
