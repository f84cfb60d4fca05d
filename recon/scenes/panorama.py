"""Moving HDR sequences from equirectangular panoramas.

Sources of a panorama (:func:`load_panorama`):

- ``"default"``: the shipped CC0 panorama ``recon/data/courtyard_128x256.npz``
  (luminance, 4 x 4 area-averaged from Greg Zaal's "courtyard", see
  ``recon/data/README.md``); always available, used by ``tespike demo``;
- ``"city"``, ``"courtyard"``, ``"forest"``, ``"studio"``, ``"sunset"``: the
  five CC0 panoramas, shipped downsized to 128 x 256 (4 x 4 area means of the
  512 x 1024 originals; ``recon/data/<name>_128x256.npz``, float16, and for
  courtyard the default file itself), so every built-in scene works from a
  clone. With the environment variable ``TESPIKE_HDRI_DIR`` set, the full-size
  ``<name>.exr`` files of that folder are used instead (an :class:`InputError`
  names the folder when one is missing);
- any path to an ``.exr`` or ``.hdr`` file.

A sequence is a camera window moving over the panorama (see
:mod:`tespike.recon.scenes.warp`): a pan along the longitude (exact sub-pixel motion,
wrapping round), a tilt, a rotation, a zoom, or all at once, with optional
moving bright sources added, then normalised so the brightest pixel of the
whole sequence is ``peak`` (paper appendix A.2.2).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from pathlib import Path

import numpy as np

from tespike.golden.errors import InputError
from tespike.golden.paths import path_text

from .color import DEFAULT_WEIGHTS, check_weights, to_gray
from .procedural import moving_spots
from .warp import render_window

#: The five panoramas of the project's data folder (CC0, Greg Zaal / HDRI Haven).
PANORAMAS = ("city", "courtyard", "forest", "studio", "sunset")
DATA_DIR = Path(__file__).resolve().parent.parent / "data"
DEFAULT_PANORAMA_FILE = DATA_DIR / "courtyard_128x256.npz"
MOTIONS = ("pan", "tilt", "rotate", "zoom", "mixed")


#: Downsizing factor of the shipped copies (512 x 1024 -> 128 x 256).
SHIPPED_FACTOR = 4


def hdri_dir() -> Path | None:
    """Folder of full-size panoramas the user asked for (``$TESPIKE_HDRI_DIR``), else ``None``."""
    env = os.environ.get("TESPIKE_HDRI_DIR")
    return Path(env) if env else None


def shipped_panorama_file(name: str) -> Path:
    """The shipped downsized copy of panorama ``name`` (courtyard's is the default scene's file)."""
    return DEFAULT_PANORAMA_FILE if name in ("default", "courtyard") else DATA_DIR / f"{name}_128x256.npz"


def load_panorama(source: str | Path = "default", weights: str = DEFAULT_WEIGHTS) -> np.ndarray:
    """Luminance of a panorama, float64 (H, W), >= 0 (see the module docstring).

    A full-size or user file is read once per process and returned read-only
    (:func:`file_luminance`): the data engine moves cameras over the same panoramas clip
    after clip. A shipped copy is small and returned as a new array each call."""
    path_text(source, "panorama")            # (a number had been os.fspath's TypeError)
    check_weights(weights)
    if str(source) == "default" or (str(source) in PANORAMAS and hdri_dir() is None):
        if weights != DEFAULT_WEIGHTS:          # (they had been ignored)
            raise InputError(f"panorama {str(source)!r}: the shipped copy is stored as {DEFAULT_WEIGHTS} "
                             f"luminance; grayscale weights {weights!r} need the full-size file "
                             "(TESPIKE_HDRI_DIR, docs/scenes.md)")
        with np.load(shipped_panorama_file(str(source)), allow_pickle=False) as npz:
            return npz["luminance"].astype(np.float64)
    if str(source) in PANORAMAS:
        path = hdri_dir() / f"{source}.exr"
        if not path.is_file():
            raise InputError(f"panorama {str(source)!r} not found at {str(path)!r} "
                             "(set TESPIKE_HDRI_DIR to the folder holding the five .exr panoramas)")
    else:
        path = Path(source)
        if not path.is_file():
            raise InputError(f"panorama {str(source)!r} is neither 'default', one of "
                             f"{', '.join(PANORAMAS)}, nor an existing .exr/.hdr file")
    return file_luminance(str(path.resolve()), path.stat().st_mtime_ns, weights)


@functools.lru_cache(maxsize=64)
def file_luminance(path: str, mtime_ns: int, weights: str) -> np.ndarray:
    """The luminance of one panorama file (read-only; cached by path and modification time)."""
    from .hdr_io import read_image
    luminance = to_gray(read_image(path), weights, what=path)
    luminance.setflags(write=False)
    return luminance


def block_mean(image: np.ndarray, factor: int) -> np.ndarray:
    """Area-average ``factor x factor`` blocks (linear light: a downsized pixel collects
    the light of the pixels it covers)."""
    height, width = image.shape
    if height % factor or width % factor:
        raise InputError(f"image {height} x {width} is not divisible into {factor} x {factor} blocks")
    return image.reshape(height // factor, factor, width // factor, factor).mean(axis=(1, 3))


def build_default_panorama(exr_path: str | Path, out: str | Path = DEFAULT_PANORAMA_FILE,
                           factor: int = SHIPPED_FACTOR, dtype=np.float32) -> np.ndarray:
    """Make a shipped panorama from a full-size EXR (how recon/data was built): the default
    (courtyard) in float32, the other four with ``dtype=np.float16`` (their luminance lies
    within float16's normal range, relative step 2^-11; half the size)."""
    from tespike.golden.io import atomic_output
    from .hdr_io import read_image

    luminance = block_mean(to_gray(read_image(exr_path), DEFAULT_WEIGHTS), factor).astype(dtype)
    if not np.isfinite(luminance).all() or (luminance[luminance != 0] < np.finfo(dtype).tiny).any():
        raise InputError(f"{str(exr_path)!r}: its luminance does not fit {np.dtype(dtype).name}'s normal range")
    with atomic_output(out) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, luminance=luminance,
                                source=np.array(f"{Path(exr_path).name}, Rec. 709 luminance, "
                                                f"{factor}x{factor} area mean"))
    return luminance


@dataclasses.dataclass(frozen=True)
class CameraPath:
    """Window centre (cy, cx) in panorama pixels, angle (radians), zoom; each moving
    linearly per frame (zoom geometrically)."""

    cy: float
    cx: float
    angle: float = 0.0
    zoom: float = 1.0
    vy: float = 0.0
    vx: float = 0.0
    spin: float = 0.0
    zoom_rate: float = 1.0

    def at(self, k: int) -> tuple[float, float, float, float]:
        return (self.cy + self.vy * k, self.cx + self.vx * k, self.angle + self.spin * k,
                self.zoom * self.zoom_rate ** k)


def random_path(rng: np.random.Generator, motion: str, pano_shape: tuple[int, int],
                height: int, width: int, frames: int) -> CameraPath:
    """A random camera path of the named kind that keeps the window inside the latitudes."""
    if motion not in MOTIONS:
        raise InputError(f"unknown motion {motion!r} (known: {', '.join(MOTIONS)})")
    pano_h, pano_w = pano_shape
    speed = rng.uniform(0.3, 1.5) * (1 if rng.integers(2) else -1)
    kw: dict = {"cx": rng.uniform(0, pano_w)}
    if motion in ("pan", "mixed"):
        kw["vx"] = speed
    if motion in ("tilt", "mixed"):
        kw["vy"] = rng.uniform(0.2, 0.8) * (1 if rng.integers(2) else -1)
    if motion in ("rotate", "mixed"):
        kw["spin"] = math.radians(rng.uniform(0.2, 1.0)) * (1 if rng.integers(2) else -1)
    if motion in ("zoom", "mixed"):
        kw["zoom_rate"] = math.exp(rng.uniform(0.003, 0.01) * (1 if rng.integers(2) else -1))
    # keep the (rotated) window and its tilt within the panorama's rows where possible
    half = 0.5 * math.hypot(height, width) if "spin" in kw else 0.5 * height
    travel = abs(kw.get("vy", 0.0)) * max(0, frames - 1)
    low, high = half, pano_h - 1 - half - travel
    cy = rng.uniform(low, high) if high > low else 0.5 * (pano_h - 1) - 0.5 * travel
    if kw.get("vy", 0.0) < 0:
        cy += travel
    path = CameraPath(cy=cy, **kw)
    return path if _rows_fit(path, frames, height, width, pano_h) else _slowed(path, frames, height, width, pano_h)


def _row_reach(path: CameraPath, frames: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(centre row, half the rows spanned) of the window at each frame of ``path``: the rotated,
    zoomed window's extent in the panorama's rows (its sub-samples' half pixel where it zooms out)."""
    k = np.arange(max(1, frames))
    angle, zoom = path.angle + path.spin * k, path.zoom * path.zoom_rate ** k
    pad = np.where(zoom < 1.0, 0.5, 0.0)
    half = (np.abs(np.cos(angle)) * ((height - 1) / 2 + pad) + np.abs(np.sin(angle)) * ((width - 1) / 2 + pad)) / zoom
    return path.cy + path.vy * k, half


def _rows_fit(path: CameraPath, frames: int, height: int, width: int, pano_h: int) -> bool:
    """Whether every frame's window lies within the panorama's rows (none reaches a clamped row)."""
    centre, half = _row_reach(path, frames, height, width)
    return bool(np.all(centre - half >= -1e-9) and np.all(centre + half <= pano_h - 1 + 1e-9))


def _slowed(path: CameraPath, frames: int, height: int, width: int, pano_h: int) -> CameraPath:
    """``path`` re-centred, else with its tilt, spin and zoom halved until some centre row keeps
    every frame's window within the panorama's rows (a long tilt or zoom-out, or a turning wide
    window, ran past them and showed the clamped edge rows stretched): the least slowing that fits,
    centred in the rows it may use; at worst the still window, which fits (:func:`check_window`)."""
    for halvings in range(41):
        f = 0.5 ** halvings
        slower = dataclasses.replace(path, cy=0.0, vy=path.vy * f, spin=path.spin * f,
                                     zoom_rate=path.zoom_rate ** f)
        centre, half = _row_reach(slower, frames, height, width)
        low, high = float(np.max(half - centre)), float(np.min(pano_h - 1 - half - centre))
        if low <= high:
            return dataclasses.replace(slower, cy=0.5 * (low + high))
    return dataclasses.replace(path, cy=0.5 * (pano_h - 1), vy=0.0, spin=0.0, zoom_rate=1.0)


def render_path(panorama: np.ndarray, path: CameraPath, frames: int, height: int,
                width: int) -> np.ndarray:
    """The camera path's frames, float64 (K, H, W), unnormalised."""
    out = np.empty((frames, height, width))
    for k in range(frames):
        cy, cx, angle, zoom = path.at(k)
        out[k] = render_window(panorama, height, width, cy, cx, angle, zoom)
    return out


def check_window(panorama_shape: tuple[int, int], height: int, width: int, source) -> None:
    """Refuse a ``height`` x ``width`` camera window larger than its panorama: its rows past the
    panorama's would be copies of the edge rows (the latitude is clamped) and its columns would
    show the panorama again beside itself (the longitude wraps round)."""
    rows, columns = panorama_shape
    if height > rows or width > columns:
        shipped = str(source) == "default" or (str(source) in PANORAMAS and hdri_dir() is None)
        more = ("; the full-size panoramas, 512 x 1024, are used with TESPIKE_HDRI_DIR set to their "
                "folder" if shipped and str(source) != "default" else "")
        raise InputError(f"a {height} x {width} window is larger than the panorama {str(source)!r} "
                         f"({rows} x {columns}): its rows would repeat the edge rows and its columns the "
                         f"panorama; ask for at most {rows} x {columns}{more}")


def panorama_sequence(rng: np.random.Generator, frames: int, height: int, width: int, *,
                      source: str | Path = "default", motion: str = "pan", sources: int = 0,
                      source_gain: tuple[float, float] = (1e2, 1e4)) -> np.ndarray:
    """A moving window over a panorama with ``sources`` moving bright spots added,
    each ``source_gain`` (log-uniform range) x the sequence's median. Float64, unnormalised;
    a window larger than the panorama is refused (:func:`check_window`)."""
    panorama = load_panorama(source)
    check_window(panorama.shape, height, width, source)
    path = random_path(rng, motion, panorama.shape, height, width, frames)
    scene = render_path(panorama, path, frames, height, width)
    if sources:
        low, high = (math.log10(g) for g in source_gain)
        gains = 10.0 ** rng.uniform(low, high, sources) * np.median(scene)
        scene += np.tensordot(gains, moving_spots(rng, frames, height, width, sources), axes=1)
    return scene
