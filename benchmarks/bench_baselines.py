"""The learned baselines' complexity beside the paper's Table 10: parameters, FLOPs, CPU latency.

Per method (Spk2ImgNet, BSF, MambaSpike, and the project's network as the
reference of the same run) and size (``cpu``, ``paper``):

- parameters (trainable);
- FLOPs of one 384 x 512 frame, counted by ``torch.utils.flop_counter`` on
  the meta device (no arithmetic is done; convolutions, matrix products and
  einsums are counted, 2 per multiply-add; ``grid_sample``, elementwise and
  the scan's exponentials are not);
- CPU latency of one 384 x 512 frame at 1 and 2 threads (``torch.utils.benchmark``,
  median of ``blocked_autorange``); the ``paper`` sizes are timed on a 96 x 128
  crop and scaled by 16 (every layer's cost is proportional to the pixel
  count), marked ``x16``. The ratio to the project's network's ``cpu`` size in
  the same run is printed beside it, so a busy machine's figures can be read.

The paper's Table 10 (an RTX 3090 GPU, frame size not stated) is printed beside.

    python3 benchmarks/bench_baselines.py [--sizes cpu paper] [--threads 1 2] [--min-run-time 2]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import torch  # noqa: E402
import torch.utils.benchmark as benchmark  # noqa: E402

from tespike.recon.baselines import BASELINES  # noqa: E402
from tespike.recon.complexity import FLOP_HEIGHT, FLOP_WIDTH, PAPER_TABLE10, flops_per_frame  # noqa: E402
from tespike.recon.learned import method_radius  # noqa: E402
from tespike.recon.learning.layers import parameter_count  # noqa: E402
from tespike.recon.net.model import TESpikeNet  # noqa: E402
from tespike.recon.net.sizes import NetSizes  # noqa: E402

def build(method: str, size: str) -> torch.nn.Module:
    if method == "net":
        return TESpikeNet(NetSizes.preset(size))
    model_cls, sizes_cls = BASELINES[method]
    return model_cls(sizes_cls.preset(size))


def paper_row(method: str) -> str:
    """The paper's Table 10 row of a method: parameters, FLOPs, testing time (GPU)."""
    row = PAPER_TABLE10[method]
    return f"{row.parameters / 1e6:.3f}M, {row.flops / 1e12:.3f}T, {row.seconds:.3f}s"


def seconds(model: torch.nn.Module, height: int, width: int, threads: int, min_run_time: float) -> float:
    light = torch.rand(1, model.sizes.span, height, width)
    timer = benchmark.Timer(stmt="model(light, None, 1.0)", globals={"model": model, "light": light}, num_threads=threads,
                            setup="torch.set_num_threads(%d)" % threads)
    with torch.inference_mode():
        model(light, None, 1.0)                         # warm-up, untimed
        return timer.blocked_autorange(min_run_time=min_run_time).median


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["cpu", "paper"], choices=["cpu", "paper"])
    parser.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--methods", nargs="+", default=["net", *BASELINES], choices=["net", *BASELINES])
    parser.add_argument("--min-run-time", type=float, default=2.0, help="seconds of timing per figure")
    args = parser.parse_args()
    torch.manual_seed(0)
    reference = {}
    print(f"| method | size | parameters | GFLOPs / {FLOP_HEIGHT} x {FLOP_WIDTH} frame | receptive radius (px) | "
          "threads | CPU s / frame | / net cpu | paper Table 10 (params, FLOPs, GPU time) |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for method in args.methods:
        for size in args.sizes:
            model = build(method, size).eval().to(memory_format=torch.channels_last)
            count = flops_per_frame(model)
            radius = method_radius(model.sizes)
            for threads in args.threads:
                if size == "cpu":
                    secs, note = seconds(model, FLOP_HEIGHT, FLOP_WIDTH, threads, args.min_run_time), ""
                else:
                    secs = 16 * seconds(model, FLOP_HEIGHT // 4, FLOP_WIDTH // 4, threads, args.min_run_time)
                    note = " (x16)"
                if method == "net" and size == "cpu":
                    reference[threads] = secs
                ratio = f"{secs / reference[threads]:.2f}" if threads in reference else "-"
                paper = paper_row(method) if size == "paper" else ""
                print(f"| {method} | {size} | {parameter_count(model):,} | {count / 1e9:.1f} | "
                      f"{radius} | {threads} | {secs:.3f}{note} | {ratio} | {paper} |",
                      flush=True)


if __name__ == "__main__":
    main()
