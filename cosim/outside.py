"""What the outside simulators (Verilator, Icarus) share: port bit packing, the
capture check against SPEC section 6, the build cache and the errors.

Both simulators drive only the ports SPEC section 6 fixes for the generated
array (``clk``, ``rst``, ``charge``, ``frame_valid``, ``frame``). ``charge`` and
``frame`` are flat vectors: pixel ``i = r * W + c`` sits at bits
``[i * width +: width]``. Here they travel as rows of little-endian 32-bit words
(word 0 holds bits 31..0), which is also how Verilator stores a wide port
(``VlWide``), so the C++ harness copies words without touching bits.

Sampling convention (both harnesses): after reset, before rising edge ``t`` the
harness puts ``charge`` row ``t`` on the port, lets the logic settle and samples
``frame_valid`` / ``frame``; then the edge comes. The frame of readout interval
``k`` ends at pixel clock ``k * L + L - 1``; it must be sampled at
``k * L + L - 1 + latency`` with one fixed ``latency`` in ``0..L`` (0 only for a
frame computed combinationally in the interval's last clock; a registered frame
has latency >= 1).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import shutil
import subprocess
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, TespikeError, is_count

from . import children

#: Clocks with ``rst`` high before pixel clock t = 0 (synchronous reset needs >= 1 edge).
RESET_CLOCKS = 2

#: Bound on the bytes of 0/1 values the bit packer holds at once.
_PACK_CHUNK_BITS = 1 << 25


class OutsideSimulatorError(TespikeError, RuntimeError):
    """An outside simulator is missing, failed to build, failed to run, or broke the ports' contract."""


class SimulatorMissingError(OutsideSimulatorError):
    """The simulator executable (verilator, iverilog, vvp) is not on PATH."""


class SimulatorBuildError(OutsideSimulatorError):
    """Compiling the Verilog and the harness failed; the message holds the first error line."""


class SimulatorRunError(OutsideSimulatorError):
    """The compiled simulation failed, or its outputs broke SPEC section 6."""


# -- the SPEC ports ----------------------------------------------------------------
def words_per_row(pixels: int, bits: int) -> int:
    """32-bit words holding one flat port of ``pixels * bits`` bits."""
    _check_bits(bits, "words_per_row")
    if not is_count(pixels):                           # (-1 had needed 0 words)
        raise InputError(f"words_per_row: pixels {pixels!r} must be an integer >= 0")
    return (pixels * bits + 31) // 32


def _check_bits(bits, what: str) -> None:
    if not (is_count(bits, 1) and bits <= 32):
        raise InputError(f"{what} handles 1..32 bits per value, not {bits!r}")


def pack_rows(values: np.ndarray, bits: int) -> np.ndarray:
    """(T, N) unsigned values of ``bits`` bits -> (T, words_per_row) uint32, pixel i at bits [i*bits +: bits].

    Values are integers of ``0 .. 2^bits - 1`` (refused in one line otherwise: -1 and 64 had been
    wrapped into the field, a float truncated); bits above ``N * bits`` in the last word are zero.
    """
    values = np.asarray(values)
    if values.ndim != 2:
        raise InputError(f"pack_rows wants (T, N), got shape {values.shape}")
    _check_bits(bits, "pack_rows")
    if values.dtype.kind not in "iu":
        raise InputError(f"pack_rows packs integers, not {values.dtype} values")
    if values.size and (int(values.min()) < 0 or int(values.max()) >= 1 << bits):
        bad = int(values.min()) if int(values.min()) < 0 else int(values.max())
        raise InputError(f"pack_rows: value {bad} does not fit {bits} bits (0..{(1 << bits) - 1})")
    T, N = values.shape
    nw = words_per_row(N, bits)
    out = np.empty((T, nw), np.uint32)
    step = max(1, _PACK_CHUNK_BITS // max(1, N * 32))
    for a in range(0, T, step):
        chunk = np.ascontiguousarray(values[a:a + step], dtype="<u4")
        bitplanes = np.unpackbits(chunk.view(np.uint8).reshape(len(chunk), N, 4), axis=2,
                                  bitorder="little")[:, :, :bits].reshape(len(chunk), N * bits)
        padded = np.zeros((len(chunk), nw * 32), np.uint8)
        padded[:, :N * bits] = bitplanes
        out[a:a + step] = np.packbits(padded, axis=1, bitorder="little").view("<u4")
    return out


def unpack_rows(words: np.ndarray, pixels: int, bits: int) -> np.ndarray:
    """Inverse of :func:`pack_rows`: (K, words_per_row) uint32 -> (K, pixels) int64."""
    _check_bits(bits, "unpack_rows")
    words = np.asarray(words)
    if words.dtype.kind not in "iu":
        raise InputError(f"unpack_rows reads integer words, not {words.dtype}")
    words = np.ascontiguousarray(words, dtype="<u4")
    if words.ndim != 2 or words.shape[1] != words_per_row(pixels, bits):
        raise InputError(f"unpack_rows wants (K, {words_per_row(pixels, bits)}) words, got {words.shape}")
    K = words.shape[0]
    bitplanes = np.unpackbits(words.view(np.uint8).reshape(K, 4 * words.shape[1]), axis=1,
                              bitorder="little")
    fields = bitplanes[:, :pixels * bits].reshape(K, pixels, bits).astype(np.int64)
    return fields @ (np.int64(1) << np.arange(bits, dtype=np.int64))


def rows_to_hex(words: np.ndarray, bits: int) -> list[str]:
    """(T, nw) uint32 rows -> one hex string per row, most significant digit first, ceil(bits/4) digits."""
    digits = (bits + 3) // 4
    nw = words.shape[1]
    if words.shape[0] == 0:
        return []
    text = np.ascontiguousarray(words[:, ::-1], dtype=">u4").tobytes().hex()
    per_row = nw * 8
    return [text[i * per_row + per_row - digits:(i + 1) * per_row] for i in range(words.shape[0])]


def hex_to_rows(lines: Sequence[str], bits: int) -> np.ndarray:
    """Hex strings (as ``$fwrite("%h")`` prints a ``bits``-wide vector) -> (K, nw) uint32 rows."""
    nw = (bits + 31) // 32
    rows = np.zeros((len(lines), nw), np.uint32)
    _check_bits_wide(bits)
    for i, line in enumerate(lines):
        try:
            raw = bytes.fromhex(line.rjust(nw * 8, "0"))
            if len(raw) != 4 * nw:
                raise ValueError
        except (TypeError, ValueError):
            raise InputError(f"line {i + 1} {str(line)[:40]!r} is no {bits}-bit hex value") from None
        rows[i] = np.frombuffer(raw, ">u4")[::-1]
    return rows


def _check_bits_wide(bits) -> None:
    if not is_count(bits, 1):
        raise InputError(f"hex_to_rows: bits {bits!r} must be an integer >= 1")


def check_captures(clocks: np.ndarray, config: SensorConfig, readouts: int, what: str) -> int:
    """Check the clocks at which ``frame_valid`` was sampled high against SPEC section 6.

    ``clocks`` are the sample indices (see the module docstring) of every
    capture of a run that went on until the last readout was seen (or L + 1
    clocks past the stimulus). There must be exactly ``readouts`` of them, one
    per readout interval, all with the same latency in 0..L. Returns that latency.
    """
    config = SensorConfig.required(config, "check_captures")
    L = config.clocks_per_readout
    clocks = np.asarray(clocks, np.int64)
    if len(clocks) != readouts:
        raise SimulatorRunError(
            f"{what}: frame_valid was high {len(clocks)} times in the run, expected {readouts} "
            f"(one per readout interval of L = {L} clocks, latency at most L)")
    ends = np.arange(readouts, dtype=np.int64) * L + (L - 1)
    latency = clocks[:readouts] - ends
    if readouts and (latency != latency[0]).any():
        k = int(np.flatnonzero(latency != latency[0])[0])
        raise SimulatorRunError(
            f"{what}: frame_valid latency is not fixed: interval 0 at clock {int(clocks[0])} "
            f"(latency {int(latency[0])}), interval {k} at clock {int(clocks[k])} "
            f"(latency {int(latency[k])}); SPEC section 6 wants one per interval, L = {L} apart")
    if readouts and not 0 <= latency[0] <= L:
        raise SimulatorRunError(
            f"{what}: frame_valid latency {int(latency[0])} clocks is outside 0..L = {L} "
            "(SPEC section 6)")
    return int(latency[0]) if readouts else 0


# -- processes and the build cache ----------------------------------------------
def require_tool(name: str, package: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise SimulatorMissingError(
            f"{name!r} is not on PATH; install it (Debian/Ubuntu: apt-get install {package})")
    return path


def first_error_line(text: str) -> str:
    """The first line of compiler output that reads like an error, else the last non-empty line."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    for line in lines:
        low = line.lower()
        if "%error" in low or "error:" in low or "syntax error" in low or "i give up" in low:
            return line
    return lines[-1] if lines else "(no output)"


def default_cache_root() -> Path:
    """``$TESPIKE_CACHE``, else ``$XDG_CACHE_HOME/tespike``, else ``~/.cache/tespike``; refused in one line
    naming the variable where it names something other than a folder (the build failed on 'X/verilator':
    Not a directory, naming neither the variable nor the cache)."""
    for variable, sub in (("TESPIKE_CACHE", ""), ("XDG_CACHE_HOME", "tespike")):
        value = os.environ.get(variable)
        if value:
            if os.path.lexists(value) and not os.path.isdir(value):
                raise InputError(f"${variable} {value!r} (where the build cache lives) is not a directory: "
                                 "point it at a folder, or unset it")
            return Path(value, sub)
    return Path.home() / ".cache" / "tespike"


def content_hash(*parts: str | bytes) -> str:
    digest = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        digest.update(len(data).to_bytes(8, "little"))
        digest.update(data)
    return digest.hexdigest()[:20]


@contextlib.contextmanager
def cache_entry(root: Path, key: str) -> Iterator[tuple[Path, bool]]:
    """Lock one cache entry; yield (final directory, already built).

    The caller builds in a hidden folder of ``root`` (:func:`tespike.golden.atomic.work_folder`: removed
    with the run, by the janitor if it is killed) renamed into place only when the build succeeded,
    so an interrupted build never leaves a broken entry (the cocotb builds had run in the entry
    itself). The lock (``flock`` on ``<key>.lock``) keeps two processes from building the same
    thing at once.
    """
    root.mkdir(parents=True, exist_ok=True)
    final = root / key
    with open(root / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield final, (final / "done").is_file()


def run_process(argv: list[str], *, cwd: Path | None = None, timeout: float | None = None
                ) -> subprocess.CompletedProcess:
    return children.run(argv, cwd=cwd, capture_output=True, text=True, timeout=timeout)
