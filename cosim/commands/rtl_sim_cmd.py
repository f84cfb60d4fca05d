"""``tespike rtl-sim``: the RTL pixel array simulated on a per-clock stimulus (SPEC section 6)."""

import sys

from .common import add_config_argument

HELP = "simulate the Amaranth RTL pixel array on a per-clock electron stimulus E.npy"

#: backend -> (module, function(config, stimulus) -> words); imported only when chosen.
BACKENDS = {
    "verilator": ("cosim.verilator", "run_verilator"),
    "icarus": ("cosim.icarus", "run_icarus"),
}


def add_arguments(parser):
    add_config_argument(parser)
    parser.add_argument("--stimulus", required=True, help="E.npy: integer (T, H, W) electrons per pixel clock")
    parser.add_argument("--out", required=True, help="S.npz to write: readout words and the full config")
    parser.add_argument("--vcd", help="also write the waveform W.vcd (amaranth backend; about 5x slower) "
                                      "and a GTKWave save file beside it")
    parser.add_argument("--gtkw", help="GTKWave save file to write with --vcd (default: the VCD path with .gtkw)")
    parser.add_argument("--backend", choices=("amaranth", *BACKENDS), default="amaranth",
                        help="simulator: amaranth (Python, default), or verilator / icarus on the generated Verilog")
    parser.add_argument("--check", action="store_true",
                        help="also run the golden model and exit 1 naming the first word where they differ "
                             "(S.npz still holds the RTL's stream)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (same as --progress off)")


def _backend(name):
    import importlib

    from golden.errors import TespikeError
    module, function = BACKENDS[name]
    try:
        return getattr(importlib.import_module(module), function)
    except ModuleNotFoundError as exc:
        if exc.name != module:
            raise
        raise TespikeError(f"backend {name!r} is not available in this installation "
                           f"(module {module} is missing)") from None


def _check_backend_words(words, config, stimulus, backend):
    """A backend must return integer words (T / L, H, W) that SPEC section 4 allows."""
    import numpy as np

    from golden.decode import check_words
    from golden.errors import TespikeError
    T, H, W = stimulus.shape
    expected = (T // config.clocks_per_readout, H, W)
    words = np.asarray(words)
    if words.shape != expected or words.dtype.kind not in "iu":
        raise TespikeError(f"backend {backend!r} returned {words.dtype} words of shape {words.shape}, "
                           f"not integer words of shape {expected}")
    check_words(words, config)
    return words


def run(args) -> int:
    from pathlib import Path

    from cosim.cli import progress_wanted, report
    from golden.config import load_config
    from golden.errors import InputError
    from golden.io import load_stimulus, save_stream
    from golden.paths import check_outputs

    gtkw = args.gtkw
    if args.vcd is not None:
        if args.backend != "amaranth":
            raise InputError(f"--vcd is only written by the amaranth backend, not {args.backend!r}")
        gtkw = gtkw if gtkw is not None else str(Path(args.vcd).with_suffix(".gtkw"))
    elif gtkw is not None:
        raise InputError("--gtkw needs --vcd (a save file describes a waveform)")
    # every output checked, and kept apart from the inputs, before anything is written
    check_outputs({"--out": args.out, "--vcd": args.vcd, "--gtkw": gtkw},
                  {"--stimulus": args.stimulus, "--config": args.config})
    config = load_config(args.config)
    stimulus = load_stimulus(args.stimulus, config)
    progress = False if args.no_progress else progress_wanted(args)

    if args.backend == "amaranth":
        from cosim.rtlsim import RTLProtocolError, rtl_words
        try:
            words = rtl_words(config, stimulus, vcd_path=args.vcd, gtkw_path=gtkw,
                              progress=progress)
        except RTLProtocolError as exc:
            print(f"tespike rtl-sim: internal error: the RTL broke the output protocol: {exc}",
                  file=sys.stderr)
            return 1
    else:
        words = _backend(args.backend)(config, stimulus)
    save_stream(args.out, _check_backend_words(words, config, stimulus, args.backend), config)
    K, H, W = words.shape
    report(args, f"wrote {args.out}: {K} readouts of {H} x {W} {config.mode.upper()} words "
                 f"({args.backend} RTL)" + (f", {args.vcd} and {gtkw}" if args.vcd else ""))
    if args.check:
        return _compare_with_golden(words, config, stimulus, args.backend)
    return 0


def _compare_with_golden(words, config, stimulus, backend) -> int:
    """One line on stderr: RTL == golden, or where the first difference is."""
    import numpy as np

    from golden.sensor import simulate
    expected = simulate(config, stimulus)
    differ = np.argwhere(np.asarray(words) != expected)
    if len(differ) == 0:
        print(f"tespike rtl-sim: {backend} RTL == golden model for {expected.shape[0]} readouts of "
              f"{expected.shape[1]} x {expected.shape[2]} pixels", file=sys.stderr)
        return 0
    k, r, c = (int(i) for i in differ[0])
    print(f"tespike rtl-sim: {backend} RTL != golden model: {len(differ)} words differ, first at readout {k} "
          f"pixel ({r}, {c}): RTL {int(words[k, r, c])}, golden {int(expected[k, r, c])}", file=sys.stderr)
    return 1
