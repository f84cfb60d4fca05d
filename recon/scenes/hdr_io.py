"""HDR image files: Radiance RGBE (.hdr) in numpy, OpenEXR (.exr), and frame folders.

HDR video datasets (HDM-HDR-2014, Kalantari13) ship as one ``.exr`` or
``.hdr`` file per frame. :func:`load_hdr_sequence` turns such a folder into a
light sequence ``I`` (K, H, W) the way the paper does (appendix A.2.2):
grayscale, then one division by the sequence's largest pixel.

Radiance RGBE follows Greg Ward's format: a text header (``#?RADIANCE``,
``FORMAT=32-bit_rle_rgbe``, optional ``EXPOSURE=``), a resolution line such
as ``-Y 512 +X 768``, then scanlines of 4-byte pixels (R, G, B mantissas and
a shared exponent E), flat or in "new" run-length encoding. A pixel decodes
as ``mantissa * 2^(E - 136)`` (E = 0 means black) -- the rule of Bruce
Walter's ``rgbe.c`` that OpenCV, imageio and most dataset pipelines use
(Radiance's own ``colr_color`` adds 0.5 to the mantissa; the difference is
below the format's 1/256 quantisation). ``EXPOSURE=`` values and ``COLORCORR=``
triples (per channel) are multipliers already applied to the pixels, so the
reader divides them out, refusing a product that would take lit pixels past
float32's range or below its smallest normal number.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from tespike.golden.errors import InputError, is_count, one_line
from tespike.golden.io import atomic_output, check_frame_shape
from tespike.golden.paths import check_input_file, path_text

from .color import DEFAULT_WEIGHTS, check_weights, normalise_sequence, to_gray

#: File name endings read as frames (case-insensitive).
FRAME_SUFFIXES = (".exr", ".hdr", ".pic", ".rgbe")

_RESOLUTION = re.compile(rb"^([+-])([XY]) (\d+) ([+-])([XY]) (\d+)$")

#: Digits of a side in the resolution line (a billion pixels a side is past any frame read here).
_SIZE_DIGITS = 9

#: Characters of a header line quoted in a refusal (a line may be a 400-digit number).
_QUOTED = 40


def _quoted(line: bytes) -> str:
    """A header line as a refusal quotes it: ``repr`` of its text, its middle cut past _QUOTED characters."""
    text = line.decode("latin-1")
    if len(text) > _QUOTED:
        text = text[:_QUOTED - 12] + "..." + text[-9:]
    return repr(text)


# ---------------------------------------------------------------- RGBE codec
def rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    """uint8 ``(..., 4)`` RGBE pixels -> float32 ``(..., 3)`` linear RGB."""
    rgbe = np.asarray(rgbe)
    if rgbe.dtype != np.uint8 or rgbe.shape[-1:] != (4,):    # (another shape had been an IndexError)
        raise InputError(f"RGBE pixels must be uint8 (..., 4), not {rgbe.dtype} {rgbe.shape}")
    exponent = rgbe[..., 3].astype(np.int32)
    scale = np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0)
    return (rgbe[..., :3].astype(np.float64) * scale[..., None]).astype(np.float32)


def float_to_rgbe(rgb: np.ndarray) -> np.ndarray:
    """float ``(..., 3)`` linear RGB (finite, >= 0) -> uint8 ``(..., 4)`` RGBE.

    Walter's rule: the largest channel v = f * 2^e with f in [0.5, 1) sets the
    exponent e + 128; mantissas are ``floor(c * 256 / 2^e)``. Values below
    1e-32 become black; values at or above 2^127 cannot be stored and are
    refused.
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.shape[-1:] != (3,):
        raise InputError(f"RGBE encoding needs (..., 3) RGB values, not shape {rgb.shape}")
    if rgb.size and (not np.isfinite(rgb).all() or rgb.min() < 0):
        raise InputError("RGBE encoding needs finite, non-negative values")
    top = rgb.max(axis=-1) if rgb.size else np.zeros(rgb.shape[:-1])
    if top.size and top.max() >= 2.0 ** 127:
        raise InputError(f"value {top.max():g} is too large for RGBE (must be < 2^127)")
    fraction, exponent = np.frexp(top)
    dark = top < 1e-32
    safe = np.where(dark, 1.0, top)
    factor = np.where(dark, 0.0, fraction * 256.0 / safe)
    out = np.zeros(rgb.shape[:-1] + (4,), np.uint8)
    out[..., :3] = np.floor(rgb * factor[..., None]).clip(0, 255).astype(np.uint8)
    out[..., 3] = np.where(dark, 0, exponent + 128).astype(np.uint8)
    return out


# ---------------------------------------------------------------- .hdr reader
#: A header number as Radiance writes it (C's atof: no ``1_0``, ``inf`` or ``nan``, which Python's float takes).
_HEADER_NUMBER = re.compile(rb"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def _header_numbers(line: bytes, count: int, path: str) -> np.ndarray:
    """The ``count`` numbers of an EXPOSURE= or COLORCORR= header line, each finite and > 0 (the
    multipliers already applied to the pixels, which the reader divides out)."""
    key, _, text = line.partition(b"=")
    words = text.split()
    if len(words) != count or not all(_HEADER_NUMBER.fullmatch(word) for word in words):
        raise InputError(f"{path!r}: bad header line {_quoted(line)} "
                         f"({key.decode('latin-1')}= takes {count} number(s))")
    values = np.array([float(word) for word in words])
    if not (np.isfinite(values).all() and (values > 0).all()):
        raise InputError(f"{path!r}: header line {_quoted(line)} must hold finite numbers > 0")
    return values


def _parse_header(data: bytes, path: str) -> tuple[int, np.ndarray, tuple]:
    """Return (offset of pixel data, exposure per channel: the product of the EXPOSURE= and
    COLORCORR= lines, (rows, cols, row-axis info))."""
    if not data.startswith(b"#?"):
        raise InputError(f"{path!r} is not a Radiance HDR file (it must start with '#?')")
    pos = 0
    exposure = np.ones(1)
    fmt = None
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise InputError(f"{path!r}: header never ends (no blank line before the resolution)")
        line = data[pos:end].rstrip(b"\r")
        pos = end + 1
        if not line:
            break
        if line.startswith(b"FORMAT="):
            fmt = line[7:].strip().decode("latin-1")
        elif line.startswith(b"EXPOSURE="):
            exposure = exposure * _header_numbers(line, 1, path)
        elif line.startswith(b"COLORCORR="):       # (a per-channel EXPOSURE, Radiance's header)
            exposure = exposure * _header_numbers(line, 3, path)
    if fmt is not None and fmt != "32-bit_rle_rgbe":
        raise InputError(f"{path!r}: FORMAT={fmt} is not supported (only 32-bit_rle_rgbe)")
    end = data.find(b"\n", pos)
    if end < 0:
        raise InputError(f"{path!r}: missing resolution line")
    match = _RESOLUTION.match(data[pos:end].strip())
    if not match or match.group(2) == match.group(5):
        raise InputError(f"{path!r}: bad resolution line {_quoted(data[pos:end])} "
                         "(expected e.g. '-Y 512 +X 768')")
    sign1, axis1, n1, sign2, axis2, n2 = match.groups()
    if max(len(n1), len(n2)) > _SIZE_DIGITS:          # (int() of 4,300 digits or more raises)
        raise InputError(f"{path!r}: image size in the resolution line {_quoted(data[pos:end])} is too "
                         f"large (at most {_SIZE_DIGITS} digits a side)")
    return end + 1, exposure, (sign1, axis1, int(n1), sign2, int(n2))


def _decode_scanline(data: bytes, pos: int, width: int, path: str, row: int) -> tuple[bytes, int]:
    """One scanline -> (width * 4 bytes in pixel order, new offset)."""
    head = data[pos:pos + 4]
    if (8 <= width <= 0x7FFF and len(head) == 4 and head[0] == 2 and head[1] == 2
            and not head[2] & 0x80):
        if (head[2] << 8) | head[3] != width:
            raise InputError(f"{path!r}: scanline {row} run-length header says width "
                             f"{(head[2] << 8) | head[3]}, the file says {width}")
        pos += 4
        planes = []
        for component in range(4):
            plane = bytearray()
            while len(plane) < width:
                if pos >= len(data):
                    raise InputError(f"{path!r}: data ends inside scanline {row}")
                count = data[pos]
                if count > 128:
                    count -= 128
                    if pos + 1 >= len(data):
                        raise InputError(f"{path!r}: data ends inside scanline {row}")
                    plane += bytes((data[pos + 1],)) * count
                    pos += 2
                else:
                    if count == 0:
                        raise InputError(f"{path!r}: zero-length run in scanline {row}")
                    if pos + 1 + count > len(data):
                        raise InputError(f"{path!r}: data ends inside scanline {row}")
                    plane += data[pos + 1:pos + 1 + count]
                    pos += 1 + count
            if len(plane) != width:
                raise InputError(f"{path!r}: runs overrun scanline {row} "
                                 f"(component {component}: {len(plane)} values for width {width})")
            planes.append(plane)
        pixels = np.frombuffer(b"".join(planes), np.uint8).reshape(4, width).T
        return pixels.tobytes(), pos
    if pos + 4 * width > len(data):
        raise InputError(f"{path!r}: data ends inside scanline {row}")
    flat = np.frombuffer(data, np.uint8, 4 * width, pos).reshape(width, 4)
    if ((flat[:, 0] == 1) & (flat[:, 1] == 1) & (flat[:, 2] == 1)).any():
        raise InputError(f"{path!r}: scanline {row} uses old-style run-length encoding, "
                         "which this reader does not support")
    return data[pos:pos + 4 * width], pos + 4 * width


def read_hdr(path: str | Path) -> np.ndarray:
    """Read a Radiance RGBE file -> float32 (H, W, 3) linear RGB, top row first."""
    path = path_text(path, "HDR file")                # (None had been "cannot read HDR file 'None'")
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read HDR file {path!r}: {exc.strerror}") from None
    pos, exposure, (sign1, axis1, n1, sign2, n2) = _parse_header(data, path)
    if n1 < 1 or n2 < 1:
        raise InputError(f"{path!r}: image size {n1} x {n2} must be at least 1 x 1")
    rows = []
    for row in range(n1):
        line, pos = _decode_scanline(data, pos, n2, path, row)
        rows.append(line)
    if pos != len(data):                    # (a second image, or text, would be dropped unread)
        raise InputError(f"{path!r}: {len(data) - pos} byte(s) after the last of its {n1} scanlines "
                         "(a corrupt or concatenated file)")
    pixels = np.frombuffer(b"".join(rows), np.uint8).reshape(n1, n2, 4)
    rgb = rgbe_to_float(pixels)
    # Standard orientation is "-Y H +X W": scanlines top to bottom, left to right.
    if axis1 == b"Y":
        if sign1 == b"+":
            rgb = rgb[::-1]
        if sign2 == b"-":
            rgb = rgb[:, ::-1]
    else:                                   # scanlines are columns
        rgb = rgb.transpose(1, 0, 2)
        if sign1 == b"-":
            rgb = rgb[:, ::-1]
        if sign2 == b"+":
            rgb = rgb[::-1]
    if (exposure != 1.0).any():
        lit = rgb >= np.finfo(np.float32).tiny     # (RGBE holds subnormals too: those stay as they are)
        with np.errstate(over="ignore", under="ignore"):
            rgb = (rgb.astype(np.float64) / exposure).astype(np.float32)
        factor = " ".join(f"{value:g}" for value in exposure)
        if not np.isfinite(rgb).all():      # (the pixels are finite: RGBE holds no infinity)
            raise InputError(f"{path!r}: its exposure {factor} (the EXPOSURE= and COLORCORR= lines' product) "
                             "divides its pixel values beyond float32's range")
        if (rgb[lit] < np.finfo(np.float32).tiny).any():   # (lit pixels made 0 or subnormal: lost)
            raise InputError(f"{path!r}: its exposure {factor} (the EXPOSURE= and COLORCORR= lines' product) "
                             "divides lit pixel values below float32's smallest normal number")
    return np.ascontiguousarray(rgb)


# ---------------------------------------------------------------- .hdr writer
def _rle_encode(plane: np.ndarray) -> bytes:
    """New-style Radiance run-length encoding of one component of one scanline."""
    values = plane.tobytes()
    n = len(values)
    out = bytearray()
    i = 0
    literal_start = 0

    def flush_literal(start: int, stop: int) -> None:
        while start < stop:
            chunk = min(128, stop - start)
            out.append(chunk)
            out.extend(values[start:start + chunk])
            start += chunk

    while i < n:
        run = 1
        while i + run < n and run < 127 and values[i + run] == values[i]:
            run += 1
        if run >= 4:
            flush_literal(literal_start, i)
            out.append(128 + run)
            out.append(values[i])
            i += run
            literal_start = i
        else:
            i += run
    flush_literal(literal_start, n)
    return bytes(out)


def _image_to_write(image, what: str) -> np.ndarray:
    """``image`` as float64 for a writer named ``what``: real numbers only (a complex image had lost
    its imaginary part with a warning, text was numpy's conversion error)."""
    image = np.asarray(image)
    if image.dtype.kind not in "fiu":
        raise InputError(f"{what}: image dtype {image.dtype} is not real numbers")
    return image.astype(np.float64, copy=False)


def write_hdr(path: str | Path, image: np.ndarray, *, rle: bool = True) -> None:
    """Write float (H, W, 3) RGB or (H, W) gray as a Radiance RGBE file, atomically.

    ``rle`` selects new-style run-length encoding (used whenever the width
    allows it, 8..32767) or flat scanlines.
    """
    image = _image_to_write(image, "write_hdr")
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=-1)
    if image.ndim != 3 or image.shape[-1] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise InputError(f"write_hdr needs an (H, W, 3) or (H, W) image, not shape {image.shape}")
    height, width = image.shape[:2]
    pixels = float_to_rgbe(image)
    parts = [b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n", f"-Y {height} +X {width}\n".encode()]
    use_rle = rle and 8 <= width <= 0x7FFF
    for row in pixels:
        if use_rle:
            parts.append(bytes((2, 2, width >> 8, width & 0xFF)))
            parts.extend(_rle_encode(row[:, c]) for c in range(4))
        else:
            parts.append(row.tobytes())
    with atomic_output(path) as tmp:
        Path(tmp).write_bytes(b"".join(parts))


# ---------------------------------------------------------------- OpenEXR
@contextlib.contextmanager
def _library_output() -> Iterator[Callable[[], str]]:
    """Hold what a C library writes on file descriptors 1 and 2 (OpenEXR prints its faults and
    warnings there, beside the exception it raises); yields a function giving the first line
    held, so that a refusal stays one line on stderr and carries the library's cause."""
    import tempfile
    sys.stdout.flush()
    sys.stderr.flush()
    with tempfile.TemporaryFile() as held:
        saved = [os.dup(1), os.dup(2)]
        os.dup2(held.fileno(), 1)
        os.dup2(held.fileno(), 2)

        def first_line() -> str:
            held.seek(0)
            lines = held.read(4096).decode("utf-8", "replace").strip().splitlines()
            return " ".join(lines[0].split()) if lines else ""
        try:
            yield first_line
        finally:
            for number, copy in zip((1, 2), saved):
                os.dup2(copy, number)
                os.close(copy)


def _exr_contents(path: str, header_only: bool = False) -> dict:
    """The OpenEXR file ``path``'s channels (name -> pixels), or with ``header_only`` its header
    (no pixel decoded); a missing or corrupt file is one line (the library's own words where it
    printed them: "found corrupt leader")."""
    import OpenEXR

    if not Path(path).is_file():
        raise InputError(f"cannot read EXR file {path!r}: no such file")
    try:
        with open(path, "rb") as handle:
            magic = handle.read(4)
    except OSError as exc:
        raise InputError(f"cannot read EXR file {path!r}: {exc.strerror}") from None
    if magic != EXR_MAGIC:                  # (the library said "Unable to open ... for read", as if unreadable)
        other = " (a Radiance .hdr file, by its first bytes)" if magic.startswith(b"#?") else ""
        raise InputError(f"{path!r} is not an OpenEXR file: it does not start with EXR's magic number{other}")
    with _library_output() as said:
        try:
            with OpenEXR.File(path, header_only=header_only) as handle:
                parts = len(handle.parts)
                contents = dict(handle.header()) if header_only else \
                    {name: np.asarray(ch.pixels) for name, ch in handle.channels().items()}
            failure = None
        except Exception as exc:  # the binding raises plain Exceptions for corrupt files
            failure = exc
            said_first = said()
    if failure is not None:
        raise InputError(f"cannot read EXR file {path!r}: {one_line(said_first.removeprefix(f'{path}: ') or failure)}")
    if parts != 1:                          # (the channels read are the first part's: the others would be dropped)
        raise InputError(f"EXR file {path!r} holds {parts} parts (images): give one image per frame file")
    return contents


#: The first four bytes of every OpenEXR file.
EXR_MAGIC = bytes((0x76, 0x2F, 0x31, 0x01))

#: Scan lines per chunk of each OpenEXR compression (its id in the header), for the end check.
_EXR_LINES = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}

#: Version flags of an OpenEXR file that is not one part of scan lines (tiled, deep, multi-part).
_EXR_NOT_SCANLINE = 0x200 | 0x800 | 0x1000


def _exr_bytes_after(path: str) -> int:
    """Bytes after the last chunk of a single-part scan-line OpenEXR file (the library reads its chunks
    by their offsets and ignores what follows them: two files joined, a copy that overran); 0 where
    the file is another kind (tiled, deep, multi-part, an unknown compression) or its offsets are not
    all readable, which the library itself judges. Mapped, not read: only the header, the offset table
    and each chunk's 8-byte head are touched."""
    import mmap
    with open(path, "rb") as file:
        if os.fstat(file.fileno()).st_size < 8:
            return 0
        with mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _exr_tail(data)


def _exr_tail(data) -> int:
    """:func:`_exr_bytes_after` on the file's bytes ``data`` (a memory map)."""
    import struct
    if data[:4] != b"\x76\x2f\x31\x01" or int.from_bytes(data[4:8], "little") & _EXR_NOT_SCANLINE:
        return 0
    pos, window, compression = 8, None, None
    try:
        while data[pos]:                                   # attributes until an empty name
            name_end = data.find(b"\0", pos)
            type_end = data.find(b"\0", name_end + 1)
            if name_end < 0 or type_end < 0:
                return 0
            size = int.from_bytes(data[type_end + 1:type_end + 5], "little", signed=True)
            value = data[type_end + 5:type_end + 5 + size]
            name = data[pos:name_end]
            if name == b"dataWindow" and size == 16:
                window = struct.unpack("<4i", value)
            elif name == b"compression" and size == 1:
                compression = value[0]
            pos = type_end + 5 + size
        pos += 1
    except (IndexError, struct.error):
        return 0
    if window is None or compression not in _EXR_LINES:
        return 0
    chunks = -(-(window[3] - window[1] + 1) // _EXR_LINES[compression])
    if chunks < 1 or pos + 8 * chunks > len(data):
        return 0
    end = 0
    for offset in struct.unpack_from(f"<{chunks}Q", data, pos):
        if not pos + 8 * chunks <= offset <= len(data) - 8:
            return 0
        end = max(end, offset + 8 + int.from_bytes(data[offset + 4:offset + 8], "little", signed=True))
    return max(0, len(data) - end)


def read_exr(path: str | Path) -> np.ndarray:
    """Read an OpenEXR file -> float32 (H, W, 3) RGB or (H, W) for a luminance-only 'Y' file."""
    path = path_text(path, "EXR file")
    channels = _exr_contents(path)
    extra = _exr_bytes_after(path)
    if extra:
        raise InputError(f"EXR file {path!r}: {extra} byte(s) after the last of its chunks (two files joined, "
                         "or a copy that overran?)")
    for name in ("RGB", "RGBA"):
        if name in channels:
            return channels[name][..., :3].astype(np.float32)
    if all(c in channels for c in "RGB"):
        return np.stack([channels[c] for c in "RGB"], axis=-1).astype(np.float32)
    if "Y" in channels:
        return channels["Y"].astype(np.float32)
    raise InputError(f"EXR file {path!r} has channels {sorted(channels)}; need R, G, B or Y")


def write_exr(path: str | Path, image: np.ndarray) -> None:
    """Write float32 (H, W, 3) RGB or (H, W) as 'Y' to an OpenEXR file, atomically (tests, examples);
    light that is no finite number >= 0 within float32's range is refused, as :func:`write_hdr` refuses
    what RGBE cannot hold (NaN, negative light and 1e300, written as infinity, had been written)."""
    import OpenEXR

    image = _image_to_write(image, "write_exr")
    if image.size and (not np.isfinite(image).all() or image.min() < 0
                       or image.max() > float(np.finfo(np.float32).max)):
        raise InputError("write_exr needs finite, non-negative values within float32's range")
    if image.ndim not in (2, 3) or min(image.shape[:2], default=0) < 1:
        raise InputError(f"write_exr needs an (H, W, 3) or (H, W) image of at least 1 x 1, not shape {image.shape}")
    image = np.ascontiguousarray(image, dtype=np.float32)
    if image.ndim == 3 and image.shape[-1] == 3:
        channels = {"RGB": image}
    elif image.ndim == 2:
        channels = {"Y": image}
    else:
        raise InputError(f"write_exr needs an (H, W, 3) or (H, W) image, not shape {image.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_output(path) as tmp:
        with OpenEXR.File(header, channels) as handle:
            handle.write(tmp)


# ---------------------------------------------------------------- folders
def read_image(path: str | Path) -> np.ndarray:
    """Read one HDR frame by its ending: ``.exr`` or Radiance (``.hdr``, ``.pic``, ``.rgbe``)."""
    check_input_file(path, "HDR frame")         # a FIFO or device would block or mislead
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        return read_exr(path)
    if suffix in FRAME_SUFFIXES:
        return read_hdr(path)
    raise InputError(f"{str(path)!r}: unknown HDR file type {suffix!r} "
                     f"(known: {', '.join(FRAME_SUFFIXES)})")


def frame_size(path: str | Path) -> tuple[int, int]:
    """(H, W) of one HDR frame from its header alone (no pixel is decoded), as :func:`read_image`
    would give it: a sequence's frames are checked for one size before any work starts."""
    check_input_file(path, "HDR frame")
    path = str(path)
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        header = _exr_contents(path, header_only=True)
        try:
            low, high = header["dataWindow"]
            return int(high[1]) - int(low[1]) + 1, int(high[0]) - int(low[0]) + 1
        except (KeyError, TypeError, ValueError, IndexError):
            raise InputError(f"cannot read EXR file {path!r}: its header has no data window") from None
    if suffix not in FRAME_SUFFIXES:
        raise InputError(f"{path!r}: unknown HDR file type {suffix!r} (known: {', '.join(FRAME_SUFFIXES)})")
    try:
        with open(path, "rb") as handle:
            data = handle.read(1 << 12)
            while True:              # the header is a few hundred bytes: read until it parses, doubling
                try:                 # what is read (a file with no header end costs its size, once)
                    _, _, (_, axis1, n1, _, n2) = _parse_header(data, path)
                    break
                except InputError:
                    more = handle.read(len(data))
                    if not more:
                        raise
                    data += more
    except OSError as exc:
        raise InputError(f"cannot read HDR file {path!r}: {exc.strerror}") from None
    return (n1, n2) if axis1 == b"Y" else (n2, n1)


def sequence_size(paths: list, what: str) -> tuple[int, int]:
    """(H, W) of every frame of a sequence (``what`` names it), from the frames' headers alone:
    a frame of another size is refused naming both, before any frame is decoded."""
    if not paths:                                     # (an IndexError)
        raise InputError(f"{what} has no frames")
    first = frame_size(paths[0])
    for path in paths[1:]:
        size = frame_size(path)
        if size != first:
            raise InputError(f"frame {str(path)!r} is {size[0]} x {size[1]}, but the first frame of {what} "
                             f"({str(paths[0])!r}) is {first[0]} x {first[1]}; all frames of a sequence must "
                             "have the same size")
    return first


def _natural_key(name: str) -> tuple:
    """Numbers compared as numbers (ASCII digit runs: ``'²'`` is text), case aside, then the name
    itself: a total order, so ``f1``, ``f01`` and ``F1`` come in one order whatever the folder's."""
    parts = re.split(r"([0-9]+)", name)
    return [int(part) if i % 2 else part.lower() for i, part in enumerate(parts)], name


def list_frames(folder: str | Path) -> list[Path]:
    """The HDR frames of a folder, sorted by name (numbers compared as numbers: 2 < 10). Every
    entry named as a frame must be one: a dangling link, a folder or a FIFO so named is refused
    in one line (it was skipped, and the sequence came out a frame short, exit 0)."""
    from tespike.golden.paths import check_input_file, path_text
    folder = Path(path_text(folder, "HDR sequence folder"))
    if not folder.is_dir():
        raise InputError(f"HDR sequence folder {str(folder)!r} does not exist or is not a folder")
    frames = [p for p in folder.iterdir() if p.suffix.lower() in FRAME_SUFFIXES]
    for path in frames:
        check_input_file(path, "HDR frame")
    if not frames:
        raise InputError(f"HDR sequence folder {str(folder)!r} holds no frames "
                         f"(files ending in {', '.join(FRAME_SUFFIXES)})")
    return sorted(frames, key=lambda p: _natural_key(p.name))


def _check_crop_and_blocks(size: tuple[int, int], crop: tuple[int, int] | None, downscale: int,
                           what: str) -> None:
    """Refuse a crop larger than frames of ``size``, or a cropped size that is not a whole
    number of ``downscale`` x ``downscale`` blocks (rows or columns would be dropped)."""
    if crop is not None:
        height, width = crop
        if height < 1 or width < 1 or height > size[0] or width > size[1]:
            raise InputError(f"{what}: cannot crop {height} x {width} out of {size[0]} x {size[1]}")
        size = crop
    if downscale > 1:
        height, width = (n // downscale * downscale for n in size)
        if height == 0 or width == 0:
            raise InputError(f"{what}: {size[0]} x {size[1]} is smaller than one "
                             f"{downscale} x {downscale} block")
        if (height, width) != tuple(size):
            raise InputError(f"{what}: {size[0]} x {size[1]} is not a whole number of {downscale} x "
                             f"{downscale} blocks (the last rows or columns would be dropped): crop it to "
                             f"{height}x{width} first, or downscale by a factor of both sides")


def _crop_and_shrink(gray: np.ndarray, crop: tuple[int, int] | None, downscale: int) -> np.ndarray:
    """A frame centre-cropped to ``crop`` and area-averaged over ``downscale`` blocks (both
    checked by :func:`_check_crop_and_blocks`)."""
    if crop is not None:
        height, width = crop
        top, left = (gray.shape[0] - height) // 2, (gray.shape[1] - width) // 2
        gray = gray[top:top + height, left:left + width]
    if downscale > 1:
        height, width = gray.shape
        gray = gray.reshape(height // downscale, downscale, width // downscale, downscale).mean(axis=(1, 3))
    return gray


def load_hdr_sequence(folder: str | Path, *, weights: str = DEFAULT_WEIGHTS, peak: float = 1.0,
                      max_frames: int | None = None, crop: tuple[int, int] | None = None,
                      downscale: int = 1, progress: bool = False) -> np.ndarray:
    """A folder of ``.exr`` / ``.hdr`` frames -> light ``I`` float32 (K, H, W), brightest pixel = ``peak``.

    Frames are sorted by name, converted to grayscale (:func:`to_gray`, negatives
    clipped at 0), optionally centre-cropped to ``crop`` = (H, W) (the paper
    crops its test frames to 512 x 384) and area-averaged over ``downscale``
    x ``downscale`` blocks (it resizes training frames; the cropped size must be a
    whole number of blocks: nothing is dropped), and the whole sequence is divided by
    its largest pixel (paper appendix A.2.2). All frames must have the same size.
    """
    from tqdm import tqdm

    if max_frames is not None and not is_count(max_frames, 1):
        raise InputError(f"max_frames = {max_frames!r} must be an integer >= 1")
    if crop is not None:
        crop = check_frame_shape(crop, "crop (H, W)")
    check_weights(weights)
    paths = list_frames(folder)
    if max_frames is not None:
        paths = paths[:max_frames]
    if type(downscale) is not int or downscale < 1:
        raise InputError(f"downscale = {downscale!r} must be an integer >= 1")
    size = sequence_size(paths, f"HDR sequence {str(folder)!r}")
    _check_crop_and_blocks(size, crop, downscale, f"HDR sequence {str(folder)!r}")
    frames = []
    for path in tqdm(paths, desc="reading frames", unit="frame", disable=not progress):
        gray = to_gray(read_image(path), weights, what=f"frame {str(path)!r}")
        if gray.shape != size:          # (changed since its header was read)
            raise InputError(f"frame {str(path)!r} is {gray.shape[0]} x {gray.shape[1]}, but its header "
                             f"said {size[0]} x {size[1]}")
        frames.append(_crop_and_shrink(gray, crop, downscale).astype(np.float32))
    return normalise_sequence(np.stack(frames), peak, what=f"HDR sequence {str(folder)!r}")
