"""Files of SPEC section 6: stimulus E.npy, scene I.npy, stream S.npz, images R.npy.

Every writer goes through :func:`atomic_output`, so a failed or interrupted run
never leaves a half-written file; every reader refuses bad input with an
:class:`InputError` that names the file and the problem.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator

import numpy as np

from .config import SensorConfig
from .errors import InputError


@contextlib.contextmanager
def atomic_output(path: str | Path) -> Iterator[str]:
    """Yield a temporary path beside ``path``; move it into place only on success."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"cannot write {str(path)!r}: directory {str(directory)!r} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=directory)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _load_npy(path: str | Path, what: str, mmap_mode: str | None = None) -> np.ndarray:
    try:
        array = np.load(path, allow_pickle=False, mmap_mode=mmap_mode)
    except FileNotFoundError:
        raise InputError(f"{what} file {str(path)!r} does not exist") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"{what} file {str(path)!r} is not a readable .npy array: {exc}") from None
    if not isinstance(array, np.ndarray):
        raise InputError(f"{what} file {str(path)!r} holds an archive, not one .npy array")
    return array


def check_stimulus(stimulus: np.ndarray, config: SensorConfig, *, whole_readouts: bool = True,
                   scan_values: bool = True) -> np.ndarray:
    """Refuse a per-clock electron array that SPEC section 3 does not allow.

    It must be a numpy integer array (a float or bool array is refused even when
    its values are whole) of shape ``(T, H, W)`` with every value in
    ``[0, 2^input_bits - 1]`` and, unless ``whole_readouts`` is false, T a
    multiple of L. ``scan_values=False`` checks only dtype and shape (for a
    caller that checks the values slice by slice). Returns the array unchanged.
    """
    if not isinstance(stimulus, np.ndarray):
        raise InputError(f"stimulus must be a numpy array, not {type(stimulus).__name__}")
    if stimulus.dtype.kind not in "iu":
        raise InputError(f"stimulus dtype {stimulus.dtype} is not an integer type "
                         "(float and bool arrays are refused even when whole)")
    if stimulus.ndim != 3:
        raise InputError(f"stimulus shape {stimulus.shape} must be (T, H, W)")
    clocks, height, width = stimulus.shape
    if height < 1 or width < 1:
        raise InputError(f"stimulus shape {stimulus.shape}: H and W must be at least 1")
    L = config.clocks_per_readout
    if whole_readouts and clocks % L:
        raise InputError(f"stimulus has T = {clocks} pixel clocks, not a multiple of "
                         f"L = clocks_per_tick * alpha = {L}")
    if scan_values and stimulus.size:
        # A dtype that cannot hold a bad value is not scanned (a pass over a large
        # stimulus costs as much as simulating part of it).
        info = np.iinfo(stimulus.dtype)
        low = 0 if info.min >= 0 else int(stimulus.min())
        high = 0 if info.max <= config.input_max else int(stimulus.max())
        if low < 0:
            raise InputError(f"stimulus value {low} is negative (electrons per clock must be "
                             f"in 0..2^input_bits - 1 = {config.input_max})")
        if high > config.input_max:
            raise InputError(f"stimulus value {high} exceeds 2^input_bits - 1 = {config.input_max} "
                             f"(input_bits = {config.input_bits})")
    return stimulus


def load_stimulus(path: str | Path, config: SensorConfig) -> np.ndarray:
    """Read and check ``E.npy``, memory-mapped read-only so a large file stays on disk.

    The range check streams through the file in slices of about 2^24 values,
    so it too needs memory bounded by the slice, not by the file.
    """
    stimulus = _load_npy(path, "stimulus", mmap_mode="r")
    if stimulus.ndim != 3 or stimulus.dtype.kind not in "iu":
        return check_stimulus(stimulus, config)
    check_stimulus(stimulus, config, scan_values=False)     # dtype, shape and T rules
    step = max(1, (1 << 24) // max(1, stimulus[0].size))
    for start in range(0, stimulus.shape[0], step):
        check_stimulus(stimulus[start:start + step], config, whole_readouts=False)
    return stimulus


def check_scene(scene: np.ndarray, *, scan_values: bool = True) -> np.ndarray:
    """Refuse a light array that SPEC section 6 does not allow; return it as float64.

    ``scan_values=False`` checks only type and shape and returns the array
    unchanged (for a caller that checks and converts it slice by slice).
    """
    if not isinstance(scene, np.ndarray):
        raise InputError(f"scene must be a numpy array, not {type(scene).__name__}")
    if scene.dtype.kind != "f":
        raise InputError(f"scene dtype {scene.dtype} is not a float type (light per readout interval "
                         "must be a float array, SPEC section 6; an integer array is refused "
                         "like a float stimulus is)")
    if scene.ndim != 3:
        raise InputError(f"scene shape {scene.shape} must be (K, H, W)")
    if scene.shape[1] < 1 or scene.shape[2] < 1:
        raise InputError(f"scene shape {scene.shape}: H and W must be at least 1")
    if not scan_values:
        return scene
    scene = scene.astype(np.float64, copy=False)
    if scene.size:
        if not np.isfinite(scene).all():
            bad = scene[~np.isfinite(scene)][0]
            raise InputError(f"scene holds a non-finite light value ({bad}); light must be finite")
        low = float(scene.min())
        if low < 0:
            raise InputError(f"scene holds a negative light value ({low}); light must be >= 0")
    return scene


def load_scene(path: str | Path, *, memory_map: bool = False) -> np.ndarray:
    """Read and check ``I.npy`` (light per readout interval, 1.0 = design light).

    ``memory_map=True`` leaves the file on disk (read-only memory map, in the
    file's own dtype) and checks the values one slice of readouts at a time,
    so memory stays bounded by the slice; the caller converts what it reads.
    """
    if not memory_map:
        return check_scene(_load_npy(path, "scene"))
    scene = check_scene(_load_npy(path, "scene", mmap_mode="r"), scan_values=False)
    step = max(1, (1 << 22) // max(1, scene[0].size))
    for start in range(0, scene.shape[0], step):
        check_scene(np.asarray(scene[start:start + step]))
    return scene


def unsigned_dtype(bits: int) -> np.dtype:
    """Smallest unsigned dtype that holds ``bits`` bits (at most 32)."""
    return np.dtype(np.uint8 if bits <= 8 else np.uint16 if bits <= 16 else np.uint32)


def word_dtype(config: SensorConfig) -> np.dtype:
    """Smallest unsigned dtype that holds a readout word."""
    return unsigned_dtype(config.word_bits)


def save_stream(path: str | Path, words: np.ndarray, config: SensorConfig) -> None:
    """Write ``S.npz``: ``words`` (K, H, W) and ``config``, the full configuration as JSON."""
    words = np.asarray(words)
    if words.ndim != 3:
        raise InputError(f"stream words shape {words.shape} must be (K, H, W)")
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, words=words.astype(word_dtype(config), copy=False),
                     config=np.array(config.to_json()))


def load_stream(path: str | Path) -> tuple[np.ndarray, SensorConfig]:
    """Read ``S.npz``; return ``(words, config)`` with the words checked legal."""
    from .decode import check_words
    try:
        with np.load(path, allow_pickle=False) as npz:
            if "words" not in npz or "config" not in npz:
                raise InputError(f"stream file {str(path)!r} must hold 'words' and 'config'")
            words = npz["words"]
            config_text = str(npz["config"])
    except FileNotFoundError:
        raise InputError(f"stream file {str(path)!r} does not exist") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"stream file {str(path)!r} is not a readable .npz archive: {exc}") from None
    try:
        config = SensorConfig.from_dict(json.loads(config_text))
    except json.JSONDecodeError as exc:
        raise InputError(f"stream file {str(path)!r}: 'config' is not JSON: {exc}") from None
    if words.dtype.kind not in "iu" or words.ndim != 3:
        raise InputError(f"stream file {str(path)!r}: 'words' must be an integer (K, H, W) array, "
                         f"not {words.dtype} {words.shape}")
    check_words(words, config)
    return words, config


def save_images(path: str | Path, images: np.ndarray) -> None:
    """Write ``R.npy``: float32 (K, H, W) reconstructed light, atomically."""
    images = np.asarray(images, dtype=np.float32)
    if images.ndim != 3:
        raise InputError(f"image array shape {images.shape} must be (K, H, W)")
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, images)
