"""The dataset store, synthesis into it and evaluation over it, in this process (no cluster)."""

import csv
import os
import shutil

import numpy as np

import pytest
import zarr

from tespike.cosim.cli import main
from tespike.cosim.dataset.cluster import Runner
from tespike.cosim.dataset.build import build_dataset, hdr_sources, scene_sources
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.fastsim import simulate_scene
from tespike.recon.dataset import DatasetStore, compare_stores, tile_seed
from tespike.recon.dataset.evaluate import evaluate_store
from tespike.recon.scenes import load_hdr_sequence, make_scene
from tespike.recon.scenes.hdr_io import write_exr, write_hdr

CONFIGS = {"te": SensorConfig(mode="te"), "ml": SensorConfig(mode="ml")}


def hdr_folder(root, rng, sequences=(("alpha", 5, 20, 28), ("beta", 3, 18, 22))):
    """Sub-folders of random HDR frames (EXR RGB, and one Radiance file) with a wide range."""
    for name, frames, height, width in sequences:
        (root / name).mkdir(parents=True)
        for k in range(frames):
            rgb = (rng.random((height, width, 3)) ** 6 * 1e3).astype(np.float32)
            if k == 1:
                write_hdr(root / name / f"f{k:03d}.hdr", rgb)
            else:
                write_exr(root / name / f"f{k:03d}.exr", rgb)
    return root


def build(url, sources, seed=7, configs=CONFIGS, **kwargs):
    with Runner() as run:
        return build_dataset(str(url), sources, configs, seed, run, **kwargs)


def test_single_tile_stream_is_simulate_scene_with_the_tile_seed(tmp_path):
    counts = build(tmp_path / "s.zarr", scene_sources(["moderate"], 10, 24, 32), seed=5)
    assert counts == {"done": 1, "skipped": 0, "pixel_readouts": 2 * 10 * 24 * 32,
                      "store": str(tmp_path / "s.zarr"), "rebuilt": []}
    store = DatasetStore.open(tmp_path / "s.zarr")
    light = make_scene("moderate", 10, 24, 32, seed=0)
    assert store.light("moderate").dtype == np.float32
    assert np.array_equal(store.light("moderate").compute(), light)
    for name, config in CONFIGS.items():
        words = store.words("moderate", name)
        assert words.dtype == np.uint8
        expected = simulate_scene(config, light, seed=np.random.default_rng(tile_seed(5, "moderate", config, 0, 0)))
        assert np.array_equal(words.compute(), expected)
        attrs = store.array("moderate", f"streams/{name}").attrs.asdict()
        assert SensorConfig.from_json(attrs["config"]) == config and attrs["seed"] == 5 and attrs["complete"]
    assert store.info("moderate")["complete"] and store.info("moderate")["peak"] == 1.0


def test_hdr_light_equals_load_hdr_sequence_across_chunks_and_tiles(tmp_path, rng):
    root = hdr_folder(tmp_path / "hdr", rng)
    sources = hdr_sources(root)
    assert [(s.name, s.shape) for s in sources] == [("alpha", (5, 20, 28)), ("beta", (3, 18, 22))]
    build(tmp_path / "a.zarr", sources, chunk_frames=2, tile=(8, 8))
    build(tmp_path / "b.zarr", sources, chunk_frames=3, tile=(8, 8))
    store = DatasetStore.open(tmp_path / "a.zarr")
    assert store.sequences() == ["alpha", "beta"]
    for name in ("alpha", "beta"):
        assert np.array_equal(store.light(name).compute(), load_hdr_sequence(root / name))
    # the time chunking is storage only: the streams do not change with it
    other = DatasetStore.open(tmp_path / "b.zarr")
    for name in ("alpha", "beta"):
        for sensor in CONFIGS:
            assert np.array_equal(store.words(name, sensor).compute(), other.words(name, sensor).compute())
    # tiles draw different random streams (they are independent tiles)
    words = store.words("alpha", "te").compute()
    assert not np.array_equal(words[:, :8, :8], words[:, :8, 8:16])


def test_resume_redoes_only_unfinished_parts_and_readers_ignore_them(tmp_path, rng):
    root = hdr_folder(tmp_path / "hdr", rng)
    sources = hdr_sources(root) + scene_sources(["sun"], 6, 16, 16)
    build(tmp_path / "ref.zarr", sources, tile=(8, 8))
    build(tmp_path / "cut.zarr", sources, tile=(8, 8))
    # an interrupted run: one sequence never marked complete, one stream half-written
    group = zarr.open_group(str(tmp_path / "cut.zarr"), mode="r+")
    group["beta"].attrs.update(complete=False)
    group["beta/streams/ml"].attrs.update(complete=False)
    group["beta/streams/ml"][:, :8, :8] = 0
    assert DatasetStore.open(tmp_path / "cut.zarr").sequences() == ["alpha", "sun"]
    assert DatasetStore.open(tmp_path / "cut.zarr").sequences(complete=False) == ["alpha", "beta", "sun"]
    done = []
    with Runner() as run:
        counts = build_dataset(str(tmp_path / "cut.zarr"), sources, CONFIGS, 7, run, tile=(8, 8),
                            report=done.append)
    assert done == ["beta"] and counts["skipped"] == 2
    assert compare_stores(tmp_path / "ref.zarr", tmp_path / "cut.zarr") == []
    # a different seed, sensor list or tile would not match the streams already there
    for kwargs in ({"seed": 8}, {"configs": {"te": CONFIGS["te"]}}, {"tile": (16, 16)}):
        with pytest.raises(InputError, match="resume with the same settings"):
            build(tmp_path / "cut.zarr", sources, **{"tile": (8, 8), **kwargs})


def test_resume_rebuilds_a_complete_sequence_whose_chunk_is_damaged(tmp_path, capsys):
    """A resumed build kept complete sequences unread: a truncated or altered chunk stayed, and only
    ``evaluate --store`` found it (its CRC-32C). The resume now checks them and rebuilds the array."""
    import shutil
    args = ["dataset", "--scene", "sun", "--scene", "default", "--frames", "6", "--height", "16", "--width", "16",
            "--config", "te", "--config", "ml"]
    assert main([*args, "--out", str(tmp_path / "ref.zarr"), "--quiet"]) == 0
    shutil.copytree(tmp_path / "ref.zarr", tmp_path / "cut.zarr")
    light = tmp_path / "cut.zarr" / "sun" / "light" / "c" / "0" / "0" / "0"
    words = tmp_path / "cut.zarr" / "sun" / "streams" / "ml" / "c" / "0" / "0" / "0"
    data = bytearray(light.read_bytes())
    data[len(data) // 2] ^= 0x01
    light.write_bytes(bytes(data))
    words.write_bytes(words.read_bytes()[:10])
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "cut.zarr")]) == 0
    out = capsys.readouterr().out
    assert f"sequence 'sun' was complete, but chunk {str(light)!r} fails its CRC-32C check (and 1 more)" \
        in out, out
    assert "(1 already complete, 1 rebuilt where damaged)" in out, out
    assert compare_stores(tmp_path / "ref.zarr", tmp_path / "cut.zarr") == []
    assert main([*args, "--out", str(tmp_path / "cut.zarr")]) == 0          # nothing left to rebuild
    assert "(2 already complete)" in capsys.readouterr().out


def test_tiled_scores_equal_whole_frame_scores(tmp_path):
    build(tmp_path / "s.zarr", scene_sources(["lights", "decades"], 12, 30, 41), tile=(8, 8))
    with Runner() as run:
        whole = evaluate_store(str(tmp_path / "s.zarr"), run, methods=["tfp", "tfi"])
        tiled = evaluate_store(str(tmp_path / "s.zarr"), run, methods=["tfp", "tfi"], tile=(16, 16))
    assert len(whole.results) == 2 * 2 * 2
    for a, b in zip(whole.results, tiled.results):
        assert (a.sequence, a.sensor, a.method) == (b.sequence, b.sensor, b.method)
        assert a.psnr_mu == pytest.approx(b.psnr_mu, rel=1e-12)
        assert a.ssim_mu == pytest.approx(b.ssim_mu, rel=1e-12)
        assert np.isnan(a.ms_per_frame) and a.frames_scored == 4
    with Runner() as run, pytest.raises(InputError, match="method 'net' is spatial: sequence '.*' has frames larger"):
        evaluate_store(str(tmp_path / "s.zarr"), run, methods=["tfp", "net"], tile=(16, 16))
    with Runner() as run, pytest.raises(InputError, match="--window 25: wider than any window of the 12-readout"):
        evaluate_store(str(tmp_path / "s.zarr"), run, methods=["tfp"], window=25)   # (it was the whole sequence)
    for sequence in ("lights", "decades"):
        for key, image in whole.strips[sequence].items():
            if isinstance(key, tuple):
                assert np.array_equal(image, tiled.strips[sequence][key])


def test_store_scores_equal_the_serial_evaluation(tmp_path):
    """On the same light and words, the store path gives recon.evaluate's numbers exactly."""
    from tespike.recon.evaluate import evaluate

    build(tmp_path / "s.zarr", scene_sources(["moderate"], 12, 24, 32), seed=3)
    store = DatasetStore.open(tmp_path / "s.zarr")
    streams = {m: store.words("moderate", m).compute() for m in CONFIGS}
    serial = evaluate([("moderate", store.light("moderate").compute())],
                      lambda config, light, rng: streams[config.mode], methods=["tfp", "tfi"],
                      sensors=("te", "ml"), configs=CONFIGS, progress=False)
    walked = []

    def progress(total):                                 # (--progress: a bar of the finished tasks)
        def wrap(items):
            for item in items:
                walked.append(total)
                yield item
        return wrap

    with Runner() as run:
        stored = evaluate_store(str(tmp_path / "s.zarr"), run, methods=["tfp", "tfi"], progress=progress)
    assert [(r.sequence, r.sensor, r.method, r.psnr_mu, r.ssim_mu) for r in serial.results] == \
           [(r.sequence, r.sensor, r.method, r.psnr_mu, r.ssim_mu) for r in stored.results]
    assert walked == [4] * 4                             # one sequence x two sensors x two methods


def run_here(capsys, *args):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_dataset_and_evaluate_store(tmp_path, capsys):
    store = tmp_path / "s.zarr"
    SensorConfig(mode="ml", ml_bits=6).save(tmp_path / "ml6.json")
    code, out, err = run_here(capsys, "dataset", "--scene", "lights", "--scene", "sun", "--frames", 10,
                              "--height", 16, "--width", 20, "--config", "te", "--config", tmp_path / "ml6.json",
                              "--out", store, "--seed", 2)
    assert code == 0, err
    assert "wrote 2 sequence(s)" in out and "sun complete" in out
    assert zarr.open_group(str(store), mode="r")["sun/streams/ml6"].dtype == np.uint8
    code, out, err = run_here(capsys, "dataset", "--scene", "lights", "--scene", "sun", "--frames", 10,
                              "--height", 16, "--width", 20, "--config", "te", "--config", tmp_path / "ml6.json",
                              "--out", store, "--seed", 2)
    assert code == 0 and "(2 already complete)" in out, err
    code, out, err = run_here(capsys, "evaluate", "--store", store, "--methods", "tfp", "--out", tmp_path / "ev")
    assert code == 0, err
    assert "| TFP_TE |" in out and "| TFP_ML6 |" in out
    rows = list(csv.DictReader(open(tmp_path / "ev" / "table.csv")))
    assert rows[0]["te_name"] == "TFP_TE" and rows[0]["te_ms_per_frame"] == ""
    assert (tmp_path / "ev" / "strips" / "sun.png").is_file()
    assert not list((tmp_path / "ev").rglob("*.part"))


def test_a_store_another_run_writes_is_refused_and_left_alone(tmp_path, capsys):
    """Two runs writing one new store with other seeds had both ended with exit 0 on a store whose
    chunks mixed their streams, or one removed the store the other was writing: a run holds its store
    (flock on its folder) and a second is refused in one line, before it writes or removes anything."""
    import fcntl
    store = tmp_path / "s.zarr"
    args = ("dataset", "--scene", "lights", "--frames", 4, "--height", 16, "--width", 20, "--config", "te",
            "--out", store)
    code, out, err = run_here(capsys, *args, "--seed", 1)
    assert code == 0, err
    before = {p.relative_to(store): p.read_bytes() for p in store.rglob("*") if p.is_file()}
    held = os.open(store, os.O_RDONLY | os.O_DIRECTORY)       # another run writing it
    try:
        fcntl.flock(held, fcntl.LOCK_EX)
        refused(capsys, *args, "--seed", 2, "is held by another process (another run writing it)")
        (tmp_path / "link.zarr").symlink_to(store)            # the same store through a link: held too
        refused(capsys, *args[:-1], tmp_path / "link.zarr", "--seed", 2, "is held by another process")
        assert {p.relative_to(store): p.read_bytes() for p in store.rglob("*") if p.is_file()} == before
        (tmp_path / "new.zarr").mkdir()                       # an empty folder another run made and holds
        os.close(held)
        held = os.open(tmp_path / "new.zarr", os.O_RDONLY | os.O_DIRECTORY)
        fcntl.flock(held, fcntl.LOCK_EX)
        refused(capsys, *args[:-1], tmp_path / "new.zarr", "is held by another process")
        assert (tmp_path / "new.zarr").is_dir()                  # (not removed as a store this run made)
    finally:
        os.close(held)
    code, out, err = run_here(capsys, *args[:-1], tmp_path / "new.zarr")
    assert code == 0, err


def test_a_store_removed_and_made_again_during_the_run_is_no_success(tmp_path, capsys, monkeypatch):
    """The store removed early in a run: Zarr's next writes made its folders again, under a root without
    the dataset's attributes, and the run ended with exit 0 on a store every command then refused."""
    import shutil

    import zarr

    from tespike.recon.dataset.store import DatasetStore
    real = DatasetStore.create_or_resume.__func__

    def removed_meanwhile(cls, url, **kwargs):
        store = real(cls, url, **kwargs)
        shutil.rmtree(url)                                # (another program, early in the run)
        zarr.open_group(url, mode="w")                    # (a write making the group's folders again)
        return store
    monkeypatch.setattr(DatasetStore, "create_or_resume", classmethod(removed_meanwhile))
    store = tmp_path / "s.zarr"
    code, out, err = run_here(capsys, "dataset", "--scene", "lights", "--frames", 4, "--height", 16, "--width", 20,
                              "--config", "te", "--out", store)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert f"dataset store {str(store)!r} was removed during the run" in lines[0], err


def refused(capsys, *args_and_word):
    *args, word = args_and_word
    code, out, err = run_here(capsys, *args)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and word in lines[0], err
    assert out == "", out              # refused before the command says what it will do


def test_cli_refusals(tmp_path, capsys, rng):
    out = tmp_path / "s.zarr"
    refused(capsys, "dataset", "--scene", "sun", "--out", out, "--config")
    refused(capsys, "dataset", "--config", "te", "--out", out, "nothing to build")
    refused(capsys, "dataset", "--scene", "sun", "--config", "te", "--config", "te", "--out", out, "already given")
    (tmp_path / "ml-msb.json").write_text('{"mode": "te"}')     # (evaluate --store took it for the msb camera)
    refused(capsys, "dataset", "--scene", "sun", "--config", "te", "--config", tmp_path / "ml-msb.json", "--out", out,
            "named as the preset 'ml-msb' but holds another configuration")
    refused(capsys, "dataset", "--scene", "magic", "--config", "te", "--out", out, "magic")
    refused(capsys, "dataset", "--scene", "sun", "--config", "te", "--workers", 0, "--out", out, "--workers")
    refused(capsys, "dataset", "--scene", "sun", "--config", "te", "--workers", 2, "--scheduler",
            "tcp://127.0.0.1:1", "--out", out, "exclude")
    refused(capsys, "dataset", "--hdr", tmp_path / "none", "--config", "te", "--out", out, "none")
    (tmp_path / "empty" / "seq").mkdir(parents=True)
    refused(capsys, "dataset", "--hdr", tmp_path / "empty", "--config", "te", "--out", out, "no frames")
    assert not out.exists()
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "keep.txt").write_text("mine")
    refused(capsys, "dataset", "--scene", "sun", "--config", "te", "--out", tmp_path / "taken", "not a dataset store")
    assert (tmp_path / "taken" / "keep.txt").read_text() == "mine"
    # frames of different sizes in one sequence: refused from the frames' headers, before the
    # plan line (it was found by the task that read the frame, after the plan was printed)
    root = hdr_folder(tmp_path / "hdr", rng, sequences=(("odd", 2, 12, 12),))
    write_exr(root / "odd" / "f009.exr", np.ones((12, 13, 3), np.float32))
    code, out_text, err = run_here(capsys, "dataset", "--hdr", root, "--config", "te", "--out", tmp_path / "o.zarr")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "f009.exr' is 12 x 13" in err, err
    assert out_text == ""
    assert not (tmp_path / "o.zarr").exists()
    DatasetStore.create_or_resume(str(tmp_path / "o.zarr"), seed=0, configs={"te": SensorConfig()})
    refused(capsys, "evaluate", "--store", tmp_path / "o.zarr", "--out", tmp_path / "ev", "no complete sequence")
    refused(capsys, "evaluate", "--store", tmp_path / "nope.zarr", "--out", tmp_path / "ev", "does not exist")
    code, out_text, _ = run_here(capsys, "evaluate", "--store", tmp_path / "taken", "--out", tmp_path / "ev")
    assert code == 2 and out_text == ""                    # refused before the "evaluate: ... on" line
    refused(capsys, "evaluate", "--store", tmp_path / "taken", "--out", tmp_path / "ev", "is a folder but not a dataset store")
    refused(capsys, "evaluate", "--store", tmp_path / "o.zarr", "--set", "moderate", "--out", tmp_path / "ev", "--set")
    refused(capsys, "evaluate", "--workers", 2, "--out", tmp_path / "ev", "--store")
    assert not (tmp_path / "ev").exists()


def test_a_failure_after_the_build_says_the_store_is_kept_for_a_resume(tmp_path, capsys, monkeypatch):
    """A run that fails once its sequences are complete (here: while its cluster closes, as one
    starved of memory can) keeps the store and says so in its line, as a failure during the build does."""
    from tespike.cosim.dataset import cluster

    def failing_exit(self, *exc):
        raise RuntimeError("can't start new thread")
    monkeypatch.setattr(cluster.Runner, "__exit__", failing_exit)
    out = tmp_path / "D.zarr"
    code, _, err = run_here(capsys, "dataset", "--scene", "default", "--frames", "4", "--height", "16", "--width",
                            "16", "--config", "te", "--progress", "off", "--out", out)
    assert code != 0 and len(err.strip().splitlines()) == 1, err
    assert f"(store {str(out)!r} keeps 1 complete sequence(s); the same command resumes it)" in err, err
    assert out.is_dir()


def test_store_scores_the_frames_the_serial_evaluation_scores_with_a_learned_method(tmp_path):
    """A sequence longer than a learned method's span: both evaluations score only the frames whose
    span lies inside it (the store scored the window's frames, so its cells differed from the
    serial evaluation's)."""
    from tespike.recon.evaluate import evaluate, learned_span, scored_frames

    frames = 66
    build(tmp_path / "s.zarr", scene_sources(["moderate"], frames, 16, 16), seed=3, configs={"te": CONFIGS["te"]})
    store = DatasetStore.open(tmp_path / "s.zarr")
    words = store.words("moderate", "te").compute()
    serial = evaluate([("moderate", store.light("moderate").compute())], lambda config, light, rng: words,
                      methods=["tfp", "net"], sensors=("te",), configs={"te": CONFIGS["te"]}, progress=False,
                      repeats=1)
    with Runner() as run:
        stored = evaluate_store(str(tmp_path / "s.zarr"), run, methods=["tfp", "net"])
    expected = scored_frames(frames, 9, learned_span(["net"]))
    assert expected.stop - expected.start < frames - 8          # the span, not the window, decides
    assert stored.span == serial.span == learned_span(["net"])
    for a, b in zip(serial.results, stored.results):
        assert a.method == b.method and a.frames_scored == b.frames_scored == expected.stop - expected.start
        assert a.psnr_mu == pytest.approx(b.psnr_mu, abs=1e-3) and a.ssim_mu == pytest.approx(b.ssim_mu, abs=1e-4)


@pytest.mark.parametrize("extra, words", [
    (("--scene", "sun", "--grayscale", "rec601"), ("--grayscale", "--hdr")),
    (("--hdr", "HDR", "--height", "16"), ("--height", "--scene")),
    (("--hdr", "HDR", "--width", "16"), ("--width", "--scene")),
])
def test_an_option_of_a_source_not_given_is_refused(tmp_path, capsys, extra, words):
    """--grayscale with built-in scenes only, or --height / --width with HDR folders only, was
    dropped without a word (the store was that of a run without it)."""
    import re
    (tmp_path / "HDR").mkdir()
    extra = tuple(str(tmp_path / a) if a == "HDR" else a for a in extra)
    assert main(["dataset", *extra, "--config", "te", "--out", str(tmp_path / "d.zarr")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and re.search(".*".join(words), err), err
    assert not (tmp_path / "d.zarr").exists()


def _tamper(path, change):
    import json
    document = json.loads(path.read_text())
    change(document, document.get("attributes", {}))
    path.write_text(json.dumps(document))


STORE_DAMAGE = {
    "a deleted chunk file": (lambda s: (s / "sun/streams/te/c/0/0/0").unlink(), "holds 0 of the 1 chunk files"),
    "seed not a number": (lambda s: _tamper(s / "zarr.json", lambda d, a: a.update(seed="abc")), "attribute seed"),
    "configs missing": (lambda s: _tamper(s / "zarr.json", lambda d, a: a.pop("configs")), "configs is missing"),
    "configs a list": (lambda s: _tamper(s / "zarr.json", lambda d, a: a.update(configs=[])), "attribute configs"),
    "tile a number": (lambda s: _tamper(s / "zarr.json", lambda d, a: a.update(tile=5)), "attribute tile"),
    "chunk_frames text": (lambda s: _tamper(s / "zarr.json", lambda d, a: a.update(chunk_frames="x")), "chunk_frames"),
    "peak missing": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: a.pop("peak")), "peak is missing"),
    "peak text": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: a.update(peak="x")), "attribute peak"),
    # (above the light's maximum every score rose: PSNR-mu 550 dB, exit 0)
    "peak above the light's": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: a.update(peak=2.0)),
                               "records peak 2, its light's maximum is 1"),
    "frames altered": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: a.update(frames=10)), "has shape"),
    "height text": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: a.update(height="abc")), "attribute height"),
    "stream config gone": (lambda s: _tamper(s / "sun/streams/te/zarr.json", lambda d, a: a.pop("config")),
                           "another configuration"),
    "stream shape altered": (lambda s: _tamper(s / "sun/streams/te/zarr.json", lambda d, a: d.update(shape=[8, 16, 16])),
                             "has shape (8, 16, 16)"),
    "sequence zarr.json gone": (lambda s: (s / "sun/zarr.json").unlink(), "zarr.json' is missing"),
    "a stream removed": (lambda s: shutil.rmtree(s / "sun/streams/te"), "its array streams/te is missing"),
    "the light removed": (lambda s: shutil.rmtree(s / "sun/light"), "its array light is missing"),
    "a stream never finished": (lambda s: _tamper(s / "sun/streams/te/zarr.json", lambda d, a: a.update(complete=False)),
                                "its array streams/te was never finished"),
    # (Zarr's words showed both checksums as Python bytes)
    "a chunk byte flipped": (lambda s: _flip_middle(s / "sun/light/c/0/0/0"),
                             "c/0/0/0' is damaged (its CRC-32C does not match its bytes)"),
    # JSON, but not metadata Zarr reads (a flipped byte renames a key): Zarr's TypeError was a traceback
    "a sequence's key renamed": (lambda s: _rename_key(s / "sun/zarr.json", "attributes"), "sun/zarr.json' is damaged"),
    "an array's codec key renamed": (lambda s: _rename_key(s / "sun/light/zarr.json", "endian"),
                                     "light/zarr.json' is damaged"),
    # a node_type Zarr does not know was its ValueError traceback; a sequence's read as an array was
    # "holds no complete sequence"; the root's "holds no zarr.json"
    "a sequence's node_type unknown": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: d.update(node_type="x")),
                                       "sun/zarr.json' is damaged (its node_type is 'x')"),
    "a sequence's node_type array": (lambda s: _tamper(s / "sun/zarr.json", lambda d, a: d.update(node_type="array")),
                                     "sun/zarr.json' is damaged (its node_type is 'array')"),
    "an array's node_type unknown": (lambda s: _tamper(s / "sun/light/zarr.json", lambda d, a: d.update(node_type="x")),
                                     "light/zarr.json' is damaged"),
    "the root's node_type unknown": (lambda s: _tamper(s / "zarr.json", lambda d, a: d.update(node_type="x")),
                                     "its node_type is 'x', not 'group'"),
}


def _flip_middle(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def _rename_key(path, key):
    path.write_text(path.read_text().replace(f'"{key}"', f'"{key[:-1]}x"', 1))


@pytest.fixture(scope="module")
def small_store(tmp_path_factory):
    import contextlib
    import io
    root = tmp_path_factory.mktemp("store")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                     "--config", "te", "--config", "ml-msb", "--out", str(root / "D.zarr"), "-q"]) == 0
    return root / "D.zarr"


@pytest.mark.parametrize("damage", sorted(STORE_DAMAGE))
def test_evaluate_store_refuses_a_store_whose_metadata_or_chunks_were_altered(tmp_path, capsys, small_store, damage):
    """Each was a traceback (attributes read unchecked) or, worse, scores with exit 0: a deleted
    chunk read as zeros, a stream of another shape or configuration, a sequence without its
    zarr.json left out of the table's means."""
    import shutil
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    change, words = STORE_DAMAGE[damage]
    change(store)
    capsys.readouterr()
    assert main(["evaluate", "--store", str(store), "--out", str(tmp_path / "E"), "--methods", "tfp", "-q"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and words in err, err
    assert not (tmp_path / "E").exists()


@pytest.mark.parametrize("damage", ["cut", "a key renamed", "node_type unknown", "node_type array"])
def test_resume_rebuilds_a_sequence_whose_metadata_is_damaged(tmp_path, capsys, small_store, damage):
    """A sequence's zarr.json cut short or with a key renamed: the resume died in Zarr's JSONDecodeError
    or TypeError (a traceback); it now makes the sequence anew, as for a damaged chunk, and says so."""
    import shutil
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    meta = store / "sun" / "zarr.json"
    if damage == "cut":
        meta.write_bytes(meta.read_bytes()[:96])
    elif damage.startswith("node_type"):
        _tamper(meta, lambda d, a: d.update(node_type=damage.split()[1]))
    else:
        _rename_key(meta, "attributes")
    capsys.readouterr()
    assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                 "--config", "te", "--config", "ml-msb", "--out", str(store)]) == 0
    out = capsys.readouterr().out
    assert f"{str(meta)!r} is damaged" in out and "rebuilt where damaged" in out, out
    assert compare_stores(small_store, store) == []


def test_a_store_removed_while_it_is_read_is_named_gone(tmp_path, small_store):
    """A store (or a sequence's array) removed during ``evaluate --store`` was Zarr's "No array found
    in store file://... at path ..." or a KeyError traceback."""
    import shutil

    from tespike.recon.dataset.store import DatasetStore
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    opened = DatasetStore.open(str(store))
    shutil.rmtree(store / "sun" / "streams" / "te")
    with pytest.raises(InputError, match=r"'sun/streams/te' is gone \(removed while the run read it"):
        opened.words("sun", "te")
    # as a Dask worker sends it back: pickled with its context, which Zarr's ArrayNotFoundError (not
    # unpickled) had turned into a bare Exception(repr), a traceback of evaluate --store --workers 2
    from distributed.core import error_message
    from distributed.protocol import pickle

    from tespike.recon.dataset.store import open_array
    with pytest.raises(InputError, match=r"'sun/streams/te' is gone \(removed while the run read it") as gone:
        open_array(str(store), "sun/streams/te")
    sent = pickle.loads(error_message(gone.value)["exception"].data)
    assert type(sent) is InputError and str(sent) == str(gone.value)
    from tespike.recon.dataset.store import mark_complete
    with pytest.raises(InputError, match=r"'sun/streams/te' is gone \(removed while the run read it"):
        mark_complete(str(store), "sun/streams/te")      # (the last write of a part: Zarr's traceback)
    shutil.rmtree(store)
    with pytest.raises(InputError, match=r"dataset store '.*D\.zarr' is gone: it was removed or moved"):
        opened.light("sun")
    with pytest.raises(InputError, match=r"^dataset store '.*D\.zarr' does not exist$"):
        compare_stores(str(small_store), str(store))


def test_resume_rebuilds_an_array_whose_chunk_file_was_deleted(tmp_path, capsys, small_store):
    """The resume checked the CRC of the chunk files present only: a deleted one was never noticed
    ("1 already complete") and read as zeros."""
    import shutil
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    (store / "sun/light/c/0/0/0").unlink()
    capsys.readouterr()
    assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                 "--config", "te", "--config", "ml-msb", "--out", str(store)]) == 0
    assert "of its 1 chunk files missing: rebuilding what is damaged" in capsys.readouterr().out
    assert compare_stores(small_store, store) == []


@pytest.mark.parametrize("part", ["streams/te", "light"])
def test_resume_rebuilds_an_array_removed_from_a_complete_sequence(tmp_path, capsys, small_store, part):
    """The resume called a sequence whose array was removed complete ("1 already complete"), left a new
    empty array in its place, and evaluate --store scored its fill value with exit 0."""
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    shutil.rmtree(store / "sun" / part)
    capsys.readouterr()
    assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                 "--config", "te", "--config", "ml-msb", "--out", str(store)]) == 0
    assert f"its array {part} is missing or unfinished: rebuilding" in capsys.readouterr().out
    assert compare_stores(small_store, store) == []


def test_a_file_given_as_a_store_is_named_a_file(tmp_path, capsys):
    """A file at the store's path was said not to exist."""
    (tmp_path / "F.zarr").write_text("hi")
    assert main(["evaluate", "--store", str(tmp_path / "F.zarr"), "--out", str(tmp_path / "E")]) == 2
    assert "is a file, not a dataset store" in capsys.readouterr().err


def test_a_link_to_nothing_given_as_a_store_is_named_so(tmp_path, capsys):
    """A symlink loop (or a dangling link) at the store's path was called a file."""
    (tmp_path / "L.zarr").symlink_to(tmp_path / "L.zarr")
    assert main(["evaluate", "--store", str(tmp_path / "L.zarr"), "--out", str(tmp_path / "E")]) == 2
    assert "is a link to nothing (a loop, or a target that is gone)" in capsys.readouterr().err


def test_a_zarr_format_2_store_is_refused_untouched(tmp_path, capsys):
    """A Zarr-v2 group with the store's attributes made `dataset` fail with a traceback after it
    had replaced a sequence's arrays with version-2 groups."""
    import zarr
    from tespike.golden.config import SensorConfig
    store = tmp_path / "v2"
    group = zarr.open_group(str(store), mode="w", zarr_format=2)
    group.attrs.update({"format": "tespike-dataset", "version": 1, "seed": 0,
                        "configs": {"te": SensorConfig.preset("te").to_dict()}, "tile": [256, 256],
                        "chunk_frames": 16})
    before = sorted(p.relative_to(store) for p in store.rglob("*"))
    assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                 "--config", "te", "--out", str(store)]) == 2
    assert "is a Zarr format 2 store; tespike dataset stores are Zarr format 3" in capsys.readouterr().err
    assert sorted(p.relative_to(store) for p in store.rglob("*")) == before
    assert main(["evaluate", "--store", str(store), "--out", str(tmp_path / "E")]) == 2
    assert "Zarr format 2" in capsys.readouterr().err


def test_an_illegal_stored_word_is_named_with_its_store_sequence_and_stream(tmp_path, capsys, small_store):
    """The refusal named the word and its index only: which store, sequence and stream it was in, not."""
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    zarr.open(str(store / "sun/streams/te"), mode="r+")[1, 5, 7] = 16      # no TE word of the preset
    capsys.readouterr()
    assert main(["evaluate", "--store", str(store), "--out", str(tmp_path / "E"), "--methods", "tfp",
                 "-q"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and f"dataset store {str(store)!r}, sequence 'sun', stream 'te': readout " \
        "word 16 at index (1, 5, 7)" in err, err                         # (readout, row, column), not flattened
    zarr.open(str(store / "sun/streams/te"), mode="r+")[1, 5, 7] = 0
    zarr.open(str(store / "sun/streams/te"), mode="r+")[2, 12, 13] = 16
    with Runner() as run, pytest.raises(InputError, match=r"word 16 at index \(2, 12, 13\)"):
        evaluate_store(str(store), run, methods=["tfp"], tile=(8, 8))   # a tile's word, named in its frame


def test_a_resume_refuses_frames_rewritten_since_and_rebuilds_an_unfinished_sequence_from_them(tmp_path, rng):
    """Frames rewritten in place between two runs (the same names, sizes and shapes) are not
    mixed into one store: a complete sequence made from the old bytes is refused in one line,
    an unfinished one is made again from the new frames, bit for bit as a fresh build."""
    root = hdr_folder(tmp_path / "hdr", rng)
    build(tmp_path / "d.zarr", hdr_sources(root), tile=(8, 8))
    frame = root / "beta" / "f002.exr"
    write_exr(frame, (rng.random((18, 22, 3)) ** 6 * 1e3).astype(np.float32))     # rewritten in place
    with pytest.raises(InputError, match="'beta' .* frames whose files have changed since") as caught:
        build(tmp_path / "d.zarr", hdr_sources(root), tile=(8, 8))
    assert "\n" not in str(caught.value) and not getattr(caught.value, "__notes__", None)   # no "resumes it"
    group = zarr.open_group(str(tmp_path / "d.zarr"), mode="r+")
    group["beta"].attrs.update(complete=False)                                     # as an interrupted run leaves it
    build(tmp_path / "d.zarr", hdr_sources(root), tile=(8, 8))
    build(tmp_path / "fresh.zarr", hdr_sources(root), tile=(8, 8))
    assert compare_stores(tmp_path / "fresh.zarr", tmp_path / "d.zarr") == []
    assert np.array_equal(DatasetStore.open(tmp_path / "d.zarr").light("beta").compute(),
                          load_hdr_sequence(root / "beta"))


def test_a_full_disk_while_a_resume_checks_its_sequences_says_a_rerun_resumes(tmp_path, monkeypatch):
    """A refusal of the store as it stands has no "resumes it" note (a rerun would be refused
    again); a full disk met while the sequences are checked has it, as anywhere else."""
    import errno
    sources = scene_sources(["sun", "moderate"], 4, 16, 16)
    build(tmp_path / "d.zarr", sources[:1])
    prepare = DatasetStore.prepare_sequence

    def full(self, name, *rest):
        if name == "moderate":
            raise OSError(errno.ENOSPC, "No space left on device")
        return prepare(self, name, *rest)

    monkeypatch.setattr(DatasetStore, "prepare_sequence", full)
    with pytest.raises(InputError, match="cannot write dataset store") as caught:
        build(tmp_path / "d.zarr", sources)
    assert any(note.endswith("the same command resumes it)") for note in caught.value.__notes__)


@pytest.mark.parametrize("damage", ["a deleted chunk file", "peak missing", "peak text", "stream config gone",
                                    "stream shape altered", "a stream removed", "the light removed",
                                    "a stream never finished"])
def test_a_resume_repairs_what_evaluate_store_refuses_in_a_sequence(tmp_path, capsys, small_store, damage):
    """evaluate --store refuses a damaged sequence and says to run tespike dataset again: that run
    rebuilds it (it called an edited stream "already complete" and repaired nothing), bit for bit."""
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    STORE_DAMAGE[damage][0](store)
    capsys.readouterr()
    assert main(["evaluate", "--store", str(store), "--out", str(tmp_path / "E"), "--methods", "tfp", "-q"]) == 2
    assert "tespike dataset" in capsys.readouterr().err                 # (it says to run it again)
    assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                 "--config", "te", "--config", "ml-msb", "--out", str(store), "-q"]) == 0
    assert compare_stores(small_store, store) == []
    assert main(["evaluate", "--store", str(store), "--out", str(tmp_path / "E"), "--methods", "tfp", "-q"]) == 0


def test_a_sequence_named_as_zarrs_metadata_file_is_refused(tmp_path, capsys, rng):
    """An HDR sub-folder named zarr.json collided with the store's own file ('File exists')."""
    root = hdr_folder(tmp_path / "hdr", rng, sequences=(("zarr.json", 2, 12, 12),))
    code, _, err = run_here(capsys, "dataset", "--hdr", root, "--config", "te", "--out", tmp_path / "o.zarr")
    assert code == 2 and "'zarr.json' is reserved" in err and not (tmp_path / "o.zarr").exists()


@pytest.mark.parametrize("inside", ["D.zarr", "seq/D.zarr"])
def test_a_store_inside_an_hdr_folder_is_refused(tmp_path, capsys, rng, inside):
    """``--out HD/D.zarr`` was built once; the next run read the store as a sequence folder without
    frames, so the same command (the documented resume) was refused for ever."""
    root = hdr_folder(tmp_path / "hdr", rng, sequences=(("seq", 2, 12, 12),))
    code, _, err = run_here(capsys, "dataset", "--hdr", root, "--config", "te", "--out", root / inside)
    assert code == 2 and len(err.splitlines()) == 1 and f"lies inside --hdr {str(root)!r}" in err, err
    assert not (root / inside).exists()


def test_hdr_light_below_float32s_normal_range_is_refused(tmp_path, capsys):
    """A sequence whose darkest lit pixel is below float32's normal range once its brightest is 1 was stored
    with half its lit pixels 0 (exit 0), where scene --folder and evaluate --folder refuse it."""
    (tmp_path / "hdr" / "deep").mkdir(parents=True)
    for k in range(2):
        rgb = np.full((12, 12, 3), 1e-12, np.float32)
        rgb[0, 0] = 1e30                                   # (Radiance's exponent holds both)
        write_hdr(tmp_path / "hdr" / "deep" / f"f{k}.hdr", rgb)
    code, _, err = run_here(capsys, "dataset", "--hdr", tmp_path / "hdr", "--config", "te", "--out", tmp_path / "d.zarr")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "below float32's normal range" in err, err
    assert "f0.hdr" in err or "f1.hdr" in err


def test_resume_rebuilds_a_sequence_whose_size_attribute_is_damaged(tmp_path, capsys, small_store):
    """A complete sequence whose width attribute was lost: the resume said it 'was made with width = None,
    not 16', blaming the flags for damage; it is made again, as other damage is."""
    import shutil
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    _tamper(store / "sun/zarr.json", lambda d, a: a.pop("width"))
    capsys.readouterr()
    assert main(["dataset", "--scene", "sun", "--frames", "4", "--height", "16", "--width", "16",
                 "--config", "te", "--config", "ml-msb", "--out", str(store)]) == 0
    out = capsys.readouterr().out
    assert "its attribute width is None" in out and "rebuilt where damaged" in out, out
    assert compare_stores(small_store, store) == []


def test_results_inside_the_store_they_score_are_refused(tmp_path, capsys, small_store):
    """evaluate --store D.zarr --out D.zarr/ev wrote its results among the sequences, exit 0."""
    import shutil
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)
    capsys.readouterr()
    assert main(["evaluate", "--store", str(store), "--out", str(store / "ev"), "--methods", "tfp", "-q"]) == 2
    assert "lies inside --store" in capsys.readouterr().err and not (store / "ev").exists()


def test_light_from_frames_replaced_during_the_run_is_never_marked_complete(tmp_path):
    """A frame replaced while dataset --hdr ran gave a store with its light under the old frames' digest:
    refused, and a resume with the old frames back called the mixed store complete."""
    from tespike.cosim.dataset.build import finish_light
    from tespike.recon.scenes.hdr_io import write_hdr
    seq = tmp_path / "H" / "seq"
    seq.mkdir(parents=True)
    for i in range(2):
        write_hdr(seq / f"f{i}.hdr", np.full((4, 4, 3), 1.0 + i, np.float32))
    source, = hdr_sources(tmp_path / "H")
    write_hdr(seq / "f1.hdr", np.full((4, 4, 3), 7.0, np.float32))       # replaced mid-run
    with pytest.raises(InputError, match="frames of sequence 'seq' changed while this run read them"):
        finish_light(str(tmp_path / "D.zarr"), "seq/light", [1.0], 2.0, source)


def test_a_thread_that_cannot_start_is_no_damaged_store(tmp_path, capsys, small_store, monkeypatch):
    """Zarr reads through a thread pool: with no room for a thread (``ulimit -v``, too many processes)
    its RuntimeError was taken for a damaged file, so ``evaluate --store`` told the user to rebuild a
    sound store, and a resumed ``dataset`` removed a sound sequence to make it anew."""
    import shutil
    store = tmp_path / "D.zarr"
    shutil.copytree(small_store, store)

    def no_thread(*args, **kwargs):
        raise RuntimeError("can't start new thread")
    monkeypatch.setattr(zarr, "open_array", no_thread)
    monkeypatch.setattr(zarr, "open", no_thread)
    monkeypatch.setattr(zarr.Group, "__getitem__", no_thread)
    capsys.readouterr()
    assert main(["evaluate", "--store", str(store), "--out", str(tmp_path / "E"), "--methods", "tfp", "-q"]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "cannot start a thread" in err and "damaged" not in err, err
    with pytest.raises(RuntimeError, match="can't start new thread"):
        DatasetStore.open(str(store))._rebuild_if_unreadable("sun")
    monkeypatch.undo()
    assert compare_stores(small_store, store) == []


@pytest.mark.parametrize("mode", ["w", "w-", "a", "x", None])
def test_open_refuses_a_mode_that_would_write_and_leaves_the_folder_alone(tmp_path, mode):
    """Zarr's 'w' clears the folder it is given: DatasetStore.open(folder, 'w') had emptied it (a
    library call on /tmp emptied /tmp)."""
    from tespike.recon.dataset import DatasetStore
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(InputError, match=f"^dataset store mode {mode!r}: must be 'r' or 'r\\+'"):
        DatasetStore.open(tmp_path, mode)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"] and (tmp_path / "keep.txt").read_text() == "mine"
    from tespike.recon.dataset.store import open_array
    with pytest.raises(InputError, match=f"^dataset store array mode {mode!r}: must be 'r' or 'r\\+'$"):
        open_array(tmp_path, "a", mode)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_a_store_that_is_no_path_or_a_seed_that_is_no_count_is_refused_in_one_line(tmp_path):
    """``DatasetStore.open(3)`` said the store "does not exist", and ``create_or_resume`` took a seed of
    2.5 as 2 (``int()``), a store whose streams no one asked for."""
    from tespike.recon.dataset import DatasetStore
    with pytest.raises(InputError, match="^dataset store: a path must be a str or an os.PathLike, not int$"):
        DatasetStore.open(3)
    with pytest.raises(InputError, match="^dataset store: a path must be a str or an os.PathLike, not list$"):
        DatasetStore.create_or_resume([str(tmp_path)], seed=1, configs={"te": SensorConfig()})
    for seed in (2.5, -1, True, "1"):
        with pytest.raises(InputError, match=f"^dataset store seed {seed!r}: must be an integer >= 0$"):
            DatasetStore.create_or_resume(tmp_path / "s.zarr", seed=seed, configs={"te": SensorConfig()})
    assert not (tmp_path / "s.zarr").exists()


def test_store_sizes_and_sequence_attributes_are_checked_before_anything_is_written(tmp_path):
    """A tile of (2.5, 4) was stored as (2, 4), chunk_frames 2.5 as 2; a tile of (0, 4) or no
    configuration wrote the store and then called it altered; a sequence's shape of (2.5, 4, 4) made
    K = 2, a source of 5 was stored; ``tiles(5, 5, (0, 4))`` was a ZeroDivisionError."""
    from tespike.recon.dataset import DatasetStore
    from tespike.recon.dataset.store import tiles
    url = tmp_path / "s.zarr"
    for options, words in (({"tile": (2.5, 4)}, r"^dataset store tile \(rows, cols\) \(2.5, 4\)"),
                           ({"tile": (0, 4)}, r"^dataset store tile \(rows, cols\) \(0, 4\)"),
                           ({"chunk_frames": 2.5}, r"^dataset store chunk_frames 2.5: must be an integer >= 1$"),
                           ({"chunk_frames": True}, r"^dataset store chunk_frames True: must be an integer >= 1$"),
                           ({"configs": {}}, r"^dataset store configs: must map one or more sensor names")):
        with pytest.raises(InputError, match=words):
            DatasetStore.create_or_resume(url, **{"seed": 0, "configs": {"te": SensorConfig()}, **options})
        assert not url.exists()
    store = DatasetStore.create_or_resume(url, seed=0, configs={"te": SensorConfig()})
    for shape, source, words in (((2.5, 4, 4), "x", r"shape \(2.5, 4, 4\): must be \(K, H, W\), integers >= 1$"),
                                 ((True, 4, 4), "x", r"shape \(True, 4, 4\): must be"),
                                 ((2, 4, 4), 5, "source 5: must be text$")):
        with pytest.raises(InputError, match="^sequence 'a' " + words):
            store.prepare_sequence("a", shape, source)
    with pytest.raises(InputError, match=r"^tile \(rows, cols\) \(0, 4\): H and W must be integers of at least 1$"):
        tiles(5, 5, (0, 4))


def test_the_store_builders_and_evaluation_refuse_names_counts_and_runners_that_are_none(tmp_path, small_store):
    """``hdr_sources(folder, max_frames=-1)`` had dropped the last frame and True kept one; a scene's
    name given as text was read letter by letter ("unknown scene 'd'"), and so were evaluate_store's
    methods ("unknown method 't'"); a tile of 0 was a ZeroDivisionError, a run of None a TypeError after
    the planning, and options for a method not run were dropped without a word."""
    for frames in (-1, True, 2.5):
        with pytest.raises(InputError, match=f"^max_frames = {frames!r}: must be an integer >= 1$"):
            hdr_sources(tmp_path, max_frames=frames)
    with pytest.raises(InputError, match=r"^unknown grayscale weights \['rec709'\]"):
        hdr_sources(tmp_path, weights=["rec709"])
    assert [s.name for s in scene_sources("default", 2, 8, 8)] == ["default"]
    run = Runner(workers=1)
    with pytest.raises(InputError, match=r"^tile \(rows, cols\) \(0, 4\): H and W must be integers of at least 1$"):
        evaluate_store(small_store, run, tile=(0, 4))
    with pytest.raises(InputError, match="^run: must run the evaluation's tasks"):
        evaluate_store(small_store, None)
    with pytest.raises(InputError, match=r"^options for 'tfi': no method of this evaluation \(tfp\) has that name$"):
        evaluate_store(small_store, run, methods="tfp", options={"tfi": {"search": "window"}})
