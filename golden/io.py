"""Files of SPEC section 6: stimulus E.npy, scene I.npy, stream S.npz, images R.npy.

Every writer goes through :func:`atomic_output`, so a failed or interrupted run
never leaves a half-written file; every reader refuses bad input with an
:class:`InputError` that names the file and the problem.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tokenize
import zipfile
import zlib
from pathlib import Path
from typing import Iterator

import numpy as np

from .atomic import atomic_output, held_mapping, taken_descriptors, watch_descriptor
from .config import SensorConfig
from .decode import check_words
from .errors import InputError, TespikeError, check_flag, is_count, one_line
from .paths import check_input_file

#: What numpy raises for a .npy header whose text is damaged (its dict cut or a byte flipped: it
#: parses the text as Python, and its fallback's tokenizer raises TokenError, not a ValueError).
HEADER_ERRORS = (SyntaxError, tokenize.TokenError)


def header_damaged(exc: BaseException) -> bool:
    """Whether numpy's refusal of a .npy (or an .npz member) is its header's text being damaged: a
    parse error (:data:`HEADER_ERRORS`), ``ast.literal_eval``'s ValueError, whose words show an AST
    node's repr (``malformed node or string on line 1: <ast.Name object at 0x...>``), not a cause,
    or numpy's "Cannot parse header", which quotes the damaged bytes."""
    return isinstance(exc, HEADER_ERRORS) or (isinstance(exc, ValueError) and any(
        words in str(exc) for words in ("malformed node or string", "Cannot parse header")))

__all__ = ["atomic_output", "check_frame_shape", "check_scene", "check_stimulus", "load_npy", "load_scene",
           "load_stimulus", "load_stream", "open_npz", "save_images", "save_stream", "scan_light", "scene_name",
           "unsigned_dtype", "word_dtype", "write_npz"]


def load_npy(path: str | Path, what: str, mmap_mode: str | None = None) -> np.ndarray:
    """One .npy array (never a pickle or an archive), or one line naming ``what`` and the file."""
    check_input_file(path, what)
    magic = _magic(path, what)
    if magic.startswith(b"PK"):
        raise InputError(f"{what} file {str(path)!r} holds an archive, not one .npy array")
    if magic != b"\x93NUMPY":                          # (np.load would try it as a pickle and say so)
        raise InputError(f"{what} file {str(path)!r} is not a readable .npy array (no .npy header)")
    layout = _npy_layout(path, what)                  # (read once: before the load, and for the bytes after it)
    try:
        array = np.load(path, allow_pickle=False, mmap_mode=mmap_mode)
    except (OSError, ValueError, EOFError, OverflowError, *HEADER_ERRORS) as exc:   # (Overflow: a header
        refuse_starved(exc, what, path)                            # shape whose product is negative, mapped)
        cause = "its header is damaged" if header_damaged(exc) else one_line(exc)
        raise InputError(f"{what} file {str(path)!r} is not a readable .npy array: {cause}") from None
    if not isinstance(array, np.ndarray):
        if hasattr(array, "close"):
            array.close()
        raise InputError(f"{what} file {str(path)!r} holds an archive, not one .npy array")
    if layout is None:                                 # (a header np.load read and we could not)
        raise InputError(f"{what} file {str(path)!r} is not a readable .npy array")
    header, size = layout
    extra = size - header - array.nbytes               # np.load ignores bytes after the array
    if extra:
        raise InputError(f"{what} file {str(path)!r} holds {extra} bytes after its {array.dtype} "
                         f"{array.shape} array (a corrupt or concatenated file)")
    if mmap_mode is not None:                          # cut short while mapped: named, not a bare bus error
        held_mapping(path, header + array.nbytes)
    return array


def _npy_layout(path, what: str) -> tuple[int, int] | None:
    """(header bytes, file bytes) of a .npy file, read from its header; a file shorter than its header
    says is refused in those words (numpy says "mmap length is greater than file size" or "cannot
    reshape array of size ..."), and so is one of Python objects (numpy: "Array can't be
    memory-mapped" or "allow_pickle=False"). None for a header numpy cannot read: np.load's own
    refusal names what is wrong."""
    try:
        with open(path, "rb") as handle:
            shape, _, dtype, header = _npy_header(handle)
            size = os.fstat(handle.fileno()).st_size
    except (OSError, ValueError, EOFError, *HEADER_ERRORS):
        return None
    if dtype.hasobject:
        raise InputError(f"{what} file {str(path)!r} holds Python objects (dtype {dtype}), not numbers")
    expected = header + int(np.prod(shape, dtype=object)) * dtype.itemsize
    if size < expected:
        raise InputError(f"{what} file {str(path)!r} is cut short: {size} of the {expected} bytes its header "
                         f"promises ({dtype} {tuple(shape)})")
    return header, size


def _magic(path, what: str) -> bytes:
    """The first six bytes of an input file (.npy and .npz files are told apart by them)."""
    try:
        with open(path, "rb") as handle:
            return handle.read(6)
    except OSError as exc:
        refuse_starved(exc, what, path)
        raise InputError(f"cannot read {what} file {str(path)!r}: {one_line(exc)}") from None


def check_stimulus(stimulus: np.ndarray, config: SensorConfig, *, whole_readouts: bool = True,
                   scan_values: bool = True, what: str = "stimulus") -> np.ndarray:
    """Refuse a per-clock electron array that SPEC section 3 does not allow.

    It must be a numpy integer array (a float or bool array is refused even when
    its values are whole) of shape ``(T, H, W)`` with every value in
    ``[0, 2^input_bits - 1]`` and, unless ``whole_readouts`` is false, T a
    multiple of L. ``scan_values=False`` checks only dtype and shape (for a
    caller that checks the values slice by slice). ``what`` names the array in refusals (e.g.
    ``stimulus file 'E.npy'``). Returns the array unchanged.
    """
    if not isinstance(stimulus, np.ndarray):
        raise InputError(f"{what} must be a numpy array, not {type(stimulus).__name__}")
    if stimulus.dtype.kind not in "iu":
        raise InputError(f"{what} dtype {stimulus.dtype} is not an integer type "
                         "(float and bool arrays are refused even when whole)")
    if stimulus.ndim != 3:
        raise InputError(f"{what} shape {stimulus.shape} must be (T, H, W)")
    clocks, height, width = stimulus.shape
    if height < 1 or width < 1:
        raise InputError(f"{what} shape {stimulus.shape}: H and W must be at least 1")
    L = config.clocks_per_readout
    if whole_readouts and clocks % L:
        raise InputError(f"{what} has T = {clocks} pixel clocks, not a multiple of "
                         f"L = clocks_per_tick * alpha = {L}")
    if scan_values and stimulus.size:
        # A dtype that cannot hold a bad value is not scanned (a pass over a large
        # stimulus costs as much as simulating part of it).
        info = np.iinfo(stimulus.dtype)
        low = 0 if info.min >= 0 else int(stimulus.min())
        high = 0 if info.max <= config.input_max else int(stimulus.max())
        if low < 0:
            raise InputError(f"{what} value {low} is negative (electrons per clock must be "
                             f"in 0..2^input_bits - 1 = {config.input_max})")
        if high > config.input_max:
            raise InputError(f"{what} value {high} exceeds 2^input_bits - 1 = {config.input_max} "
                             f"(input_bits = {config.input_bits})")
    return stimulus


def load_stimulus(path: str | Path, config: SensorConfig) -> np.ndarray:
    """Read and check ``E.npy``, memory-mapped read-only so a large file stays on disk.

    The range check streams through the file in slices of about 2^24 values,
    so it too needs memory bounded by the slice, not by the file.
    """
    config = SensorConfig.required(config, "load_stimulus")
    stimulus = load_npy(path, "stimulus", mmap_mode="r")
    if stimulus.ndim == 3 and stimulus.shape[0] == 0:
        raise InputError(f"stimulus file {str(path)!r} has T = 0 pixel clocks (no readout to make)")
    what = f"stimulus file {str(path)!r}"
    if stimulus.ndim != 3 or stimulus.dtype.kind not in "iu":
        return check_stimulus(stimulus, config, what=what)
    check_stimulus(stimulus, config, scan_values=False, what=what)     # dtype, shape and T rules
    step = max(1, (1 << 24) // max(1, stimulus[0].size))
    for start in range(0, stimulus.shape[0], step):
        check_stimulus(stimulus[start:start + step], config, whole_readouts=False, what=what)
    return stimulus


def check_frame_shape(shape, what: str = "frame shape") -> tuple[int, int]:
    """``shape`` as ``(H, W)``: two integers, each at least 1 (a pixel array's, SPEC section 6),
    refused in one line otherwise (numpy had refused a negative one in its own words, and taken
    three numbers or an empty frame)."""
    try:
        height, width = shape
    except (TypeError, ValueError):
        raise InputError(f"{what} {shape!r}: must be (H, W), two integers") from None
    if not (is_count(height, 1) and is_count(width, 1)):
        raise InputError(f"{what} {shape!r}: H and W must be integers of at least 1")
    return int(height), int(width)


def check_scene(scene: np.ndarray, *, scan_values: bool = True, what: str = "scene") -> np.ndarray:
    """Refuse a light array that SPEC section 6 does not allow; return it as float64.

    ``scan_values=False`` checks only type and shape and returns the array
    unchanged (for a caller that checks and converts it slice by slice).
    ``what`` names the array in refusals (e.g. ``reference 'I.npy'`` for ``tespike score``).
    """
    if not isinstance(scene, np.ndarray):
        raise InputError(f"{what} must be a numpy array, not {type(scene).__name__}")
    if scene.dtype.kind != "f":
        raise InputError(f"{what} dtype {scene.dtype} is not a float type (light per readout interval "
                         "must be a float array, SPEC section 6; an integer array is refused "
                         "like a float stimulus is)")
    if scene.ndim != 3:
        raise InputError(f"{what} shape {scene.shape} must be (K, H, W)")
    if scene.shape[1] < 1 or scene.shape[2] < 1:
        raise InputError(f"{what} shape {scene.shape}: H and W must be at least 1")
    if not scan_values:
        return scene
    scan_light(scene, what)                            # (in its own dtype: a long double's own values)
    return scene.astype(np.float64, copy=False)


def scan_light(light: np.ndarray, what: str = "scene") -> None:
    """Refuse a non-finite or negative value of a float light array, in its own
    dtype (nothing converted: two reductions, no temporary; a NaN anywhere makes
    the minimum NaN). The values are those float64 would hold, so the message
    is the one :func:`check_scene` gives after converting."""
    light = np.asarray(light)                            # (a list had been an AttributeError)
    if light.dtype.kind not in "fiu":
        raise InputError(f"{what}: dtype {light.dtype} is not real numbers")
    if not light.size:
        return
    low, high = light.min(), light.max()
    if low >= 0 and high <= np.finfo(np.float64).max:   # (a long double's 1e4000 is finite, inf in float64)
        return
    finite = np.isfinite(light)
    if not finite.all():
        bad = np.float64(light[~finite][0])
        raise InputError(f"{what} holds a non-finite light value ({bad}); light must be finite")
    if low < 0:
        raise InputError(f"{what} holds a negative light value ({str(low)}); light must be >= 0")
    raise InputError(f"{what} holds a light value ({str(high)}) beyond float64's range, in which light is "
                     "simulated and scored")


def load_scene(path: str | Path, *, memory_map: bool = False, what: str | None = None,
               scan_values: bool = True) -> np.ndarray:
    """Read and check ``I.npy`` (light per readout interval, 1.0 = design light).

    ``memory_map=True`` leaves the file on disk (read-only memory map, in the
    file's own dtype) and checks the values one slice of readouts at a time,
    so memory stays bounded by the slice; the caller converts what it reads.
    ``scan_values=False`` (with ``memory_map``) leaves the values to a caller that checks
    each readout as it reads it (:func:`tespike.golden.fastsim.simulate_scene`, named by
    :func:`scene_name`); the dtype, shape and file are checked all the same.
    ``what`` names the file in refusals (default "scene": ``tespike score`` says "reference").
    """
    name = "scene" if what is None else what
    check_flag(memory_map, "load_scene memory_map")     # ('no' had been a memory map)
    check_flag(scan_values, "load_scene scan_values")
    scene = load_npy(path, name, mmap_mode="r")
    name = scene_name(path, what)                                   # values refused naming the file
    scene = check_scene(scene, scan_values=False, what=name)
    if scene.shape[0] == 0:
        raise InputError(f"scene file {str(path)!r} has K = 0 readout intervals (nothing to simulate)"
                         if what is None else f"{name} has K = 0 frames")
    if not memory_map:
        return check_scene(np.array(scene), what=name)
    if not scan_values:
        return scene
    step = max(1, (1 << 22) // max(1, scene[0].size))
    for start in range(0, scene.shape[0], step):
        scan_light(np.asarray(scene[start:start + step]), name)
    return scene


def scene_name(path: str | Path, what: str | None = None) -> str:
    """How :func:`load_scene` names the light file ``path`` in a refusal of its values."""
    return f"{'scene' if what is None else what} file {str(path)!r}"


def unsigned_dtype(bits: int) -> np.dtype:
    """Smallest unsigned dtype that holds ``bits`` bits (at most 32)."""
    return np.dtype(np.uint8 if bits <= 8 else np.uint16 if bits <= 16 else np.uint32)


def word_dtype(config: SensorConfig) -> np.dtype:
    """Smallest unsigned dtype that holds a readout word."""
    return unsigned_dtype(config.word_bits)


def save_stream(path: str | Path, words: np.ndarray, config: SensorConfig) -> None:
    """Write ``S.npz``: ``words`` (K, H, W) and ``config``, the full configuration as JSON. The words
    must be integers, each a legal word of ``config`` (:func:`tespike.golden.decode.check_words`), so
    that the cast to the smallest word dtype changes none (a float, negative or too large word had
    been truncated or wrapped into the file)."""
    config = SensorConfig.required(config, "save_stream")
    words = np.asarray(words)
    if words.ndim != 3:
        raise InputError(f"stream words shape {words.shape} must be (K, H, W)")
    check_words(words, config)
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            write_npz(handle, words=words.astype(word_dtype(config), copy=False),
                      config=np.array(config.to_json()))


def write_npz(handle, **arrays: np.ndarray) -> None:
    """``np.savez(handle, **arrays)``, the same archive (uncompressed, Zip64 members as numpy
    writes them, read by ``np.load``), each array written from its own memory: ``np.savez``
    copies an array into a bytes object first (its ``write_array`` does for any file that is
    not a plain file, as an archive member is), 3-5 ms of a 12.6 MB stream's 10."""
    with zipfile.ZipFile(handle, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as archive:
        for name, array in arrays.items():
            array = np.asarray(array)
            if not array.flags.c_contiguous:
                array = array.copy(order="C")
            header = np.lib.format.header_data_from_array_1_0(array)
            with archive.open(f"{name}.npy", mode="w", force_zip64=True) as member:
                try:
                    np.lib.format.write_array_header_1_0(member, header)
                except ValueError:                          # (a header past 64 KiB: format 2.0)
                    np.lib.format.write_array_header_2_0(member, header)
                member.write(memoryview(array.reshape(-1)).cast("B") if array.size else b"")


def _npy_header(member) -> tuple[tuple[int, ...], bool, np.dtype, int | None]:
    """(shape, Fortran order, dtype, the header's length in bytes or None) of the .npy array an open
    archive member starts with, read from its first bytes."""
    version = np.lib.format.read_magic(member)
    read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                   else np.lib.format.read_array_header_2_0)
    shape, fortran, dtype = read_header(member)
    return shape, fortran, dtype, member.tell() if hasattr(member, "tell") else None


def _stored_member(path: str | Path, key: str) -> np.ndarray | None:
    """A read-only memory map of the uncompressed (``np.savez``) array ``np.load`` calls ``key``
    (stored as ``key.npy``, or as ``key`` itself), after its CRC is verified by streaming through it;
    ``None`` if the member is compressed."""
    opened = watch_descriptor(path)                     # (watched from before the CRC's read)
    try:
        return _mapped_member(path, key, opened)
    finally:
        if opened is not None and opened not in taken_descriptors():
            os.close(opened)


def _mapped_member(path: str | Path, key: str, opened: int | None) -> np.ndarray | None:
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        name = f"{key}.npy" if f"{key}.npy" in names else key
        info = archive.getinfo(name)
        if info.compress_type != zipfile.ZIP_STORED or info.flag_bits & 0x1:
            return None
        with archive.open(info) as member:            # reading to the end checks the CRC
            shape, fortran, dtype, header = _npy_header(member)
            while member.read(1 << 22):
                pass
    if header is None or dtype.hasobject:
        return None
    with open(path, "rb") as handle:               # the member's data starts after its local header
        handle.seek(info.header_offset)
        local = handle.read(30)
        if len(local) < 30 or local[:4] != b"PK\x03\x04":
            raise zipfile.BadZipFile(f"bad local header of member {name!r}")
        start = info.header_offset + 30 + int.from_bytes(local[26:28], "little") + \
            int.from_bytes(local[28:30], "little")
    count = int(np.prod(shape, dtype=np.int64))
    if header + count * dtype.itemsize > info.file_size:
        raise ValueError(f"member {name!r} is shorter than its header's shape {shape}")
    if count == 0:
        return np.zeros(shape, dtype)
    held_mapping(path, start + header + count * dtype.itemsize, opened)   # (cut short while mapped: named)
    return np.memmap(path, dtype=dtype, mode="r", offset=start + header, shape=shape,
                     order="F" if fortran else "C")


#: What reading a truncated or corrupt .npz archive raises (numpy, zipfile, zlib).
NPZ_ERRORS = (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error, NotImplementedError,
              RuntimeError, *HEADER_ERRORS)


@contextlib.contextmanager
def open_npz(path: str | Path, what: str, holding: str = "") -> Iterator[np.lib.npyio.NpzFile]:
    """``np.load`` of an .npz archive (``what`` file: stream, calibration...) whose members are read
    inside the ``with``; any reading fault there (a truncated archive, a bad CRC, a .npy array, no
    zip header) is one :class:`InputError` naming ``what`` and the file. ``holding`` says what the
    archive should hold, for the refusal of a .npy array."""
    shown = str(path)
    check_input_file(path, what)
    magic = _magic(path, what)
    if magic == b"\x93NUMPY":
        raise InputError(f"{what} file {shown!r} is a .npy array, not an .npz archive"
                         + (f" {holding}" if holding else ""))
    if not magic.startswith(b"PK"):
        raise InputError(f"{what} file {shown!r} is not a readable .npz archive (no zip header)")
    try:
        _check_member_sizes(path)
        with np.load(path, allow_pickle=False) as npz:
            yield npz
    except InputError:
        raise
    except NPZ_ERRORS as exc:
        refuse_starved(exc, what, path)
        cause = "a member's .npy header is damaged" if header_damaged(exc) else one_line(exc)
        raise InputError(f"{what} file {shown!r} is not a readable .npz archive: {cause}") from None


def _npz_key(name: str) -> str:
    """The key ``np.load`` gives an archive member: its name without a final ``.npy``."""
    return name[:-4] if name.endswith(".npy") else name


def _check_member_sizes(path: str | Path) -> None:
    """Refuse (ValueError) an .npy member whose header's shape needs more bytes than the member holds,
    read from its first bytes and the archive's directory before numpy allocates the shape (a
    400-byte archive declaring 9 TiB was reported as running out of memory), or fewer (numpy
    ignores bytes after the array, as a bare .npy's are refused: :func:`load_npy`); and an
    archive holding one member name twice (numpy reads the last, unseen by most zip tools); and bytes
    after the archive's end record (zip readers find the record near the end and ignore what follows:
    two files joined, or a copy that overran)."""
    check_archive_end(path)
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        keys = [_npz_key(name) for name in names]     # the names np.load gives (".npy" dropped)
        twice = sorted({key for key in keys if keys.count(key) > 1})
        if twice:
            stored = sorted({name for name, key in zip(names, keys) if key == twice[0]})
            raise ValueError(f"member {twice[0]!r} is stored twice"
                             + (f" (as {' and '.join(map(repr, stored))})" if len(stored) > 1 else ""))
        for info in archive.infolist():
            if info.flag_bits & 0x1:
                continue
            if not info.filename.endswith(".npy"):   # np.load reads any member that starts as .npy does
                with archive.open(info) as member:
                    if member.read(len(np.lib.format.MAGIC_PREFIX)) != np.lib.format.MAGIC_PREFIX:
                        continue
            with archive.open(info) as member:
                shape, _, dtype, header = _npy_header(member)
            if header is None or dtype.hasobject:
                continue
            size = header + int(np.prod(shape, dtype=object)) * dtype.itemsize
            if size > info.file_size:
                raise ValueError(f"member {info.filename!r} is shorter than its header's shape {shape}")
            if size < info.file_size:
                raise ValueError(f"member {info.filename!r} holds {info.file_size - size} bytes after its "
                                 f"{shape} array")


#: A zip archive's end record: its signature, and its size without the comment that may follow it;
#: the zip64 end record's signature and size, and its locator's (just before the end record).
_END_SIGNATURE, _END_SIZE = b"PK\x05\x06", 22
_ZIP64_SIGNATURE, _ZIP64_RECORD = b"PK\x06\x06", 56
_ZIP64_LOCATOR_SIGNATURE, _ZIP64_LOCATOR = b"PK\x06\x07", 20


def check_archive_end(path: str | Path) -> None:
    """Refuse (ValueError) an archive that is not the whole file: bytes after its end-of-directory
    record (with the comment it declares), or before its first member (the directory's size and offset,
    from the zip64 record where there is one, fall short of the record's place: a second archive joined
    to a first is read as the second alone). The record is the one :mod:`zipfile` reads: the file's last 22
    bytes where they are one without a comment, else the last signature in the final 64 KiB; an
    archive without one is left to :mod:`zipfile`, whose message says so."""
    with open(path, "rb") as file:
        size = file.seek(0, os.SEEK_END)
        start = max(0, size - (_END_SIZE + 0xFFFF))
        file.seek(start)
        tail = file.read()
        if tail[-_END_SIZE:][:4] == _END_SIGNATURE and tail[-2:] == b"\0\0":
            at = len(tail) - _END_SIZE
        else:
            at = tail.rfind(_END_SIGNATURE)
            if at < 0 or at + _END_SIZE > len(tail):
                return
            extra = len(tail) - (at + _END_SIZE + int.from_bytes(tail[at + 20:at + 22], "little"))
            if extra > 0:
                raise ValueError(f"{extra} bytes follow the archive's end")
        record = start + at                                 # the end record's place in the file
        directory_size, directory_at = (int.from_bytes(tail[at + k:at + k + 4], "little") for k in (12, 16))
        if record >= _ZIP64_RECORD + _ZIP64_LOCATOR:         # zip64 records just before it (torch always writes them)
            file.seek(record - _ZIP64_RECORD - _ZIP64_LOCATOR)
            zip64 = file.read(_ZIP64_RECORD + _ZIP64_LOCATOR)
            if zip64[:4] == _ZIP64_SIGNATURE and zip64[_ZIP64_RECORD:][:4] == _ZIP64_LOCATOR_SIGNATURE:
                record -= _ZIP64_RECORD + _ZIP64_LOCATOR
                directory_size, directory_at = (int.from_bytes(zip64[k:k + 8], "little") for k in (40, 48))
    if 0xFFFFFFFF in (directory_size, directory_at):        # zip64 values without their records: zipfile's to say
        return
    before = record - directory_size - directory_at
    if before > 0:
        raise ValueError(f"{before} bytes come before the archive (two archives joined?)")


def refuse_starved(exc: BaseException, what: str, path) -> None:
    """A read that failed for want of file handles or memory, not for the file: one line saying so
    (instead of calling the file unreadable)."""
    if not isinstance(exc, OSError):
        return
    from .resources import file_handles_fault
    cause = file_handles_fault(exc) or ("out of memory" if exc.errno == errno.ENOMEM else None)
    if cause:
        raise InputError(f"cannot read {what} file {str(path)!r}: {cause}") from None


def load_stream(path: str | Path, *, memory_map: bool = False) -> tuple[np.ndarray, SensorConfig]:
    """Read ``S.npz``; return ``(words, config)`` with the words checked legal.

    Anything but a readable zip archive holding ``words`` and ``config`` is
    refused in one line: a ``.npy`` array, a truncated or corrupt archive (bad
    CRC, unknown compression, an encrypted member), a stream with K, H or W = 0.
    ``memory_map=True`` leaves uncompressed words (as ``np.savez`` writes them)
    on disk as a read-only memory map; compressed words are read into memory.
    """
    shown = str(path)
    with open_npz(path, "stream", "holding 'words' and 'config'") as npz:
        if "words" not in npz.files or "config" not in npz.files:
            raise InputError(f"stream file {shown!r} must hold 'words' and 'config' "
                             f"(it holds {', '.join(npz.files) or 'nothing'})")
        extra = [name for name in npz.files if name not in ("words", "config")]
        if extra:                                      # (it would be ignored: SPEC's stream holds the two)
            raise InputError(f"stream file {shown!r} holds {', '.join(map(repr, extra))} beside 'words' and "
                             "'config': a stream holds those two only (SPEC section 6)")
        config_text = npz["config"]
        words = _stored_member(path, "words") if memory_map else None
        if words is None:
            words = npz["words"]
    config = config_member(config_text, f"stream file {shown!r}")
    if words.dtype.kind not in "iu" or words.ndim != 3:
        raise InputError(f"stream file {shown!r}: 'words' must be an integer (K, H, W) array, "
                         f"not {words.dtype} {words.shape}")
    if 0 in words.shape:
        raise InputError(f"stream file {shown!r}: 'words' shape {words.shape} is empty "
                         "(K, H and W must be at least 1)")
    try:
        check_words(words, config)
    except InputError as exc:
        raise InputError(f"stream file {shown!r}: {exc}") from None
    return words, config


def text_member(value: np.ndarray, what: str, key: str) -> str:
    """The text an .npz file holds as its member ``key`` (a 0-d string; bytes are read as UTF-8), or
    one line starting with ``what`` (the file)."""
    if value.ndim != 0 or value.dtype.kind not in "US":
        raise InputError(f"{what}: {key!r} must be a 0-d string, not {value.dtype} {value.shape}")
    text = value.item()
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"{what}: {key!r} holds bytes that are not UTF-8 text") from None
    return text


def config_member(value: np.ndarray, what: str) -> SensorConfig:
    """The configuration an .npz file holds as its ``config`` member (a 0-d string of JSON; bytes are
    read as UTF-8), or one line starting with ``what`` (the file)."""
    text = text_member(value, what, "config")
    try:
        return SensorConfig.from_json(text, whole=True)
    except TespikeError as exc:
        raise InputError(f"{what}: {exc}") from None


def images_array(shape: tuple[int, int, int], out: np.ndarray | None = None) -> np.ndarray:
    """The float32 (K, H, W) array of an ``R.npy`` a reconstruction fills: ``out`` checked, or a new one."""
    if not (isinstance(shape, tuple) and len(shape) == 3 and all(is_count(n) for n in shape)):
        raise InputError(f"images shape {shape!r}: must be (K, H, W), three integers >= 0")
    if out is None:
        return np.empty(shape, np.float32)
    if not isinstance(out, np.ndarray):                  # (a list had been an AttributeError)
        raise InputError(f"out must be a float32 {tuple(shape)} numpy array, not {type(out).__name__}")
    if not out.flags.writeable:                          # (numpy's "assignment destination is read-only")
        raise InputError("out is read-only: give an array the reconstruction can fill")
    if out.shape != tuple(shape) or out.dtype != np.float32:
        raise InputError(f"out must be float32 {tuple(shape)}, not {out.dtype} {out.shape}")
    return out


def save_images(path: str | Path, images: np.ndarray) -> None:
    """Write ``R.npy``: float32 (K, H, W) reconstructed light, atomically; light that is no finite,
    real number >= 0 within float32's range is refused (NaN, negative and complex light had been
    written, and 1e39 as infinity)."""
    images = np.asarray(images)
    if images.ndim != 3:
        raise InputError(f"image array shape {images.shape} must be (K, H, W)")
    scan_light(images, "reconstructed images")
    if images.size and float(images.max()) > float(np.finfo(np.float32).max):
        raise InputError(f"reconstructed images hold light ({float(images.max()):.6g}) beyond the range of "
                         "R.npy's float32")
    images = images.astype(np.float32, copy=False)
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, images)
