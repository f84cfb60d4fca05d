"""Every learned reconstruction method: name -> (module class, sizes class), and its weights.

A learned method's module takes (N, span, H, W) light decoded by golden's one
decoder (scene units, key moment in the middle, H and W multiples of
``sizes.pyramid_factor``), the readouts of the span that lie in the stream and
the sensor's one-spike light, and returns (N, 1, H, W) light at the key moment;
its sizes dataclass is a :class:`tespike.recon.learning.sizes.SizesMixin` with
``span`` and ``pyramid_factor``. The machinery they share (output head,
alignment, deformable convolution, weights file, tiled inference) is
:mod:`tespike.recon.learning`, the mu-law :mod:`tespike.recon.mulaw`; one trainer
(:mod:`tespike.recon.train`) and one data engine (:mod:`tespike.recon.engine`) serve them
all. Each module reports how far its output pixels reach (:func:`method_radius`, derived by
:mod:`tespike.recon.reach`).

Shipped weights live in :data:`WEIGHTS_DIR`, one file per method and sensor
preset: ``<preset>.pt`` for the project's network (``net``), ``<method>-<preset>.pt``
for a baseline (e.g. ``bsf-te.pt``). :func:`load_learned` takes them, or a file
the user names (``--weights``), and refuses in one line a file of another
method or sensor, or a configuration no weights were shipped for (naming the
command that trains them).
Importing this module does not import torch (command lines check names quickly).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from pathlib import Path

from tespike.golden.config import PRESETS, SensorConfig
from tespike.golden.errors import InputError, one_line
from tespike.golden.paths import path_text

from .settings import check_known

#: The learned methods in the paper's row order, its learned baselines then the network: name -> what
#: it is. ``mambaspike1`` is MambaSpike of one parsing branch, the paper's spade row on the msb camera
#: (shipped for ml-msb only: on TE and the full count ``mambaspike`` has one branch already).
LEARNED_SUMMARIES = {
    "spk2imgnet": "Spk2ImgNet (Zhao et al. 2021, re-implemented)",
    "bsf": "BSF (Zhao et al. 2024, re-implemented)",
    "mambaspike1": "MambaSpike of one parsing branch (the paper's spade row, msb camera)",
    "mambaspike": "MambaSpike (selective scan, re-implemented; several parsings on the msb camera)",
    "net": "the paper's network (section 5)",
}
#: Names of the learned methods, in that order.
LEARNED = tuple(LEARNED_SUMMARIES)
#: The folder of the shipped weights.
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


def learned_methods() -> dict[str, tuple[type, type]]:
    from .baselines import BASELINES
    from .net.model import TESpikeNet
    from .net.sizes import NetSizes
    return {"net": (TESpikeNet, NetSizes), **BASELINES}


def method_classes(name: str) -> tuple[type, type]:
    methods = learned_methods()
    check_known(name, methods, "learned method")
    return methods[name]


def method_radius(sizes) -> int:
    """Frame pixels an output pixel of the learned method of ``sizes`` can reach (an upper bound;
    :func:`tespike.recon.learning.infer.module_radius`)."""
    from .learning.infer import module_radius
    for model_cls, sizes_cls in learned_methods().values():
        if type(sizes) is sizes_cls:
            return module_radius(model_cls, sizes)
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
    check_known(method, LEARNED, "learned method")
    config = SensorConfig.required(config, "weights_path")
    preset = preset_of(config)
    if preset is None:
        near = next((name for name, keys in PRESETS.items() if str(SensorConfig(**keys)) == str(config)), None)
        differs = f" ({config.differences_text(SensorConfig(**PRESETS[near]), 'the stream', f'the {near} preset')})" \
            if near else ""
        raise InputError(f"the stream's configuration {config.describe()}{differs} is none of the presets "
                         f"{', '.join(PRESETS)} "
                         f"that {method} weights are shipped for: train weights for it with "
                         f"'tespike train --method {method} --config C.json --out W.pt' and pass --weights W.pt")
    path = WEIGHTS_DIR / weights_name(method, preset)
    if not path.is_file():
        raise InputError(f"no {method} weights for the {preset} camera: {str(path)!r} is missing (train them "
                         f"with 'tespike train --method {method} --config {preset} --minutes M --out W.pt' "
                         f"and pass --weights W.pt)")
    return path


def load_learned(config: SensorConfig, method: str, weights: str | Path | None = None):
    """The ``method`` module for streams of ``config``, in eval mode: from the file ``weights``, or the
    shipped one (None); refused in one line where the file is missing or unreadable, holds another
    method or was trained for another configuration."""
    config = SensorConfig.required(config, "load_learned")
    path = weights_path(config, method) if weights is None else Path(path_text(weights, "weights"))
    what = "weights" if weights is None else "--weights"
    model, trained_for, _ = load_weights(path, what, method)
    if trained_for != config:
        raise InputError(f"{method} {what} {str(path)!r} were trained for another configuration than the stream's: "
                         f"{config.differences_text(trained_for, 'the stream', 'the weights')}")
    return model


@functools.lru_cache(maxsize=8)
def _load_cached(path: str, mtime: float, what: str):
    import torch

    from .learning.weights import read_weights
    payload = read_weights(path, what)
    try:
        module, sizes_class = method_classes(payload["method"])
        model = module(sizes_class.from_dict(payload["sizes"]))
    except InputError as exc:
        raise InputError(f"{what} {path!r}: {exc}") from None
    except (MemoryError, RuntimeError) as exc:         # sizes no machine holds (torch's allocation failure)
        raise InputError(f"{what} {path!r}: its sizes {payload['sizes']!r} make a module too large for this "
                         f"machine's memory ({one_line(exc, 120)})") from None
    state = payload["state_dict"]
    if isinstance(state, dict):              # a diverged run's weights would make a light file of NaN
        bad = next((name for name, tensor in state.items() if isinstance(tensor, torch.Tensor)
                    and tensor.is_floating_point() and not bool(torch.isfinite(tensor).all())), None)
        if bad is not None:
            raise InputError(f"{what} {path!r}: tensor {bad!r} holds a value that is not finite "
                             "(a training that diverged?)")
        own = model.state_dict()             # load_state_dict converts another dtype without a word
        odd = next((name for name, tensor in state.items() if isinstance(tensor, torch.Tensor)
                    and name in own and tensor.dtype != own[name].dtype), None)
        if odd is not None:
            raise InputError(f"{what} {path!r}: tensor {odd!r} is {state[odd].dtype}, not the module's "
                             f"{own[odd].dtype} (converting it would change its values)")
    try:
        model.load_state_dict(state)
    except (RuntimeError, TypeError, AttributeError) as exc:
        raise InputError(f"{what} {path!r} do not fit a {payload['method']} module "
                         f"({one_line(exc, 300)})") from None      # (torch's first line names no tensor)
    model.eval().to(memory_format=torch.channels_last)
    return model, payload["config"], payload["meta"], payload["method"]


def load_weights(path: str | Path, what: str = "weights", method: str | None = None):
    """(module in eval mode, the sensor configuration it was trained for, how it was made) of any learned
    method's weights file; ``what`` names the file in a refusal (a flag, or "weights"); ``method``: the
    method the file must hold (refused in one line where it holds another's module)."""
    *loaded, held = _cached(path, what)
    if method is not None and held != method:   # (by the recorded name: mambaspike1 and mambaspike share a class)
        wanted = method_classes(method)[0]
        raise InputError(f"{what} {str(path)!r} holds {held} weights (a {type(loaded[0]).__name__}), not "
                         f"{method}'s {wanted.__name__}")
    return tuple(loaded)


def weights_method(path: str | Path, what: str = "weights") -> str:
    """The learned method a weights file holds, as recorded in it (read once, like :func:`load_weights`)."""
    return _cached(path, what)[3]


def _cached(path: str | Path, what: str):
    """(module, config, meta, method) of weights file ``path``, read once while it is unchanged."""
    path = Path(path_text(path, what))
    try:
        mtime = path.stat().st_mtime
    except OSError as exc:
        raise InputError(f"cannot read {what} {str(path)!r}: {exc.strerror}") from None
    return _load_cached(str(path), mtime, what)


def weights_by_sensor(paths, configs) -> dict[tuple[str, str], Path]:
    """(method, sensor) -> the weights file to use for it, from weights files the user gave
    (``--weights``, repeatable) and ``configs`` (sensor name -> configuration): each file serves its
    method on every sensor of the configuration it was trained for. Refused in one line: a file that
    cannot be read, one trained for none of the sensors, two for the same method and sensor."""
    if isinstance(paths, (str, os.PathLike)):            # (one file: its letters had been taken as files)
        paths = [paths]
    if not isinstance(configs, Mapping):
        raise InputError(f"configs: must map sensor names to configurations, not {type(configs).__name__}")
    for name, config in configs.items():
        SensorConfig.required(config, f"sensor {name!r}")
    chosen: dict[tuple[str, str], Path] = {}
    for path in (Path(path_text(p, "--weights")) for p in paths):
        _, trained_for, _ = load_weights(path, "--weights")
        method = weights_method(path, "--weights")
        sensors = [name for name, config in configs.items() if config == trained_for]
        if not sensors:
            raise InputError(f"--weights {str(path)!r} were trained for {trained_for.describe()}, none of the sensors "
                             f"evaluated ({', '.join(configs)})")
        for sensor in sensors:
            if (method, sensor) in chosen:
                raise InputError(f"--weights {str(chosen[method, sensor])!r} and {str(path)!r} are both "
                                 f"{method} weights for the {sensor} sensor: give one")
            chosen[method, sensor] = path
    return chosen

