"""``tespike stimulus``: scene light I.npy -> per-clock electrons E.npy (SPEC section 6).

The electrons are those ``tespike simulate --method per-clock`` draws with the
same ``--seed``, ``--dark-current`` and ``--no-noise`` (photon shot noise,
Poisson per pixel clock; :func:`golden.fastsim.iter_scene_stimulus`), so

    tespike stimulus --seed N ... --out E.npy
    tespike golden --stimulus E.npy ...        (or tespike rtl-sim)

gives the stream ``tespike simulate --method per-clock --seed N`` gives, bit for
bit, and the law of the default fast ``simulate`` (which draws other random
numbers per readout interval, hence other words for the same seed). E.npy holds
K * L * H * W values, so the command refuses sizes above ``--max-bytes``;
it is written one readout interval at a time into a memory-mapped file.
"""

HELP = "turn a light scene I.npy into the per-clock electron stimulus E.npy of golden / rtl-sim"

#: Largest E.npy written unless --max-bytes says otherwise (1 GiB).
MAX_BYTES = 1 << 30


def add_arguments(parser):
    parser.add_argument("--config", required=True, help="JSON config file, or 'te' / 'ml' / 'ml-msb'")
    parser.add_argument("--scene", required=True,
                        help="I.npy: float (K, H, W) light per readout interval, 1.0 = design light")
    parser.add_argument("--out", required=True, help="E.npy to write: unsigned (K * L, H, W) electrons per clock")
    parser.add_argument("--seed", type=int, default=None,
                        help="seed of the random generator, as in 'simulate' (default: fresh entropy)")
    parser.add_argument("--dark-current", choices=("none", "eq12", "eq13"), default="none",
                        help="dark current model of the paper's eq. 12 or 13 (default: none)")
    parser.add_argument("--no-noise", action="store_true",
                        help="no shot noise: the expected electrons, spread deterministically")
    parser.add_argument("--max-bytes", type=int, default=MAX_BYTES,
                        help=f"refuse a stimulus larger than this (default {MAX_BYTES} = 1 GiB)")
    parser.add_argument("--quiet", action="store_true", help="print nothing on success")


def run(args) -> int:
    import sys

    import numpy as np

    from golden.config import load_config
    from golden.errors import InputError
    from golden.fastsim import iter_scene_stimulus
    from golden.io import atomic_output, load_scene
    from golden.light import stimulus_dtype

    config = load_config(args.config)
    if args.seed is not None and args.seed < 0:
        raise InputError(f"--seed {args.seed}: must be >= 0")
    if args.no_noise and args.dark_current != "none":
        raise InputError(f"--dark-current {args.dark_current} is random; it cannot be combined with --no-noise")
    scene = load_scene(args.scene, memory_map=True)
    K, H, W = scene.shape
    L = config.clocks_per_readout
    dtype = stimulus_dtype(config)
    size = K * L * H * W * dtype.itemsize
    if args.max_bytes < 1:
        raise InputError(f"--max-bytes {args.max_bytes}: must be >= 1")
    if size > args.max_bytes:
        raise InputError(f"stimulus of K * L x H x W = {K} * {L} x {H} x {W} {dtype} values is "
                         f"{size} bytes, above --max-bytes {args.max_bytes}: crop the scene, "
                         "or simulate it with 'tespike simulate'")
    stream = iter_scene_stimulus(config, scene, seed=args.seed, dark_current=args.dark_current,
                                 noise=not args.no_noise)
    if sys.stderr.isatty() and K > 1:
        from tqdm import tqdm
        stream = tqdm(stream, total=K, desc="stimulus", unit="readout", delay=2.0, leave=False)
    with atomic_output(args.out) as tmp:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=dtype, shape=(K * L, H, W))
        try:
            for k, electrons in enumerate(stream):
                out[k * L:(k + 1) * L] = electrons
            out.flush()
        finally:
            del out
    if not args.quiet:
        print(f"wrote {args.out}: {K * L} x {H} x {W} {dtype} electrons per pixel clock "
              f"(K = {K} readouts of L = {L} clocks, seed {args.seed})")
    return 0
