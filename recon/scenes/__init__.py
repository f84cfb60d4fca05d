"""Light sequences ``I`` (K, H, W) for the simulator: built-in scenes, panoramas, user folders.

Every built-in scene is deterministic given its name and seed and is
normalised so that its brightest pixel over the whole sequence is ``peak``
(1.0 = the design light, paper appendix A.2.2). Random numbers come from
:func:`scene_rng`, which keeps two domains apart: the public one (``tespike
scene``, examples, tuning, training) and the held-out one used only by the
evaluation set (:mod:`tespike.recon.scenes.heldout`), so no seed a user or a training
run can ask for ever reproduces an evaluation scene.
"""

from __future__ import annotations

import zlib
from typing import Callable

import numpy as np

from tespike.golden.errors import InputError, check_flag, is_count
from tespike.golden.resources import require_memory

from . import procedural
from .color import DEFAULT_WEIGHTS, LUMA_WEIGHTS, normalise_sequence, to_gray
from .hdr_io import load_hdr_sequence, read_hdr, read_image, write_hdr
from .panorama import MOTIONS, PANORAMAS, load_panorama, panorama_sequence

PUBLIC, HELDOUT = 0, 1
#: Largest frames x height x width a built-in scene is made at (about 1.5 GB of float64 work).
MAX_VOXELS = 200_000_000


def scene_rng(name: str, seed: int, *, heldout: bool = False) -> np.random.Generator:
    """The random generator of scene ``name`` with ``seed`` in the public or held-out domain."""
    if type(seed) is not int or seed < 0:
        raise InputError(f"seed = {seed!r} must be an integer >= 0")
    return np.random.default_rng([HELDOUT if heldout else PUBLIC, zlib.crc32(name.encode()), seed])


def _panorama(source: str) -> Callable:
    def make(rng, frames, height, width, *, motion="pan", sources=None):
        count = (0 if source == "default" else 2) if sources is None else sources
        return panorama_sequence(rng, frames, height, width, source=source, motion=motion, sources=count)
    make.__doc__ = (f"a camera window ({', '.join(MOTIONS)}) over the {source!r} panorama (shipped at "
                    f"128 x 256{'' if source == 'default' else '; full size from $TESPIKE_HDRI_DIR'})")
    return make


#: name -> (generator(rng, frames, height, width, **options), one-line description)
SCENES: dict[str, tuple[Callable, str]] = {
    "default": (_panorama("default"), "pan over the shipped CC0 courtyard panorama (the demo scene)"),
    **{name: (_panorama(name), f"camera over the CC0 {name} panorama, two moving bright sources (shipped "
                               "at 128 x 256; full size from $TESPIKE_HDRI_DIR)") for name in PANORAMAS},
    "moderate": (procedural.moderate_scene, "textured background and highlights, peak 100..300 x median"),
    "lights": (procedural.light_sources_scene, "textured background, moving lights 1e2..1e5 x its median"),
    "sun": (procedural.sun_scene, "stiff: sun 1e6 x background, near-black and zero-light regions"),
    "decades": (procedural.decades_scene, "stiff: 12-decade log ramp moving sideways, zero-light band"),
}


def check_scene_request(name: str, frames, height, width, flags: bool = False) -> None:
    """Refuse a built-in scene's request in one line: an unknown ``name``, a size that is not an
    integer >= 1, or more than :data:`MAX_VOXELS` values. ``flags``: name the sizes as the command
    line's ``--frames``, ``--height``, ``--width``."""
    if not isinstance(name, str) or name not in SCENES:
        raise InputError(f"unknown scene {name!r} (known: {', '.join(SCENES)})")
    for key, value in (("frames", frames), ("height", height), ("width", width)):
        if type(value) is not int or value < 1:
            raise InputError(f"--{key} {value!r} must be an integer >= 1" if flags
                             else f"scene {key} = {value!r} must be an integer >= 1")
    if frames * height * width > MAX_VOXELS:
        raise InputError(f"--frames {frames} --height {height} --width {width}: a scene {name!r} of "
                         f"{frames * height * width} values exceeds the limit of {MAX_VOXELS}" if flags
                         else f"scene {name!r} of {frames} x {height} x {width} = {frames * height * width} "
                              f"values exceeds the limit of {MAX_VOXELS}")


#: What a panorama scene's generator takes beside its sizes (:func:`make_scene`'s ``options``).
PANORAMA_OPTIONS = ("motion", "sources")


def make_scene(name: str, frames: int = 24, height: int = 96, width: int = 128, *, seed: int = 0,
               peak: float = 1.0, heldout: bool = False, **options) -> np.ndarray:
    """Built-in scene ``name`` -> float32 light (K, H, W), brightest pixel = ``peak``.

    ``options`` go to the generator (``motion=`` and ``sources=`` for panoramas; ``None`` is the
    default). ``heldout``: the held-out domain's scene of the same name and seed (never trained on).
    """
    check_scene_request(name, frames, height, width)
    check_flag(heldout, "heldout")                     # ("False" had given the held-out scene)
    if name in ("default",) + PANORAMAS:
        options = {k: v for k, v in options.items() if v is not None}
        unknown = sorted(set(options) - set(PANORAMA_OPTIONS))
        if unknown:
            raise InputError(f"scene {name!r} takes no options {unknown} (its options: {', '.join(PANORAMA_OPTIONS)})")
        sources = options.get("sources", 0)
        if not is_count(sources):
            raise InputError(f"scene {name!r} sources = {sources!r}: must be an integer >= 0")
        # each moving source is drawn whole (K x H x W float64) before the sum
        require_memory(8 * frames * height * width * (1 + sources),
                       f"scene {name!r} of {frames} x {height} x {width} values with {sources} sources")
    elif any(v is not None for v in options.values()):
        raise InputError(f"scene {name!r} takes no options {sorted(k for k, v in options.items() if v is not None)}")
    else:
        options = {}
    generator = SCENES[name][0]
    light = generator(scene_rng(name, seed, heldout=heldout), frames, height, width, **options)
    return normalise_sequence(light, peak, what=f"scene {name!r}")


__all__ = ["SCENES", "PANORAMAS", "MOTIONS", "LUMA_WEIGHTS", "DEFAULT_WEIGHTS", "make_scene", "scene_rng",
           "to_gray", "normalise_sequence", "load_hdr_sequence", "load_panorama", "read_hdr",
           "write_hdr", "read_image"]
