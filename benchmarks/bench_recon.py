"""Speed and error of the training-free reconstructions (TFP, TFI) at 384 x 512.

Prints, for each method and window, frames per second on the given number of
torch CPU threads (median of ``--repeat`` runs), the ratio to golden's numpy
decoder timed in the same run (the baseline: decoding alone), and the error
against the ground truth (PSNR-mu and SSIM-mu, mu = 5000, peak = the scene's
peak; PU21-PSNR at 4000 cd/m^2 per unit), then writes a PNG of error against
run time. The scene is generated (a horizontal light ramp over four decades
with stripes, a bright disc moving 4 pixels per readout, a dark patch with
fine texture) and simulated with :func:`tespike.golden.fastsim.simulate_scene` when
it is available, else with the cycle-exact :mod:`tespike.golden.sensor` on per-clock
Poisson electrons (slow: progress shown).

    python3 benchmarks/bench_recon.py [--mode te|ml] [--frames 16] [--threads 2] [--png out.png | --docs]
                                      [--save-stream S.npz | --stream S.npz]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.recon.walltime import median_seconds  # noqa: E402
from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig  # noqa: E402
from tespike.golden.decode import decode_light  # noqa: E402
from benchmarks.plotfile import add_png_arguments, png_path  # noqa: E402
from tespike.recon.pictures import save_figure  # noqa: E402


def hdr_scene(frames: int, height: int, width: int, seed: int = 0) -> np.ndarray:
    """(K, H, W) light: ramp 1e-4..1 with stripes, moving bright disc, dark textured patch."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    ramp = 10 ** (-4 + 4 * x / (width - 1))
    stripes = 0.35 + 0.65 * (0.5 + 0.5 * np.sin(2 * np.pi * y / 24))
    base = ramp * stripes
    patch = (slice(height // 8, height // 3), slice(width // 8, width // 2))
    base[patch] = 1e-3 * (1 + 0.5 * rng.random(base[patch].shape))
    scene = np.empty((frames, height, width))
    for k in range(frames):
        cx, cy = width * 0.3 + 4 * k, height * 0.65
        disc = (x - cx) ** 2 + (y - cy) ** 2 < (height / 8) ** 2
        scene[k] = np.where(disc, 0.9, base)
    return scene


def simulate(config: SensorConfig, scene: np.ndarray, seed: int) -> np.ndarray:
    try:
        from tespike.golden.fastsim import simulate_scene
    except ImportError:
        simulate_scene = None
    if simulate_scene is not None:
        return simulate_scene(config, scene, seed=seed)
    from tqdm import tqdm
    from tespike.golden.sensor import PixelArrayModel
    rng = np.random.default_rng(seed)
    L = config.clocks_per_readout
    array = PixelArrayModel(config, scene.shape[1:])
    words = []
    for light in tqdm(scene, desc="per-clock simulation (golden.sensor)", unit="readout"):
        electrons = rng.poisson(np.broadcast_to(light * DESIGN_ELECTRONS / L, (L,) + light.shape))
        words.append(array.feed(np.minimum(electrons, config.input_max).astype(np.int64)))
    return np.concatenate(words)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=("te", "ml"), default="te")
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--height", type=int, default=384)
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    add_png_arguments(parser, "bench_recon.png")
    parser.add_argument("--save-stream", help="also write the simulated stream to this S.npz")
    parser.add_argument("--stream", help="use this S.npz (made with --save-stream and the same "
                                         "--mode/--frames/--height/--width) instead of simulating")
    args = parser.parse_args(argv)
    png_path(args, "bench_recon.png")

    import torch

    from tespike.recon.methods import reconstruct
    from tespike.recon.metrics import psnr_mu, psnr_pu21, ssim_mu

    torch.set_num_threads(args.threads)
    config = SensorConfig.preset(args.mode)
    scene = hdr_scene(args.frames, args.height, args.width)
    from tespike.golden.io import load_stream, save_stream
    if args.stream:
        words, config = load_stream(args.stream)
        if words.shape != scene.shape or config != SensorConfig.preset(args.mode):
            raise SystemExit(f"{args.stream}: stream {words.shape} / {config} does not match "
                             f"the scene {scene.shape} / mode {args.mode}")
    else:
        words = simulate(config, scene, args.seed)
    if args.save_stream:
        save_stream(args.save_stream, words, config)
    K, H, W = words.shape
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{config.mode.upper()} stream {K} x {H} x {W}, torch {torch.__version__}, "
          f"{torch.get_num_threads()} threads, {os.cpu_count()} CPUs, load average {load:.1f}")

    base_t, _ = median_seconds(lambda: decode_light(words, config), args.repeat)
    print(f"baseline golden.decode.decode_light (numpy): {K / base_t:8.1f} fps")
    runs = [("tfp", {"window": w}) for w in (1, 3, 9, 17)] + \
           [("tfi", {"window": 9, "search": "stream"}), ("tfi", {"window": 9, "search": "window"}), ("tfi", {"window": 3, "search": "window"})]
    print(f"{'method':26s} {'fps':>8s} {'ms/frame':>9s} {'x decode':>9s} {'PSNR-mu':>8s} {'SSIM-mu':>8s} {'PU21':>7s}")
    rows = []
    for method, opts in runs:
        seconds, images = median_seconds(lambda: reconstruct(words, config, method, **opts), args.repeat)
        p = float(np.mean(psnr_mu(images, scene, peak=float(scene.max()))))
        s = float(np.mean(ssim_mu(images, scene, peak=float(scene.max()))))
        u = float(np.mean(psnr_pu21(images, scene)))
        label = method + " " + " ".join(f"{k}={v}" for k, v in opts.items())
        rows.append((label, 1000 * seconds / K, p))
        print(f"{label:26s} {K / seconds:8.1f} {1000 * seconds / K:9.2f} {seconds / base_t:9.2f} "
              f"{p:8.2f} {s:8.3f} {u:7.2f}")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, ms, p in rows:
        ax.scatter(ms, p)
        ax.annotate(label, (ms, p), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel(f"run time per {H}x{W} frame [ms] ({args.threads} threads, load {load:.1f})")
    ax.set_ylabel("PSNR-mu [dB] (mu = 5000)")
    ax.set_title(f"training-free reconstruction, {config.mode.upper()} stream")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, args.png, dpi=120)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
