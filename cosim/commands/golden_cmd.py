"""``tespike golden``: the cycle-exact golden model on an explicit per-clock stimulus."""

HELP = "run the bit-exact golden model on a per-clock electron stimulus E.npy"


def add_arguments(parser):
    parser.add_argument("--config", required=True, help="JSON config file, or 'te' / 'ml' for a mode's defaults")
    parser.add_argument("--stimulus", required=True, help="E.npy: integer (T, H, W) electrons per pixel clock")
    parser.add_argument("--out", required=True, help="S.npz to write: readout words and the full config")


def run(args) -> int:
    from golden.config import load_config
    from golden.io import load_stimulus, save_stream
    from golden.sensor import simulate

    config = load_config(args.config)
    stimulus = load_stimulus(args.stimulus, config)
    save_stream(args.out, simulate(config, stimulus), config)
    return 0
