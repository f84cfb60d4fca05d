"""``tespike reconstruct``: a stream S.npz to reconstructed light R.npy (TFP, TFI, the network)."""

HELP = "reconstruct light images R.npy from a TE or ML stream S.npz (tfp, tfi, net)"

METHOD_CHOICES = ("tfp", "tfi", "net")

#: Most torch CPU threads ``--threads`` accepts.
MAX_THREADS = 256


def add_arguments(parser):
    parser.add_argument("--stream", required=True, help="S.npz: readout words and the full config")
    parser.add_argument("--method", required=True,
                        help="tfp (mean decoded light over the window), tfi (spike interval) or net "
                             "(the paper's network, shipped weights for the te, ml and ml-msb presets)")
    parser.add_argument("--out", required=True, help="R.npy to write: float32 (K, H, W) light, I = 1 is 42000 e-")
    parser.add_argument("--window", type=int, default=None,
                        help="tfp/tfi: readouts per window, odd (default 9, paper 6.4); net sees 61 readouts")
    parser.add_argument("--device", default="cpu", help="torch device (default cpu)")
    parser.add_argument("--search", choices=("stream", "window"), default="stream",
                        help="tfi only: look for the spike interval in the whole stream (default) or the window")
    parser.add_argument("--threads", type=int, default=None,
                        help=f"torch CPU threads, 1..{MAX_THREADS} (default: torch's choice)")


def run(args) -> int:
    from cosim.console import progress_wanted, report
    from golden.errors import InputError
    from golden.io import atomic_output, load_stream
    from golden.paths import check_outputs
    from cosim.room import require_room, reserved_memmap

    # every check that needs no torch comes first, so a refusal is quick
    if args.method not in METHOD_CHOICES:
        raise InputError(f"unknown method {args.method!r} (offered: {', '.join(METHOD_CHOICES)})")
    if args.method == "net" and args.window is not None:
        raise InputError(f"--window applies to methods 'tfp' and 'tfi'; 'net' sees the 61 readouts it was "
                         "trained on")
    window = 9 if args.window is None else args.window
    if window < 1 or window % 2 == 0:
        raise InputError(f"--window {window}: window = {window} must be an odd integer >= 1")
    if args.threads is not None and not 1 <= args.threads <= MAX_THREADS:
        raise InputError(f"--threads {args.threads}: must be in 1..{MAX_THREADS}")
    if args.method != "tfi" and args.search != "stream":
        raise InputError(f"--search applies to method 'tfi' only, not {args.method!r}")
    check_outputs({"--out": args.out}, {"--stream": args.stream})
    words, config = load_stream(args.stream, memory_map=True)     # stays on disk
    K, H, W = words.shape
    require_room(f"the {K} images of {H} x {W} pixels", disk={args.out: 4 * K * H * W})
    if args.method == "net":
        from recon.net.infer import load_weights, weights_path
        load_weights(weights_path(config))      # refuse a configuration without weights before writing

    import torch

    from recon.methods import reconstruct

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    options = {"search": args.search} if args.method == "tfi" else {}
    import numpy as np
    with atomic_output(args.out, "--out") as tmp:
        # R.npy is filled block by block through a memory map of the output file (its blocks
        # reserved first), so neither the words nor the images need to fit in memory
        images = reserved_memmap(tmp, np.float32, (K, H, W))
        reconstruct(words, config, args.method, window=window, device=args.device,
                    progress=progress_wanted(args), out=images, **options)
        images.flush()
        del images
    report(args, f"wrote {args.out}: {K} {args.method} images of {H} x {W} pixels")
    return 0
