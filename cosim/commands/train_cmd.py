"""``tespike train``: train a learned reconstruction method on the data engine's clips (paper section 6.3).

The trainer's options (:class:`tespike.recon.train.TrainOptions`) keep their defaults in one
place, the trainer: an option not given is not passed on, and ``--help`` reads the
defaults from there when it is printed (importing torch then only).
"""

import argparse

from .common import MAX_THREADS, TORCH_FILE, add_config_argument, check_threads_argument

HELP = "train a learned reconstruction method for one sensor configuration (resumable, CPU or GPU)"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True

#: Flags whose default is the trainer's (their dest is the TrainOptions field).
TRAINER_FLAGS = ("method", "size", "loss", "lr", "steps_per_epoch", "halve_every", "batch", "crop",
                 "workers", "pool", "refresh", "validate_every", "seed", "device", "warmup", "floor")


class _TrainerDefaults(argparse.HelpFormatter):
    """Fills ``%(default)s`` of the trainer's flags with :class:`TrainOptions`'s defaults."""

    def _expand_help(self, action):
        if action.dest in TRAINER_FLAGS:
            import dataclasses

            from tespike.recon.train import TrainOptions
            default = {f.name: f.default for f in dataclasses.fields(TrainOptions)}[action.dest]
            return self._get_help_string(action) % dict(vars(action), default=default, prog=self._prog)
        return super()._expand_help(action)


def add_arguments(parser):
    from tespike.recon.calibration import CALIBRATION_READOUTS          # (numpy and golden only: no torch)
    from tespike.recon.engine.clips import NOISE_DRAW, EngineRecipe
    low_peak, high_peak = EngineRecipe.__dataclass_fields__["peak"].default
    parser.formatter_class = _TrainerDefaults
    add_config_argument(parser, required=False, default="te")
    parser.add_argument("--out", required=True, help="weights file to write (.pt); its run folder is OUT with the suffix .run (w.pt: w.run/)")

    def trainer(flag, help, **kw):
        parser.add_argument(flag, default=argparse.SUPPRESS, help=help + " (default %(default)s)", **kw)

    trainer("--method", "learned method: net or a baseline")
    trainer("--size", "method size: cpu (the shipped default) or paper")
    parser.add_argument("--ablation", type=int, default=None, metavar="CASE",
                        help="train the paper's Table 3 ablation case 1..6 instead of the whole network")
    trainer("--loss", "l1 (paper eq. 7) or mu-l1 (after the mu-law)")
    trainer("--lr", "initial learning rate", type=float)
    trainer("--warmup", "steps over which the learning rate ramps up linearly (a warm start's --init "
                        "weights meet a fresh Adam state)", type=int)
    trainer("--floor", "the output's floor of zero light in training: clamp (no gradient below it) or "
                       "straight-through (clamped, the gradient passed as if not; inference is the same)",
            choices=("clamp", "straight-through"))
    trainer("--steps-per-epoch", "steps per epoch", type=int)
    trainer("--halve-every", "epochs between learning-rate halvings", type=int)
    trainer("--batch", "batch size", type=int)
    trainer("--crop", "random crop side", type=int)
    parser.add_argument("--steps", type=int, default=None, help="step budget")
    parser.add_argument("--minutes", type=float, default=None, help="wall-time budget in minutes")
    parser.add_argument("--hdr", action="append", default=[], metavar="DIR",
                        help="also train on this folder of .exr/.hdr frames (a quarter of the clips; repeatable)")
    parser.add_argument("--panoramas", action="append", default=[], metavar="DIR",
                        help="also move cameras over every equirectangular .exr/.hdr panorama of this folder "
                             "(beside the four shipped training panoramas; a file named courtyard, the held-out "
                             "panorama, is left out; repeatable)")
    parser.add_argument("--peak", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                        help="the clips' brightest light, drawn log-uniformly in [LOW, HIGH] x the design "
                             f"light (default: the engine's {low_peak:g} {high_peak:g})")
    parser.add_argument("--noise-fraction", type=float, default=None, metavar="P",
                        help="share of clips recorded by a random noisy sensor (dark current eq. 12/13 at "
                             f"{NOISE_DRAW['dark_level'][0]:g}..{NOISE_DRAW['dark_level'][1]:g} x, "
                             "DSNU, hot pixels, PRNU, comparator offset; recon.engine.clips.NOISE_DRAW), its "
                             "decoded light corrected by the sensor's exact calibration as inference corrects a "
                             "learned method's input, target the scene light (default 0: shot noise only)")
    parser.add_argument("--noisy-input", choices=("mean", "law"), default=None,
                        help="what a noisy clip's method sees: its light less the sensor's mean dark rate, over "
                             "its gain (mean, the default: every shipped file's training), or also less the dark "
                             "law's upper tail, as inference reads a stream whose calibration has a dark law "
                             f"(law: a {CALIBRATION_READOUTS}-readout dark stream per noisy clip, and the input made in "
                             "the trainer; "
                             "about 25 s a 128 x 128 clip on one CPU core, fast on a GPU)")
    trainer("--workers", "data-engine processes making clips ahead (0: in this process)", type=int)
    trainer("--pool", "clips a step draws from", type=int)
    trainer("--refresh", "steps between two new clips entering the pool", type=int)
    trainer("--validate-every", "steps between validations on the held-out set (0: never)", type=int)
    trainer("--seed", "seed of the draws and of the initial weights", type=int)
    trainer("--device", "torch device: cpu, or cuda on a machine that has one")
    parser.add_argument("--threads", type=int, default=1,
                        help=f"torch CPU threads, 1..{MAX_THREADS} (default 1: two runs share two cores better "
                             "than one run; "
                             "the trainer alone leaves torch's own setting)")
    parser.add_argument("--init", default=None, metavar="WEIGHTS",
                        help="start from this weights file's tensors of matching name and shape")
    parser.add_argument("--resume", action="store_true", help="continue the run of the run folder (w.run/checkpoint.pt)")
    parser.add_argument("--force", action="store_true",
                        help="start a new run where the run folder holds an earlier one (its files are removed first)")


def _frame_files(folder: str) -> list:
    """Every HDR file under a ``--hdr`` or ``--panoramas`` folder (at any depth)."""
    from pathlib import Path

    from tespike.recon.scenes.hdr_io import FRAME_SUFFIXES
    return [p for p in Path(folder).rglob("*") if p.suffix.lower() in FRAME_SUFFIXES and p.is_file()]


def run(args) -> int:
    import contextlib
    from pathlib import Path

    from tespike.golden.atomic import folder_held
    from tespike.golden.config import PRESETS, load_config
    from tespike.golden.errors import InputError
    from tespike.golden.paths import check_distinct, check_output_dir, check_outputs

    config = load_config(args.config)
    if args.steps is None and args.minutes is None:
        raise InputError("give a budget: --steps N or --minutes M")
    check_threads_argument(args.threads)
    if args.peak is not None:
        from tespike.recon.engine.clips import check_peak_range
        check_peak_range(args.peak, "--peak {:g} {:g}".format(*args.peak))
    if args.noise_fraction is not None and not 0 <= args.noise_fraction <= 1:
        raise InputError(f"--noise-fraction {args.noise_fraction}: must lie in [0, 1]")
    if args.noisy_input is not None and not args.noise_fraction:
        raise InputError(f"--noisy-input {args.noisy_input} says what a noisy clip's method sees: give "
                         "--noise-fraction P > 0 too (without it no clip is noisy)")
    from tespike.recon.scenes.hdr_io import list_frames
    for folder in args.hdr:   # (before --force removes an earlier run: its clips come after the start)
        try:
            list_frames(folder)
        except InputError as exc:
            raise InputError(f"--hdr {folder!r}: {exc}") from None
    panoramas = shipped = ()
    if args.panoramas:
        from tespike.recon.engine.clips import TRAIN_PANORAMAS as shipped, panorama_files
        panoramas = shipped + tuple(f for folder in args.panoramas for f in panorama_files(folder))
    out = Path(args.out)
    preset = args.config in PRESETS
    config_input = {} if preset else {"--config": args.config}
    if args.init is not None:
        from tespike.golden.paths import check_input_file
        check_input_file(args.init, "--init weights")       # (a folder was "no such weights file")
    if args.init is not None and args.resume:
        raise InputError("--init starts a new run; --resume continues one: give one of them")
    if args.force and args.resume:
        raise InputError("--force starts a new run over an earlier one; --resume continues it: give one of them")

    from tespike.recon.train import RUN_FILES, TrainOptions

    # --out and the run folder's files are never one of the files the run reads (or its folders hold)
    # (every file of the folders, the held-out panorama too; the shipped panoramas beside them)
    inputs = [*config_input.items(), *([("--init", args.init)] if args.init else []),
              *(("a frame of --hdr", frame) for folder in args.hdr for frame in _frame_files(folder)),
              *(("a panorama of --panoramas", panorama) for folder in args.panoramas
                for panorama in _frame_files(folder)),
              *(("a shipped panorama", panorama) for panorama in shipped)]
    check_outputs({"--out": args.out}, inputs, {"--out": TORCH_FILE})
    from tespike.golden.paths import written_through
    if written_through(args.out):      # (it trained to the end, then could not write)
        raise InputError(f"--out {args.out!r} is a device or FIFO: a run writes a weights file and its run "
                         "folder beside it (OUT.run); give a file name")
    # every option checked (TrainOptions) before the run folder is: a bad one is the first thing said
    given = {flag: getattr(args, flag) for flag in TRAINER_FLAGS if hasattr(args, flag)}
    options = TrainOptions(config=args.config if preset else config.to_json(), ablation=args.ablation,
                           steps=args.steps, minutes=args.minutes, threads=args.threads,
                           recipe={"folders": tuple(args.hdr), **({"peak": tuple(args.peak)} if args.peak else {}),
                                   **({"panoramas": panoramas} if panoramas else {}),
                                   **({"noise_fraction": args.noise_fraction} if args.noise_fraction else {}),
                                   **({"noisy_input": args.noisy_input} if args.noisy_input else {})},
                           init=args.init, **given)
    run_folder = out.with_suffix(".run")
    check_output_dir(run_folder, "--out's run folder")
    check_distinct(inputs, {f"the run folder's {name}": run_folder / name for name in RUN_FILES})
    with contextlib.ExitStack() as held:      # (another run writing it: refused before its files are read)
        if run_folder.is_dir():
            held.enter_context(folder_held(run_folder, f"run folder {str(run_folder)!r}"))
        return _checked_and_trained(args, options, out, run_folder, inputs)


def _checked_and_trained(args, options, out, run_folder, inputs) -> int:
    """The run folder's earlier run checked against --resume and --force (the folder held, where it
    exists), then the run."""
    import shlex
    import sys
    from pathlib import Path

    from tespike.cosim.console import progress_wanted, report
    from tespike.golden.errors import InputError
    from tespike.recon.train import CHECKPOINT, RUN_FILES, train
    earlier = [name for name in RUN_FILES if (run_folder / name).exists()]
    if earlier and not args.resume and not args.force and not any(
            name in earlier for name in (CHECKPOINT, "best.pt")):
        # a run killed before its first checkpoint: nothing to resume or keep but its first log rows
        print(f"tespike train: {str(run_folder)!r} holds only the logs of a run that saved no checkpoint "
              f"({', '.join(earlier)}): starting anew over them", file=sys.stderr)
        earlier = []
    if earlier and not args.resume and not args.force:   # a new run would mix with, or remove, the earlier
        raise InputError(f"--out's run folder {str(run_folder)!r} holds an earlier run ({', '.join(earlier)}): "
                         "continue it with --resume, start anew with --force (its files are removed), "
                         "or give another --out")

    command = "tespike " + " ".join(shlex.quote(a) for a in args.argv)   # (main's argv: in-process too)
    try:
        train(options, out, resume=args.resume, progress=progress_wanted(args), command=command)
    except InputError as exc:     # the recipe holds folders made absolute: name them as the user typed them
        text = str(exc)
        for folder in (*args.hdr, *(args.panoramas or ())):
            text = text.replace(str(Path(folder).resolve()), folder.rstrip("/") or folder)
        if text == str(exc):
            raise
        raise InputError(text) from None
    report(args, f"wrote {out} (run log, loss curve and checkpoint in {out.with_suffix('.run')})")
    return 0
