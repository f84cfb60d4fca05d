"""Dataset building and store evaluation throughput with 1 and 2 workers, and the per-core
figures docs/distributed.md projects the paper's full dataset from.

Prints, in one run on this machine:

* building (``tespike dataset``'s code: EXR frames read twice, light written, TE and ML
  streams simulated) of real HDR content (the shipped panorama under three camera
  motions, written as EXR frame folders) with ``--workers 1`` (in this process) and ``--workers 2`` (a
  LocalCluster of two processes; its start-up is not counted): pixel-readouts/s
  (summed over sensors), sequences/hour, the speed-up of 2 workers over 1, and the
  CPU time of the processes that ran the tasks (the per-core cost, which the load of a
  shared machine does not change);
* evaluation over the store (TFP and TFI, every sequence x sensor) with 1 and 2 workers;
* bytes on disk per pixel-readout of the light and of each stream (compressed);
* per core: simulation alone per pixel-readout, and reading one 1920 x 1080 OpenEXR frame.

The stores of the two runs are compared bit for bit. Run with ``nice -n 19`` on a
shared machine; figures vary with the load, compare within one run.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tespike.cosim.dataset.cluster import Runner  # noqa: E402
from tespike.cosim.dataset.build import build_dataset, hdr_sources, read_gray  # noqa: E402
from tespike.golden.config import SensorConfig  # noqa: E402
from tespike.golden.fastsim import simulate_scene  # noqa: E402
from tespike.recon.dataset import compare_stores  # noqa: E402
from tespike.recon.dataset.evaluate import evaluate_store  # noqa: E402
from tespike.recon.scenes import make_scene  # noqa: E402
from tespike.recon.scenes.hdr_io import write_exr  # noqa: E402


def folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def _cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def cpu_seconds(run: Runner) -> float:
    """CPU seconds (user + system) used so far by whatever runs the tasks: this process,
    or every worker process of the cluster."""
    if run.client is None:
        return _cpu_seconds()
    return sum(run.client.run(_cpu_seconds).values())


def make_hdr_folder(root: Path, frames: int, height: int, width: int) -> int:
    """Real HDR content: the shipped CC0 panorama under three camera motions, one EXR per frame."""
    count = 0
    for motion in ("pan", "tilt", "zoom"):
        light = make_scene("default", frames, height, width, seed=0, motion=motion)
        (root / motion).mkdir(parents=True)
        for k, frame in enumerate(light):
            write_exr(root / motion / f"{k:04d}.exr", frame * 1000.0)
        count += 1
    return count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--width", type=int, default=512)
    args = parser.parse_args()

    configs = {"te": SensorConfig(mode="te"), "ml": SensorConfig(mode="ml")}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        count = make_hdr_folder(tmp / "hdr", args.frames, args.height, args.width)
        sources = hdr_sources(tmp / "hdr")
        readouts = sum(int(np.prod(s.shape)) for s in sources)          # per sensor
        print(f"{count} HDR sequences (EXR) of {args.frames} x {args.height} x {args.width}, sensors te + ml: "
              f"{readouts * len(configs):,} pixel-readouts per dataset")
        total = readouts * len(configs)
        print("\n| workers | build wall s | pixel-readouts/s | sequences/hour | CPU s | CPU us / pixel-readout "
              "| evaluation wall s | CPU s | CPU us / pixel-readout / method |")
        print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |", flush=True)
        rows = {}
        for workers in (1, 2):
            url = str(tmp / f"w{workers}.zarr")
            with Runner(workers) as run:
                # hand-written timing: CPU seconds of worker processes (torch.utils.benchmark sees this process's wall time only)
                cpu, start = cpu_seconds(run), time.perf_counter()
                build_dataset(url, sources, configs, 0, run)
                s_wall, s_cpu = time.perf_counter() - start, cpu_seconds(run) - cpu
                cpu, start = cpu_seconds(run), time.perf_counter()
                evaluate_store(url, run, methods=["tfp", "tfi"])
                e_wall, e_cpu = time.perf_counter() - start, cpu_seconds(run) - cpu
            rows[workers] = s_wall, e_wall
            print(f"| {workers} | {s_wall:.1f} | {total / s_wall:.3g} | {3600 * count / s_wall:.0f} | {s_cpu:.1f} "
                  f"| {1e6 * s_cpu / total:.2f} | {e_wall:.1f} | {e_cpu:.1f} | {1e6 * e_cpu / (2 * total):.2f} |",
                  flush=True)
        same = compare_stores(tmp / "w1.zarr", tmp / "w2.zarr") == []
        print(f"\nspeed-up of 2 workers over 1 (wall): build x{rows[1][0] / rows[2][0]:.2f}, "
              f"evaluation x{rows[1][1] / rows[2][1]:.2f}; stores bit-identical: {same}")

        # per-core breakdown, in this process
        light = make_scene("default", args.frames, args.height, args.width, seed=0)
        for name, config in configs.items():
            start = time.process_time()
            simulate_scene(config, light, seed=0, workers=1)       # one core, like a worker's task
            print(f"simulation alone, {name}: {1e6 * (time.process_time() - start) / light.size:.3f} CPU us "
                  "per pixel-readout")
        frame = tmp / "frame.exr"
        write_exr(frame, np.asarray(make_scene("default", 1, 1080, 1920, seed=0)[0]) * 1000.0)
        start = time.process_time()
        for _ in range(3):
            read_gray(str(frame), "rec709")
        print(f"read + gray one 1920 x 1080 EXR frame (Y channel, ZIP): "
              f"{(time.process_time() - start) / 3 * 1e3:.0f} CPU ms, file {frame.stat().st_size / 1e6:.2f} MB")

        store = tmp / "w1.zarr"
        light_bytes = sum(folder_bytes(store / s.name / "light") for s in sources)
        line = f"bytes on disk per pixel-readout: light {light_bytes / readouts:.3f} (float32, raw 4)"
        for name in configs:
            size = sum(folder_bytes(store / s.name / "streams" / name) for s in sources)
            line += f", {name} words {size / readouts:.3f} (uint8, raw 1)"
        print(line)


if __name__ == "__main__":
    main()
