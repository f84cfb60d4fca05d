"""tespike.golden.io: the stimulus reader is memory-mapped and checks every slice."""

import re

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.io import (check_scene, check_stimulus, load_scene, load_stimulus, load_stream, save_stream,
                               scan_light)


def test_load_stimulus_is_memory_mapped(tmp_path):
    np.save(tmp_path / "e.npy", np.ones((480, 2, 3), np.uint16))
    stim = load_stimulus(tmp_path / "e.npy", SensorConfig())
    assert isinstance(stim, np.memmap) and not stim.flags.writeable
    assert stim.shape == (480, 2, 3)


def test_bad_value_far_into_a_large_file_is_found(tmp_path, monkeypatch):
    stim = np.zeros((240 * 40, 1, 1), np.int32)
    stim[-1, 0, 0] = 70000
    np.save(tmp_path / "e.npy", stim)
    with pytest.raises(InputError, match="70000"):
        load_stimulus(tmp_path / "e.npy", SensorConfig())
    stim[-1, 0, 0] = -3
    np.save(tmp_path / "e.npy", stim)
    with pytest.raises(InputError, match="-3"):
        load_stimulus(tmp_path / "e.npy", SensorConfig())


def test_T_rule_checked_on_the_whole_file(tmp_path):
    np.save(tmp_path / "e.npy", np.zeros((241, 1, 1), np.uint8))
    with pytest.raises(InputError, match="multiple"):
        load_stimulus(tmp_path / "e.npy", SensorConfig())


def test_dtype_that_cannot_hold_a_bad_value_is_not_scanned():
    class Exploding(np.ndarray):
        def min(self, *a, **k):
            raise AssertionError("scanned")
        max = min
    stim = np.zeros((240, 1, 1), np.uint16).view(Exploding)
    assert check_stimulus(stim, SensorConfig()) is stim                    # uint16 with E = 16
    with pytest.raises(AssertionError, match="scanned"):
        check_stimulus(stim, SensorConfig(input_bits=12))                  # uint16 can exceed 2^12 - 1
    with pytest.raises(AssertionError, match="scanned"):
        check_stimulus(np.zeros((240, 1, 1), np.int16).view(Exploding), SensorConfig())   # may be negative


def test_load_scene_memory_mapped_keeps_dtype_and_values(tmp_path):
    light = np.random.default_rng(0).random((5, 3, 4)).astype(np.float32)
    np.save(tmp_path / "i.npy", light)
    scene = load_scene(tmp_path / "i.npy", memory_map=True)
    assert isinstance(scene, np.memmap) and scene.dtype == np.float32
    assert np.array_equal(np.asarray(scene), light)
    assert np.array_equal(load_scene(tmp_path / "i.npy"), light.astype(np.float64))


@pytest.mark.parametrize("bad, message", [(np.nan, "non-finite"), (-0.5, "negative")])
def test_load_scene_memory_mapped_finds_a_bad_value_in_a_late_slice(tmp_path, bad, message):
    # 2^22 values per slice: a 1 x 2048 x 2048 frame is one slice, so the bad value sits in the 3rd
    light = np.zeros((3, 2048, 2048), np.float32)
    light[2, -1, -1] = bad
    np.save(tmp_path / "i.npy", light)
    with pytest.raises(InputError, match=message):
        load_scene(tmp_path / "i.npy", memory_map=True)
    with pytest.raises(InputError, match="must be \\(K, H, W\\)"):
        np.save(tmp_path / "j.npy", np.zeros((2, 2), np.float32))
        load_scene(tmp_path / "j.npy", memory_map=True)


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
@pytest.mark.parametrize("values", [[0.5, np.nan, -1.0], [0.5, -np.inf, 2.0], [np.inf, 0.5, 0.0],
                                    [0.5, -0.1, 3.0], [0.5, -0.0, 1e4]])
def test_scan_light_refuses_as_check_scene_does_without_converting(dtype, values):
    """scan_light (two reductions in the array's own dtype) gives check_scene's
    message, the non-finite value before a negative one; -0.0 is light 0."""
    light = np.array(values, dtype).reshape(1, 1, 3)
    try:
        check_scene(light)
    except InputError as exc:
        with pytest.raises(InputError) as caught:
            scan_light(light)
        assert str(caught.value) == str(exc)
    else:
        assert np.all(light >= 0)
        scan_light(light)


def test_a_compressed_member_declaring_more_than_it_holds_is_named_not_out_of_memory(tmp_path):
    """A 400-byte compressed S.npz whose words header declares (100000, 10000, 10000) was reported
    as "out of memory" (numpy allocated the shape first), naming no file."""
    import io
    import zipfile

    from tespike.golden.io import load_stream
    config_member = io.BytesIO()
    np.save(config_member, np.array(SensorConfig().to_json()))
    header = "{'descr': '|u1', 'fortran_order': False, 'shape': (100000, 10000, 10000), }"
    header = header + " " * (118 - len(header)) + "\n"
    with zipfile.ZipFile(tmp_path / "big.npz", "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("words.npy", b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode()
                         + b"\0" * 256)
        archive.writestr("config.npy", config_member.getvalue())
    with pytest.raises(InputError, match=r"stream file '.*big.npz' .*member 'words.npy' is shorter than its "
                                         r"header's shape \(100000, 10000, 10000\)"):
        load_stream(tmp_path / "big.npz")


@pytest.mark.parametrize("compression", [0, 8])            # stored (np.savez) and deflated
def test_a_member_with_bytes_after_its_array_or_a_name_stored_twice_is_refused(tmp_path, compression):
    """numpy ignored bytes after an .npz member's array (a bare .npy's are refused) and read the
    last of two members of one name (the first is what most zip tools show): both were accepted."""
    import io
    import warnings
    import zipfile

    from tespike.golden.io import load_stream
    config = SensorConfig()

    def member(array):
        buffer = io.BytesIO()
        np.save(buffer, array)
        return buffer.getvalue()
    words = np.zeros((2, 3, 4), np.uint8)
    with zipfile.ZipFile(tmp_path / "tail.npz", "w", compression) as archive:
        archive.writestr("words.npy", member(words) + b"junk")
        archive.writestr("config.npy", member(np.array(config.to_json())))
    with pytest.raises(InputError, match=r"'.*tail\.npz' .*member 'words.npy' holds 4 bytes after its \(2, 3, 4\) array"):
        load_stream(tmp_path / "tail.npz")
    with zipfile.ZipFile(tmp_path / "twice.npz", "w", compression) as archive, warnings.catch_warnings():
        warnings.simplefilter("ignore")                      # (zipfile warns of the duplicate name)
        archive.writestr("words.npy", member(words + 1))
        archive.writestr("words.npy", member(words))
        archive.writestr("config.npy", member(np.array(config.to_json())))
    with pytest.raises(InputError, match=r"'.*twice\.npz' .*member 'words' is stored twice"):
        load_stream(tmp_path / "twice.npz")
    np.savez(tmp_path / "ok.npz", words=words, config=config.to_json())      # as tespike writes it
    assert np.array_equal(load_stream(tmp_path / "ok.npz")[0], words)
    # np.load names 'words.npy' and 'words' alike: one archive holding both was read as one or the
    # other, by command ('view' read the second), and a member named without .npy skipped the checks
    with zipfile.ZipFile(tmp_path / "both.npz", "w", compression) as archive:
        archive.writestr("words.npy", member(words + 1))
        archive.writestr("config.npy", member(np.array(config.to_json())))
        archive.writestr("words", member(words))
    with pytest.raises(InputError, match=r"'.*both\.npz' .*member 'words' is stored twice "
                                         r"\(as 'words' and 'words.npy'\)"):
        load_stream(tmp_path / "both.npz")
    with zipfile.ZipFile(tmp_path / "bare.npz", "w", compression) as archive:
        archive.writestr("words", member(words + 1) + b"junk")
        archive.writestr("config", member(np.array(config.to_json())))
    with pytest.raises(InputError, match=r"'.*bare\.npz' .*member 'words' holds 4 bytes after its \(2, 3, 4\) array"):
        load_stream(tmp_path / "bare.npz")
    with zipfile.ZipFile(tmp_path / "bare.npz", "w", compression) as archive:   # np.load reads it: so do we
        archive.writestr("words", member(words + 1))
        archive.writestr("config", member(np.array(config.to_json())))
    for memory_map in (False, True):
        assert np.array_equal(load_stream(tmp_path / "bare.npz", memory_map=memory_map)[0], words + 1)


def test_bytes_after_an_archives_end_are_refused(tmp_path):
    """zip readers find an archive's end record near the end and ignore what follows it (two files
    joined, a copy that overran), or read a second archive joined to a first as the second alone: the
    archive was read as if whole. A comment the record declares is the archive's own."""
    import zipfile

    from tespike.golden.io import load_stream
    words = np.zeros((2, 3, 4), np.uint8)
    np.savez(tmp_path / "s.npz", words=words, config=SensorConfig().to_json())
    whole = (tmp_path / "s.npz").read_bytes()
    (tmp_path / "joined.npz").write_bytes(whole + whole[:100])
    with pytest.raises(InputError, match=r"stream file '.*joined\.npz' is not a readable .npz archive: "
                                         r"100 bytes follow the archive's end"):
        load_stream(tmp_path / "joined.npz")
    np.savez(tmp_path / "t.npz", words=words[:1], config=SensorConfig().to_json())
    (tmp_path / "two.npz").write_bytes(whole + (tmp_path / "t.npz").read_bytes())
    with pytest.raises(InputError, match=rf"'.*two\.npz' is not a readable .npz archive: {len(whole)} bytes come "
                                         r"before the archive \(two archives joined\?\)"):
        load_stream(tmp_path / "two.npz")                    # (zip readers read the second alone)
    with zipfile.ZipFile(tmp_path / "s.npz", "a") as archive:
        archive.comment = b"made by hand"
    assert np.array_equal(load_stream(tmp_path / "s.npz")[0], words)
    with open(tmp_path / "s.npz", "ab") as file:
        file.write(b"\0")
    with pytest.raises(InputError, match="1 bytes follow the archive's end"):
        load_stream(tmp_path / "s.npz")


def test_a_config_member_stored_as_bytes_is_read_as_utf8(tmp_path):
    """np.array(text.encode()) is a 0-d string array too (dtype S): it was read as "b'{...}'" and
    refused as "not valid JSON"."""
    from tespike.golden.io import load_stream
    config = SensorConfig()
    words = np.zeros((2, 3, 4), np.uint8)
    np.savez(tmp_path / "s.npz", words=words, config=np.array(config.to_json().encode()))
    back, read = load_stream(tmp_path / "s.npz")
    assert read == config and np.array_equal(back, words)
    np.savez(tmp_path / "bad.npz", words=words, config=np.array(b"\xff\xfe"))
    with pytest.raises(InputError, match="bad.npz.*'config' holds bytes that are not UTF-8"):
        load_stream(tmp_path / "bad.npz")


def test_a_stream_with_a_member_beside_words_and_config_is_refused(tmp_path):
    """The extra member was ignored without a word (a stream holds the two, SPEC section 6)."""
    from tespike.golden.io import load_stream
    words = np.zeros((2, 3, 4), np.uint8)
    np.savez(tmp_path / "s.npz", words=words, config=np.array(SensorConfig().to_json()), other=np.zeros(3))
    with pytest.raises(InputError, match=r"s.npz' holds 'other' beside 'words' and 'config'"):
        load_stream(tmp_path / "s.npz")


def test_a_long_double_scene_is_checked_in_its_own_values(tmp_path):
    """1e4000 is finite in a long double and inf in float64: the memory-mapped scan passed it and the
    simulator ran on inf; -1e-4000 was refused as "negative light value (-0.0)"."""
    from tespike.golden.io import load_scene
    light = np.full((2, 3, 4), 0.5, np.longdouble)
    np.save(tmp_path / "fine.npy", light)
    for memory_map in (True, False):
        assert np.array_equal(np.asarray(load_scene(tmp_path / "fine.npy", memory_map=memory_map), np.float64),
                              np.full((2, 3, 4), 0.5))
    big, tiny = light.copy(), light.copy()
    big[1, 2, 3] = np.longdouble("1e4000")
    tiny[0, 1, 1] = -np.longdouble("1e-4000")
    np.save(tmp_path / "big.npy", big)
    np.save(tmp_path / "tiny.npy", tiny)
    for memory_map in (True, False):
        with pytest.raises(InputError, match=r"big.npy' holds a light value \(1e\+4000\) beyond float64's range"):
            load_scene(tmp_path / "big.npy", memory_map=memory_map)
        with pytest.raises(InputError, match=r"tiny.npy' holds a negative light value \(-1e-4000\)"):
            load_scene(tmp_path / "tiny.npy", memory_map=memory_map)


def test_a_damaged_npy_header_is_one_line_in_a_file_and_in_an_archive(tmp_path):
    """A flipped byte in a .npy header's dict made numpy's fallback parser raise tokenize.TokenError,
    not a ValueError: a 56-line traceback from every loader (a stream's words member too)."""
    from tespike.golden.io import load_scene, load_stream
    np.save(tmp_path / "I.npy", np.full((2, 3, 4), 0.5))
    data = bytearray((tmp_path / "I.npy").read_bytes())
    data[10] ^= 0x5A                                   # the header dict's "{" -> "!"
    (tmp_path / "I.npy").write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"I.npy' is not a readable .npy array: its header is damaged"):
        load_scene(tmp_path / "I.npy")
    np.save(tmp_path / "J.npy", np.full((2, 3, 4), 0.5))         # a byte of the dict's text: a name,
    data = bytearray((tmp_path / "J.npy").read_bytes())          # not a literal ("malformed node or string
    for flip in (0x01, 0xFF):                                     # ... <ast.Name object at 0x...>"), or
        data[data.find(b"alse") - 1] ^= flip                      # not text ("Cannot parse header: ...")
        (tmp_path / "J.npy").write_bytes(bytes(data))
        with pytest.raises(InputError, match=r"J.npy' is not a readable .npy array: its header is damaged$"):
            load_scene(tmp_path / "J.npy")
        data[data.find(b"alse") - 1] ^= flip
    np.savez(tmp_path / "S.npz", words=np.zeros((2, 3, 4), np.uint8), config=np.array(SensorConfig().to_json()))
    data = bytearray((tmp_path / "S.npz").read_bytes())
    data[data.find(b"\x93NUMPY") + 10] ^= 0x5A
    (tmp_path / "S.npz").write_bytes(bytes(data))
    for memory_map in (True, False):
        with pytest.raises(InputError, match=r"S.npz' is not a readable .npz archive: (a member's .npy header "
                                             r"is damaged|Bad CRC-32 for file 'words.npy')"):
            load_stream(tmp_path / "S.npz", memory_map=memory_map)


def test_write_npz_is_the_archive_np_savez_writes(tmp_path):
    """The stream's writer (each array from its own memory) gives np.savez's archive: the same
    members, dtypes, shapes and values, stored uncompressed with Zip64 extras, as np.load and
    load_stream's memory map of a stored member read it."""
    import zipfile
    from tespike.golden.io import write_npz
    arrays = dict(words=np.arange(60, dtype=np.uint8).reshape(3, 4, 5), config=np.array('{"x": "\u00e9"}'),
                  big_endian=np.arange(7, dtype=">u2"), empty=np.zeros((0, 3)), scalar=np.float64(3.5),
                  strided=np.arange(10)[::2], fortran=np.asfortranarray(np.arange(6.0).reshape(2, 3)))
    with open(tmp_path / "ours.npz", "wb") as handle:
        write_npz(handle, **arrays)
    np.savez(tmp_path / "numpy.npz", **arrays)
    ours, theirs = np.load(tmp_path / "ours.npz"), np.load(tmp_path / "numpy.npz")
    assert ours.files == theirs.files == list(arrays)
    for name in arrays:
        assert ours[name].dtype == theirs[name].dtype and ours[name].shape == theirs[name].shape
        np.testing.assert_array_equal(ours[name], theirs[name])
    with zipfile.ZipFile(tmp_path / "ours.npz") as archive, zipfile.ZipFile(tmp_path / "numpy.npz") as other:
        assert archive.testzip() is None
        assert [(i.filename, i.compress_type, i.flag_bits) for i in archive.infolist()] == \
            [(i.filename, i.compress_type, i.flag_bits) for i in other.infolist()]
    config = SensorConfig()
    words = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4) % 16
    save_stream(tmp_path / "S.npz", words, config)
    loaded, loaded_config = load_stream(tmp_path / "S.npz")
    np.testing.assert_array_equal(loaded, words)
    assert loaded_config == config


@pytest.mark.parametrize("words, refusal", [
    (np.full((1, 2, 2), 3.0), "dtype float64 is not an integer type"),
    (np.full((1, 2, 2), -1), "readout word -1 at index \\(0, 0, 0\\)"),
    (np.full((1, 2, 2), 16), "readout word 16 at index \\(0, 0, 0\\)"),
    (np.full((1, 2, 2), 288), "readout word 288 at index \\(0, 0, 0\\)"),
])
def test_save_stream_writes_no_word_its_cast_would_change(words, refusal, tmp_path):
    """A float word had been truncated, -1 and 288 wrapped into uint8 (255, 32), and 16 (no TE word)
    written, each silently; nothing is left behind."""
    with pytest.raises(InputError, match=refusal):
        save_stream(tmp_path / "S.npz", words, SensorConfig())
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("call", [lambda path: save_stream(path, np.zeros((1, 1, 1), np.uint8), SensorConfig()),
                                  load_stream, load_scene, lambda path: load_stimulus(path, SensorConfig())])
def test_a_path_that_is_no_file_name_is_refused_in_one_line(call):
    """(A number had been os.fspath's TypeError.)"""
    for path in (5, 2.5, None, b"S.npz"):
        with pytest.raises(InputError, match=f"a path must be a str or an os.PathLike, not {type(path).__name__}$"):
            call(path)


def test_load_stimulus_refuses_a_preset_name_in_one_line(tmp_path):
    """A preset's name where the configuration belongs was an AttributeError of its first field."""
    from tespike.golden.errors import ConfigError
    path = tmp_path / "E.npy"
    np.save(path, np.zeros((240, 1, 1), np.uint16))
    with pytest.raises(ConfigError, match="^load_stimulus: configuration must be a SensorConfig"):
        load_stimulus(path, "te")


@pytest.mark.parametrize("images, words", [
    (np.full((1, 2, 2), np.nan), "reconstructed images holds a non-finite light value (nan); light must be finite"),
    (-np.ones((1, 2, 2)), "reconstructed images holds a negative light value (-1.0); light must be >= 0"),
    (np.full((1, 2, 2), 1 + 5j), "reconstructed images: dtype complex128 is not real numbers"),
    (np.full((1, 2, 2), 1e39), "reconstructed images hold light (1e+39) beyond the range of R.npy's float32"),
], ids=["nan", "negative", "complex", "past-float32"])
def test_save_images_refuses_light_that_is_none_and_writes_nothing(tmp_path, images, words):
    """NaN, negative and complex light had been written (the imaginary part dropped with a warning),
    and 1e39 as infinity."""
    from tespike.golden.io import save_images
    with pytest.raises(InputError, match="^" + re.escape(words) + "$"):
        save_images(tmp_path / "R.npy", images)
    assert not list(tmp_path.iterdir())


def test_the_images_shape_scan_and_scene_flags_are_checked_in_one_line(tmp_path):
    """``images_array((1, -2, 2))`` was numpy's "negative dimensions", ``scan_light`` of a list an
    AttributeError, and ``load_scene(p, memory_map='no')`` a memory map."""
    from tespike.golden.io import images_array, scan_light
    with pytest.raises(InputError, match=r"^images shape \(1, -2, 2\): must be \(K, H, W\), three integers >= 0$"):
        images_array((1, -2, 2))
    with pytest.raises(InputError, match=r"^scene holds a negative light value \(-1.0\)"):
        scan_light([1.0, -1.0])
    path = tmp_path / "I.npy"
    np.save(path, np.ones((1, 2, 2), np.float32))
    with pytest.raises(InputError, match="^load_scene memory_map = 'no': must be True or False$"):
        load_scene(path, memory_map="no")


def test_an_input_written_over_while_a_command_reads_it_stops_its_output(tmp_path):
    """A stream memory-mapped by ``reconstruct`` and written over in place meanwhile (``dd
    conv=notrunc``) gave a reconstruction blending the two streams, exit 0. While a command watches
    its inputs, an output is not moved into place once an input it maps was written over; a file
    replaced at the path, or removed, left what was read whole; a library caller is never watched."""
    import os

    from tespike.golden.atomic import watching_inputs
    from tespike.golden.io import load_npy, load_stream, save_images, save_stream
    config = SensorConfig()
    save_stream(tmp_path / "S.npz", np.ones((2, 3, 4), np.uint8), config)
    np.save(tmp_path / "I.npy", np.ones((2, 3, 4), np.float32))
    out = tmp_path / "R.npy"

    def write_over(path):
        with open(path, "r+b") as handle:                    # in place: the same file, new bytes
            handle.seek(-1, os.SEEK_END)
            byte = handle.read(1)
            handle.seek(-1, os.SEEK_END)
            handle.write(byte)
        info = os.stat(path)
        os.utime(path, ns=(info.st_atime_ns, info.st_mtime_ns + 1_000_000))   # (a coarse clock's tick)
    for name, read in (("S.npz", lambda p: load_stream(p, memory_map=True)),
                       ("I.npy", lambda p: load_npy(p, "scene", mmap_mode="r"))):
        with watching_inputs():
            read(tmp_path / name)
            save_images(out, np.zeros((1, 2, 2)))            # unchanged: written
            write_over(tmp_path / name)
            with pytest.raises(InputError, match=rf"input file '.*{name}' was written over while the command "
                                                 "read it"):
                save_images(out, np.ones((1, 2, 2)))
        assert np.load(out).max() == 0 and not list(tmp_path.glob(".*.part"))
    with watching_inputs():                                  # replaced by a new file: what was read is whole
        load_stream(tmp_path / "S.npz", memory_map=True)
        save_stream(tmp_path / "S.npz", np.zeros((2, 3, 4), np.uint8), config)
        save_images(out, np.ones((1, 2, 2)))
    load_stream(tmp_path / "S.npz", memory_map=True)          # no command: not watched
    write_over(tmp_path / "S.npz")
    save_images(out, np.full((1, 2, 2), 2.0))
    assert np.load(out).max() == 2
