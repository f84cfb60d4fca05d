"""``tespike dataset``: HDR frame folders and built-in scenes -> a dataset store of light and streams."""

import os

from .common import CONFIG_HELP, config_name

HELP = ("simulate every sequence of a folder of HDR frame folders (and/or built-in scenes) with "
        "every sensor configuration into a Zarr dataset store, locally or on a Dask cluster")
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True


#: Rows and columns of the built-in scenes (--scene) unless --height / --width say otherwise.
SCENE_SIZE = (96, 128)


def add_arguments(parser):
    parser.add_argument("--hdr", metavar="DIR", action="append", default=[],
                        help="folder with one sub-folder of .exr/.hdr frames per sequence "
                             "(grayscale, normalised per sequence to peak 1; repeatable)")
    parser.add_argument("--scene", metavar="NAME", action="append", default=[],
                        help="also a built-in scene (see tespike scene --list; repeatable)")
    parser.add_argument("--frames", type=int, default=None,
                        help="built-in scenes: readouts (default 24); HDR folders: at most this many "
                             "frames (default all)")
    parser.add_argument("--height", type=int, default=None, help=f"rows of built-in scenes (default {SCENE_SIZE[0]})")
    parser.add_argument("--width", type=int, default=None, help=f"columns of built-in scenes (default {SCENE_SIZE[1]})")
    parser.add_argument("--grayscale", default=None, help="luminance weights of HDR frames: rec709 "
                                                          "(default) or rec601")
    parser.add_argument("--config", metavar="C", action="append", default=[],
                        help=f"sensor: {CONFIG_HELP} (repeatable; streams are named after the preset or "
                             "the file's stem)")
    parser.add_argument("--out", required=True, metavar="STORE",
                        help="dataset store (Zarr folder) to make, or to resume if it exists")
    parser.add_argument("--seed", type=int, default=0, help="root seed of the shot noise (default 0)")
    parser.add_argument("--chunk-frames", type=int, default=16,
                        help="readouts per chunk and per task along time (default 16)")
    parser.add_argument("--workers", type=int, default=None,
                        help="worker processes on this machine (default 1: in this process, no server)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="address of a running Dask scheduler (e.g. tcp://10.0.0.1:8786)")


def sensor_configs(specs):
    """``--config`` values -> {stream name: SensorConfig}, names unique, configurations distinct."""
    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.recon.dataset.store import check_name

    configs = {}
    for spec in specs:
        name = config_name(spec, configs)
        check_name(name, f"sensor configuration {spec!r}:")
        config = load_config(spec)
        same = [other for other, c in configs.items() if c == config]
        if same:
            raise InputError(f"--config {spec!r} is the same sensor as {same[0]!r}")
        configs[name] = config
    return configs


def run(args) -> int:
    import time

    from tespike.cosim.console import bar, progress_wanted, report
    from tespike.cosim.dataset.cluster import Runner, check_cluster_options
    from tespike.cosim.dataset.build import (build_dataset, discard_unfinished_store, hdr_sources,
                                             note_resumable, scene_sources, writing_local_store)
    from tespike.golden.errors import InputError

    check_cluster_options(args.workers, args.scheduler)
    if not args.config:
        raise InputError(f"--config is required ({CONFIG_HELP}; repeatable)")
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames {args.frames} must be >= 1")
    if args.chunk_frames < 1:
        raise InputError(f"--chunk-frames {args.chunk_frames} must be an integer >= 1")
    from tespike.golden.resources import require_memory
    from tespike.recon.dataset.store import TILE
    # a task holds one chunk of light (float32) and its words: Zarr allocates it whole, whatever
    # the sequence's length (a typo of a few digits failed after the start line, naming no option)
    require_memory(args.chunk_frames * TILE[0] * TILE[1] * 8,
                   f"--chunk-frames {args.chunk_frames} (chunks of {args.chunk_frames} x {TILE[0]} x {TILE[1]})")
    if args.seed < 0:
        raise InputError(f"--seed {args.seed!r} must be an integer >= 0")
    if "://" not in args.out:          # a local store: its folder can be checked before any work
        from tespike.golden.paths import check_output_dir, lies_inside
        check_output_dir(args.out, "--out")
        for folder in args.hdr:        # the next run would read the store as one of its sequences
            if lies_inside(args.out, folder):
                raise InputError(f"--out {args.out!r} lies inside --hdr {folder!r}, whose sub-folders are read "
                                 "as sequences: a resume would read the store as one; put it elsewhere")
    # options of one kind of source, given without it, would be dropped: refused
    if args.grayscale is not None and not args.hdr:
        raise InputError("--grayscale weighs the colours of --hdr frames; built-in scenes are grey already "
                         "(give --hdr DIR, or leave --grayscale out)")
    for flag, value in (("--height", args.height), ("--width", args.width)):
        if value is not None and not args.scene:
            raise InputError(f"{flag} sizes the built-in scenes of --scene; --hdr frames keep their own size "
                             f"(give --scene NAME, or leave {flag} out)")
    configs = sensor_configs(args.config)
    sources = []
    for folder in args.hdr:
        grey = {} if args.grayscale is None else {"weights": args.grayscale}   # (hdr_sources' default)
        sources += hdr_sources(folder, max_frames=args.frames, **grey)
    height, width = (SCENE_SIZE[0] if args.height is None else args.height,
                     SCENE_SIZE[1] if args.width is None else args.width)
    sources += scene_sources(args.scene, args.frames or 24, height, width)
    if not sources:
        raise InputError("nothing to build: give --hdr DIR and/or --scene NAME")
    start = time.perf_counter()
    made_or_resumed = []                                  # (set once the store is there: build_dataset's start)
    with writing_local_store(args.out) as made:           # (a second run writing it: refused here)
        try:
            with Runner(args.workers, args.scheduler) as runner:
                counts = build_dataset(args.out, sources, configs, args.seed, runner,
                                       chunk_frames=args.chunk_frames,
                                       report=lambda name: report(args, f"dataset: {name} complete"),
                                       notice=lambda text: report(args, f"dataset: {text}"),
                                       starting=lambda: (made_or_resumed.append(True),
                                                         report(args, f"dataset: {len(sources)} sequence(s) x "
                                                                      f"{len(configs)} sensor(s) on {runner.where}")),
                                       progress=(lambda total: bar("dataset", "sequence", total))
                                       if progress_wanted(args) else None)
        except BaseException as exc:
            if isinstance(exc, Exception) and made_or_resumed and "://" not in args.out and not os.path.isdir(args.out):
                raise InputError(f"dataset store {args.out!r} was removed during the run: nothing is kept to "
                                 "resume") from None      # (it said what a resume keeps, or gave Zarr's words)
            kept = discard_unfinished_store(args.out, made)   # the workers have stopped: nothing writes there now
            note_resumable(exc, args.out, kept)           # (also for a failure after the build)
            raise
    seconds = time.perf_counter() - start
    rebuilt = f", {len(counts['rebuilt'])} rebuilt where damaged" if counts["rebuilt"] else ""
    report(args, f"wrote {counts['done']} sequence(s) to {args.out} ({counts['skipped']} already complete{rebuilt}), "
                 f"{counts['pixel_readouts']} pixel-readouts in {seconds:.1f} s")
    return 0
