"""``tespike reconstruct``: a stream S.npz to reconstructed light R.npy (TFP, TFI, the learned methods)."""

from tespike.golden.config import DESIGN_ELECTRONS
from tespike.recon.learned import LEARNED, LEARNED_SUMMARIES
from tespike.recon.settings import DEFAULT_WINDOW, TFI_SEARCH, TRAINING_FREE

from .common import MAX_THREADS, NPY_FILE

#: The keys of recon.methods.RECON_METHODS (named here without importing torch, so refusals are quick).
METHOD_CHOICES = (*TRAINING_FREE, *LEARNED)

HELP = f"reconstruct light images R.npy from a TE or ML stream S.npz ({', '.join(METHOD_CHOICES)})"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True


def add_arguments(parser):
    parser.add_argument("--stream", required=True, help="S.npz: readout words and the full config")
    parser.add_argument("--method", required=True,
                        help="; ".join(f"{name}: {summary}" for name, summary in
                                       {**TRAINING_FREE, **LEARNED_SUMMARIES}.items())
                        + ". A learned method uses the weights shipped for the stream's preset where there "
                          "are some (recon/weights/), or --weights")
    parser.add_argument("--out", required=True, help=f"R.npy to write: float32 (K, H, W) light, I = 1 is {DESIGN_ELECTRONS} e-")
    parser.add_argument("--window", type=int, default=None,
                        help=f"tfp, and tfi with --search window: readouts per window, odd (default {DEFAULT_WINDOW}, paper section 6.4); learned methods see the "
                             "span of readouts their sizes fix")
    parser.add_argument("--weights", default=None, metavar="W.pt",
                        help="learned methods: this weights file ('tespike train --out W.pt') instead of the "
                             "shipped one; it must hold the method and be trained for the stream's configuration")
    parser.add_argument("--device", default="cpu", help="torch device (default cpu)")
    parser.add_argument("--search", choices=TFI_SEARCH, default=None,
                        help="tfi only: look for the spike interval in the whole stream (default) or the window")
    parser.add_argument("--calibration", metavar="C.npz",
                        help="a calibration of the sensor that recorded the stream ('tespike calibrate'): "
                             "every method corrected for each pixel's dark current and gain; with the dark "
                             "law 'tespike calibrate' writes, TFP estimates each window's light under the "
                             "law, TFI and the learned methods take it out of each readout's light; a "
                             "calibration without a law (format 1) corrects TFP's output by (x - dark) / gain "
                             "(docs/reconstruction.md, 'Calibration')")
    parser.add_argument("--threads", type=int, default=None,
                        help=f"torch CPU threads, 1..{MAX_THREADS} (default: torch's choice)")


def run(args) -> int:
    from tespike.cosim.console import progress_wanted, report
    from tespike.golden.errors import InputError
    from tespike.golden.io import atomic_output, load_stream
    from tespike.golden.paths import check_outputs
    from tespike.recon.settings import DEFAULT_WINDOW, check_known, check_window, check_window_reach, uses_window

    from .common import check_threads_argument
    from tespike.cosim.headroom import require_room, reserved_memmap

    # every check that needs no torch comes first, so a refusal is quick
    check_known(args.method, METHOD_CHOICES)
    if args.method in LEARNED and args.window is not None:
        from tespike.recon.learned import method_span
        raise InputError(f"--window applies to methods 'tfp' and 'tfi'; {args.method!r} sees the "
                         f"{method_span(args.method)} readouts its sizes fix")
    if args.method != "tfi" and args.search is not None:    # (even at tfi's default: it would be dropped)
        raise InputError(f"--search applies to method 'tfi' only, not {args.method!r}")
    search = args.search or "stream"
    if args.method == "tfi" and args.window is not None and not uses_window("tfi", search):
        raise InputError("--window applies to tfi with --search window only (tfi searches the whole stream "
                         "by default, whatever the window)")
    window = DEFAULT_WINDOW if args.window is None else args.window
    check_window(window, "--window")
    check_threads_argument(args.threads)
    if args.weights is not None and args.method not in LEARNED:
        raise InputError(f"--weights applies to the learned methods ({', '.join(LEARNED)}), not {args.method!r}")
    check_outputs({"--out": args.out},
                  {"--stream": args.stream, "--calibration": args.calibration, "--weights": args.weights},
                  {"--out": NPY_FILE})
    words, config = load_stream(args.stream, memory_map=True)     # stays on disk
    K, H, W = words.shape
    if args.window is not None:
        check_window_reach(window, K, f"this {K}-readout stream")
    calibration = None
    if args.calibration is not None:
        from tespike.recon.calibration import check_matches, load_calibration
        calibration = load_calibration(args.calibration)
        check_matches(calibration, config, (H, W), f"stream {args.stream!r}", f"calibration {args.calibration!r}")
    require_room(f"the {K} images of {H} x {W} pixels", disk={args.out: 4 * K * H * W})

    import torch

    from tespike.recon.methods import reconstruct

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    options = {"search": search} if args.method == "tfi" else {}
    import numpy as np
    with atomic_output(args.out, "--out") as tmp:
        # R.npy is filled block by block through a memory map of the output file (its blocks
        # reserved first), so neither the words nor the images need to fit in memory
        images = reserved_memmap(tmp, np.float32, (K, H, W))
        reconstruct(words, config, args.method, window=window, device=args.device,
                    progress=progress_wanted(args), out=images, calibration=calibration, weights=args.weights,
                    **options)
        images.flush()
        del images
    report(args, f"wrote {args.out}: {K} {args.method} images of {H} x {W} pixels")
    return 0
