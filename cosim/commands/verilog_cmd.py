"""``tespike verilog``: Verilog of an H x W TE or ML pixel array (SPEC section 6)."""

from .common import MAX_PIXELS, MAX_STREAM_PIXELS, add_array_arguments, add_config_argument

HELP = ("write the Verilog of an H x W pixel array (top te_pixel_array / ml_pixel_array; "
        "with --lanes N the streaming top te_pixel_array_stream / ml_pixel_array_stream)")

def add_arguments(parser):
    add_config_argument(parser)
    add_array_arguments(parser, what=f" (H x W <= {MAX_PIXELS}; {MAX_STREAM_PIXELS} with --lanes)")
    parser.add_argument("--out", required=True, help="A.v to write")


def run(args) -> int:
    from pathlib import Path

    from tespike.cosim.console import report
    from tespike.golden.config import load_config
    from tespike.golden.io import atomic_output
    from tespike.golden.paths import check_outputs

    from .common import check_array_arguments

    check_outputs({"--out": args.out}, {"--config": args.config}, {"--out": (".v", ".sv")})
    config = load_config(args.config)
    check_array_arguments(config, args.height, args.width, args.lanes)   # before the slow conversion
    pixels = args.height * args.width
    if args.lanes is None:
        from tespike.rtl.names import module_names
        from tespike.rtl.verilog import array_verilog
        text, what = array_verilog(config, args.height, args.width), module_names(config)["top"]
    else:
        from tespike.golden.beats import beat_count
        from tespike.rtl.names import stream_module_names
        from tespike.rtl.verilog_stream import stream_array_verilog
        text = stream_array_verilog(config, args.height, args.width, args.lanes)
        what = (f"{stream_module_names(config)['top']}, {args.lanes} lanes, "
                f"{beat_count(pixels, args.lanes)} beats per readout interval")
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(text)
    report(args, f"wrote {args.out}: {what}, {args.height} x {args.width} pixels")
    return 0
