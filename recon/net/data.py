"""Training and evaluation sequences for the network, simulated once and cached on disk.

A sequence is light ``(K, H, W)`` normalised to a peak of 1 over the whole
sequence (paper appendix A.2.2) and its stream, simulated by golden's fast
simulator (shot noise, one seed per sequence). Training sequences are camera
paths over the four training panoramas (moving bright sources added until the
sequence's peak-to-median ratio reaches a drawn target, log-uniform in
``ratio_range``) and the procedural ``moderate`` and ``lights`` scenes, all from
the public random domain. Evaluation sequences (:func:`evaluation_sequences`)
use the held-out panorama (``courtyard``) and the held-out random domain, so
training and evaluation never share a source panorama or a seed domain.

The light of a recipe is cached once, the stream once per sensor configuration
(``.npy`` files named by a hash of what made them, written atomically), so a
training run never re-simulates.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from golden.config import SensorConfig
from golden.errors import InputError
from golden.fastsim import simulate_scene
from golden.io import atomic_output

from ..scenes import make_scene, normalise_sequence, scene_rng
from ..scenes.panorama import PANORAMAS, hdri_dir, load_panorama, panorama_sequence
from ..scenes.procedural import moving_spots

#: The panorama kept out of training: evaluation uses only it (and held-out seeds).
HELDOUT_PANORAMA = "courtyard"
TRAIN_PANORAMAS = tuple(p for p in PANORAMAS if p != HELDOUT_PANORAMA)


@dataclasses.dataclass(frozen=True)
class DataRecipe:
    """What the training set is made of; its hash names the cache files."""

    sequences: int = 48
    frames: int = 80
    height: int = 128
    width: int = 128
    panoramas: tuple[str, ...] = TRAIN_PANORAMAS
    procedural: float = 0.25            # fraction of procedural (moderate / lights) sequences
    ratio_range: tuple[float, float] = (20.0, 1000.0)
    seed: int = 0
    folders: tuple[str, ...] = ()       # user .exr/.hdr sequences, one folder each, added to the set
    downscale: int = 1                  # area-average factor for the folders' frames

    def __post_init__(self) -> None:
        for key in ("sequences", "frames", "height", "width"):
            if type(getattr(self, key)) is not int or getattr(self, key) < 1:
                raise InputError(f"data recipe {key} = {getattr(self, key)!r}: must be an integer >= 1")
        if HELDOUT_PANORAMA in self.panoramas:
            raise InputError(f"data recipe: panorama {HELDOUT_PANORAMA!r} is held out for evaluation")
        object.__setattr__(self, "panoramas", tuple(self.panoramas))
        object.__setattr__(self, "folders", tuple(str(Path(f).resolve()) for f in self.folders))
        object.__setattr__(self, "ratio_range", tuple(float(r) for r in self.ratio_range))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def key(self) -> str:
        """Hash of the recipe and of the user folders' file names and sizes (their content changes it)."""
        from ..scenes.hdr_io import list_frames
        fields = self.to_dict()
        if hdri_dir() is None:      # the shipped 128 x 256 panoramas, not full-size files: other light
            fields["panorama_copies"] = "shipped-128x256"
        if not self.folders and self.downscale == 1:    # generated sequences only: the fields they use
            del fields["folders"], fields["downscale"]
            return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:16]
        files = [[(p.name, p.stat().st_size) for p in list_frames(f)] for f in self.folders]
        text = json.dumps([fields, files], sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @property
    def total(self) -> int:
        """Sequences in the set: the generated ones, then one per user folder."""
        return self.sequences + len(self.folders)


def reach_ratio(light: np.ndarray, rng: np.random.Generator, ratio: float) -> np.ndarray:
    """Add one moving bright source so that peak / median of the sequence is at least ``ratio``."""
    median = float(np.median(light))
    if median <= 0 or light.max() >= ratio * median:
        return light
    spot = moving_spots(rng, *light.shape, 1)[0]
    return light + (ratio * median) * spot


def folder_sequence(recipe: DataRecipe, folder: str) -> np.ndarray:
    """The first ``frames`` frames of a user folder, centre-cropped to height x width, peak 1."""
    from ..scenes.hdr_io import load_hdr_sequence
    light = load_hdr_sequence(folder, max_frames=recipe.frames, downscale=recipe.downscale)
    k, h, w = light.shape
    if k < recipe.frames or h < recipe.height or w < recipe.width:
        raise InputError(f"training folder {folder!r} gives {k} x {h} x {w} (frames x rows x columns), "
                         f"less than the recipe's {recipe.frames} x {recipe.height} x {recipe.width}")
    y, x = (h - recipe.height) // 2, (w - recipe.width) // 2
    return normalise_sequence(light[:, y:y + recipe.height, x:x + recipe.width], 1.0, what=folder)


def training_sequence(recipe: DataRecipe, index: int) -> np.ndarray:
    """Sequence ``index`` of the recipe: float32 light (K, H, W), peak 1 (public seed domain)."""
    if index >= recipe.sequences:
        return folder_sequence(recipe, recipe.folders[index - recipe.sequences])
    rng = scene_rng("net-train", recipe.seed * 1_000_003 + index)
    shape = (recipe.frames, recipe.height, recipe.width)
    if rng.uniform() < recipe.procedural:
        name = "moderate" if rng.uniform() < 0.6 else "lights"
        return make_scene(name, *shape, seed=int(rng.integers(2 ** 31)))
    source = recipe.panoramas[int(rng.integers(len(recipe.panoramas)))]
    motion = ("pan", "tilt", "rotate", "zoom", "mixed")[int(rng.integers(5))]
    light = panorama_sequence(rng, *shape, source=source, motion=motion, sources=0)
    low, high = np.log(recipe.ratio_range)
    light = reach_ratio(light, rng, float(np.exp(rng.uniform(low, high))))
    return normalise_sequence(light, 1.0, what=f"training sequence {index}")


def cache_dir(path: str | Path | None = None) -> Path:
    """``path``, else ``$TESPIKE_CACHE/net-data``, else ``~/.cache/tespike/net-data``."""
    if path is not None:
        return Path(path)
    root = os.environ.get("TESPIKE_CACHE") or Path.home() / ".cache" / "tespike"
    return Path(root) / "net-data"


def _cached(path: Path, make) -> np.ndarray:
    if path.is_file():
        return np.load(path, mmap_mode="r", allow_pickle=False)
    array = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, array, allow_pickle=False)
    return np.load(path, mmap_mode="r", allow_pickle=False)


def stream_seed(recipe: DataRecipe, config: SensorConfig, index: int) -> np.random.SeedSequence:
    """The shot-noise seed of sequence ``index`` for ``config``: fixed by what made it."""
    digest = hashlib.sha256(json.dumps([recipe.key(), config.to_dict(), index]).encode()).digest()
    return np.random.SeedSequence(int.from_bytes(digest[:16], "little"))


def training_set(config: SensorConfig, recipe: DataRecipe = DataRecipe(), *,
                 cache: str | Path | None = None, progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(light float32 (N, K, H, W), words (N, K, H, W)), from the cache or made and cached."""
    folder = cache_dir(cache)
    indices = range(recipe.total)

    def bar(what):
        if not progress:
            return indices
        from tqdm import tqdm
        return tqdm(indices, desc=what, unit="sequence")

    key = recipe.key()
    light = _cached(folder / f"light-{key}.npy",
                    lambda: np.stack([training_sequence(recipe, i) for i in bar("training light")]))
    config_key = hashlib.sha256(config.to_json().encode()).hexdigest()[:12]
    words = _cached(folder / f"words-{key}-{config_key}.npy",
                    lambda: np.stack([simulate_scene(config, np.asarray(light[i]), workers=1,   # runs share cores
                                                     seed=np.random.default_rng(stream_seed(recipe, config, i)))
                                      for i in bar(f"simulate {config.mode}")]))
    return light, words


def evaluation_sequences(count: int = 4, frames: int = 72, height: int = 128, width: int = 160,
                         ratio_range: tuple[float, float] = (70.0, 250.0)) -> list[tuple[str, np.ndarray]]:
    """Held-out (label, light) sequences: camera paths over the held-out panorama with
    peak-to-median in ``ratio_range`` (bright sources added where the window alone is
    flatter), and the held-out ``moderate`` scenes; none shares a panorama or a seed
    domain with training."""
    out = []
    load_panorama(HELDOUT_PANORAMA)          # refuse early, naming the folder, if it is missing
    for i in range(count):
        rng = scene_rng("net-eval", i, heldout=True)
        motion = ("pan", "mixed", "tilt", "zoom")[i % 4]
        light = panorama_sequence(rng, frames, height, width, source=HELDOUT_PANORAMA, motion=motion)
        light = reach_ratio(light, rng, float(np.exp(rng.uniform(*np.log(ratio_range)))))
        out.append((f"{HELDOUT_PANORAMA}-{motion}-{i}", normalise_sequence(light, 1.0)))
    for i in range(2):
        out.append((f"moderate-{i}", make_scene("moderate", frames, height, width, seed=i, heldout=True)))
    return out
