"""What every learned method's sizes dataclass shares: presets by name, JSON round trip, one-line checks,
the sizes of the pyramid alignment and of the sub-streams.

A method's sizes are a frozen dataclass that subclasses :class:`PyramidSizes`
(every learned method here aligns features on a pyramid; with
:class:`SubstreamSizes` where it reads sub-streams), sets ``PAPER`` (the paper's size,
keyword arguments over the defaults, which are the shipped CPU size) and ``LABEL`` (how an
error names it), and checks its own fields in ``__post_init__`` after
``super().__post_init__()`` with :meth:`SizesMixin._need` and friends. The
sizes travel in every weights file (``to_dict``) and are read back by field
name, so a file written before a field was renamed still loads: :data:`RENAMED`
maps the old names to the new.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Mapping

from tespike.golden.errors import InputError

from ..mulaw import MU

#: Old field name -> its name now, for sizes read from files written before the rename
#: (the baselines' ``windows`` / ``step`` are the network's ``substreams`` / ``stride``).
RENAMED = {"windows": "substreams", "step": "stride"}
#: The sizes every learned method is built in: ``cpu``, the shipped one (its defaults), and the paper's.
SIZE_PRESETS = ("cpu", "paper")


class SizesMixin:
    """``preset``, ``to_dict``, ``from_dict`` and checks for a frozen sizes dataclass."""

    #: The paper's size: keyword arguments over the defaults, which are the shipped CPU size.
    PAPER: ClassVar[dict[str, Any]] = {}
    LABEL: ClassVar[str] = "method"

    def _need(self, key: str, ok: bool, rule: str) -> None:
        if not ok:
            raise InputError(f"{self.LABEL} size {key} = {getattr(self, key)!r}: must be {rule}")

    def _need_ints(self, *keys: str, least: int = 1) -> None:
        for key in keys:
            value = getattr(self, key)
            self._need(key, type(value) is int and value >= least, f"an integer >= {least}")

    def _need_substreams(self) -> None:
        """The fields of :class:`SubstreamSizes`."""
        self._need_ints("substreams", "window", "stride")
        self._need("substreams", self.substreams % 2 == 1, "odd (the key sub-stream sits in the middle)")
        self._need("window", self.window % 2 == 1, "odd (centred on its moment)")

    def _need_positive(self, *keys: str) -> None:
        for key in keys:
            value = getattr(self, key)
            self._need(key, isinstance(value, (int, float)) and not isinstance(value, bool)
                       and float(value) > 0 and float(value) < float("inf"), "a finite number > 0")

    @classmethod
    def preset(cls, name: str):
        """The size ``name`` of :data:`SIZE_PRESETS`: ``cpu`` (the defaults) or ``paper`` (:attr:`PAPER`)."""
        if name not in SIZE_PRESETS:
            raise InputError(f"unknown {cls.LABEL} size {name!r} (known: {', '.join(SIZE_PRESETS)})")
        return cls(**cls.PAPER) if name == "paper" else cls()

    @classmethod
    def for_camera(cls, name: str, config):
        """The preset ``name`` as built for a camera of ``config`` (a
        :class:`tespike.golden.config.SensorConfig`): the preset itself unless a method's
        published design differs between cameras (MambaSpike's parsings)."""
        return cls.preset(name)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]):
        if not isinstance(data, Mapping):
            raise InputError(f"{cls.LABEL} sizes must be a mapping of size keys, not {type(data).__name__}")
        fields = {f.name for f in dataclasses.fields(cls)}
        data = {RENAMED.get(key, key) if RENAMED.get(key) in fields else key: value for key, value in data.items()}
        unknown = sorted(set(data) - fields)
        if unknown:
            raise InputError(f"unknown {cls.LABEL} size key {unknown[0]!r}")
        for key, value in data.items():      # a JSON round trip turns tuples into lists
            if isinstance(value, list):
                data[key] = tuple(value)
        return cls(**data)


@dataclasses.dataclass(frozen=True)
class SubstreamSizes:
    """The sub-streams a method reads around the key moment (the paper's eq. 4): ``substreams``
    (odd, the key one in the middle) of ``window`` readouts, their starts ``stride`` apart. The
    defaults are the network's, 5 of 13 readouts 12 apart (61 readouts); a method reading other
    sub-streams redeclares them (Spk2ImgNet's and BSF's: :class:`tespike.recon.baselines.common.BaselineSubstreams`)."""

    substreams: int = 5
    window: int = 13
    stride: int = 12

    @property
    def span(self) -> int:
        """Readouts seen around the key moment: (substreams - 1) * stride + window."""
        return (self.substreams - 1) * self.stride + self.window


@dataclasses.dataclass(frozen=True)
class PyramidSizes(SizesMixin):
    """The sizes every learned method here shares: features of ``channels`` at 1 / ``unshuffle`` of
    the frame (a pixel-unshuffle: no pixel dropped), aligned on a pyramid of ``levels`` levels by
    deformable convolutions of ``dcn_kernel`` taps a side (odd) whose offsets are at most
    ``max_offset`` pixels of their level (``max_offset * tanh``: stable training, a finite
    receptive field, exact tiled inference); ``mu``: the mu-law that compresses the HDR light
    before the first layer. The defaults are the shipped CPU size."""

    unshuffle: int = 4
    channels: int = 16
    levels: int = 3
    dcn_kernel: int = 3
    max_offset: float = 8.0
    mu: float = MU

    def __post_init__(self) -> None:
        self._need_ints("unshuffle", "channels", "levels", "dcn_kernel")
        self._need("dcn_kernel", self.dcn_kernel % 2 == 1, "odd")
        self._need_positive("max_offset", "mu")

    @property
    def pyramid_factor(self) -> int:
        """H and W must be multiples of this: the fold and the pyramid's halvings."""
        return self.unshuffle << (self.levels - 1)

    def check_input(self, light) -> None:
        """Refuse a module input that is not (N, span, H, W) with H and W multiples of
        :attr:`pyramid_factor` (``span``: the method's, from its sub-streams or its own rule)."""
        if light.dim() != 4:
            raise ValueError(f"input has shape {tuple(light.shape)}: need (N, {self.span}, H, W)")
        _, span, h, w = light.shape
        if span != self.span or h % self.pyramid_factor or w % self.pyramid_factor:
            raise ValueError(f"input (N, {span}, {h}, {w}): need span {self.span} and H, W multiples of "
                             f"{self.pyramid_factor}")
