"""Yosys generic synthesis of the streaming top against pixel count: cells per pixel, time, memory.

For each array (paper TE configuration, L = 240, N = ceil(H W / L) lanes, the fewest
that fit; default 16 x 16, 64 x 64, 128 x 128 and the paper's 400 x 250) the script
generates the streaming Verilog (``tespike.rtl.verilog_stream.stream_array_verilog``) and runs
``tespike.cosim.synthesis.synthesize_hierarchy`` on it (``synth``, hierarchy kept, the flow of
``tespike synthesize``). Printed per size: cells, flip-flops and transistors per pixel,
cells per pixel as a ratio to the first size's (issue 26's target: within 10 %), and
Yosys's wall time, CPU time and peak resident memory (target at 400 x 250: under 10
minutes and 8 GB on 2 cores).

Run from the repository root:
``nice -n 10 python3 benchmarks/bench_synthesis.py [--sizes 16x16 64x64 128x128 400x250] [--config te]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tespike.cosim.synthesis import hierarchy_total, synthesize_hierarchy  # noqa: E402
from tespike.golden.config import load_config  # noqa: E402
from tespike.golden.beats import min_lanes  # noqa: E402
from tespike.rtl.names import stream_module_names  # noqa: E402
from tespike.rtl.verilog_stream import stream_array_verilog  # noqa: E402


def size(text: str) -> tuple[int, int]:
    height, _, width = text.partition("x")
    return int(height), int(width)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", type=size, default=[(16, 16), (64, 64), (128, 128), (400, 250)])
    parser.add_argument("--config", default="te", help="preset or JSON file (default te)")
    args = parser.parse_args(argv)
    config = load_config(args.config)
    top = stream_module_names(config)["top"]
    print(f"{top}, {args.config}, yosys synth (hierarchy kept), N = ceil(H W / L) lanes")
    print("| array | pixels | lanes | cells | cells/pixel | of first | flip-flops/pixel | transistors/pixel "
          "| generate s | yosys wall s | yosys CPU s | yosys peak MB |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    first = None
    for height, width in args.sizes:
        pixels = height * width
        lanes = min_lanes(config, height, width)
        start = time.perf_counter()
        text = stream_array_verilog(config, height, width, lanes)
        generate = time.perf_counter() - start
        result = synthesize_hierarchy(text, top)
        total = hierarchy_total(result["modules"], top)
        per_pixel = total["cells"] / pixels
        first = first or per_pixel
        run = result["run"]
        print(f"| {height} x {width} | {pixels} | {lanes} | {total['cells']} | {per_pixel:.2f} | "
              f"{per_pixel / first:.3f} | {total['flops'] / pixels:.2f} | "
              f"{total['transistors'] / pixels:.0f}-{total['transistors_max'] / pixels:.0f} | {generate:.1f} | "
              f"{run['seconds']:.1f} | {run['cpu_seconds']:.1f} | {run['peak_mb']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
