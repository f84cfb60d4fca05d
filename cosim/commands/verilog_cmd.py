"""``tespike verilog``: Verilog of an H x W TE or ML pixel array (SPEC section 6)."""

from .common import add_config_argument

HELP = "write the Verilog of an H x W pixel array (top te_pixel_array / ml_pixel_array)"

#: Largest array written: 65536 pixels. The charge and frame ports are H * W * E
#: and H * W * Wd bits wide (up to 2^21 bits at E = 32); larger arrays take
#: minutes to convert and give ports beyond what the simulators here read well.
MAX_PIXELS = 1 << 16


def add_arguments(parser):
    add_config_argument(parser)
    parser.add_argument("--height", required=True, type=int, help="pixel rows H >= 1 (H x W <= 65536)")
    parser.add_argument("--width", required=True, type=int, help="pixel columns W >= 1 (H x W <= 65536)")
    parser.add_argument("--out", required=True, help="A.v to write")


def run(args) -> int:
    from pathlib import Path

    from cosim.cli import report
    from golden.config import load_config
    from golden.errors import InputError
    from golden.io import atomic_output
    from golden.paths import check_outputs
    from rtl.array import check_array_size

    check_outputs({"--out": args.out}, {"--config": args.config})
    config = load_config(args.config)
    check_array_size(args.height, args.width)     # refuse before the slow import and conversion
    if args.height * args.width > MAX_PIXELS:
        raise InputError(f"--height {args.height} x --width {args.width} = {args.height * args.width} "
                         f"pixels: at most {MAX_PIXELS} (e.g. 256 x 256) are supported")
    from rtl.verilog import array_verilog

    text = array_verilog(config, args.height, args.width)
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(text)
    report(args, f"wrote {args.out}: {'te' if config.is_te else 'ml'}_pixel_array, "
                 f"{args.height} x {args.width} pixels")
    return 0
