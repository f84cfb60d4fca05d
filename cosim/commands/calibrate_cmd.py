"""``tespike calibrate``: dark and flat streams of one sensor -> per-pixel dark rate and gain C.npz.

Record the dark stream with no light (``tespike simulate`` on a scene of zeros)
and the flat stream under uniform light of a known level, below the TE overflow
level (0.067 for the paper's TE camera; docs/reconstruction.md "Calibration"),
both with the sensor's ``--noise`` and ``--sensor-seed``; ``--flat-light`` states
that level. The file format is :mod:`tespike.recon.calibration`'s.
"""

from tespike.golden.config import DESIGN_ELECTRONS

HELP = "estimate a sensor's per-pixel dark rate and gain C.npz from a dark and a flat stream"


def add_arguments(parser):
    parser.add_argument("--dark", required=True, help="D.npz: a stream recorded in the dark")
    parser.add_argument("--flat", required=True, help="F.npz: a stream of the same sensor under uniform light")
    parser.add_argument("--flat-light", required=True, type=float,
                        help=f"the flat's light, scene units (1 = design light, {DESIGN_ELECTRONS} e- per readout)")
    parser.add_argument("--out", required=True, help="C.npz to write: dark and gain maps, config, readouts")


def run(args) -> int:
    from tespike.cosim.console import report
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_stream
    from tespike.golden.paths import check_outputs
    from .common import NPZ_FILE
    from tespike.recon.calibration import calibration_summary, estimate, save_calibration

    check_outputs({"--out": args.out}, {"--dark": args.dark, "--flat": args.flat}, {"--out": NPZ_FILE})
    dark, config = load_stream(args.dark, memory_map=True)
    flat, flat_config = load_stream(args.flat, memory_map=True)
    difference = config.differences_text(flat_config, args.dark, args.flat)
    if difference is not None:
        raise InputError(f"--dark and --flat were recorded with different configurations: {difference}")
    calibration = estimate(dark, flat, config, args.flat_light)
    save_calibration(args.out, calibration)
    report(args, f"wrote {args.out}: {calibration_summary(calibration)}")
    return 0
