"""Output bandwidth of the streaming readout (SPEC section 6) for TE, ML count and ML msb.

At the paper's settings: a 400 x 250 sensor (the spike camera's), the presets
``te``, ``ml`` and ``ml-msb`` (L = 240 pixel clocks per readout interval) and the
paper's readout rate of 40 kHz ("a readout frequency up to 40k Hz", its
introduction), that is a pixel clock of 40 kHz x L = 9.6 MHz. Printed per
camera: word bits, the data that must leave (H W Wd bits per readout interval,
in Gbit/s), the fewest lanes that fit one interval's beats in one interval
(N = ceil(H W / L)), the output pins they take (N Wd) and what those pins carry
at the pixel clock. The parallel top (one H W Wd-bit port) would need H W Wd
pins. ``tespike.golden.beats.output_bandwidth`` computes each line.

``python3 benchmarks/stream_bandwidth.py [--height 400 --width 250 --readout-hz 40000]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.beats import output_bandwidth  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--height", type=int, default=400)
    parser.add_argument("--width", type=int, default=250)
    parser.add_argument("--readout-hz", type=float, default=40e3, help="readout intervals per second")
    args = parser.parse_args(argv)
    print(f"{args.height} x {args.width} pixels, {args.readout_hz / 1e3:g} kHz readout")
    print(f"{'camera':>8} {'L':>4} {'pixel clock':>11} {'Wd':>3} {'Gbit/s':>7} {'min N':>6} "
          f"{'pins':>5} {'pins Gbit/s':>11} {'parallel pins':>13}")
    for name in ("te", "ml", "ml-msb"):
        config = SensorConfig.preset(name)
        clock = args.readout_hz * config.clocks_per_readout
        b = output_bandwidth(config, args.height, args.width, clock)
        print(f"{name:>8} {config.clocks_per_readout:4d} {clock / 1e6:8.2f} MHz {b['word_bits']:3d} "
              f"{b['bits_per_s'] / 1e9:7.2f} {b['min_lanes']:6d} {b['pins']:5d} "
              f"{b['port_bits_per_s'] / 1e9:11.2f} {args.height * args.width * b['word_bits']:13d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
