"""HDR files: RGBE codec on known bytes, .hdr reader/writer, EXR, frame folders."""

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.recon.scenes import hdr_io
from tespike.recon.scenes.color import normalise_sequence, to_gray
from tespike.recon.scenes.hdr_io import (float_to_rgbe, list_frames, load_hdr_sequence, read_exr, read_hdr,
                                 rgbe_to_float, write_exr, write_hdr)
from tests.conftest import FULL_SIZE_HDRI

HEADER = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n"


def test_rgbe_known_bytes_decode():
    pixels = np.array([[128, 64, 32, 129],      # 2^(129-136) = 1/128 per mantissa step
                       [255, 0, 1, 136],        # exponent 136: mantissa is the value
                       [200, 100, 50, 0],       # exponent 0 is black whatever the mantissas
                       [1, 2, 3, 120]], np.uint8)
    expected = np.array([[1.0, 0.5, 0.25], [255.0, 0.0, 1.0], [0.0, 0.0, 0.0],
                         [2.0 ** -16, 2.0 ** -15, 3 * 2.0 ** -16]], np.float32)
    assert np.array_equal(rgbe_to_float(pixels), expected)


def test_rgbe_known_values_encode():
    rgb = np.array([[1.0, 0.5, 0.25], [0.0, 0.0, 0.0], [1e-40, 0, 0], [3.0, 1.0, 0.0]])
    expected = np.array([[128, 64, 32, 129], [0, 0, 0, 0], [0, 0, 0, 0], [192, 64, 0, 130]], np.uint8)
    assert np.array_equal(float_to_rgbe(rgb), expected)


@pytest.mark.parametrize("bad", [np.array([[-1.0, 0, 0]]), np.array([[np.nan, 0, 0]]),
                                 np.array([[2.0 ** 128, 0, 0]]), np.zeros((2, 4))])
def test_rgbe_encode_refuses(bad):
    with pytest.raises(InputError):
        float_to_rgbe(bad)


def test_reader_hand_built_run_length_scanline(tmp_path):
    green = bytes(range(10, 18))
    line = bytes((2, 2, 0, 8)) + bytes((136, 128)) + bytes((8,)) + green + bytes((136, 0)) + bytes((136, 129))
    path = tmp_path / "rle.hdr"
    path.write_bytes(HEADER + b"-Y 1 +X 8\n" + line)
    image = read_hdr(path)
    assert image.shape == (1, 8, 3) and image.dtype == np.float32
    assert np.array_equal(image[0, :, 0], np.ones(8))
    assert np.array_equal(image[0, :, 1], np.arange(10, 18) / 128)
    assert np.array_equal(image[0, :, 2], np.zeros(8))


def test_reader_flat_scanlines_orientation_and_exposure(tmp_path):
    pixels = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4) + 120
    data = pixels.tobytes()
    (tmp_path / "flat.hdr").write_bytes(HEADER + b"-Y 2 +X 3\n" + data)
    (tmp_path / "up.hdr").write_bytes(HEADER + b"+Y 2 +X 3\n" + data)
    (tmp_path / "exp.hdr").write_bytes(b"#?RADIANCE\nEXPOSURE=2\nEXPOSURE=4\n\n-Y 2 +X 3\n" + data)
    expected = rgbe_to_float(pixels)
    assert np.array_equal(read_hdr(tmp_path / "flat.hdr"), expected)
    assert np.array_equal(read_hdr(tmp_path / "up.hdr"), expected[::-1])
    assert np.allclose(read_hdr(tmp_path / "exp.hdr"), expected / 8, rtol=1e-7)
    # COLORCORR: a per-channel multiplier already applied, divided out as EXPOSURE is
    (tmp_path / "corr.hdr").write_bytes(b"#?RADIANCE\nEXPOSURE=2\nCOLORCORR=1 0.5 4\n\n-Y 2 +X 3\n" + data)
    assert np.allclose(read_hdr(tmp_path / "corr.hdr"), expected / (2 * np.array([1, 0.5, 4])), rtol=1e-7)


@pytest.mark.parametrize("rle", [True, False])
def test_writer_round_trip(tmp_path, rng, rle):
    image = np.exp(rng.normal(0, 4, (13, 37, 3)))
    image[3:6] = 2.5                                   # long runs for the encoder
    image[7, :, 1] = 0.0
    write_hdr(tmp_path / "x.hdr", image, rle=rle)
    back = read_hdr(tmp_path / "x.hdr").astype(np.float64)
    top = image.max(axis=-1, keepdims=True)
    assert np.all(np.abs(back - image) <= top / 128)    # RGBE keeps 8 bits of the largest channel
    assert np.all(back <= image)                        # mantissas truncate
    assert np.array_equal(back[3:6], np.full((3, 37, 3), 2.5))


def test_writer_rle_is_smaller_and_equal(tmp_path):
    image = np.ones((4, 200, 3))
    write_hdr(tmp_path / "r.hdr", image, rle=True)
    write_hdr(tmp_path / "f.hdr", image, rle=False)
    assert (tmp_path / "r.hdr").stat().st_size < (tmp_path / "f.hdr").stat().st_size / 10
    assert np.array_equal(read_hdr(tmp_path / "r.hdr"), read_hdr(tmp_path / "f.hdr"))


@pytest.mark.parametrize("content, words", [
    (b"P6\n", ["not a Radiance"]),
    (HEADER + b"-Y 2 +X 8\n" + bytes((2, 2, 0, 8, 136)), ["ends inside scanline 0"]),
    (HEADER + b"-Y 1 +X 3\n" + bytes(8), ["ends inside scanline 0"]),
    (b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n" + bytes(4), ["xyze"]),
    (HEADER + b"-Y 1 +X 2\n" + bytes((1, 1, 1, 5, 0, 0, 0, 0)), ["old-style"]),
    (HEADER + b"-Z 1 +X 2\n", ["resolution"]),
    (HEADER + b"-Y 1 +X 8\n" + bytes((2, 2, 0, 9)) + bytes(20), ["width 9"]),
    # a second image or text after the last scanline was dropped unread
    (HEADER + b"-Y 1 +X 1\n" + bytes((128, 64, 32, 129)) + HEADER + b"-Y 1 +X 1\n" + bytes(4),
     ["byte(s) after the last of its 1 scanlines", "concatenated"]),
    (HEADER + b"-Y 1 +X 1\n" + bytes((128, 64, 32, 129)) + b"garbage\n", ["8 byte(s) after"]),
    # an exposure that overflows was blamed on the pixel data
    (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1e-300\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)),
     ["exposure 1e-300", "beyond float32's range"]),
    # ... and one that underflows turned a lit frame black without a word
    (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1e60\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)),
     ["exposure 1e+60", "below float32's smallest normal"]),
    (b"#?RADIANCE\nCOLORCORR=1 1e60 1\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)),
     ["exposure 1 1e+60 1", "below float32's smallest normal"]),
    # header numbers as C's atof reads them (Python's float took 1_0 as 10, and inf)
    (b"#?RADIANCE\nEXPOSURE=1_0\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)), ["EXPOSURE=1_0", "1 number"]),
    (b"#?RADIANCE\nEXPOSURE=inf\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)), ["EXPOSURE=inf"]),
    (b"#?RADIANCE\nEXPOSURE=0\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)), ["EXPOSURE=0", "> 0"]),
    (b"#?RADIANCE\nCOLORCORR=1 2\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)), ["COLORCORR=1 2", "3 number"]),
    # a size of 5,000 digits was int()'s ValueError traceback (past its 4,300 digits)
    (HEADER + b"-Y " + b"9" * 5000 + b" +X 8\n" + bytes(256), ["resolution line", "too large", "9 digits"]),
    # a 400-digit exposure was quoted whole, and the cut line lost the cause
    (b"#?RADIANCE\nEXPOSURE=1" + b"0" * 400 + b"\n\n-Y 1 +X 1\n" + bytes((128, 64, 32, 129)),
     ["EXPOSURE=1000", "must hold finite numbers > 0"]),
])
def test_reader_refuses_bad_files(tmp_path, content, words):
    path = tmp_path / "bad.hdr"
    path.write_bytes(content)
    with pytest.raises(InputError) as info:
        read_hdr(path)
    assert str(path) in str(info.value) and all(w in str(info.value) for w in words)
    assert len(str(info.value)) < 200 + len(str(path))       # (a header line is quoted short)


def test_exr_round_trip(tmp_path, rng):
    rgb = np.exp(rng.normal(0, 5, (6, 9, 3))).astype(np.float32)
    write_exr(tmp_path / "c.exr", rgb)
    write_exr(tmp_path / "y.exr", rgb[..., 0])
    assert np.array_equal(read_exr(tmp_path / "c.exr"), rgb)
    assert np.array_equal(read_exr(tmp_path / "y.exr"), rgb[..., 0])
    (tmp_path / "junk.exr").write_bytes(b"not an exr at all")
    with pytest.raises(InputError, match="junk.exr' is not an OpenEXR file"):
        read_exr(tmp_path / "junk.exr")
    # a Radiance file named .Exr: the library's "Unable to open ... for read" sounded like permissions
    write_hdr(tmp_path / "f4.Exr", rgb)
    with pytest.raises(InputError, match=r"f4.Exr' is not an OpenEXR file.*a Radiance .hdr file"):
        hdr_io.read_image(tmp_path / "f4.Exr")


@pytest.mark.parametrize("compression", ["NO_COMPRESSION", "ZIP_COMPRESSION", "PIZ_COMPRESSION", "DWAB_COMPRESSION"])
def test_bytes_after_an_exr_files_last_chunk_are_refused(tmp_path, rng, compression):
    """OpenEXR reads a file's chunks by their offsets and ignored what followed the last (two files
    joined, a copy that overran), as the Radiance reader refuses: the chunks' ends are read from the
    offset table, for every scan-line compression (1 to 256 lines a chunk)."""
    import OpenEXR
    rgb = rng.random((300, 7, 3)).astype(np.float32)
    with OpenEXR.File({"compression": getattr(OpenEXR, compression), "type": OpenEXR.scanlineimage},
                      {"RGB": rgb}) as handle:
        handle.write(str(tmp_path / "f.exr"))
    assert read_exr(tmp_path / "f.exr").shape == (300, 7, 3)
    whole = (tmp_path / "f.exr").read_bytes()
    (tmp_path / "joined.exr").write_bytes(whole + whole[:5])
    with pytest.raises(InputError, match=r"EXR file '.*joined\.exr': 5 byte\(s\) after the last of its chunks"):
        read_exr(tmp_path / "joined.exr")


def test_gray_weights_and_clipping():
    pixel = np.array([[[1.0, 2.0, 4.0], [-0.03, 1.0, 0.0]]])     # a dip below 0 of 0.75 % of the peak: clipped
    assert np.allclose(to_gray(pixel), [[0.2126 + 1.4304 + 0.2888, 0.7152]])
    assert np.allclose(to_gray(pixel, "rec601"), [[0.299 + 1.174 + 0.456, 0.587]])
    pixel[0, 1, 0] = -0.5                                              # 12.5 % of it: not light
    with pytest.raises(InputError, match="negative values down to -0.5"):
        to_gray(pixel)
    with pytest.raises(InputError, match="weights"):
        to_gray(pixel, "srgb-ish")
    with pytest.raises(InputError, match="non-finite"):
        to_gray(np.array([[np.inf, 0.0]]))


def test_normalise_sequence_uses_one_factor():
    frames = np.array([[[1.0, 2.0]], [[4.0, 0.0]]])
    out = normalise_sequence(frames)
    assert out.dtype == np.float32 and np.array_equal(out, frames / 4)
    assert np.array_equal(normalise_sequence(frames, 1000.0), frames * 250)
    for bad in (np.zeros((2, 1, 2)), -frames, np.full((1, 1, 1), np.nan)):
        with pytest.raises(InputError):
            normalise_sequence(bad)


def _frame(value, shape=(4, 10)):
    return np.full(shape + (3,), value, np.float32)


def test_folder_sorted_by_name_numbers_as_numbers(tmp_path):
    write_exr(tmp_path / "frame10.exr", _frame(8.0))
    write_hdr(tmp_path / "frame2.hdr", _frame(2.0))
    write_exr(tmp_path / "frame1.EXR", _frame(1.0))
    (tmp_path / "notes.txt").write_text("not a frame")
    assert [p.name for p in list_frames(tmp_path)] == ["frame1.EXR", "frame2.hdr", "frame10.exr"]
    light = load_hdr_sequence(tmp_path)
    assert light.shape == (3, 4, 10) and light.dtype == np.float32
    assert np.allclose(light[:, 0, 0], [1 / 8, 2 / 8, 1.0])
    assert light.max() == 1.0
    assert load_hdr_sequence(tmp_path, max_frames=2, peak=3.0).max() == 3.0


def test_a_frames_size_comes_from_its_header_as_reading_it_gives(tmp_path):
    """frame_size reads only the header (EXR data window, Radiance resolution line, columns-first
    orientation transposed) and agrees with the decoded frame; a header that is not one is refused."""
    from tespike.recon.scenes.hdr_io import frame_size, read_image
    write_exr(tmp_path / "rgb.exr", _frame(1.0, (5, 10)))
    write_exr(tmp_path / "y.exr", np.ones((3, 9), np.float32))
    for name in ("rgb.exr", "y.exr"):
        assert frame_size(tmp_path / name) == read_image(tmp_path / name).shape[:2]
    pixels = b"".join(bytes([128, 64, 32, 129]) for _ in range(2 * 3))     # flat (no run-length) scanlines
    for line, shape in ((b"-Y 2 +X 3", (2, 3)), (b"+X 2 -Y 3", (3, 2))):
        path = tmp_path / f"{shape[0]}x{shape[1]}.hdr"
        path.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + line + b"\n" + pixels)
        assert frame_size(path) == read_image(path).shape[:2] == shape
    (tmp_path / "cut.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4")
    (tmp_path / "cut.exr").write_bytes((tmp_path / "rgb.exr").read_bytes()[:40])
    for name, words in (("cut.hdr", "missing resolution line"), ("cut.exr", "cannot read EXR file")):
        with pytest.raises(InputError, match=words):
            frame_size(tmp_path / name)


def test_folder_errors(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_hdr_sequence(tmp_path / "missing")
    with pytest.raises(InputError, match="holds no frames"):
        load_hdr_sequence(tmp_path)
    write_exr(tmp_path / "a.exr", _frame(1.0))
    write_exr(tmp_path / "b.exr", _frame(1.0, (5, 10)))
    with pytest.raises(InputError, match="b.exr.*same size"):
        load_hdr_sequence(tmp_path)
    (tmp_path / "b.exr").unlink()
    (tmp_path / "c.hdr").write_bytes(b"garbage")
    with pytest.raises(InputError, match="c.hdr"):
        load_hdr_sequence(tmp_path)
    (tmp_path / "c.hdr").unlink()
    write_exr(tmp_path / "d.exr", _frame(0.0))
    (tmp_path / "a.exr").unlink()
    with pytest.raises(InputError, match="every pixel is 0"):
        load_hdr_sequence(tmp_path)


def test_an_entry_named_as_a_frame_that_is_not_one_is_refused(tmp_path):
    """A dangling link, a folder or a FIFO named *.hdr was skipped: the sequence came out a frame
    short and every command that read it exited 0."""
    import os
    write_hdr(tmp_path / "frame1.hdr", _frame(1.0))
    for make, words in ((lambda p: p.symlink_to(tmp_path / "gone.hdr"), "does not exist"),
                        (lambda p: p.mkdir(), "is a directory"),
                        (lambda p: os.mkfifo(p), "is a FIFO")):
        make(tmp_path / "frame2.hdr")
        with pytest.raises(InputError, match=f"HDR frame file '.*frame2.hdr' {words}"):
            load_hdr_sequence(tmp_path)
        path = tmp_path / "frame2.hdr"
        path.rmdir() if path.is_dir() and not path.is_symlink() else path.unlink()
    assert load_hdr_sequence(tmp_path).shape[0] == 1


def test_writers_are_atomic(tmp_path):
    with pytest.raises(InputError):
        write_hdr(tmp_path / "x.hdr", np.full((2, 2, 3), np.nan))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match="does not exist"):
        write_hdr(tmp_path / "no" / "x.hdr", np.ones((2, 2)))


def test_reads_a_panorama_written_as_exr(tmp_path):
    """The shipped city panorama (HDR, 4e3 : 1 peak to median) survives an EXR round trip."""
    from tespike.recon.scenes.panorama import load_panorama
    luminance = load_panorama("city").astype(np.float32)
    write_exr(tmp_path / "city.exr", np.repeat(luminance[:, :, None], 3, axis=2))
    rgb = hdr_io.read_image(tmp_path / "city.exr")
    assert rgb.shape == (128, 256, 3) and rgb.dtype == np.float32
    gray = to_gray(rgb)
    assert np.allclose(gray, luminance, rtol=1e-6) and gray.max() > 1e3 * np.median(gray)


@pytest.mark.skipif(not (FULL_SIZE_HDRI / "city.exr").is_file(), reason="full-size HDR panoramas not present")
def test_reads_the_full_size_panoramas():
    rgb = hdr_io.read_image(FULL_SIZE_HDRI / "city.exr")
    assert rgb.shape == (512, 1024, 3) and rgb.dtype == np.float32
    gray = to_gray(rgb)
    assert gray.min() >= 0 and gray.max() > 1e4 * np.median(gray)


def test_folder_crop_and_downscale(tmp_path):
    image = np.arange(6 * 10, dtype=np.float32).reshape(6, 10) + 1
    write_exr(tmp_path / "a.exr", image)
    light = load_hdr_sequence(tmp_path, crop=(4, 6), peak=float(image[1:5, 2:8].max()))
    assert np.array_equal(light[0], image[1:5, 2:8])
    shrunk = load_hdr_sequence(tmp_path, crop=(4, 8), downscale=4)
    assert shrunk.shape == (1, 1, 2)
    blocks = image[1:5, 1:9].reshape(1, 4, 2, 4).mean(axis=(1, 3))
    assert np.allclose(shrunk[0] * blocks.max(), blocks)
    with pytest.raises(InputError, match="cannot crop"):
        load_hdr_sequence(tmp_path, crop=(7, 4))
    with pytest.raises(InputError, match="smaller than one"):
        load_hdr_sequence(tmp_path, downscale=7)
    with pytest.raises(InputError, match=r"6 x 10 is not a whole number of 4 x 4 blocks.*crop it to 4x8"):
        load_hdr_sequence(tmp_path, downscale=4)            # rows 5-6 and columns 9-10 were dropped
    assert load_hdr_sequence(tmp_path, crop=(6, 8), downscale=2).shape == (1, 3, 4)
    with pytest.raises(InputError, match="downscale"):
        load_hdr_sequence(tmp_path, downscale=0)


def test_a_path_that_is_no_path_is_refused_in_one_line():
    """(load_panorama, load_hdr_sequence and the dataset's hdr_sources of a number had been os.fspath's
    TypeError.)"""
    from tespike.recon.scenes.panorama import load_panorama
    from tespike.cosim.dataset.build import hdr_sources
    for call, what in ((load_panorama, "panorama"), (load_hdr_sequence, "HDR sequence folder"), (hdr_sources, "--hdr")):
        with pytest.raises(InputError, match=f"^{what}: a path must be a str or an os.PathLike, not int$"):
            call(3)


def test_the_hdr_writers_and_readers_refuse_what_is_no_light_or_path_in_one_line(tmp_path):
    """write_exr wrote NaN, negative light and 1e300 (as infinity), and an empty frame was OpenEXR's
    RuntimeError naming the temporary; write_hdr dropped a complex image's imaginary part; read_hdr(None)
    said it could not read 'None'; sequence_size([]) and rgbe_to_float of (2, 3) were IndexErrors."""
    from tespike.recon.scenes.hdr_io import read_exr, read_hdr, rgbe_to_float, sequence_size, write_exr, write_hdr
    for image in (np.full((2, 2, 3), np.nan), -np.ones((2, 2, 3)), np.full((2, 2, 3), 1e300)):
        with pytest.raises(InputError, match="^write_exr needs finite, non-negative values within float32's range$"):
            write_exr(tmp_path / "e.exr", image)
    with pytest.raises(InputError, match=r"^write_exr needs an \(H, W, 3\) or \(H, W\) image of at least 1 x 1"):
        write_exr(tmp_path / "e.exr", np.ones((0, 2, 3)))
    for write, name in ((write_hdr, "write_hdr"), (write_exr, "write_exr")):
        with pytest.raises(InputError, match=f"^{name}: image dtype complex128 is not real numbers$"):
            write(tmp_path / "c.hdr", np.full((2, 2, 3), 1 + 5j))
    assert not list(tmp_path.iterdir())
    for read, name in ((read_hdr, "HDR file"), (read_exr, "EXR file")):
        with pytest.raises(InputError, match=f"^{name}: a path must be a str or an os.PathLike, not NoneType$"):
            read(None)
    with pytest.raises(InputError, match="^the sequence has no frames$"):
        sequence_size([], "the sequence")
    with pytest.raises(InputError, match=r"^RGBE pixels must be uint8 \(\.\.\., 4\), not uint8 \(2, 3\)$"):
        rgbe_to_float(np.ones((2, 3), np.uint8))
