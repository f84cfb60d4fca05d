"""``tespike stimulus``: scene light I.npy -> per-clock electrons E.npy (SPEC section 6).

The electrons are those ``tespike simulate --method per-clock`` draws with the
same ``--seed``, ``--dark-current``, ``--noise``, ``--sensor-seed`` and ``--no-noise`` (photon shot noise,
Poisson per pixel clock; :func:`tespike.golden.fastsim.iter_scene_stimulus`), so

    tespike stimulus --seed N ... --out E.npy
    tespike golden --stimulus E.npy ...        (or tespike rtl-sim)

gives the stream ``tespike simulate --method per-clock --seed N`` gives, bit for
bit, and the law of the default fast ``simulate`` (which draws other random
numbers per readout interval, hence other words for the same seed).
``--crop`` and ``--readouts`` keep a window of pixels and the first readouts:
the electrons (and the sensor maps) are still drawn for the whole frame, so the window holds exactly
the electrons of those pixels in the full stimulus (what ``tespike demo``
gives the RTL). E.npy holds
K * L * H * W values, so the command refuses sizes above ``--max-bytes``;
it is written one readout interval at a time into a memory-mapped file.
"""

from .common import NPY_FILE, add_light_arguments, decimal, light_front_end

HELP = "turn a light scene I.npy into the per-clock electron stimulus E.npy of golden / rtl-sim"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True

#: Largest E.npy written unless --max-bytes says otherwise (1 GiB).
MAX_BYTES = 1 << 30


def add_arguments(parser):
    add_light_arguments(parser, out_help="E.npy to write: unsigned (K * L, H, W) electrons per clock",
                        seed_help="seed of the random generator, as in 'simulate' (default: fresh entropy)",
                        no_noise_help="no shot noise: the expected electrons, spread deterministically")
    parser.add_argument("--max-bytes", type=int, default=MAX_BYTES,
                        help=f"refuse a stimulus larger than this (default {MAX_BYTES} = 1 GiB)")
    parser.add_argument("--crop", metavar="Y,X,H,W",
                        help="keep only rows Y..Y+H-1 and columns X..X+W-1 (same electrons as the full stimulus)")
    parser.add_argument("--readouts", type=int, help="keep only the first K readout intervals")


def run(args) -> int:
    import itertools

    from tespike.cosim.console import bar, progress_wanted, report
    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.golden.fastsim import iter_scene_stimulus
    from tespike.golden.io import atomic_output, load_scene
    from tespike.golden.light import stimulus_dtype
    from tespike.cosim.headroom import require_room, reserved_memmap

    from tespike.golden.paths import check_outputs
    check_outputs({"--out": args.out}, {"--scene": args.scene, "--config": args.config, "--noise": args.noise},
                  {"--out": NPY_FILE})
    config = load_config(args.config)
    sensor = light_front_end(args)
    scene = load_scene(args.scene, memory_map=True)
    K, H, W = scene.shape
    rows, cols = slice(0, H), slice(0, W)
    if args.crop is not None:
        try:
            y, x, h, w = (decimal(v.strip()) for v in args.crop.split(","))
        except ValueError:
            raise InputError(f"--crop {args.crop!r} must be four integers Y,X,H,W") from None
        if min(h, w) < 1:
            raise InputError(f"--crop {args.crop!r}: the crop's height and width must be >= 1 (got {h} x {w})")
        if min(y, x) < 0 or y + h > H or x + w > W:
            raise InputError(f"--crop {args.crop!r}: rows {y}..{y + h - 1}, columns {x}..{x + w - 1} "
                             f"are not inside the {H} x {W} scene")
        rows, cols, H, W = slice(y, y + h), slice(x, x + w), h, w
    if args.readouts is not None:
        if not 1 <= args.readouts <= K:
            raise InputError(f"--readouts {args.readouts}: must be in 1..K = {K}")
        K = args.readouts
    L = config.clocks_per_readout
    dtype = stimulus_dtype(config)
    size = K * L * H * W * dtype.itemsize
    if args.max_bytes < 1:
        raise InputError(f"--max-bytes {args.max_bytes}: must be >= 1")
    if size > args.max_bytes:
        raise InputError(f"stimulus of K * L x H x W = {K} * {L} x {H} x {W} {dtype} values is "
                         f"{size} bytes, above --max-bytes {args.max_bytes}: crop the scene, "
                         "or simulate it with 'tespike simulate'")
    # the whole scene sets the generator's budget, so the first K readouts are those of the full stimulus
    stream = itertools.islice(iter_scene_stimulus(config, scene, seed=args.seed, dark_current=args.dark_current,
                                                  noise=not args.no_noise, sensor=sensor), K)
    if progress_wanted(args) and K > 1:
        stream = bar("stimulus", total=K)(stream)
    require_room(f"the stimulus of {K * L} x {H} x {W} {dtype} values", disk={args.out: size})
    with atomic_output(args.out) as tmp:
        out = reserved_memmap(tmp, dtype, (K * L, H, W))
        try:
            for k, electrons in enumerate(stream):
                out[k * L:(k + 1) * L] = electrons[:, rows, cols]
            out.flush()
        finally:
            del out
    report(args, f"wrote {args.out}: {K * L} x {H} x {W} {dtype} electrons per pixel clock "
                 f"(K = {K} readouts of L = {L} clocks, "
                 + ("no noise)" if args.no_noise else "fresh seed)" if args.seed is None else f"seed {args.seed})"))
    return 0
