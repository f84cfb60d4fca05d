"""The held-out evaluation set and the panorama (tuning) set.

Evaluation scenes are procedural scenes of the project's own making drawn
from the held-out random domain of :func:`tespike.recon.scenes.scene_rng`, so they
share no seed, and no pixel, with anything made for tuning, training or
examples (the panorama set below, ``tespike scene``, the demo). Panorama
sequences are for tuning and examples only, as the data folder's README asks.
"""

from __future__ import annotations

import numpy as np

from . import make_scene
from .panorama import PANORAMAS

#: (label, scene name, held-out seed): three moderately HDR scenes and one of each stiff kind.
EVALUATION_SET = (
    ("moderate-a", "moderate", 0),
    ("moderate-b", "moderate", 1),
    ("moderate-c", "moderate", 2),
    ("lights", "lights", 0),
    ("sun", "sun", 0),
    ("decades", "decades", 0),
)
#: The subset the quality targets are about (peak 100..300 x median).
MODERATE_SET = tuple(entry for entry in EVALUATION_SET if entry[1] == "moderate")
#: Names of sequence sets :func:`sequence_set` can build.
SETS = ("heldout", "moderate", "panoramas", "default")


def sequence_set(name: str, frames: int, height: int, width: int) -> list[tuple[str, np.ndarray]]:
    """The named set of (label, light (K, H, W)) sequences.

    ``heldout``: :data:`EVALUATION_SET`; ``moderate``: its moderately HDR part;
    ``panoramas``: a mixed-motion camera over each of the five panoramas
    (tuning and examples); ``default``: the demo scene.
    """
    from tespike.golden.errors import InputError

    if name in ("heldout", "moderate"):
        entries = EVALUATION_SET if name == "heldout" else MODERATE_SET
        return [(label, make_scene(scene, frames, height, width, seed=seed, heldout=True))
                for label, scene, seed in entries]
    if name == "panoramas":
        return [(p, make_scene(p, frames, height, width, motion="mixed")) for p in PANORAMAS]
    if name == "default":
        return [("default", make_scene("default", frames, height, width))]
    raise InputError(f"unknown sequence set {name!r} (known: {', '.join(SETS)})")
