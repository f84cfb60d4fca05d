"""Every learned reconstruction method: name -> (module class, sizes class), and its shipped weights.

A learned method's module takes (N, span, H, W) light decoded by golden's one
decoder (scene units, key moment in the middle, H and W multiples of
``sizes.pyramid_factor``) and returns (N, 1, H, W) light at the key moment;
its sizes dataclass has ``preset(name)``, ``to_dict``/``from_dict``, ``span``
and ``pyramid_factor``. One trainer (:mod:`recon.net.train`), one data engine
(:mod:`recon.engine`) and one tiled inference (:mod:`recon.net.infer`) serve
them all. Each module reports how far its output pixels reach
(:func:`receptive_radius`, derived from its sub-modules by :mod:`recon.reach`).

Shipped weights live in :data:`WEIGHTS_DIR`, one file per method and sensor
preset: ``<preset>.pt`` for the project's network (``net``), ``<method>-<preset>.pt``
for a baseline (e.g. ``bsf-te.pt``). :func:`weights_path` finds them and refuses,
in one line naming the file and the command that trains it, where there are none.
Importing this module does not import torch (command lines check names quickly).
"""

from __future__ import annotations

import functools
from pathlib import Path

from golden.config import PRESETS, SensorConfig
from golden.errors import InputError

#: Names of the learned methods in the paper's row order: its learned baselines, then the network.
LEARNED = ("spk2imgnet", "bsf", "mambaspike", "net")
#: The folder of the shipped weights (beside the network's code).
WEIGHTS_DIR = Path(__file__).resolve().parent / "net" / "weights"


def learned_methods() -> dict[str, tuple[type, type]]:
    from .baselines import BASELINES
    from .net.model import TESpikeNet
    from .net.sizes import NetSizes
    return {"net": (TESpikeNet, NetSizes), **BASELINES}


def method_classes(name: str) -> tuple[type, type]:
    methods = learned_methods()
    if name not in methods:
        raise InputError(f"unknown learned method {name!r} (known: {', '.join(methods)})")
    return methods[name]


@functools.lru_cache(maxsize=64)
def receptive_radius(sizes) -> int:
    """Frame pixels an output pixel of the learned method of ``sizes`` can reach (an upper bound).

    Derived from the module built from ``sizes`` (on the meta device: no memory,
    no weights) by :func:`recon.reach.receptive_radius`, so any change of a kernel,
    a level, an offset bound or a window shows in it.
    """
    import torch

    from .reach import receptive_radius as derived
    for model_cls, sizes_cls in learned_methods().values():
        if type(sizes) is sizes_cls:
            with torch.device("meta"):
                model = model_cls(sizes)
            return derived(model)
    raise InputError(f"{type(sizes).__name__} is the sizes of no learned method")


def method_span(name: str, size: str = "cpu") -> int:
    """Readouts a learned method sees around each key moment: the span its sizes fix."""
    return method_classes(name)[1].preset(size).span


def preset_of(config: SensorConfig) -> str | None:
    """The name of the preset ``config`` equals, else None."""
    for name, keys in PRESETS.items():
        if SensorConfig(**keys) == config:
            return name
    return None


def weights_name(method: str, preset: str) -> str:
    """File name of the shipped weights: ``<preset>.pt`` for the network, ``<method>-<preset>.pt`` else."""
    return f"{preset}.pt" if method == "net" else f"{method}-{preset}.pt"


def weights_path(config: SensorConfig, method: str = "net") -> Path:
    """The shipped weights of ``method`` for ``config``; a one-line refusal where there are none."""
    if method not in LEARNED:
        raise InputError(f"unknown learned method {method!r} (known: {', '.join(LEARNED)})")
    preset = preset_of(config)
    if preset is None:
        raise InputError(f"the stream's configuration {config} is none of the presets {', '.join(PRESETS)} "
                         f"that {method} weights are shipped for (train weights for it with "
                         f"'tespike train --method {method} --config C.json --out W.pt')")
    path = WEIGHTS_DIR / weights_name(method, preset)
    if not path.is_file():
        raise InputError(f"no {method} weights for the {preset} camera: {str(path)!r} is missing (train them "
                         f"with 'tespike train --method {method} --config {preset} --minutes M --out {path}')")
    return path


def load_learned(config: SensorConfig, method: str):
    """The shipped ``method`` module for ``config``, in eval mode; refused in one line where its
    weights are missing, hold another method or were trained for another configuration."""
    path = weights_path(config, method)
    model, trained_for, _ = load_weights(path)
    wanted = method_classes(method)[0]
    if type(model) is not wanted:
        raise InputError(f"weights {str(path)!r} hold a {type(model).__name__}, not {method}'s {wanted.__name__}")
    if trained_for != config:
        raise InputError(f"{method} weights {str(path)!r} were trained for {trained_for}, the stream is {config}")
    return model


@functools.lru_cache(maxsize=8)
def _load_cached(path: str, mtime: float):
    import torch
    payload = torch.load(path, map_location="cpu", weights_only=True)
    module, sizes_class = method_classes(payload.get("method", "net"))
    model = module(sizes_class.from_dict(payload["sizes"]))
    model.load_state_dict(payload["state_dict"])
    model.eval().to(memory_format=torch.channels_last)
    return model, SensorConfig.from_dict(payload["config"]), payload.get("meta", {})


def load_weights(path: str | Path):
    """(model in eval mode, the sensor configuration it was trained for, how it was made) of any learned method."""
    import pickle
    import zipfile
    path = Path(path)
    try:
        return _load_cached(str(path), path.stat().st_mtime)
    except OSError as exc:
        raise InputError(f"cannot read network weights {str(path)!r}: {exc.strerror}") from None
    except (RuntimeError, KeyError, TypeError, ValueError, EOFError, pickle.UnpicklingError,
            zipfile.BadZipFile) as exc:
        raise InputError(f"network weights {str(path)!r} are not a tespike weights file "
                         f"({str(exc).splitlines()[0][:100] if str(exc) else type(exc).__name__})") from None
