"""``tespike reconstruct``: a stream S.npz to reconstructed light R.npy (training-free methods)."""

HELP = "reconstruct light images R.npy from a TE or ML stream S.npz (tfp, tfi)"

#: Offered here; the learned model ('net') joins when its weights ship.
METHOD_CHOICES = ("tfp", "tfi")


def add_arguments(parser):
    parser.add_argument("--stream", required=True, help="S.npz: readout words and the full config")
    parser.add_argument("--method", required=True,
                        help="tfp (mean decoded light over the window) or tfi (spike interval)")
    parser.add_argument("--out", required=True, help="R.npy to write: float32 (K, H, W) light, I = 1 is 42000 e-")
    parser.add_argument("--window", type=int, default=9, help="readouts per window, odd (default 9, paper 6.4)")
    parser.add_argument("--device", default="cpu", help="torch device (default cpu)")
    parser.add_argument("--search", choices=("stream", "window"), default="stream",
                        help="tfi only: look for the spike interval in the whole stream (default) or the window")
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")


def run(args) -> int:
    import sys
    from pathlib import Path

    from golden.errors import InputError
    from golden.io import load_stream, save_images

    # every check that needs no torch comes first, so a refusal is quick
    if args.method not in METHOD_CHOICES:
        raise InputError(f"unknown method {args.method!r} (offered: {', '.join(METHOD_CHOICES)})")
    if args.window < 1 or args.window % 2 == 0:
        raise InputError(f"--window {args.window}: window = {args.window} must be an odd integer >= 1")
    if args.threads is not None and args.threads < 1:
        raise InputError(f"--threads {args.threads}: must be >= 1")
    if args.method != "tfi" and args.search != "stream":
        raise InputError(f"--search applies to method 'tfi' only, not {args.method!r}")
    out_dir = Path(args.out).parent
    if not out_dir.is_dir():
        raise InputError(f"cannot write {args.out!r}: directory {str(out_dir)!r} does not exist")
    words, config = load_stream(args.stream)

    import torch

    from recon.methods import reconstruct

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    options = {"search": args.search} if args.method == "tfi" else {}
    images = reconstruct(words, config, args.method, window=args.window, device=args.device,
                         progress=sys.stderr.isatty(), **options)
    save_images(args.out, images)
    return 0
