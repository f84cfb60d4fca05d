"""What every learned method's sizes dataclass shares: presets by name, JSON round trip, one-line checks.

A method's sizes are a frozen dataclass that subclasses :class:`SizesMixin`,
sets ``PRESETS`` (name -> keyword arguments) and ``LABEL`` (how an error names
it), and checks itself in ``__post_init__`` with :meth:`SizesMixin._need` and
friends. The sizes travel in every weights file (``to_dict``), so a file
written before a field was renamed still loads: :data:`RENAMED` maps the old
names to the new.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Mapping

from tespike.golden.errors import InputError

#: Old field name -> its name now, for sizes read from files written before the rename
#: (the baselines' ``windows`` / ``step`` are the network's ``substreams`` / ``stride``).
RENAMED = {"windows": "substreams", "step": "stride"}


class SizesMixin:
    """``preset``, ``to_dict``, ``from_dict`` and checks for a frozen sizes dataclass."""

    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {}
    LABEL: ClassVar[str] = "method"

    def _need(self, key: str, ok: bool, rule: str) -> None:
        if not ok:
            raise InputError(f"{self.LABEL} size {key} = {getattr(self, key)!r}: must be {rule}")

    def _need_ints(self, *keys: str, least: int = 1) -> None:
        for key in keys:
            value = getattr(self, key)
            self._need(key, type(value) is int and value >= least, f"an integer >= {least}")

    def _need_substreams(self, what: str) -> None:
        """The fields of :class:`SubstreamSizes` (each sub-stream called ``what`` in a refusal)."""
        self._need_ints("substreams", "window", "stride")
        self._need("substreams", self.substreams % 2 == 1, f"odd (the key {what} sits in the middle)")
        self._need("window", self.window % 2 == 1, "odd (centred on its moment)")

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
    (odd, the key one in the middle) of ``window`` readouts, their starts ``stride`` apart.
    A method's sizes inherit these three fields first (with their own defaults)."""

    substreams: int = 5
    window: int = 13
    stride: int = 12

    @property
    def span(self) -> int:
        """Readouts seen around the key moment: (substreams - 1) * stride + window."""
        return (self.substreams - 1) * self.stride + self.window
