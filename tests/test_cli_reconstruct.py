"""tespike reconstruct: S.npz -> R.npy, with refusals of bad input (one line, no file)."""

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.io import save_stream
from tespike.recon.methods import reconstruct
from tests.cli import assert_refused, run_tespike


def make_stream(tmp_path, rng, config=SensorConfig()):
    from tespike.golden.decode import legal_words
    words = rng.choice(legal_words(config), size=(11, 3, 4))
    path = tmp_path / "S.npz"
    save_stream(path, words, config)
    return path, words, config


def test_reconstruct_both_methods(tmp_path, rng):
    stream, words, config = make_stream(tmp_path, rng)
    runs = [("tfp", ("--window", 5, "--device", "cpu", "--threads", 1), {"window": 5}),
            ("tfi", ("--search", "window"), {"search": "window"})]
    for method, flags, options in runs:      # each run starts torch: kept to two
        out = tmp_path / f"R_{method}.npy"
        result = run_tespike("reconstruct", "--stream", stream, "--method", method, "--out", out, *flags)
        assert result.returncode == 0, result.stderr
        images = np.load(out)
        assert images.dtype == np.float32 and images.shape == (11, 3, 4)
        assert np.array_equal(images, reconstruct(words, config, method, **options))


def test_refusals(tmp_path, rng):
    stream, _, _ = make_stream(tmp_path, rng, SensorConfig(mode="ml"))
    out = tmp_path / "R.npy"
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    cases = [
        (("--stream", tmp_path / "missing.npz", "--method", "tfp"), ("does not exist",)),
        (("--stream", bad, "--method", "tfp"), ("not a readable",)),
        (("--stream", stream, "--method", "cnn"), ("unknown reconstruction method 'cnn'",)),
        (("--stream", stream, "--method", "tfp", "--window", "4"), ("--window 4", "odd integer")),
        (("--stream", stream, "--method", "tfp", "--device", "cuda:7"), ("device",)),
        (("--stream", stream, "--method", "tfp", "--search", "window"), ("--search",)),
        (("--stream", stream, "--method", "tfi", "--window", "5"), ("--window", "--search window")),
        (("--stream", stream, "--method", "tfp", "--window", "23"), ("--window 23", "11-readout", "21 readouts")),
    ]
    for args, words in cases:
        assert_refused(run_tespike("reconstruct", *args, "--out", out), *words)
        assert not out.exists()
    illegal = tmp_path / "illegal.npz"
    np.savez(illegal, words=np.full((2, 2, 2), 40), config=np.array(SensorConfig().to_json()))
    assert_refused(run_tespike("reconstruct", "--stream", illegal, "--method", "tfi", "--out", out),
                   "readout word 40")
    assert not out.exists()
    assert_refused(run_tespike("reconstruct", "--stream", stream, "--method", "tfi",
                               "--out", tmp_path / "nodir" / "R.npy"), "does not exist")


def test_a_memory_mapped_int64_stream_reconstructs_without_a_torch_warning(tmp_path):
    """SPEC allows int64 words; a memory-mapped int64 stream is read-only, which torch warned about
    on stderr after the success line (uint8 streams are copied anyway)."""
    from tespike.golden.config import SensorConfig
    np.savez(tmp_path / "s.npz", words=np.full((3, 2, 2), 5, np.int64), config=SensorConfig.preset("te").to_json())
    result = run_tespike("reconstruct", "--stream", tmp_path / "s.npz", "--method", "tfp", "--out", tmp_path / "r.npy")
    assert result.returncode == 0 and result.stderr == "", result.stderr


def test_a_stream_written_over_during_the_run_writes_no_reconstruction(tmp_path, rng, monkeypatch, capsys):
    """``dd conv=notrunc`` of another stream onto S.npz while ``reconstruct`` read it gave a
    reconstruction blending the two, exit 0: refused in one line, and no R.npy."""
    import os

    import tespike.recon.methods as methods
    from tespike.cosim.cli import main
    stream, _, _ = make_stream(tmp_path, rng)
    other = tmp_path / "other.npz"
    save_stream(other, np.zeros((11, 3, 4), np.uint8), SensorConfig())
    real = methods.reconstruct

    def written_over_meanwhile(*args, **kwargs):
        images = real(*args, **kwargs)
        data = other.read_bytes()
        with open(stream, "r+b") as handle:                  # in place, as dd conv=notrunc writes
            handle.write(data[:os.path.getsize(stream)])
        info = os.stat(stream)
        os.utime(stream, ns=(info.st_atime_ns, info.st_mtime_ns + 1_000_000))   # (a coarse clock's tick)
        return images
    monkeypatch.setattr(methods, "reconstruct", written_over_meanwhile)
    out = tmp_path / "R.npy"
    assert main(["reconstruct", "--stream", str(stream), "--method", "tfp", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{str(stream)!r} was written over while the command read it" in err[0], err
    assert not out.exists() and not list(tmp_path.glob(".*.part"))
