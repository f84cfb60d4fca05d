"""Every learned reconstruction method: name -> (module class, sizes class).

A learned method's module takes (N, span, H, W) light decoded by golden's one
decoder (scene units, key moment in the middle, H and W multiples of
``sizes.pyramid_factor``) and returns (N, 1, H, W) light at the key moment;
its sizes dataclass has ``preset(name)``, ``to_dict``/``from_dict``, ``span``
and ``pyramid_factor``. One trainer (:mod:`recon.net.train`), one data engine
(:mod:`recon.engine`) and one tiled inference (:mod:`recon.net.infer`) serve
them all. Each module reports how far its output pixels reach
(:func:`receptive_radius`, derived from its sub-modules by :mod:`recon.reach`).
"""

from __future__ import annotations

import functools

from golden.errors import InputError


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
