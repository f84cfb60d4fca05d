"""``tespike evaluate``: every sequence x {ML (msb), TE, ML-count} x method -> the paper's Table 1, plots, strips.

The ML column is the paper's ML camera, the msb readout of its eq. 10; the
full-count ML camera is reported as extra rows beneath (``--ml-count-config none``
leaves it out). ``--table`` is the paper's Tables 1 and 2 whole: its rows
(:data:`TABLE_METHODS`), every metric of the project,
parameters, FLOPs and run time with its Table 10 beside, sized to finish on the
built-in held-out set in 15 minutes on 2 cores (:data:`TABLE_DEFAULTS`);
``--noise`` adds its Tables 6 to 9 (the TE camera with dark current),
``--sensor-noise N.json`` a noise sensor of :mod:`tespike.golden.noise` of its own, and
``--calibrate`` a calibrated row (``<sensor>+cal``) per method for each of them.
"""

from tespike.recon.learned import LEARNED  # (torch-free: the learned methods in the paper's order)

#: --table's methods in the paper's row order: the training-free ones, its learned baselines, the network.
TABLE_METHODS = ("tfi", "tfp", *LEARNED)
#: The default run's methods: the training-free ones and the paper's network, so the default
#: evaluation takes minutes on 2 cores (each learned baseline adds about 40 CPU seconds per
#: sequence and sensor at 24 x 96 x 128: --methods or --table name them).
DEFAULT_METHODS = ("tfp", "tfi", "net")
#: Defaults of the built-in sequences' size and of the run-time measurement: (frames, height, width, repeats);
#: --table's are cut to its time budget (docs/evaluation.md).
DEFAULTS = (24, 96, 128, 1)
TABLE_DEFAULTS = (70, 64, 96, 1)      # 70 frames: 10 scored where the learned methods' 61 readouts fit (tested)
#: --table's torch threads: on a shared machine two threads spin against the load (a 64 x 96 frame of
#: the network took 2.6 s with 2 threads against 0.04 s with 1 at load 10 on 2 cores).
TABLE_THREADS = 1
#: --table's FovVideoVDP frames per sequence (it costs about 0.5 s a frame whatever the size).
TABLE_VDP_FRAMES = 4

from tespike.recon.settings import DEFAULT_WINDOW  # noqa: E402  (after the constants the help quotes)

from .common import MAX_THREADS, check_inputs_outside, options_given  # noqa: E402
from .reconstruct_cmd import METHOD_CHOICES  # noqa: E402

#: The options that name input files or folders (none may lie inside --out, replaced whole).
INPUT_OPTIONS = ("scene", "folder", "weights", "sensor_noise", "te_config", "ml_config", "ml_count_config", "store")

HELP = ("simulate sequences with the paper's TE and ML (msb readout) sensors and the full-count ML "
        "camera, reconstruct with every method, write Table 1 (Markdown, CSV), a quality-against-run-time "
        "plot and image strips")
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True


#: What ``--store`` takes besides itself: the store's streams are scored as they are, so every
#: other option (picking or simulating sequences, the run-time repeats, your own weights) is refused away from
#: its default (:func:`check_store_options`).
STORE_OPTIONS = ("store", "workers", "scheduler", "methods", "window", "device", "out", "force")


def check_store_options(args) -> None:
    """Refuse, with ``--store``, any option of this command not in STORE_OPTIONS that is not at its
    default: the defaults are read from this module's own parser, so they are typed once."""
    import argparse

    from tespike.golden.errors import InputError
    parser = argparse.ArgumentParser(add_help=False)
    add_arguments(parser)
    for flag, dest in options_given(parser, args, keep=STORE_OPTIONS)[:1]:
        if dest == "weights":
            raise InputError("--weights does not apply with --store (its tasks use the shipped weights); "
                             "evaluate without --store to use your own")
        raise InputError(f"{flag} does not apply with --store (the store holds the sequences and their "
                         "streams, and scores them as they are)")
    from tespike.golden.paths import lies_inside
    if "://" not in args.store and lies_inside(args.out, args.store):
        raise InputError(f"--out {args.out!r} lies inside --store {args.store!r}: write the results outside "
                         "the store (it holds only sequences)")


def _named_methods(args) -> list[str]:
    """``--methods`` as a list (refused when it names none)."""
    from tespike.golden.errors import InputError
    from .common import comma_items
    methods = comma_items(args.methods, "--methods")
    if not methods:
        raise InputError(f"--methods {args.methods!r} names no method (give e.g. tfp,tfi)")
    return methods


def _run_store(args) -> int:
    """``--store``: score a dataset store's streams on a Dask cluster
    (:func:`tespike.recon.dataset.evaluate.evaluate_store`); every option it does not take refused first."""
    from tespike.cosim.console import bar, progress_wanted, report
    from tespike.cosim.dataset.cluster import Runner, check_cluster_options
    from tespike.golden.errors import InputError
    from tespike.golden.paths import check_results_dir
    from tespike.recon.dataset.evaluate import evaluate_store
    from tespike.recon.dataset.store import DatasetStore
    from tespike.recon.report import OUTPUT_FILES

    from .results import publish_results

    if not args.store:
        raise InputError("--workers and --scheduler need --store (the serial evaluation simulates "
                         "in this process)")
    check_store_options(args)
    check_cluster_options(args.workers, args.scheduler)
    check_results_dir(args.out, OUTPUT_FILES, args.force)
    check_inputs_outside(args, "out", INPUT_OPTIONS)
    methods = None if args.methods is None else _named_methods(args)
    DatasetStore.open(args.store)                       # a missing or foreign store refused before any line
    with Runner(args.workers, args.scheduler) as runner:
        evaluation = evaluate_store(args.store, runner, methods=methods, device=args.device, window=args.window,
                                    starting=lambda: report(args, f"evaluate: {args.store} on {runner.where}"),
                                    progress=(lambda total: bar("evaluate", "task", total))
                                    if progress_wanted(args) else None)
    return publish_results(args, evaluation, plot=False)


def add_arguments(parser):
    parser.add_argument("--out", required=True, help="folder for table.md, table.csv, results.csv, "
                                                     "quality_vs_time.png and strips/ (new or empty; "
                                                     "written whole when the run ends)")
    parser.add_argument("--force", action="store_true",
                        help="replace the results of a previous run in --out (never a folder holding other files)")
    parser.add_argument("--set", default="heldout",
                        help="built-in sequences: heldout (default: the project's evaluation set), "
                             "moderate (its moderately HDR part), panoramas (tuning/examples), default, "
                             "or none (only --scene / --folder)")
    parser.add_argument("--scene", action="append", default=[], metavar="I.npy",
                        help="also evaluate this light sequence (repeatable)")
    parser.add_argument("--folder", action="append", default=[], metavar="DIR",
                        help="also evaluate a folder of .exr/.hdr frames (repeatable)")
    parser.add_argument("--frames", type=int, default=None,
                        help=f"frames of built-in sequences (default {DEFAULTS[0]}; --table {TABLE_DEFAULTS[0]})")
    parser.add_argument("--height", type=int, default=None,
                        help=f"rows of built-in sequences (default {DEFAULTS[1]}; --table {TABLE_DEFAULTS[1]})")
    parser.add_argument("--width", type=int, default=None,
                        help=f"columns of built-in sequences (default {DEFAULTS[2]}; --table {TABLE_DEFAULTS[2]})")
    parser.add_argument("--methods", default=None,
                        help=f"comma-separated reconstruction methods: {', '.join(METHOD_CHOICES)} "
                             f"(default {','.join(DEFAULT_METHODS)}: a few minutes on 2 cores; a learned one "
                             "without weights for a sensor is noted, not run)")
    parser.add_argument("--weights", action="append", default=[], metavar="W.pt",
                        help="a learned method's weights file ('tespike train --out W.pt') used instead of the "
                             "shipped ones for the sensor it was trained for (repeatable; not with --store)")
    parser.add_argument("--table", action="store_true",
                        help=f"the paper's Tables 1 and 2 whole: rows {', '.join(TABLE_METHODS)} (mambaspike1: "
                             "one parsing, ML); every metric; parameters, FLOPs, run time and the paper's "
                             "Table 10 beside")
    parser.add_argument("--noise", action="store_true",
                        help="also the paper's Tables 6 to 9: the TE camera with the dark current of eq. 12 and "
                             "of eq. 13")
    parser.add_argument("--sensor-noise", action="append", default=[], metavar="N.json",
                        help="add a TE noise sensor described by N.json (golden.noise: dark level, DSNU, hot "
                             "pixels, PRNU, comparator offset), named by the file's stem, to the noise table")
    parser.add_argument("--sensor-seed", type=int, default=None,
                        help="sensor seed of every noise sensor (default 0): its per-pixel maps (needs --noise "
                             "or --sensor-noise)")
    parser.add_argument("--calibrate", action="store_true",
                        help="add a calibrated row per method for every noise sensor (its own dark and flat "
                             "streams, recon.calibration)")
    parser.add_argument("--metrics", default=None,
                        help="comma-separated further metrics: psnr_pu21, hdr_vqm, fovvideovdp (psnr_mu and "
                             "ssim_mu, always scored, may be named too; default: none; --table: all)")
    parser.add_argument("--vdp-frames", type=int, default=None,
                        help="compute FovVideoVDP (about 0.5 s a frame) on the middle N scored frames of each "
                             f"sequence (default: every scored frame; --table {TABLE_VDP_FRAMES})")
    parser.add_argument("--threads", type=int, default=None,
                        help=f"torch CPU threads, 1..{MAX_THREADS} (default: torch's choice; --table {TABLE_THREADS})")
    parser.add_argument("--repeats", type=int, default=None,
                        help=f"timed runs per method, the median reported (default {DEFAULTS[3]}; "
                             f"--table {TABLE_DEFAULTS[3]})")
    parser.add_argument("--window", type=int, default=None,
                        help=f"readouts per window, odd (default {DEFAULT_WINDOW}, paper section 6.4); at most 2 K - 1 "
                             "for the shortest sequence of K readouts")
    parser.add_argument("--te-config", default="te", help="TE sensor: JSON file or 'te' (paper b1 = b2 = 4)")
    parser.add_argument("--ml-config", default="ml-msb",
                        help="ML sensor of the table's ML column, msb readout: JSON file or 'ml-msb' "
                             "(paper 8 bits, eq. 10)")
    parser.add_argument("--ml-count-config", default=None,
                        help="full-count ML sensor of the extra rows: JSON file, 'ml' (8 bits) or 'none' "
                             "(default 'ml'; with --table 'none': the paper's tables have no such camera)")
    parser.add_argument("--seed", type=int, default=0, help="shot-noise seed (default 0)")
    parser.add_argument("--device", default="cpu", help="torch device for reconstruction (default cpu)")
    parser.add_argument("--store", metavar="STORE",
                        help="instead of simulating: score the streams of a dataset store (tespike dataset), "
                             "one task per sequence x sensor x method (docs/distributed.md)")
    parser.add_argument("--workers", type=int, default=None,
                        help="with --store: worker processes on this machine (default 1, in this process)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="with --store: a running Dask scheduler")


def run(args) -> int:
    from tespike.cosim.console import progress_wanted
    from tespike.golden.errors import InputError
    from tespike.golden.fastsim import simulate_sequence
    from tespike.golden.paths import check_results_dir

    from .common import check_threads_argument, metrics_argument
    from .results import publish_results
    from tespike.recon.evaluate import evaluate
    from tespike.recon.report import OUTPUT_FILES
    from tespike.recon.settings import check_device, check_window_reach

    check_device(args.device)                           # before any sequence is simulated
    if args.store or args.workers is not None or args.scheduler:
        return _run_store(args)
    from tespike.recon.score import METRIC_KEYS
    defaults = TABLE_DEFAULTS if args.table else DEFAULTS
    frames, height, width, repeats = (default if value is None else value for value, default in
                                      zip((args.frames, args.height, args.width, args.repeats), defaults))
    for flag, value in (("--frames", frames), ("--height", height), ("--width", width), ("--repeats", repeats)):
        if value < 1:
            raise InputError(f"{flag} {value}: must be an integer >= 1")
    from tespike.cosim.demo import MAX_REPEATS
    if repeats > MAX_REPEATS:                           # (each reconstructs every sequence again)
        raise InputError(f"--repeats {repeats}: must be in 1..{MAX_REPEATS}")
    threads = TABLE_THREADS if args.table and args.threads is None else args.threads
    check_threads_argument(threads)
    vdp_frames = TABLE_VDP_FRAMES if args.table and args.vdp_frames is None else args.vdp_frames
    if vdp_frames is not None and vdp_frames < 1:
        raise InputError(f"--vdp-frames {vdp_frames}: must be an integer >= 1")
    methods = list(TABLE_METHODS) if args.table else None       # None: DEFAULT_METHODS, noted if missing
    if args.methods is not None:
        methods = _named_methods(args)
    metrics = list(METRIC_KEYS) if args.table else []
    if args.metrics is not None:
        metrics = metrics_argument(args.metrics)
    # options of a part the run does not have would be dropped without a word
    if args.vdp_frames is not None and "fovvideovdp" not in metrics:
        raise InputError("--vdp-frames sets FovVideoVDP's frames; add fovvideovdp to --metrics, or leave it out")
    if args.set == "none":
        given = [flag for flag, value in (("--frames", args.frames), ("--height", args.height),
                                          ("--width", args.width)) if value is not None]
        if given:
            raise InputError(f"{given[0]} sizes the built-in sequences of --set; with --set none there are none "
                             "(a --scene or --folder keeps its own size)")
    ml_count = args.ml_count_config or ("none" if args.table else "ml")
    check_results_dir(args.out, OUTPUT_FILES, args.force)
    check_inputs_outside(args, "out", INPUT_OPTIONS)
    configs, noise_sensors = _sensors(args, ml_count)
    from tespike.recon.learned import weights_by_sensor
    weights = weights_by_sensor(args.weights, configs)
    unrun = sorted({method for method, _ in weights} - set(methods if methods is not None else DEFAULT_METHODS))
    if unrun:
        raise InputError(f"--weights: {unrun[0]} weights given, but {unrun[0]} is not among the methods "
                         "evaluated (add it to --methods; the file would be ignored)")
    sequences = _sequences(args, frames, height, width)
    window = DEFAULT_WINDOW if args.window is None else args.window
    if args.window is not None:      # as reconstruct: no frame's window can be that wide
        shortest, light = min(sequences, key=lambda sequence: sequence[1].shape[0])
        check_window_reach(window, light.shape[0], f"the {light.shape[0]}-readout sequence {shortest!r}")
    if args.vdp_frames is not None:  # as --window: FovVideoVDP takes at most every scored frame
        from tespike.recon.evaluate import learned_span, scored_frames
        span = learned_span(list(DEFAULT_METHODS) if methods is None else methods)
        scored = {name: scored_frames(light.shape[0], window, span) for name, light in sequences}
        name, count = min(((name, s.stop - s.start) for name, s in scored.items()), key=lambda item: item[1])
        if args.vdp_frames > count:
            raise InputError(f"--vdp-frames {args.vdp_frames}: more than the {count} scored frame(s) of sequence "
                             f"{name!r} (FovVideoVDP runs on the middle ones of them; more changes nothing)")
    if threads is not None:
        import torch
        torch.set_num_threads(threads)

    progress = progress_wanted(args) or ("lines" if args.progress == "auto" and not args.quiet else False)
    evaluation = evaluate(sequences, simulate_sequence, methods=list(DEFAULT_METHODS) if methods is None else methods,
                          sensors=tuple(configs), configs=configs, window=window, seed=args.seed,
                          device=args.device, progress=progress, repeats=repeats, metrics=metrics,
                          vdp_frames=vdp_frames, missing="note" if args.table or methods is None else None,
                          noise_sensors=noise_sensors, weights=weights)
    if args.table:
        from tespike.recon.complexity import measure
        evaluation.complexity = measure(evaluation.methods, configs["te"])
    return publish_results(args, evaluation)


def _sensors(args, ml_count: str):
    """The sensors evaluated -> (configuration per sensor key, noise sensor per key): the TE and ML msb
    cameras (and the ML count camera unless ``ml_count`` is 'none'), each checked for its mode and
    readout; with ``--noise`` / ``--sensor-noise`` the TE camera with each noise sensor, and with
    ``--calibrate`` each again, calibrated."""
    from pathlib import Path

    from tespike.golden.config import load_config
    from tespike.golden.errors import ConfigError, InputError
    from tespike.golden.noise import Sensor, load_noise
    from tespike.recon.evaluate import CALIBRATED, NOISE_SENSORS, default_noise_sensors

    from .common import sensor_seed_argument
    # option, value, sensor key, (mode, ml_readout) it must have
    wanted = [("--ml-config", args.ml_config, "ml-msb", ("ml", "msb")),
              ("--te-config", args.te_config, "te", ("te", "count"))]
    if ml_count != "none":
        wanted.append(("--ml-count-config", ml_count, "ml", ("ml", "count")))
    configs = {}
    for option, value, sensor, (kind, readout) in wanted:
        config = configs[sensor] = load_config(value)
        if (config.mode, config.ml_readout) != (kind, readout):
            raise ConfigError(f"{option} {value!r} has mode {config.mode!r}, ml_readout {config.ml_readout!r}; "
                              f"expected mode {kind!r}" + (f", ml_readout {readout!r}" if kind == "ml" else ""))
    sensor_seed = sensor_seed_argument(args.sensor_seed)
    noise_sensors = {}          # sensor key -> golden.noise.Sensor
    if args.noise:              # the paper's Tables 6 to 9: its TE camera with dark current
        noise_sensors.update(default_noise_sensors(sensor_seed))
    for path in args.sensor_noise:
        key = f"te+{Path(path).stem}"
        if key in noise_sensors or key in configs:
            raise InputError(f"--sensor-noise {path}: the sensor name {key!r} is taken by another sensor of "
                             "this run; rename the file")
        if key in NOISE_SENSORS or key.endswith(CALIBRATED):
            raise InputError(f"--sensor-noise {path}: the sensor name {key!r} is reserved for "
                             + ("--noise's built-in sensors" if key in NOISE_SENSORS else
                                f"the calibrated rows ('{CALIBRATED}' ends their names)") + "; rename the file")
        noise = load_noise(path)
        if noise.is_ideal:                  # (a column labelled '()': the TE camera's again)
            raise InputError(f"--sensor-noise {path}: describes no non-ideality (shot noise alone is the TE "
                             "camera's own column)")
        same = [other for other, sensor in noise_sensors.items() if sensor.noise == noise]
        if same:                            # (two columns of one header)
            raise InputError(f"--sensor-noise {path}: the same sensor noise as {same[0]!r}")
        noise_sensors[key] = Sensor(noise, sensor_seed)
    if args.sensor_seed is not None and not any(sensor.noise.has_maps for sensor in noise_sensors.values()):
        raise InputError(f"--sensor-seed {args.sensor_seed} draws the per-pixel maps of a noise sensor, and " + (
            "none has any (--noise's dark currents and these --sensor-noise files hold no dsnu, hot_pixels, prnu "
            "or comparator_offset)" if noise_sensors else "none is given (--noise or --sensor-noise)")
            + ": it would be ignored")
    if args.calibrate and not noise_sensors:
        raise InputError("--calibrate needs a noise sensor: --noise or --sensor-noise N.json")
    configs.update({sensor: configs["te"] for sensor in noise_sensors})
    if args.calibrate:
        configs.update({sensor + CALIBRATED: configs["te"] for sensor in noise_sensors})
    return configs, noise_sensors


def _sequences(args, frames: int, height: int, width: int) -> list:
    """(label, light) of every sequence evaluated: ``--set``'s, each ``--scene`` (memory-mapped) and
    ``--folder``; two sequences with one label are refused (they would share the tables' rows), and
    so is one file or folder given twice."""
    import os
    from pathlib import Path

    from tespike.cosim.console import progress_wanted
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_scene
    from tespike.recon.scenes import load_hdr_sequence
    from tespike.recon.scenes.heldout import sequence_set
    sequences = [] if args.set == "none" else sequence_set(args.set, frames, height, width)
    given = {name: "a sequence of --set" for name, _ in sequences}

    def label(name: str, source: str) -> str:
        """A sequence's label (its file's stem, its folder's name): one per sequence (the table's rows)."""
        if name in given:
            raise InputError(f"{source} and {given[name]} would both be labelled {name!r} in the tables: "
                             "rename one")
        given[name] = source
        return name
    files: dict[tuple[int, int], str] = {}

    def once(path, source: str) -> None:
        """Refuse a file or folder given twice under two names (a link, ``./``): scored twice, it
        would count twice in the tables' means."""
        try:
            stat = os.stat(path)
        except OSError:
            return                      # (the loader names what is wrong with it)
        key = (stat.st_dev, stat.st_ino)
        if key in files:
            raise InputError(f"{source} is the same {'folder' if Path(path).is_dir() else 'file'} as {files[key]}: "
                             "it would be scored twice; give it once")
        files[key] = source
    for path in args.scene:          # memory-mapped: read one slice at a time
        once(path, f"--scene {str(path)!r}")
        sequences.append((label(Path(path).stem, f"--scene {str(path)!r}"), load_scene(path, memory_map=True)))
    for folder in args.folder:
        once(folder, f"--folder {str(folder)!r}")
        sequences.append((label(Path(folder).name or str(folder), f"--folder {str(folder)!r}"),
                          load_hdr_sequence(folder, progress=progress_wanted(args))))
    if not sequences:
        raise InputError("nothing to evaluate: --set none and no --scene or --folder")
    return sequences
