"""Built-in scenes: determinism, normalisation, exact sub-pixel motion, dynamic range."""

import math

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.golden.io import check_scene
from tespike.recon.scenes import SCENES, make_scene, scene_rng
from tespike.recon.scenes.heldout import EVALUATION_SET, MODERATE_SET, sequence_set
from tespike.recon.scenes.panorama import (DATA_DIR, DEFAULT_PANORAMA_FILE, PANORAMAS, CameraPath, block_mean,
                                   build_default_panorama, load_panorama, render_path,
                                   shipped_panorama_file)
from tespike.recon.scenes.warp import render_window, sample_bilinear
from tests.cli import assert_refused, run_tespike
from tests.conftest import FULL_SIZE_HDRI

SHARED = (FULL_SIZE_HDRI / "courtyard.exr").is_file()
#: Every built-in scene works from a clone (the panoramas from their shipped copies).
LOCAL = list(SCENES)


@pytest.fixture(autouse=True)
def _shipped_panoramas(monkeypatch):
    """Built-in scenes as a clone has them: no full-size folder asked for."""
    monkeypatch.delenv("TESPIKE_HDRI_DIR", raising=False)


# ------------------------------------------------------------------ sampling
def test_half_pixel_shift_of_linear_ramp_is_exact():
    ramp = np.add.outer(3.0 * np.arange(8), 0.25 * np.arange(16))
    ys, xs = np.meshgrid(np.arange(1, 6) + 0.5, np.arange(2, 12) + 0.5, indexing="ij")
    assert np.allclose(sample_bilinear(ramp, ys, xs), 3.0 * ys + 0.25 * xs, rtol=0, atol=1e-12)


def test_pan_moves_by_exactly_the_speed():
    """A pan of 0.5 px per frame over a ramp: frame k is the ramp shifted by 0.5 k."""
    ramp = np.tile(0.5 * np.arange(64.0), (20, 1))
    path = CameraPath(cy=9.5, cx=20.0, vx=0.5)
    frames = render_path(ramp, path, 6, 8, 10)
    for k in range(6):
        assert np.allclose(frames[k], 0.5 * (np.arange(10) - 4.5 + 20.0 + 0.5 * k)[None], atol=1e-12)


def test_integer_pan_wraps_the_longitude_exactly(rng):
    pano = rng.random((16, 40))
    # window centre x = 38.5 for width 6: columns 36..41 -> 36..39, 0, 1
    frame = render_window(pano, 4, 6, cy=7.5, cx=38.5)
    assert np.array_equal(frame, pano[6:10, [36, 37, 38, 39, 0, 1]])


def test_quarter_turn_rotation_indexes_exactly(rng):
    pano = rng.random((21, 21))
    out = render_window(pano, 5, 5, cy=10.0, cx=10.0, angle=math.pi / 2)
    r, c = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
    # xs = cx + v, ys = cy - u with u = c - 2, v = r - 2
    assert np.allclose(out, pano[10 - (c - 2), 10 + (r - 2)], atol=1e-12)


def test_zoom_out_averages_instead_of_aliasing():
    checker = (np.indices((64, 64)).sum(axis=0) % 2).astype(float)
    out = render_window(checker, 8, 8, cy=31.5, cx=31.5, zoom=0.5)
    assert np.allclose(out, 0.5)
    twice = render_window(checker, 8, 8, cy=31.5, cx=31.5, zoom=2.0)
    assert twice.min() >= 0 and twice.max() <= 1


def test_block_mean_keeps_total_light(rng):
    image = rng.random((8, 12))
    small = block_mean(image, 4)
    assert small.shape == (2, 3) and np.isclose(small.sum() * 16, image.sum())
    with pytest.raises(InputError, match="blocks"):
        block_mean(image, 5)


# ------------------------------------------------------------------ registry
@pytest.mark.parametrize("name", LOCAL)
def test_scene_is_deterministic_normalised_and_legal(name):
    a = make_scene(name, 5, 24, 32, seed=7)
    b = make_scene(name, 5, 24, 32, seed=7)
    c = make_scene(name, 5, 24, 32, seed=8)
    assert a.dtype == np.float32 and a.shape == (5, 24, 32)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.max() == 1.0 and a.min() >= 0
    check_scene(a)
    assert make_scene(name, 5, 24, 32, seed=7, peak=1e3).max() == np.float32(1e3)
    assert not np.array_equal(a, make_scene(name, 5, 24, 32, seed=7, heldout=True))


@pytest.mark.parametrize("name", LOCAL)
def test_scene_moves(name):
    light = make_scene(name, 3, 24, 32, seed=1)
    assert not np.array_equal(light[0], light[2])


@pytest.mark.parametrize("name", [n for n in LOCAL if n != "moderate"])
def test_scene_tiny_sizes(name):
    assert make_scene(name, 1, 1, 1).shape == (1, 1, 1)
    assert make_scene(name, 2, 3, 5).max() == 1.0


def test_moderate_scene_refuses_too_small_a_frame():
    with pytest.raises(InputError, match="too small"):
        make_scene("moderate", 2, 3, 5)


@pytest.mark.parametrize("seed", range(4))
def test_moderate_scenes_peak_100_to_300_times_median(seed):
    light = make_scene("moderate", 6, 32, 48, seed=seed)
    assert 100 <= light.max() / np.median(light) <= 300


def test_light_sources_span_1e2_to_1e5_over_background():
    light = make_scene("lights", 6, 48, 64, seed=2).astype(np.float64)
    ratio = light.max() / np.median(light)
    assert 5e4 <= ratio <= 2e5


def test_sun_scene_is_stiff():
    light = make_scene("sun", 4, 48, 64, seed=0).astype(np.float64)
    assert (light == 0).any()                                  # zero-light occluder
    positive = light[light > 0]
    assert positive.min() < 1e-9                               # near-black region
    assert light.max() / np.median(light) > 1e5                # a sun in the frame


@pytest.mark.parametrize("peak", [1e-7, 1e3, 1e30])
def test_extreme_peaks(peak):
    light = make_scene("decades", 2, 8, 64, seed=1, peak=peak)
    assert np.isfinite(light).all() and light.max() == np.float32(peak) and light.min() == 0
    check_scene(light)


def test_decades_scene_spans_twelve_decades_in_one_frame():
    frame = make_scene("decades", 1, 16, 64, seed=0)[0].astype(np.float64)
    positive = frame[frame > 0]
    assert positive.max() / positive.min() > 1e11 and (frame == 0).any()


def test_make_scene_refuses(monkeypatch):
    with pytest.raises(InputError, match="unknown scene"):
        make_scene("nope")
    with pytest.raises(InputError, match="frames"):
        make_scene("moderate", 0)
    with pytest.raises(InputError, match="takes no options"):
        make_scene("sun", 2, 8, 8, motion="pan")
    with pytest.raises(InputError, match="unknown motion"):
        make_scene("default", 2, 8, 8, motion="wobble")
    with pytest.raises(InputError, match="seed"):
        scene_rng("sun", -1)
    with pytest.raises(InputError, match="exceeds"):
        make_scene("moderate", 10_000, 1000, 1000)
    # a window larger than the panorama was filled with copies of its edge rows and repeated columns
    monkeypatch.delenv("TESPIKE_HDRI_DIR", raising=False)       # (the shipped 128 x 256 copies)
    assert make_scene("city", 1, 128, 256).shape == (1, 128, 256)
    for height, width in ((129, 64), (64, 257), (400, 1200)):
        with pytest.raises(InputError, match=rf"{height} x {width} window is larger than the panorama 'city' "
                                             r"\(128 x 256\).*TESPIKE_HDRI_DIR"):
            make_scene("city", 1, height, width)


@pytest.mark.parametrize("motion", ["pan", "tilt", "rotate", "zoom", "mixed"])
def test_default_panorama_motions(motion):
    light = make_scene("default", 4, 32, 48, motion=motion, seed=3)
    assert light.max() == 1.0 and not np.array_equal(light[0], light[3])
    with_sources = make_scene("default", 4, 32, 48, motion=motion, seed=3, sources=2)
    assert not np.array_equal(light, with_sources)


@pytest.mark.parametrize("motion", ["tilt", "rotate", "zoom", "mixed"])
def test_long_camera_paths_stay_within_the_panoramas_rows(motion):
    """A tilt, a turn of a wide window or a zoom-out over many frames ran past the panorama's rows:
    the clamped edge row was shown stretched (in 6-20 % of the data engine's clips). Every sample
    of every frame (the zoom-out's sub-samples too) now lies within the rows, and the camera moves."""
    import math

    from tespike.recon.scenes.panorama import random_path
    from tespike.recon.scenes.warp import window_coords
    rows = load_panorama("default").shape[0]
    frames, height, width = 200, 96, 128
    for seed in range(12):
        path = random_path(np.random.default_rng(seed), motion, (rows, 256), height, width, frames)
        for k in range(frames):
            cy, cx, angle, zoom = path.at(k)
            steps = max(1, math.ceil(1.0 / zoom - 1e-9))
            for offset in {(-0.5 + 0.5 / steps, -0.5 + 0.5 / steps), (0.5 - 0.5 / steps, 0.5 - 0.5 / steps),
                           (-0.5 + 0.5 / steps, 0.5 - 0.5 / steps), (0.5 - 0.5 / steps, -0.5 + 0.5 / steps)}:
                ys, _ = window_coords(height, width, cy, cx, angle, zoom, offset=offset)
                assert -1e-6 <= ys.min() and ys.max() <= rows - 1 + 1e-6, (seed, k, ys.min(), ys.max())
        assert path.at(0) != path.at(frames - 1)


def test_shipped_panorama():
    pano = load_panorama("default")
    assert pano.shape == (128, 256) and np.isfinite(pano).all() and pano.min() > 0
    assert DEFAULT_PANORAMA_FILE.stat().st_size < 300_000
    assert pano.max() / np.median(pano) > 100                   # HDR


def test_the_five_panoramas_ship_small_and_hdr():
    """Every named panorama loads from the package (a clone has no data folder), HDR, small."""
    sizes = 0
    for name in PANORAMAS:
        path = shipped_panorama_file(name)
        sizes += path.stat().st_size if name != "courtyard" else 0
        pano = load_panorama(name)
        assert pano.shape == (128, 256) and np.isfinite(pano).all() and pano.min() > 0, name
        assert pano.max() / np.median(pano) > 300, name                # 4e2 .. 2e4 : 1
        light = make_scene(name, 3, 32, 40, seed=1)
        assert light.shape == (3, 32, 40) and light.max() == 1.0
    assert np.array_equal(load_panorama("courtyard"), load_panorama("default"))
    assert sizes + DEFAULT_PANORAMA_FILE.stat().st_size < 400_000
    assert sorted(p.name for p in DATA_DIR.glob("*.npz")) == sorted(f"{n}_128x256.npz" for n in PANORAMAS)
    assert "CC0" in (DATA_DIR / "README.md").read_text() and all(
        n in (DATA_DIR / "README.md").read_text() for n in PANORAMAS)


@pytest.mark.skipif(not SHARED, reason="full-size HDR panoramas not present (set TESPIKE_HDRI_DIR)")
@pytest.mark.parametrize("name", PANORAMAS)
def test_shipped_panoramas_are_rebuilt_from_the_exr(tmp_path, name):
    dtype = np.float32 if name == "courtyard" else np.float16
    rebuilt = build_default_panorama(FULL_SIZE_HDRI / f"{name}.exr", tmp_path / "p.npz", dtype=dtype)
    with np.load(shipped_panorama_file(name)) as npz:
        assert npz["luminance"].dtype == dtype and np.array_equal(rebuilt, npz["luminance"])


@pytest.mark.skipif(not SHARED, reason="full-size HDR panoramas not present (set TESPIKE_HDRI_DIR)")
def test_full_size_panorama_scene_on_request(monkeypatch):
    monkeypatch.setenv("TESPIKE_HDRI_DIR", str(FULL_SIZE_HDRI))
    assert load_panorama("courtyard").shape == (512, 1024)
    light = make_scene("courtyard", 3, 32, 40, seed=1)
    assert light.shape == (3, 32, 40) and light.max() == 1.0


def test_missing_panorama_folder_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("TESPIKE_HDRI_DIR", str(tmp_path))
    with pytest.raises(InputError, match="TESPIKE_HDRI_DIR"):
        make_scene("city", 2, 8, 8)
    with pytest.raises(InputError, match="neither"):
        load_panorama(tmp_path / "none.exr")


# ------------------------------------------------------------------ sets
def test_evaluation_set_is_held_out():
    labels = [label for label, _, _ in EVALUATION_SET]
    assert len(set(labels)) == len(labels)
    assert set(MODERATE_SET) < set(EVALUATION_SET)
    heldout = dict(sequence_set("heldout", 2, 24, 32))
    for label, name, seed in EVALUATION_SET:
        assert not np.array_equal(heldout[label], make_scene(name, 2, 24, 32, seed=seed))
    assert [label for label, _ in sequence_set("moderate", 2, 24, 32)] == [e[0] for e in MODERATE_SET]
    assert len(sequence_set("default", 2, 12, 16)) == 1
    with pytest.raises(InputError, match="unknown sequence set"):
        sequence_set("training", 2, 8, 8)


# ------------------------------------------------------------------ command
def test_scene_command_writes_the_scene(tmp_path):
    out = tmp_path / "I.npy"
    result = run_tespike("scene", "--name", "sun", "--frames", 3, "--height", 16, "--width", 20,
                         "--seed", 4, "--out", out)
    assert result.returncode == 0, result.stderr
    assert np.array_equal(np.load(out), make_scene("sun", 3, 16, 20, seed=4))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["I.npy"]


def test_scene_command_folder(tmp_path):
    from tespike.recon.scenes.hdr_io import write_hdr
    (tmp_path / "seq").mkdir()
    for i in range(3):
        write_hdr(tmp_path / "seq" / f"f{i}.hdr", np.full((4, 9), 2.0 ** i))
    result = run_tespike("scene", "--folder", tmp_path / "seq", "--out", tmp_path / "I.npy")
    assert result.returncode == 0, result.stderr
    assert np.allclose(np.load(tmp_path / "I.npy")[:, 0, 0], [0.25, 0.5, 1.0])


def test_scene_command_refuses(tmp_path):
    assert_refused(run_tespike("scene", "--name", "nope", "--out", tmp_path / "I.npy"), "nope")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, word", [
    (("--frames", "-2"), "frames"),
    (("--name", "sun", "--motion", "pan"), "--motion applies to the panorama scenes only"),
    (("--name", "moderate", "--sources", "3"), "--sources applies to the panorama scenes only"),
    (("--sources", "-1"), "sources"),
    (("--folder", "."), "no frames"),
    (("--folder", ".", "--crop", "3y4"), "HxW"),
])
def test_scene_command_refusals_in_process(tmp_path, capsys, monkeypatch, args, word):
    from tespike.cosim.cli import main
    monkeypatch.chdir(tmp_path)
    assert main(["scene", *args, "--out", str(tmp_path / "I.npy")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0]
    assert main(["scene", "--out", str(tmp_path / "no" / "I.npy")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_peak_that_would_push_lit_pixels_out_of_float32_is_refused():
    """The peak itself within float32's range is not enough: a scene of many decades scaled to a
    tiny peak put its darker pixels at subnormal values or 0 (84 lit pixels of 'decades' at 1e-35)."""
    from tespike.recon.scenes.color import normalise_sequence
    frames = np.array([[[1.0, 1e-12, 0.0]]])
    with pytest.raises(InputError, match=r"darkest lit value at 1e-47, below float32's normal range"):
        normalise_sequence(frames, 1e-35)
    out = normalise_sequence(frames, 1e-20)
    assert out.dtype == np.float32 and out[0, 0, 1] > 0 and out[0, 0, 2] == 0


@pytest.mark.parametrize("args, options, words", [
    ((["default"],), {}, r"^unknown scene \['default'\] \(known: default, "),
    (("default", 1, 8, 8), {"sources": -1}, r"^scene 'default' sources = -1: must be an integer >= 0$"),
    (("default", 1, 8, 8), {"sources": 2.5}, r"^scene 'default' sources = 2.5: must be an integer >= 0$"),
    (("default", 1, 8, 8), {"sources": True}, r"^scene 'default' sources = True: must be an integer >= 0$"),
    (("default", 1, 8, 8), {"sources": 10 ** 12}, r"^scene 'default' of 1 x 8 x 8 values with 1000000000000 "
                                                  r"sources needs about .* of memory, but only"),
    (("default", 1, 8, 8), {"speed": 3}, r"^scene 'default' takes no options \['speed'\] \(its options: motion, "
                                         r"sources\)$"),
    (("moderate", 1, 8, 8), {"heldout": "False"}, r"^heldout = 'False': must be True or False$"),
], ids=["name-list", "negative-sources", "float-sources", "bool-sources", "sources-past-memory",
        "unknown-option", "heldout-string"])
def test_make_scene_refuses_what_its_generators_cannot_take_in_one_line(args, options, words):
    """Bad sources were numpy's tracebacks (or a MemoryError of terabytes), an unknown option a
    TypeError of an inner function, and ``heldout="False"`` silently gave the held-out scene: the
    training and evaluation split leaked."""
    with pytest.raises(InputError, match=words):
        make_scene(*args, **options)


def test_hdr_sequence_and_panorama_options_are_checked_in_one_line(tmp_path):
    """``max_frames`` of 1.5 or "2" and a crop of 4 or (4, 4, 4) were Python's slice and unpacking
    tracebacks, ``max_frames=True`` loaded one frame, and grayscale weights given for a shipped
    panorama were ignored (it is stored as rec709 luminance)."""
    from tespike.recon.scenes import load_hdr_sequence, load_panorama, write_hdr
    for i in range(2):
        write_hdr(tmp_path / f"f{i}.hdr", np.full((8, 12, 3), 0.5 + i))
    for frames in (1.5, "2", True, 0):
        with pytest.raises(InputError, match=f"^max_frames = {frames!r} must be an integer >= 1$"):
            load_hdr_sequence(tmp_path, max_frames=frames)
    for crop in (4, (4, 4, 4), (4.5, 4), (0, 4)):
        with pytest.raises(InputError, match=r"^crop \(H, W\) "):
            load_hdr_sequence(tmp_path, crop=crop)
    with pytest.raises(InputError, match=r"^unknown grayscale weights \['rec709'\]"):
        load_hdr_sequence(tmp_path, weights=["rec709"])
    assert load_hdr_sequence(tmp_path, crop=(4, 6), max_frames=1).shape == (1, 4, 6)
    with pytest.raises(InputError, match="^unknown grayscale weights 'foo'"):
        load_panorama("default", weights="foo")
    with pytest.raises(InputError, match="^panorama 'default': the shipped copy is stored as rec709 luminance"):
        load_panorama("default", weights="rec601")
