"""``tespike simulate``: scene light I.npy -> readout stream S.npz, with photon shot noise."""

HELP = "simulate the sensor on a light scene I.npy (photon shot noise; fast, exact in distribution)"


def add_arguments(parser):
    parser.add_argument("--config", required=True, help="JSON config file, or 'te' / 'ml' for a mode's defaults")
    parser.add_argument("--scene", required=True,
                        help="I.npy: float (K, H, W) light per readout interval, 1.0 = design light")
    parser.add_argument("--out", required=True, help="S.npz to write: readout words and the full config")
    parser.add_argument("--seed", type=int, default=None,
                        help="seed of the random generator (default: fresh entropy)")
    parser.add_argument("--dark-current", choices=("none", "eq12", "eq13"), default="none",
                        help="dark current model of the paper's eq. 12 or 13 (default: none)")
    parser.add_argument("--no-noise", action="store_true",
                        help="no shot noise: deliver the expected electrons deterministically")
    parser.add_argument("--method", choices=("fast", "per-clock"), default="fast",
                        help="'per-clock' draws electrons every pixel clock (slow; for checking)")


def run(args) -> int:
    from cosim.cli import progress_wanted, report
    from golden.config import load_config
    from golden.errors import InputError
    from golden.fastsim import simulate_scene
    from golden.io import load_scene, save_stream
    from golden.paths import check_outputs

    check_outputs({"--out": args.out}, {"--scene": args.scene, "--config": args.config})
    config = load_config(args.config)
    scene = load_scene(args.scene, memory_map=True)     # read one readout at a time
    if args.seed is not None and args.seed < 0:
        raise InputError(f"--seed {args.seed}: must be >= 0")
    words = simulate_scene(config, scene, seed=args.seed, dark_current=args.dark_current,
                           noise=not args.no_noise, method=args.method,
                           progress=progress_wanted(args))
    save_stream(args.out, words, config)
    K, H, W = words.shape
    report(args, f"wrote {args.out}: {K} readouts of {H} x {W} {config.mode.upper()} words")
    return 0
