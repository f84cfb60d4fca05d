"""Every learned reconstruction method: name -> (module class, sizes class).

A learned method's module takes (N, span, H, W) light decoded by golden's one
decoder (scene units, key moment in the middle, H and W multiples of
``sizes.pyramid_factor``) and returns (N, 1, H, W) light at the key moment;
its sizes dataclass has ``preset(name)``, ``to_dict``/``from_dict``, ``span``
and ``pyramid_factor``. One trainer (:mod:`recon.net.train`), one data engine
(:mod:`recon.engine`) and one tiled inference (:mod:`recon.net.infer`) serve
them all.
"""

from __future__ import annotations

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
