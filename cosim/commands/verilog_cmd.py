"""``tespike verilog``: Verilog of an H x W TE or ML pixel array (SPEC section 6)."""

from .common import add_array_arguments, add_config_argument

HELP = ("write the Verilog of an H x W pixel array (top te_pixel_array / ml_pixel_array; "
        "with --lanes N the streaming top te_pixel_array_stream / ml_pixel_array_stream)")

#: Largest array written: 65536 pixels. The charge and frame ports are H * W * E
#: and H * W * Wd bits wide (up to 2^21 bits at E = 32); larger arrays take
#: minutes to convert and give ports beyond what the simulators here read well.
MAX_PIXELS = 1 << 16

#: Largest streaming array written (``--lanes``): 262144 pixels (e.g. 512 x 512), beyond the
#: paper's 400 x 250 sensor. Its Verilog has no port or literal that grows with the words
#: (only ``charge``, H * W * E bits, as SPEC section 6 fixes), and Verilator builds it in
#: time that grows with H + W (docs/outside-simulators.md, "Sensor size").
MAX_STREAM_PIXELS = 1 << 18


def add_arguments(parser):
    add_config_argument(parser)
    add_array_arguments(parser, what=" (H x W <= 65536; 262144 with --lanes)")
    parser.add_argument("--out", required=True, help="A.v to write")


def run(args) -> int:
    from pathlib import Path

    from tespike.cosim.console import report
    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.golden.io import atomic_output
    from tespike.golden.paths import check_outputs
    from tespike.rtl.array import check_array_size

    check_outputs({"--out": args.out}, {"--config": args.config})
    config = load_config(args.config)
    check_array_size(args.height, args.width)     # refuse before the slow import and conversion
    pixels = args.height * args.width
    limit, example = (MAX_PIXELS, "256 x 256") if args.lanes is None else (MAX_STREAM_PIXELS, "512 x 512")
    if pixels > limit:
        raise InputError(f"--height {args.height} x --width {args.width} = {pixels} "
                         f"pixels: at most {limit} (e.g. {example}) are supported"
                         + ("" if args.lanes is None else " with --lanes"))
    if args.lanes is None:
        from tespike.rtl.names import module_names
        from tespike.rtl.verilog import array_verilog
        text, what = array_verilog(config, args.height, args.width), module_names(config)["top"]
    else:
        from tespike.golden.beats import beat_count, check_lanes
        try:
            check_lanes(config, args.height, args.width, args.lanes)
        except InputError:
            raise
        except ValueError as exc:                 # ConfigError: name the flag
            raise InputError(f"--{exc}") from None
        from tespike.rtl.names import stream_module_names
        from tespike.rtl.verilog_stream import stream_array_verilog
        text = stream_array_verilog(config, args.height, args.width, args.lanes)
        what = (f"{stream_module_names(config)['top']}, {args.lanes} lanes, "
                f"{beat_count(pixels, args.lanes)} beats per readout interval")
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(text)
    report(args, f"wrote {args.out}: {what}, {args.height} x {args.width} pixels")
    return 0
