"""``tespike simulate``: scene light I.npy -> readout stream S.npz, with photon shot noise."""

from tespike.golden.resources import MAX_WORKERS, check_workers_argument

from .common import NPZ_FILE, add_light_arguments, light_front_end

HELP = "simulate the sensor on a light scene I.npy (photon shot noise; fast, exact in distribution)"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True


def add_arguments(parser):
    add_light_arguments(parser, out_help="S.npz to write: readout words and the full config",
                        seed_help="seed of the random generator (default: fresh entropy, so each run differs; give one to repeat a run)",
                        no_noise_help="no shot noise: deliver the expected electrons deterministically")
    from tespike.golden.fastsim.simulator import SIMULATION_METHODS
    parser.add_argument("--method", choices=SIMULATION_METHODS, default="fast",
                        help="'per-clock' draws electrons every pixel clock (slow; for checking)")
    parser.add_argument("--workers", type=int, default=None,
                        help=f"processes simulating the frame's stripes, 1..{MAX_WORKERS} (default: the "
                             "cores available; the stream does not depend on it; the fast method with "
                             "noise only)")


def run(args) -> int:
    from tespike.cosim.console import bar, counted, progress_wanted, report
    from tespike.golden.config import load_config
    from tespike.golden.fastsim import simulate_scene
    from tespike.golden.io import load_scene, save_stream, scene_name, word_dtype
    from tespike.cosim.headroom import require_room
    from tespike.golden.paths import check_outputs

    check_workers_argument(args.workers)                # before the scene is read and scanned
    if args.workers not in (None, 1) and (args.method == "per-clock" or args.no_noise):
        from tespike.golden.errors import InputError
        mode = "--method per-clock" if args.method == "per-clock" else "--no-noise"
        raise InputError(f"--workers {args.workers}: the fast simulator's stripes run in worker processes; "
                         f"{mode} runs in one (it would be ignored)")
    check_outputs({"--out": args.out}, {"--scene": args.scene, "--config": args.config, "--noise": args.noise},
                  {"--out": NPZ_FILE})
    config = load_config(args.config)
    sensor = light_front_end(args)
    # read one readout at a time, its values checked as each is simulated (simulate_scene)
    scene = load_scene(args.scene, memory_map=True, scan_values=False)
    K, H, W = scene.shape
    size = K * H * W * word_dtype(config).itemsize          # the words, in memory and in S.npz
    require_room(f"the stream of {K} readouts of {H} x {W} words", memory=size, disk={args.out: size})
    words = simulate_scene(config, scene, seed=args.seed, dark_current=args.dark_current,
                           noise=not args.no_noise, method=args.method,
                           progress=bar("simulate") if progress_wanted(args) else None, workers=args.workers,
                           sensor=sensor, what=scene_name(args.scene))
    save_stream(args.out, words, config)
    K, H, W = words.shape
    report(args, f"wrote {args.out}: {counted(K, 'readout')} of {H} x {W} {config.mode.upper()} words")
    return 0
