"""``tespike demo``: circuit to image in one command (see :mod:`tespike.cosim.demo`).

Scene -> golden model (TE, ML count, ML msb; full frame) -> the RTL on a crop of
the very same per-clock electrons, waveform and GTKWave view, stream rebuilt
from the VCD and compared bit for bit -> every reconstruction method on every
stream and on the RTL's own -> pictures and report.md. Exit 1 when the RTL and
the golden model differ (after writing everything).
"""

from tespike.cosim.backends import NAMES as BACKEND_NAMES

HELP = ("circuit to image on the built-in HDR scene: golden model, RTL on a crop (VCD, bit-exact "
        "check), reconstruction, pictures and report.md")
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True


def add_arguments(parser):
    parser.add_argument("--out", default="demo", help="output folder (default ./demo)")
    parser.add_argument("--backend", choices=BACKEND_NAMES, default=BACKEND_NAMES[0],
                        help="RTL simulator of the crop (default amaranth: no build step, writes the VCD)")
    parser.add_argument("--frames", type=int, default=32, help="readout intervals (default 32)")
    parser.add_argument("--height", type=int, default=96, help="rows (default 96)")
    parser.add_argument("--width", type=int, default=128, help="columns (default 128)")
    parser.add_argument("--crop", type=int, default=None,
                        help="RTL crop size in pixels, square (default 16, or the frame's shorter side if smaller)")
    parser.add_argument("--rtl-readouts", type=int, default=None,
                        help="readouts the RTL runs (default 16, or --frames if fewer)")
    parser.add_argument("--seed", type=int, default=0, help="scene and shot-noise seed (default 0)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per method, median, 1..100 (default 3)")
    parser.add_argument("--sensors", default="ml-msb,te,ml",
                        help="golden sensors: comma list of ml-msb, te, ml (default all; te is the RTL's)")
    parser.add_argument("--weights", action="append", default=[], metavar="W.pt",
                        help="a learned method's weights file ('tespike train --out W.pt') used instead of the "
                             "shipped ones for the sensor it was trained for (repeatable)")
    parser.add_argument("--no-hw-cost", action="store_true", help="skip the Yosys hardware cost table")
    parser.add_argument("--quiet", "-q", action="store_true",
                        help="nothing on stdout on success (no table, no verdict line) and no progress on "
                             "stderr; an RTL stream that differs is still said on stderr (exit 1)")


def run(args) -> int:
    from tespike.cosim.console import progress_wanted
    from tespike.cosim.demo import run_demo

    from .common import check_inputs_outside, comma_items
    check_inputs_outside(args, "out", ("weights",))   # (the folder is replaced whole: an input kept there would go)
    return run_demo(args.out, frames=args.frames, height=args.height, width=args.width, seed=args.seed,
                    crop=args.crop, rtl_readouts=args.rtl_readouts, backend=args.backend,
                    repeats=args.repeats, sensors=comma_items(args.sensors, "--sensors"),
                    hw_cost=not args.no_hw_cost, quiet=args.quiet,
                    bars=not args.quiet and progress_wanted(args), weights=args.weights)
