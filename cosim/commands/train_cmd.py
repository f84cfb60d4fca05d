"""``tespike train``: train a learned reconstruction method on the data engine's clips (paper section 6.3)."""

from .common import add_config_argument

HELP = "train a learned reconstruction method for one sensor configuration (resumable, CPU or GPU)"


def add_arguments(parser):
    add_config_argument(parser, required=False, default="te")
    parser.add_argument("--out", required=True, help="weights file to write (.pt); its run folder is OUT.run/")
    parser.add_argument("--method", default="net", help="learned method: net (default) or a baseline")
    parser.add_argument("--size", default="cpu", help="method size: cpu (the shipped default) or paper")
    parser.add_argument("--ablation", type=int, default=None, metavar="CASE",
                        help="train the paper's Table 3 ablation case 1..6 instead of the whole network")
    parser.add_argument("--loss", default="l1", help="l1 (paper eq. 7, default) or mu-l1 (after the mu-law)")
    parser.add_argument("--lr", type=float, default=1e-4, help="initial learning rate (default 1e-4)")
    parser.add_argument("--steps-per-epoch", type=int, default=250, help="steps per epoch (default 250)")
    parser.add_argument("--halve-every", type=int, default=10, help="epochs between learning-rate halvings")
    parser.add_argument("--batch", type=int, default=4, help="batch size (default 4)")
    parser.add_argument("--crop", type=int, default=96, help="random crop side (default 96)")
    parser.add_argument("--steps", type=int, default=None, help="step budget")
    parser.add_argument("--minutes", type=float, default=None, help="wall-time budget in minutes")
    parser.add_argument("--hdr", action="append", default=[], metavar="DIR",
                        help="also train on this folder of .exr/.hdr frames (a quarter of the clips; repeatable)")
    parser.add_argument("--workers", type=int, default=1,
                        help="data-engine processes making clips ahead (default 1; 0: in this process)")
    parser.add_argument("--pool", type=int, default=48, help="clips a step draws from (default 48)")
    parser.add_argument("--refresh", type=int, default=4,
                        help="steps between two new clips entering the pool (default 4)")
    parser.add_argument("--validate-every", type=int, default=1000,
                        help="steps between validations on the held-out set (default 1000; 0: never)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the draws and of the initial weights")
    parser.add_argument("--device", default="cpu", help="torch device (default cpu; cuda where there is one)")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch CPU threads (default 1: two runs share two cores better than one run)")
    parser.add_argument("--init", default=None, metavar="WEIGHTS",
                        help="start from this weights file's tensors of matching name and shape")
    parser.add_argument("--resume", action="store_true", help="continue from OUT.run/checkpoint.pt")


def run(args) -> int:
    import shlex
    import sys
    from pathlib import Path

    from golden.config import PRESETS, load_config
    from cosim.console import progress_wanted, report
    from golden.errors import InputError
    from golden.paths import check_output_dir, check_outputs

    config = load_config(args.config)
    if args.steps is None and args.minutes is None:
        raise InputError("give a budget: --steps N or --minutes M")
    if args.threads is not None and not 1 <= args.threads <= 1024:
        raise InputError(f"--threads {args.threads}: must be in 1..1024")
    for folder in args.hdr:
        if not Path(folder).is_dir():
            raise InputError(f"--hdr {folder!r}: not a folder of .exr/.hdr frames")
    out = Path(args.out)
    preset = args.config in PRESETS
    config_input = {} if preset else {"--config": args.config}
    if args.init is not None and not Path(args.init).is_file():
        raise InputError(f"--init {args.init!r}: no such weights file")
    if args.init is not None and args.resume:
        raise InputError("--init starts a new run; --resume continues one: give one of them")
    check_outputs({"--out": args.out}, {**config_input, **({"--init": args.init} if args.init else {})})
    check_output_dir(out.with_suffix(".run"), "--out's run folder")

    from recon.net.train import TrainOptions, train

    options = TrainOptions(sensor=args.config if preset else config.to_json(),
                           method=args.method, size=args.size, ablation=args.ablation, loss=args.loss, lr=args.lr,
                           halve_every=args.halve_every,
                           steps_per_epoch=args.steps_per_epoch, batch=args.batch, crop=args.crop,
                           steps=args.steps, minutes=args.minutes, seed=args.seed, device=args.device,
                           threads=args.threads, workers=args.workers, pool=args.pool, refresh=args.refresh,
                           validate_every=args.validate_every, recipe={"folders": tuple(args.hdr)},
                           init=args.init)
    command = "tespike train " + " ".join(shlex.quote(a) for a in sys.argv[2:])
    train(options, out, resume=args.resume, progress=progress_wanted(args), command=command)
    report(args, f"wrote {out} (run log, loss curve and checkpoint in {out.with_suffix('.run')})")
    return 0
