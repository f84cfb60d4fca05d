"""``tespike verilog``: Verilog of an H x W TE or ML pixel array (SPEC section 6)."""

from .common import add_config_argument, check_generated_array

HELP = "write the Verilog of an H x W pixel array (top te_pixel_array / ml_pixel_array)"

def add_arguments(parser):
    add_config_argument(parser)
    parser.add_argument("--height", required=True, type=int, help="pixel rows H >= 1 (H x W <= 65536)")
    parser.add_argument("--width", required=True, type=int, help="pixel columns W >= 1 (H x W <= 65536)")
    parser.add_argument("--out", required=True, help="A.v to write")


def run(args) -> int:
    from pathlib import Path

    from cosim.console import report
    from golden.config import load_config
    from golden.io import atomic_output
    from golden.paths import check_outputs

    check_outputs({"--out": args.out}, {"--config": args.config})
    config = load_config(args.config)
    check_generated_array(args.height, args.width)
    from rtl.verilog import array_verilog

    text = array_verilog(config, args.height, args.width)
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(text)
    report(args, f"wrote {args.out}: {'te' if config.is_te else 'ml'}_pixel_array, "
                 f"{args.height} x {args.width} pixels")
    return 0
