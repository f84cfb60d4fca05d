"""benchmarks/bench_recon.py runs end to end on a tiny scene (no timing is asserted)."""

import importlib.util
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def test_bench_recon_smoke(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("bench_recon", ROOT / "benchmarks" / "bench_recon.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    scene = bench.hdr_scene(3, 24, 32)
    assert scene.shape == (3, 24, 32) and scene.min() > 0 and scene.max() <= 1
    assert np.any(scene[0] != scene[2])                     # the disc moves
    png = tmp_path / "b.png"
    assert bench.main(["--mode", "ml", "--frames", "2", "--height", "16", "--width", "16",
                       "--threads", "1", "--repeat", "1", "--png", str(png)]) == 0
    out = capsys.readouterr().out
    assert "PSNR-mu" in out and "search=window" in out and png.stat().st_size > 1000
