"""What the three learned baselines share: their sizes' plumbing, input checks, windows, blocks.

Every baseline takes the project's one stream format into learned methods,
(N, span, H, W) decoded light in scene units (``recon.stream.decode_light``),
key moment at ``span // 2``, and returns (N, 1, H, W) light at the key moment.
HDR light is compressed with the project's mu-law before the first layer and
the output expanded with it (:func:`recon.net.model.compress` / ``expand``),
as the project's network does, and each ends in the project's output head
(:class:`recon.net.head.BlendHead`: a per-pixel choice among training-free
estimates plus a correction), so it starts from a sensible image and trains
stably on HDR scenes.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Mapping

import torch
from torch import nn

from golden.errors import InputError

from ..net.mulaw import compress  # noqa: F401  (re-exported for the baselines)
from ..reach import Support, support


class SizesMixin:
    """``preset``, ``to_dict``, ``from_dict`` and checks for a frozen sizes dataclass.

    A subclass sets ``PRESETS`` (name -> keyword arguments) and ``LABEL``
    (how an error names it), and calls :meth:`_need` in ``__post_init__``.
    """

    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {}
    LABEL: ClassVar[str] = "baseline"

    def _need(self, key: str, ok: bool, rule: str) -> None:
        if not ok:
            raise InputError(f"{self.LABEL} size {key} = {getattr(self, key)!r}: must be {rule}")

    def _need_ints(self, *keys: str, least: int = 1) -> None:
        for key in keys:
            value = getattr(self, key)
            self._need(key, type(value) is int and value >= least, f"an integer >= {least}")

    def _need_positive(self, *keys: str) -> None:
        for key in keys:
            value = getattr(self, key)
            self._need(key, isinstance(value, (int, float)) and not isinstance(value, bool)
                       and float(value) > 0 and float(value) < float("inf"), "a finite number > 0")

    @classmethod
    def preset(cls, name: str):
        if name not in cls.PRESETS:
            raise InputError(f"unknown {cls.LABEL} size {name!r} (known: {', '.join(cls.PRESETS)})")
        return cls(**cls.PRESETS[name])

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]):
        unknown = sorted(set(data) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise InputError(f"unknown {cls.LABEL} size key {unknown[0]!r}")
        data = dict(data)
        for f in dataclasses.fields(cls):      # JSON round trip turns tuples into lists
            if f.name in data and isinstance(data[f.name], list):
                data[f.name] = tuple(data[f.name])
        return cls(**data)


def check_input(light: torch.Tensor, span: int, factor: int) -> None:
    """Refuse an input of the wrong span or a frame size that is not a multiple of ``factor``."""
    if light.dim() != 4:
        raise ValueError(f"input has shape {tuple(light.shape)}: need (N, {span}, H, W)")
    n, s, h, w = light.shape
    if s != span or h % factor or w % factor:
        raise ValueError(f"input (N, {s}, {h}, {w}): need span {span} and H, W multiples of {factor}")


def windows(x: torch.Tensor, count: int, length: int, step: int) -> torch.Tensor:
    """(N, T, ...) -> (N, count, length, ...): ``count`` windows of ``length`` readouts ``step`` apart."""
    index = torch.arange(count, device=x.device)[:, None] * step + torch.arange(length, device=x.device)
    return x[:, index]


def centred(x: torch.Tensor, length: int) -> torch.Tensor:
    """(N, T, ...) -> the ``length`` readouts around the middle of T (T and length odd)."""
    start = (x.shape[1] - length) // 2
    return x[:, start:start + length]


def conv3(cin: int, cout: int, stride: int = 1, dilation: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, stride=stride, padding=dilation, dilation=dilation)


class ResBlock(nn.Module):
    """x + conv(act(conv(x))): the residual block of EDVR / Spk2ImgNet (reach: 2 dilation)."""

    def __init__(self, channels: int, dilation: int = 1):
        super().__init__()
        self.body = nn.Sequential(conv3(channels, channels, dilation=dilation), nn.LeakyReLU(0.1),
                                  conv3(channels, channels, dilation=dilation))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)

    def support(self, x: Support) -> Support:
        return x.union(support(self.body, x))


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
