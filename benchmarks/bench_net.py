"""The reconstruction network: quality on held-out HDR sequences and complexity (paper Tables 1 and 10).

Quality: held-out camera paths over the held-out panorama (peak-to-median 70..250)
and held-out moderate scenes, simulated for TE, the msb ML camera (the paper's
comparison) and the full-count ML camera; TFP, TFI and the network on each;
PSNR-mu / SSIM-mu (mu = 5000, divided by the ground truth's peak, no min-max
normalisation) over the frames in the middle of each sequence (those whose whole
61-readout span lies inside it), with the issue's margins printed:
net_TE - TFP_TE (target >= 6 dB), net_TE - net_msb (> 0) and net_TE - net_ML.

Complexity: parameters, FLOPs (torch.utils.flop_counter, counted at 192 x 256
and scaled by 4 to 384 x 512: every layer's cost is proportional to the pixel
count) and CPU latency at 384 x 512 (median of repeats, per thread count) for
the CPU default and the paper size; and the plain-torch DCN against conv2d.

    python3 benchmarks/bench_net.py [--quality] [--complexity] [--weights-dir DIR] [--ablation-dir DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import torch  # noqa: E402

from cosim.timing import median_seconds  # noqa: E402
from golden.config import SensorConfig  # noqa: E402
from golden.fastsim import simulate_scene  # noqa: E402
from recon.methods import reconstruct  # noqa: E402
from recon.metrics import psnr_mu, ssim_mu  # noqa: E402
from recon.net.data import evaluation_sequences  # noqa: E402
from recon.net.infer import WEIGHTS_DIR, frame, load_weights  # noqa: E402
from recon.net.model import TESpikeNet, parameter_count  # noqa: E402
from recon.net.sizes import NetSizes  # noqa: E402

SENSORS = (("TE", "te"), ("ML-msb", "ml-msb"), ("ML-count", "ml"))


def net_images(model, words, config, keys) -> np.ndarray:
    with torch.inference_mode():
        return np.stack([frame(model, words, config, k).numpy() for k in keys])


def quality(args) -> None:
    sequences = evaluation_sequences(args.sequences, args.frames, args.height, args.width)
    span = NetSizes().span
    keys = range(span // 2, args.frames - span // 2)
    if not len(keys):
        raise SystemExit(f"--frames {args.frames} leaves no frame with a whole {span}-readout span")
    scores: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    for name, light in sequences:
        ratio = float(light.max() / np.median(light))
        print(f"{name}: {light.shape}, peak / median {ratio:.0f}", flush=True)
        truth = light[list(keys)]
        for index, (label, preset) in enumerate(SENSORS):
            config = SensorConfig.preset(preset)
            words = simulate_scene(config, light, seed=np.random.default_rng([args.seed, index, len(name)]))
            methods = {"tfp": None, "tfi": None, "net": Path(args.weights_dir) / f"{preset}.pt"}
            if preset == "te" and args.ablation_dir:
                methods |= {f"case {case}": Path(args.ablation_dir) / f"case{case}.pt" for case in range(1, 7)}
            for method, path in methods.items():
                if path is not None:
                    if not path.is_file():
                        continue
                    model = load_weights(path)[0]
                    seconds, images = median_seconds(lambda: net_images(model, words, config, keys), 1)
                else:
                    seconds, images = median_seconds(lambda: reconstruct(words, config, method)[list(keys)], 1)
                seconds /= len(keys)
                p = float(np.mean(psnr_mu(images, truth, peak=float(light.max()))))
                s = float(np.mean(ssim_mu(images, truth, peak=float(light.max()))))
                scores.setdefault((label, method), []).append((p, s, seconds))
    print("\n| sensor | method | PSNR-mu (dB) | SSIM-mu | ms / frame |")
    print("| --- | --- | ---: | ---: | ---: |")
    mean = {}
    for (label, method), rows in scores.items():
        p, s, t = (float(np.mean([r[i] for r in rows])) for i in range(3))
        mean[label, method] = p
        print(f"| {label} | {method} | {p:.2f} | {s:.3f} | {1e3 * t:.1f} |")
    print()
    cases = [m for (label, m) in mean if m.startswith("case ")]
    if cases:
        print("Ablation (paper Table 3), TE: PSNR-mu of each case and its gain over the case before")
        for m in sorted(cases):
            before = f"case {int(m.split()[1]) - 1}"
            gain = f"{mean['TE', m] - mean['TE', before]:+.2f} dB" if ("TE", before) in mean else ""
            print(f"  {m}: {mean['TE', m]:.2f} dB  {gain}")
        print()
    for a, b, target in ((("TE", "net"), ("TE", "tfp"), ">= 6 dB (issue); >= 3 dB (hidden check)"),
                         (("TE", "net"), ("ML-msb", "net"), "> 0"),
                         (("TE", "net"), ("ML-count", "net"), "as measured"),
                         (("TE", "tfp"), ("ML-msb", "tfp"), "> 0"),
                         (("TE", "tfi"), ("ML-msb", "tfi"), "> 0")):
        if a in mean and b in mean:
            print(f"{a[1]}_{a[0]} - {b[1]}_{b[0]}: {mean[a] - mean[b]:+.2f} dB   (target {target})")


def complexity(args) -> None:
    print("\n| size | parameters | GFLOPs at 384 x 512 | threads | s / frame (median) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    from torch.utils.flop_counter import FlopCounterMode
    for name in ("cpu", "paper"):
        sizes = NetSizes.preset(name)
        model = TESpikeNet(sizes).eval().to(memory_format=torch.channels_last)
        with torch.inference_mode():
            counter = FlopCounterMode(display=False)
            with counter:
                model(torch.rand(1, sizes.span, 192, 256))
            flops = 4 * counter.get_total_flops()
            light = torch.rand(1, sizes.span, 384, 512)
            for threads in args.threads:
                torch.set_num_threads(threads)
                repeats = args.repeat if name == "cpu" else 1
                seconds = median_seconds(lambda: model(light), repeats, warm_up=True)[0]
                print(f"| {name} | {parameter_count(model):,} | {flops / 1e9:.1f} | {threads} | {seconds:.2f} |",
                      flush=True)
    from recon.net.deform import deform_conv2d
    torch.set_num_threads(max(args.threads))
    x = torch.rand(4, 16, 96, 128)
    weight = torch.rand(16, 16, 3, 3)
    offset = torch.randn(4, 18, 96, 128)
    mask = torch.rand(4, 9, 96, 128)
    dcn = median_seconds(lambda: deform_conv2d(x, offset, weight, padding=1, mask=mask), args.repeat, warm_up=True)[0]
    conv = median_seconds(lambda: torch.nn.functional.conv2d(x, weight, padding=1), args.repeat, warm_up=True)[0]
    print(f"\nDCN 3 x 3, 16 -> 16 channels, 4 x 96 x 128: {1e3 * dcn:.1f} ms; conv2d {1e3 * conv:.1f} ms "
          f"({dcn / conv:.1f}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quality", action="store_true", help="held-out quality (default: both parts)")
    parser.add_argument("--complexity", action="store_true", help="parameters, FLOPs, latency")
    parser.add_argument("--weights-dir", default=str(WEIGHTS_DIR), help="folder of te.pt, ml.pt, ml-msb.pt")
    parser.add_argument("--ablation-dir", default=None,
                        help="also score the TE ablation weights case1.pt .. case6.pt in this folder (Table 3)")
    parser.add_argument("--sequences", type=int, default=4, help="held-out panorama paths (default 4)")
    parser.add_argument("--frames", type=int, default=72)
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    both = not (args.quality or args.complexity)
    if args.quality or both:
        quality(args)
    if args.complexity or both:
        complexity(args)


if __name__ == "__main__":
    main()
