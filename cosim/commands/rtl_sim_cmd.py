"""``tespike rtl-sim``: the RTL pixel array simulated on a per-clock stimulus (SPEC section 6)."""

import sys

from tespike.cosim.backends import NAMES as BACKEND_NAMES

from .common import NPZ_FILE, add_config_argument

HELP = "simulate the Amaranth RTL pixel array on a per-clock electron stimulus E.npy"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True

def add_arguments(parser):
    add_config_argument(parser)
    parser.add_argument("--stimulus", required=True, help="E.npy: integer (T, H, W) electrons per pixel clock")
    parser.add_argument("--out", required=True, help="S.npz to write: readout words and the full config")
    parser.add_argument("--vcd", help="also write the waveform W.vcd (amaranth backend; the run takes about 2x as long) "
                                      "and a GTKWave save file beside it")
    parser.add_argument("--gtkw", help="GTKWave save file to write with --vcd (default: the VCD path with .gtkw; "
                                       "none where --vcd is a device or a pipe)")
    parser.add_argument("--backend", choices=BACKEND_NAMES, default=BACKEND_NAMES[0],
                        help="simulator: amaranth (Python, default), or verilator / icarus on the generated Verilog")
    parser.add_argument("--check", action="store_true",
                        help="also run the golden model and exit 1 naming the first word where they differ "
                             "(S.npz still holds the RTL's stream)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (same as --progress off)")


def run(args) -> int:
    from pathlib import Path

    from tespike.cosim.backends import backend, checked_words
    from tespike.cosim.console import counted, progress_wanted, report
    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_stimulus, save_stream, word_dtype
    from tespike.cosim.vcd import VCD_BYTES_PER_PIXEL_CLOCK
    from tespike.cosim.headroom import require_room
    from tespike.golden.paths import check_outputs, written_through

    gtkw = args.gtkw
    if args.vcd is not None:
        if args.backend != "amaranth":
            raise InputError(f"--vcd is only written by the amaranth backend, not {args.backend!r}")
        if gtkw is None and not written_through(args.vcd) and Path(args.vcd).name:
            # (no /dev/null.gtkw beside a VCD sent to a device; a nameless '.' or '/' is refused below)
            gtkw = str(Path(args.vcd).with_suffix(".gtkw"))
    elif gtkw is not None:
        raise InputError("--gtkw needs --vcd (a save file describes a waveform)")
    # every output checked, and kept apart from the inputs, before anything is written
    check_outputs({"--out": args.out, "--vcd": args.vcd, "--gtkw": gtkw},
                  {"--stimulus": args.stimulus, "--config": args.config},
                  {"--out": NPZ_FILE, "--vcd": (".vcd",), "--gtkw": (".gtkw",)})
    config = load_config(args.config)
    stimulus = load_stimulus(args.stimulus, config)
    T, H, W = stimulus.shape
    size = (T // config.clocks_per_readout) * H * W * word_dtype(config).itemsize
    outputs = {args.out: size} | ({args.vcd: VCD_BYTES_PER_PIXEL_CLOCK * T * H * W} if args.vcd else {})
    require_room(f"the RTL run of {T} clocks of {H} x {W} pixels", memory=size, disk=outputs)
    if args.no_progress and args.progress == "on":      # (one of the two would be dropped without a word)
        raise InputError("--no-progress and --progress on: give one of them")
    progress = False if args.no_progress else progress_wanted(args)

    from tespike.golden.atomic import outputs_together
    with outputs_together(args.out, args.vcd, gtkw):    # the stream, waveform and save file: this run's, or none
        if args.backend == "amaranth":
            from tespike.cosim.rtlsim import RTLProtocolError, rtl_words
            try:
                words = rtl_words(config, stimulus, vcd_path=args.vcd, gtkw_path=gtkw,
                                  progress=progress)
            except RTLProtocolError as exc:
                print(f"tespike rtl-sim: internal error: the RTL broke the output protocol: {exc}",
                      file=sys.stderr)
                return 1
        else:
            words = backend(args.backend)(config, stimulus)
        save_stream(args.out, checked_words(words, config, stimulus, args.backend), config)
    K, H, W = words.shape
    report(args, f"wrote {args.out}: {counted(K, 'readout')} of {H} x {W} {config.mode.upper()} words "
                 f"({args.backend} RTL)" + (f", {args.vcd}" if args.vcd else "") + (f" and {gtkw}" if gtkw else ""))
    if args.check:
        return _compare_with_golden(words, config, stimulus, args.backend)
    return 0


def _compare_with_golden(words, config, stimulus, backend) -> int:
    """One line on stderr: RTL == golden, or where the first difference is."""
    from tespike.cosim.compare import first_difference
    from tespike.golden.sensor import simulate
    expected = simulate(config, stimulus)
    difference = first_difference(words, expected)
    if difference is None:
        print(f"tespike rtl-sim: {backend} RTL == golden model for {expected.shape[0]} readouts of "
              f"{expected.shape[1]} x {expected.shape[2]} pixels", file=sys.stderr)
        return 0
    print(f"tespike rtl-sim: {backend} RTL != golden model: {difference.text()}", file=sys.stderr)
    return 1
