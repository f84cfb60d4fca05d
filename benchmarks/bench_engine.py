"""The training-data engine: clips and samples per second against training steps per second.

Measures, on this machine and in one run:

- clip making per family (render + fast simulation), clips per second of one process;
- the samples a clip yields while it is in the pool (``pool x refresh x batch / pool``
  draws; each a new key moment, crop and flip);
- training steps per second of a learned method (batch, crop as ``tespike train``);
- hence how many worker processes keep the trainer from waiting, and the
  measured wait of a short run with the given workers.

    python3 benchmarks/bench_engine.py [--config te] [--method net] [--clips 12] [--steps 30] [--workers 1]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402
import torch  # noqa: E402

from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.recon.engine.batches import ClipPool, draw_batch  # noqa: E402
from tespike.recon.engine.clips import EngineRecipe, make_clip  # noqa: E402
from tespike.recon.learned import method_classes  # noqa: E402
from tespike.recon.train import training_loss  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="te")
    parser.add_argument("--method", default="net")
    parser.add_argument("--clips", type=int, default=12, help="clips made per family")
    parser.add_argument("--steps", type=int, default=30, help="training steps timed")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--crop", type=int, default=96)
    parser.add_argument("--pool", type=int, default=48)
    parser.add_argument("--refresh", type=int, default=8)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = SensorConfig.preset(args.config)
    print(f"{args.config}, {args.method}: batch {args.batch}, crop {args.crop}, {args.threads} torch thread(s)")

    print("\n| family | clips | readouts (mean) | s / clip | clips / s |")
    print("| --- | ---: | ---: | ---: | ---: |")
    per_clip = {}
    for family in ("deadleaves", "panorama"):
        recipe = EngineRecipe(weights=((family, 1.0),))
        start = time.perf_counter()
        lengths = [make_clip(recipe, config, i).light.shape[0] for i in range(args.clips)]
        seconds = (time.perf_counter() - start) / args.clips
        per_clip[family] = seconds
        print(f"| {family} | {args.clips} | {np.mean(lengths):.0f} | {seconds:.3f} | {1 / seconds:.2f} |", flush=True)
    mix = dict(EngineRecipe().weights)
    clip_seconds = sum(mix[f] * per_clip[f] for f in per_clip) / sum(mix.values())

    module, sizes_class = method_classes(args.method)
    model = module(sizes_class.preset("cpu"))
    optimizer = torch.optim.Adam(model.parameters(), 1e-4)
    recipe = EngineRecipe()
    pool = ClipPool(recipe, config, capacity=args.pool, refresh=args.refresh, workers=args.workers)
    rng = np.random.default_rng(0)
    try:
        draw_start = time.perf_counter()
        for _ in range(args.steps):
            draw_batch(pool, config, model.sizes.span, args.crop, args.batch, rng)
        draw_seconds = (time.perf_counter() - draw_start) / args.steps
        inputs, truth, inside = draw_batch(pool, config, model.sizes.span, args.crop, args.batch, rng)
        start = time.perf_counter()
        for _ in range(args.steps):
            loss = training_loss(model(inputs, inside, config.spike_light), truth, "mu-l1")
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        step_seconds = (time.perf_counter() - start) / args.steps
        waited_before = pool.source.waited
        run_start = time.perf_counter()
        for step in range(args.steps):
            pool.advance_to(pool.refresh * (pool.made - pool.capacity + 1))    # one new clip per step
            inputs, _, inside = draw_batch(pool, config, model.sizes.span, args.crop, args.batch, rng)
            loss = training_loss(model(inputs, inside, config.spike_light), truth, "mu-l1")
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        run_seconds = time.perf_counter() - run_start
        waited = pool.source.waited - waited_before
    finally:
        pool.close()

    steps_per_second = 1 / (step_seconds + draw_seconds)
    clips_needed = steps_per_second / args.refresh
    print(f"\nmixed clip (recipe weights): {clip_seconds:.3f} s of one core; "
          f"drawing and decoding a batch: {1e3 * draw_seconds:.1f} ms")
    print(f"training step ({args.method}): {step_seconds:.3f} s -> {steps_per_second:.2f} steps/s, "
          f"{args.batch * steps_per_second:.1f} samples/s")
    print(f"one new clip every {args.refresh} steps: {clips_needed:.2f} clips/s needed = "
          f"{clips_needed * clip_seconds:.2f} cores of clip making "
          f"(each clip yields {args.refresh * args.batch} samples on average while in the pool)")
    print(f"stress run, one new clip every step on {args.workers} worker(s): {args.steps} steps in "
          f"{run_seconds:.1f} s, waited for clips {waited:.1f} s ({100 * waited / run_seconds:.0f} %)")


if __name__ == "__main__":
    main()
