"""``tespike verilog``: Verilog of an H x W TE or ML pixel array (SPEC section 6)."""

HELP = "write the Verilog of an H x W pixel array (top te_pixel_array / ml_pixel_array)"


def add_arguments(parser):
    parser.add_argument("--config", required=True, help="JSON config file, or 'te' / 'ml' for a mode's defaults")
    parser.add_argument("--height", required=True, type=int, help="pixel rows H >= 1")
    parser.add_argument("--width", required=True, type=int, help="pixel columns W >= 1")
    parser.add_argument("--out", required=True, help="A.v to write")


def run(args) -> int:
    from pathlib import Path

    from golden.config import load_config
    from golden.io import atomic_output
    from rtl.array import check_array_size

    config = load_config(args.config)
    check_array_size(args.height, args.width)     # refuse before the slow import and conversion
    from rtl.verilog import array_verilog

    text = array_verilog(config, args.height, args.width)
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(text)
    return 0
