"""Peak memory of ``tespike reconstruct`` and ``tespike simulate`` against the input size.

Each command runs as a user would (a fresh ``python3 -m tespike`` process) on
inputs of growing size; the peak resident memory of the child (``ru_maxrss``,
which also counts the pages of memory-mapped files it touched) is printed with
the input size and the growth between sizes. Bounded memory shows as a peak
that grows much more slowly than the input (the words and images stay on
disk, memory-mapped; the work is done in blocks).

Run from the repository root: ``python3 benchmarks/bench_memory.py [--sizes 8,32,128] [--out DIR]``
(sizes in millions of readout words; DIR defaults to a temporary folder).

``--learned``: instead, the learned methods' tiled inference (``tespike.recon.learning.infer.frame``,
one key moment): for each frame size (``--frames 384x512,1024x1024,384x4096``) and tile
(``--tiles none,auto``: the whole frame, the default core of two derived
margins; or core sides in pixels), a fresh process decodes and reconstructs one
image; its peak resident memory (``ru_maxrss``) is printed above the
process's own before the call (interpreter, torch, the model), with the run
time, the number of tiles and the largest block, and every tiled image is
compared with the whole-frame one (largest difference relative to the
image's peak; equal within float tolerance is ``allclose(rtol=1e-4,
atol=1e-6 x peak)``). ``--methods net,bsf,...``; ``net`` runs the shipped
``te`` weights, a baseline its ``cpu`` size with random weights (same cost).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def peak_rss_mb(args: list[str]) -> float:
    """Run ``python3 -m tespike ARGS`` and return its peak resident memory in MB."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    code = ("import resource, subprocess, sys; "
            "r = subprocess.run([sys.executable, '-m', 'tespike', *sys.argv[1:]], capture_output=True); "
            "sys.stderr.write(r.stderr.decode()); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(r.returncode)")
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"tespike {' '.join(args)} failed: {done.stderr.strip()}")
    return int(done.stdout.split()[-1]) / 1024


def learned_child(method: str, height: int, width: int, tile: str, threads: int, out: str) -> None:
    """One case, in this (fresh) process: prints its JSON line."""
    import json
    import resource
    import time

    import torch

    from tespike.golden.config import SensorConfig
    from tespike.recon.learned import load_weights, method_classes, weights_path
    from tespike.recon.learning.infer import blocks, frame, tile_margin

    torch.set_num_threads(threads)
    config = SensorConfig(mode="te")
    if method == "net":
        model = load_weights(weights_path(config))[0]
    else:
        model_cls, sizes_cls = method_classes(method)
        torch.manual_seed(0)
        model = model_cls(sizes_cls.preset("cpu")).eval().to(memory_format=torch.channels_last)
    words = np.random.default_rng(0).integers(0, 16, size=(1, height, width)).astype(np.uint8)
    chosen = None if tile == "none" else "auto" if tile == "auto" else int(tile)
    boxes = blocks(height, width, model, chosen)
    block = max(len(b.rows) * len(b.cols) for b in boxes)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    with torch.inference_mode():
        image = frame(model, words, config, 0, tile=chosen)
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    np.save(out, image.numpy())
    print(json.dumps({"before": before / 1024, "peak": peak / 1024, "seconds": seconds, "tiles": len(boxes),
                      "block": block, "margin": tile_margin(model)}))


def learned_table(args) -> int:
    import json

    methods = args.methods.split(",")
    frames = [tuple(int(v) for v in f.split("x")) for f in args.frames.split(",")]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    print(f"tiled inference, one image, {args.threads} thread(s); peak = ru_maxrss of a fresh process, "
          "'model' = its resident memory before the call")
    print("| method | frame | tile | margin (px) | tiles | largest block (px) | model (MB) | peak (MB) | "
          "peak - model (MB) | s | tiled vs whole (max diff / peak) |")
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    with tempfile.TemporaryDirectory() as scratch:
        for method in methods:
            for height, width in frames:
                whole = None
                for tile in args.tiles.split(","):
                    out = Path(scratch) / f"{method}-{height}-{width}-{tile}.npy"
                    done = subprocess.run([sys.executable, __file__, "--child", method, str(height), str(width), tile,
                                           str(args.threads), str(out)], capture_output=True, text=True, env=env)
                    if done.returncode != 0:
                        raise SystemExit(f"{method} {height}x{width} tile {tile} failed: {done.stderr.strip()}")
                    r = json.loads(done.stdout.split("\n")[-2])
                    image = np.load(out)
                    if tile == "none":
                        whole, check = image, "(reference)"
                    elif whole is None:
                        check = "-"
                    else:
                        peak = float(np.abs(whole).max())
                        diff = float(np.abs(image - whole).max()) / peak
                        ok = np.allclose(image, whole, rtol=1e-4, atol=1e-6 * peak)
                        check = f"{diff:.1e} {'equal' if ok else 'DIFFERENT'}"
                    print(f"| {method} | {height} x {width} | {tile} | {r['margin']} | {r['tiles']} | {r['block']:,} | "
                          f"{r['before']:.0f} | {r['peak']:.0f} | {r['peak'] - r['before']:.0f} | "
                          f"{r['seconds']:.1f} | {check} |", flush=True)
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="8,32,128", help="millions of readout words, comma-separated")
    parser.add_argument("--out", default=None, help="folder for the inputs (default: a temporary folder)")
    parser.add_argument("--learned", action="store_true", help="the learned methods' tiled inference instead")
    parser.add_argument("--methods", default="net", help="with --learned: net and/or baselines, comma-separated")
    parser.add_argument("--frames", default="384x512,1024x1024,384x4096", help="with --learned: HxW, comma-separated")
    parser.add_argument("--tiles", default="none,auto", help="with --learned: none (whole frame; first), "
                        "auto, or core sides")
    parser.add_argument("--threads", type=int, default=1, help="with --learned: torch threads")
    parser.add_argument("--child", nargs=6, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        method, height, width, tile, threads, out = args.child
        learned_child(method, int(height), int(width), tile, int(threads), out)
        return 0
    if args.learned:
        return learned_table(args)
    from tespike.golden.config import SensorConfig
    from tespike.golden.io import save_stream

    config = SensorConfig(mode="te")
    sizes = [int(s) for s in args.sizes.split(",")]
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.out or scratch)
        folder.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng(0)
        print("| words (M) | stream (MB) | reconstruct tfp peak (MB) | reconstruct tfi peak (MB) | "
              "simulate peak (MB) |")
        print("| ---: | ---: | ---: | ---: | ---: |")
        for millions in sizes:
            K = 16
            H, W = 1024, max(1, millions * (1 << 20) // (K * 1024))
            stream, scene = folder / f"s{millions}.npz", folder / f"i{millions}.npy"
            save_stream(stream, rng.integers(0, 16, size=(K, H, W)).astype(np.uint8), config)
            light = np.lib.format.open_memmap(scene, mode="w+", dtype=np.float32, shape=(K, H, W))
            light[:] = 0.5
            light.flush()
            del light
            tfp = peak_rss_mb(["reconstruct", "--stream", str(stream), "--method", "tfp",
                               "--out", str(folder / "r.npy"), "--quiet"])
            tfi = peak_rss_mb(["reconstruct", "--stream", str(stream), "--method", "tfi",
                               "--out", str(folder / "r.npy"), "--quiet"])
            sim = peak_rss_mb(["simulate", "--config", "te", "--scene", str(scene), "--seed", "1",
                               "--out", str(folder / "s.npz"), "--quiet"])
            size = stream.stat().st_size / 2 ** 20
            print(f"| {K * H * W / 2 ** 20:.0f} | {size:.0f} | {tfp:.0f} | {tfi:.0f} | {sim:.0f} |", flush=True)
            for path in (stream, scene):
                path.unlink()
    print(f"(peak resident memory of the child; the images of the largest size are "
          f"{4 * K * H * W / 2 ** 20:.0f} MB of float32 on disk)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
