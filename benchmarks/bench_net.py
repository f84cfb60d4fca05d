"""Learned methods: quality on held-out real HDR scenes and complexity (paper Tables 1 and 10).

Quality, as issue 17 checks it: camera pans over the held-out panorama
(``courtyard``: the full-size file with ``TESPIKE_HDRI_DIR``, else the shipped
copy; no bright source added), simulated for TE, the msb ML camera and the
full-count ML camera, reconstructed with TFP, TFI and every learned method
whose weights exist, scored by PSNR-mu (mu = 5000, each frame divided by the
ground truth's peak) on

- ``middle``: the frames of a long stream whose whole 61-readout span lies in it;
- ``whole``: every frame of the same stream (its ends padded, as inference does);
- ``short-16`` / ``short-32``: whole streams of 16 and 32 readouts;
- ``dim-0.3`` / ``dim-0.03``: the long streams at 0.3 and 0.03 of the design light (whole);

with the issue's margins printed (net_TE - TFP_TE >= 6 dB on the middle frames,
net_TE above both training-free methods everywhere, +2 dB over TFP when dim,
net_TE above net on the msb camera).

Complexity: parameters, FLOPs (torch.utils.flop_counter, counted at 192 x 256
and scaled by 4 to 384 x 512: every layer's cost is proportional to the pixel
count) and CPU latency at 384 x 512 (tespike.recon.walltime, per thread count)
for the CPU default and the paper size; and the plain-torch DCN against conv2d.

    python3 benchmarks/bench_net.py [--quality] [--complexity] [--weights-dir DIR] [--ablation-dir DIR]
    python3 benchmarks/bench_net.py --validation [--extended] [--compare W.pt ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import torch  # noqa: E402

from tespike.recon.walltime import median_seconds  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.fastsim import simulate_scene  # noqa: E402
from tespike.recon.calibration import correct_input, input_correction  # noqa: E402
from tespike.recon.methods import reconstruct  # noqa: E402
from tespike.recon.metrics import psnr_mu  # noqa: E402
from tespike.recon.learned import WEIGHTS_DIR  # noqa: E402
from tespike.recon.learned import load_weights  # noqa: E402
from tespike.recon.learning.infer import reconstruct_model  # noqa: E402
from tespike.recon.scenes import normalise_sequence, scene_rng  # noqa: E402
from tespike.recon.scenes.panorama import panorama_sequence  # noqa: E402
from tespike.recon.learning.layers import parameter_count  # noqa: E402
from tespike.recon.net.model import TESpikeNet  # noqa: E402
from tespike.recon.net.sizes import NetSizes  # noqa: E402

SENSORS = (("TE", "te"), ("ML-msb", "ml-msb"), ("ML-count", "ml"))


def heldout_pans(count: int, frames: int, height: int, width: int) -> list[tuple[str, np.ndarray]]:
    """Camera pans over the held-out panorama, peak 1 (held-out seed domain, no source added)."""
    out = []
    for i in range(count):
        rng = scene_rng("bench-net-pan", i, heldout=True)
        light = panorama_sequence(rng, frames, height, width, source="courtyard", motion="pan")
        out.append((f"courtyard-pan-{i}", normalise_sequence(light, 1.0)))
    return out


def quality(args) -> None:
    span = NetSizes().span
    if args.frames <= span:
        raise SystemExit(f"--frames {args.frames} leaves no frame with a whole {span}-readout span")
    middle = list(range(span // 2, args.frames - span // 2))
    cases = {"middle": (None, 1.0, middle), "whole": (None, 1.0, None), "short-16": (16, 1.0, None),
             "short-32": (32, 1.0, None), "dim-0.3": (None, 0.3, None), "dim-0.03": (None, 0.03, None)}
    scores: dict[tuple[str, str, str], list[float]] = {}
    for name, light in heldout_pans(args.sequences, args.frames, args.height, args.width):
        print(f"{name}: {light.shape}, peak / median {float(light.max() / np.median(light)):.0f}", flush=True)
        for index, (label, preset) in enumerate(SENSORS):
            config = SensorConfig.preset(preset)
            methods = {"tfp": None, "tfi": None}
            for path in sorted(Path(args.weights_dir).glob(f"*{preset}.pt")):
                method = path.stem[:-len(preset)].rstrip("-") or "net"
                if path.stem == preset or path.stem.endswith(f"-{preset}"):
                    methods[method] = path
            if preset == "te" and args.ablation_dir:
                methods |= {f"case {case}": Path(args.ablation_dir) / f"case{case}.pt" for case in range(1, 7)}
            streams = {}
            for case, (length, peak, keys) in cases.items():
                key = (length, peak)
                if key not in streams:
                    scene = light[:length] * peak
                    rng = np.random.default_rng([args.seed, index, len(name), int(1e3 * peak), length or 0])
                    streams[key] = (scene, simulate_scene(config, scene, seed=rng))
                scene, words = streams[key]
                for method, path in methods.items():
                    if path is not None and not path.is_file():
                        continue
                    if path is None:
                        images = reconstruct(words, config, method)
                    else:
                        images = reconstruct_model(load_weights(path)[0], words, config, tile=None)
                    chosen = slice(None) if keys is None else keys
                    value = float(np.mean(psnr_mu(images[chosen], scene[chosen])))
                    scores.setdefault((case, label, method), []).append(value)
    mean = {k: float(np.mean(v)) for k, v in scores.items()}
    methods = sorted({m for (_, _, m) in mean}, key=lambda m: (m not in ("tfp", "tfi"), m))
    for label, _ in SENSORS:
        print(f"\n{label}: PSNR-mu (dB), mean over {args.sequences} held-out pans")
        print("| case | " + " | ".join(methods) + " |")
        print("| --- |" + " ---: |" * len(methods))
        for case in cases:
            cells = [f"{mean[case, label, m]:.2f}" if (case, label, m) in mean else "-" for m in methods]
            print(f"| {case} | " + " | ".join(cells) + " |")
    print()
    learned = [m for m in methods if m not in ("tfp", "tfi") and not m.startswith("case ")]
    for m in learned:
        if ("middle", "TE", m) not in mean:
            continue
        print(f"{m}_TE - tfp_TE, middle frames: {mean['middle', 'TE', m] - mean['middle', 'TE', 'tfp']:+.2f} dB "
              "(target >= 6)")
        for case in cases:
            best_free = max(mean[case, "TE", "tfp"], mean[case, "TE", "tfi"])
            worst = min(v - max(scores[case, "TE", "tfp"][i], scores[case, "TE", "tfi"][i])
                        for i, v in enumerate(scores[case, "TE", m]))
            print(f"  {case}: {m}_TE - best training-free {mean[case, 'TE', m] - best_free:+.2f} dB "
                  f"(worst sequence {worst:+.2f})")
        for case in ("dim-0.3", "dim-0.03"):
            print(f"  {case}: {m}_TE - tfp_TE {mean[case, 'TE', m] - mean[case, 'TE', 'tfp']:+.2f} dB (target >= 2)")
        for other in ("ML-msb", "ML-count"):
            if ("middle", other, m) in mean:
                print(f"  middle: {m}_TE - {m}_{other} {mean['middle', 'TE', m] - mean['middle', other, m]:+.2f} dB")


def validation(args) -> None:
    """The held-out validation set of training (recon/engine/validation.py): TFP, TFI and the weights."""
    from tespike.recon.engine.validation import validation_psnr, validation_set
    for label, preset in SENSORS:
        config = SensorConfig.preset(preset)
        cases = validation_set(config, extended=args.extended)
        rows = {m: validation_psnr(lambda c: reconstruct(c.words, config, m, calibration=c.calibration), cases)
                for m in ("tfp", "tfi")}
        for path in [Path(args.weights_dir) / f"{preset}.pt", *map(Path, args.compare)]:
            if path.is_file() and load_weights(path)[1] == config:
                model = load_weights(path)[0]
                rows[str(path)] = validation_psnr(lambda c: reconstruct_model(
                    model, c.words, config, tile=None, calibration=c.calibration, inputs=c.law_inputs()), cases)
        names = list(rows["tfp"])
        print(f"\n{label}: validation PSNR-mu (dB), every frame of each case")
        print("| method | " + " | ".join(names) + " |")
        print("| --- |" + " ---: |" * len(names))
        for method, values in rows.items():
            print(f"| {method} | " + " | ".join(f"{values[n]:.2f}" for n in names) + " |", flush=True)


def candidates(args) -> None:
    """What the shared output head chooses among (recon/learning/head.py), alone, on the validation set.

    Every estimate as the head sees it (the 61-readout span of each key moment,
    stream ends padded as inference pads them), its initial blend, and the
    per-pixel oracle: the estimate closest to the truth after the metric's
    mu-law, chosen with the truth's help (a bound on what choosing can give,
    not a method).
    """
    from tespike.recon.engine.validation import validation_set
    from tespike.recon.metrics import mu_law
    from tespike.recon.learning.head import BlendHead, RADII, key_estimates
    from tespike.recon.decoding import decode_light
    from tespike.recon.learning.span import key_span, span_inside
    names = [f"mean {2 * r + 1}" for r in RADII] + ["tfi"]
    span = NetSizes().span
    for label, preset in SENSORS:
        config = SensorConfig.preset(preset)
        print(f"\n{label}: validation PSNR-mu (dB) of the head's estimates, every frame of each case")
        print("| case | " + " | ".join(names) + " | initial blend | oracle |")
        print("| --- |" + " ---: |" * (len(names) + 2))
        for case in validation_set(config):
            light = decode_light(case.words, config, dtype=torch.float64)
            if case.calibration is not None:          # a noisy case: corrected at the input, as inference does
                light = correct_input(light, input_correction(case.calibration, dtype=torch.float64))
            spans = torch.from_numpy(np.stack([key_span(len(light), k, span) for k in range(len(light))]))
            inside = torch.from_numpy(np.stack([span_inside(len(light), k, span) for k in range(len(light))]))
            estimates = key_estimates(light[spans], inside, config.spike_light)    # (K, estimates, H, W)
            head = BlendHead(4, 1, NetSizes().mu).double()
            with torch.no_grad():
                blend = head(torch.zeros(len(light), 4, *light.shape[1:], dtype=torch.float64), light[spans],
                             inside, config.spike_light)
            truth = torch.from_numpy(case.light).double()
            cells = [float(np.mean(psnr_mu(estimates[:, j].numpy(), case.light))) for j in range(len(names))]
            cells.append(float(np.mean(psnr_mu(blend[:, 0].numpy(), case.light))))
            peak = truth.flatten(1).amax(1).view(-1, 1, 1, 1)
            mapped = mu_law((estimates / peak).clamp(0, 1))
            target = mu_law((truth[:, None] / peak).clamp(0, 1))
            best = mapped.gather(1, (mapped - target).abs().argmin(1, keepdim=True))
            mse = ((best - target) ** 2).flatten(1).mean(1)
            cells.append(float((10 * torch.log10(1 / mse)).mean()))
            print(f"| {case.label} | " + " | ".join(f"{v:.2f}" for v in cells) + " |", flush=True)


def complexity(args) -> None:
    print("\n| size | parameters | GFLOPs at 384 x 512 | threads | s / frame (median) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    from torch.utils.flop_counter import FlopCounterMode
    for name in args.sizes:
        sizes = NetSizes.preset(name)
        model = TESpikeNet(sizes).eval().to(memory_format=torch.channels_last)
        with torch.inference_mode():
            counter = FlopCounterMode(display=False)
            with counter:
                model(torch.rand(1, sizes.span, 192, 256), None, 1.0)
            flops = 4 * counter.get_total_flops()
            light = torch.rand(1, sizes.span, 384, 512)
            for threads in args.threads:
                torch.set_num_threads(threads)
                repeats = args.repeat if name == "cpu" else 1
                seconds = median_seconds(lambda: model(light, None, 1.0), repeats, warm_up=True)[0]
                print(f"| {name} | {parameter_count(model):,} | {flops / 1e9:.1f} | {threads} | {seconds:.2f} |",
                      flush=True)
    from tespike.recon.learning.deform import deform_conv2d
    torch.set_num_threads(max(args.threads))
    x = torch.rand(4, 16, 96, 128)
    weight = torch.rand(16, 16, 3, 3)
    offset = torch.randn(4, 18, 96, 128)
    mask = torch.rand(4, 9, 96, 128)
    dcn = median_seconds(lambda: deform_conv2d(x, offset, weight, padding=1, mask=mask), args.repeat,
                         warm_up=True)[0]
    conv = median_seconds(lambda: torch.nn.functional.conv2d(x, weight, padding=1), args.repeat, warm_up=True)[0]
    print(f"\nDCN 3 x 3, 16 -> 16 channels, 4 x 96 x 128: {1e3 * dcn:.1f} ms; conv2d {1e3 * conv:.1f} ms "
          f"({dcn / conv:.1f}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quality", action="store_true", help="held-out quality (default: both parts)")
    parser.add_argument("--complexity", action="store_true", help="parameters, FLOPs, latency")
    parser.add_argument("--validation", action="store_true",
                        help="only the training's held-out validation set (TFP, TFI, the weights)")
    parser.add_argument("--candidates", action="store_true",
                        help="only the output head's training-free estimates, their initial blend and the oracle")
    parser.add_argument("--extended", action="store_true",
                        help="with --validation: also the six extended noisy cases (dim light, strong dark "
                             "current; recon.engine.validation.EXTENDED_CASES)")
    parser.add_argument("--compare", nargs="*", default=[], metavar="PT",
                        help="with --validation: also score these weights files (each on its own sensor)")
    parser.add_argument("--weights-dir", default=str(WEIGHTS_DIR),
                        help="folder of te.pt, ml.pt, ml-msb.pt (and METHOD-te.pt ... of other learned methods)")
    parser.add_argument("--ablation-dir", default=None,
                        help="also score the TE ablation weights case1.pt .. case6.pt in this folder (Table 3)")
    parser.add_argument("--sequences", type=int, default=3, help="held-out panorama pans (default 3)")
    parser.add_argument("--frames", type=int, default=69)
    parser.add_argument("--height", type=int, default=96)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--sizes", nargs="+", default=["cpu", "paper"], choices=["cpu", "paper"],
                        help="network sizes timed by --complexity (the paper size takes minutes per frame)")
    args = parser.parse_args()
    if args.validation:
        validation(args)
        return
    if args.candidates:
        candidates(args)
        return
    both = not (args.quality or args.complexity)
    if args.quality or both:
        quality(args)
    if args.complexity or both:
        complexity(args)


if __name__ == "__main__":
    main()
