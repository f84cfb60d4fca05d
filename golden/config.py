"""The one configuration type of the project (SPEC section 2).

Every key has a default; some defaults depend on other keys (alpha on b2, the
clock divider on b1, the threshold on mode, b1, alpha and ml_bits, the
accumulator width on the threshold). A configuration is validated when it is
made, and every refusal names the key, the value and the rule.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Mapping

from .atomic import atomic_output
from .errors import ConfigError, TespikeError
from .paths import check_input_file

#: Electrons per readout interval at the brightest designed light I = 1
#: (0.7 quantum efficiency x 60000 photons, paper section 6 / SPEC section 6).
DESIGN_ELECTRONS = 42000

#: Longest clock structure SPEC allows: L = F * alpha <= 2^24 pixel clocks.
MAX_CLOCKS_PER_READOUT = 1 << 24

#: A configuration file larger than this is refused unread (ten keys fit in a few hundred bytes).
MAX_CONFIG_BYTES = 1 << 20

KEYS = ("mode", "b1", "b2", "alpha", "clocks_per_tick", "threshold",
        "acc_bits", "input_bits", "ml_bits", "ml_readout")
MODES = ("te", "ml")
#: What an ML readout takes from the counter (SPEC section 3): all of it, or its msb's worth.
ML_READOUTS = ("count", "msb")
#: Keys added after files were first written: a recorded configuration without one reads as its
#: default (SPEC section 6: a stream without ``ml_readout`` is a count camera's).
ADDED_KEYS = ("ml_readout",)
#: Named presets of ``--config``: each mode's defaults, and the paper's msb ML camera.
PRESETS = {"te": {"mode": "te"}, "ml": {"mode": "ml"}, "ml-msb": {"mode": "ml", "ml_readout": "msb"}}


def _short(value: Any, limit: int = 60) -> str:
    """repr of a value cut short, so a message about a 5000-digit number stays one short line."""
    text = "null" if value is None else repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def parse_json(text: str | bytes, what: str, error: type = ConfigError, keys: str | None = None) -> Any:
    """A user's JSON text -> its value; ``what`` names it in the one line that refuses it: not JSON,
    a key given twice (named as ``keys`` KEY, by default "``what``: key" KEY), nesting too deep for
    the parser (a RecursionError) or an integer too long to convert (Python's digit limit)."""
    if not isinstance(text, (str, bytes, bytearray)):    # (json's TypeError named no input)
        raise error(f"{what}: JSON must be text, not {type(text).__name__}")
    try:
        return json.loads(text, object_pairs_hook=unique_keys(keys or f"{what}: key"))
    except json.JSONDecodeError as exc:
        raise error(f"{what} is not valid JSON: {exc}") from None
    except ConfigError as exc:
        raise error(str(exc)) from None
    except RecursionError:
        raise error(f"{what} is nested too deeply to read as JSON") from None
    except ValueError as exc:        # an integer of more than sys.get_int_max_str_digits() digits
        reason = str(exc).split(";")[0].split(":")[-1].strip() if "digits" in str(exc) else str(exc)
        raise error(f"{what} holds a number too long to read ({reason})") from None


def unique_keys(what: str = "config key"):
    """An object_pairs_hook of json.loads: a key given twice is refused (``what`` names it in the
    message, e.g. "config key"), not silently overwritten by the last."""
    def hook(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        data: dict[str, Any] = {}
        for key, value in pairs:
            if key in data:
                raise ConfigError(f"{what} {key!r} is given twice")
            data[key] = value
        return data
    return hook


def _default_threshold(mode: str, b1: int, alpha: int, ml_bits: int) -> int:
    if mode == "te":
        return max(1, DESIGN_ELECTRONS // ((1 << b1) * alpha))
    return max(1, DESIGN_ELECTRONS // (1 << (ml_bits - 1)))


@dataclasses.dataclass(frozen=True)
class SensorConfig:
    """A TE or ML spike-camera configuration; ``None`` fields take SPEC defaults.

    Construct with keywords (``SensorConfig(mode="ml")``), from a mapping
    (:meth:`from_dict`), from JSON text or a file (:meth:`from_json`,
    :func:`load_config`). Instances are immutable and always valid.
    """

    mode: str = "te"
    b1: int = 4
    b2: int = 4
    alpha: int | None = None
    clocks_per_tick: int | None = None
    threshold: int | None = None
    acc_bits: int | None = None
    input_bits: int = 16
    ml_bits: int = 8
    ml_readout: str = "count"

    def __post_init__(self) -> None:
        def need_int(key: str, lo: int, hi: int | None, rule: str) -> int:
            value = getattr(self, key)
            if type(value) is not int:          # bool and float are refused
                raise ConfigError(
                    f"config key {key!r} = {_short(value)}: must be a JSON integer ({rule})")
            if value < lo or (hi is not None and value > hi):
                raise ConfigError(f"config key {key!r} = {_short(value)}: must be {rule}")
            return value

        def fill(key: str, value: int) -> None:
            if getattr(self, key) is None:
                object.__setattr__(self, key, value)

        if not isinstance(self.mode, str) or self.mode not in MODES:
            raise ConfigError(f"config key 'mode' = {_short(self.mode)}: must be one of \"te\", \"ml\"")
        if not isinstance(self.ml_readout, str) or self.ml_readout not in ML_READOUTS:
            raise ConfigError(f"config key 'ml_readout' = {_short(self.ml_readout)}: "
                              f"must be one of \"count\", \"msb\"")
        if self.ml_readout == "msb" and self.mode != "ml":
            raise ConfigError(f"config key 'ml_readout' = 'msb': only with mode = \"ml\" "
                              f"(mode is {self.mode!r})")
        b1 = need_int("b1", 1, 16, "in 1..16")
        b2 = need_int("b2", 1, 16, "in 1..16")
        ml_bits = need_int("ml_bits", 1, 16, "in 1..16")
        need_int("input_bits", 1, 32, "in 1..32")
        derived = {key for key in ("alpha", "clocks_per_tick") if getattr(self, key) is None}
        fill("alpha", (1 << b2) - 1)
        alpha = need_int("alpha", 1, (1 << b2) - 1, f"in 1..2^b2 - 1 = {(1 << b2) - 1}")
        fill("clocks_per_tick", 1 << b1)
        clocks = need_int("clocks_per_tick", 1, None, ">= 1")
        if clocks * alpha > MAX_CLOCKS_PER_READOUT:
            defaults = {"alpha": "2^b2 - 1", "clocks_per_tick": "2^b1"}
            given = "; ".join(f"{key} is its default {defaults[key]}" for key in sorted(derived))
            raise ConfigError(
                f"config key 'clocks_per_tick' = {clocks}: clocks_per_tick * alpha = "
                f"{clocks * alpha} must be <= 2^24 = {MAX_CLOCKS_PER_READOUT}"
                + (f" ({given}: give smaller b1 / b2, or the keys themselves)" if given else ""))
        fill("threshold", _default_threshold(self.mode, b1, alpha, ml_bits))
        theta = need_int("threshold", 1, None, ">= 1")
        if self.acc_bits is None and theta.bit_length() + 1 > 62:     # (the derived width, named by its cause)
            raise ConfigError(f"config key 'threshold' = {_short(theta)}: must be < 2^61 with the default "
                              f"acc_bits (it would be {theta.bit_length() + 1}, at most 62); up to 2^62 - 1 "
                              "with acc_bits = 62 given")
        fill("acc_bits", theta.bit_length() + 1)
        acc_bits = need_int("acc_bits", 1, 62, "in 1..62")
        if (1 << acc_bits) - 1 < theta:
            raise ConfigError(
                f"config key 'acc_bits' = {acc_bits}: 2^acc_bits - 1 = {(1 << acc_bits) - 1} "
                f"must be >= threshold = {theta}")

    # -- construction -------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, whole: bool = False) -> "SensorConfig":
        """Build from a mapping of SPEC keys; unknown keys are refused. ``whole=True`` is for
        the configuration a file records (a stream's, a calibration's, a weights file's: SPEC
        section 6, "every key of section 2"): a missing key is refused, not given its default,
        except those older files may lack (:data:`ADDED_KEYS`)."""
        if not isinstance(data, Mapping):
            raise ConfigError(f"configuration must be a JSON object, not {type(data).__name__}")
        missing = [key for key in KEYS if key not in data and key not in ADDED_KEYS] if whole else []
        if missing:
            raise ConfigError(f"configuration lacks key{'s' * (len(missing) > 1)} "
                              f"{', '.join(map(repr, missing))} (a recorded configuration holds every key)")
        unknown = sorted(set(data) - set(KEYS), key=str)
        if unknown:
            raise ConfigError(
                f"config key {unknown[0]!r} = {_short(data[unknown[0]])}: unknown key "
                f"(known keys: {', '.join(KEYS)})")
        for key in KEYS:       # JSON null is not "use the default": every value is an integer or string
            if key in data and data[key] is None:
                raise ConfigError(f"config key {key!r} = null: must be a JSON "
                                  f"{'string' if key in ('mode', 'ml_readout') else 'integer'} "
                                  "(leave the key out to take its default)")
        return cls(**dict(data))

    @classmethod
    def from_json(cls, text: str, *, whole: bool = False) -> "SensorConfig":
        """Parse JSON text; refuse duplicate keys, deep nesting and huge numbers in one line;
        ``whole`` as :meth:`from_dict`'s."""
        return cls.from_dict(parse_json(text, "configuration", keys="config key"), whole=whole)

    @classmethod
    def preset(cls, name: str) -> "SensorConfig":
        """A named preset: ``"te"`` (paper: b1 = b2 = 4), ``"ml"`` (8-bit count) or
        ``"ml-msb"`` (8-bit counter, most-significant-bit readout: the paper's eq. 10)."""
        if not isinstance(name, str) or name not in PRESETS:
            raise ConfigError(f"unknown preset {name!r}: must be one of "
                              + ", ".join(f'"{p}"' for p in PRESETS))
        return cls(**PRESETS[name])

    def check(self) -> "SensorConfig":
        """Re-validate (instances are validated when made; this is for callers that
        want the refusal before building anything)."""
        return SensorConfig.from_dict(self.to_dict())

    @staticmethod
    def required(config, what: str = "configuration") -> "SensorConfig":
        """``config`` itself, or a :class:`ConfigError` naming ``what`` when it is no SensorConfig
        (a preset's name or a dict where the library's entry points take the object: the
        ``AttributeError`` of its first field read named neither). Instances are validated when
        made and frozen, so the type is all there is to check."""
        if not isinstance(config, SensorConfig):
            raise ConfigError(f"{what}: configuration must be a SensorConfig (SensorConfig.preset(name) or "
                              f"load_config(path)), not {type(config).__name__}")
        return config

    @staticmethod
    def checked(config, what: str = "configuration") -> "SensorConfig":
        """``config`` re-validated (:meth:`check`), or a :class:`ConfigError` naming ``what`` when it is no
        SensorConfig (a block or writer that builds from it: the RTL, the Verilog writers)."""
        return SensorConfig.required(config, what).check()

    # -- serialisation ------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {key: getattr(self, key) for key in KEYS}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=False)

    def key_differences(self, other: "SensorConfig") -> list[tuple[str, Any, Any]]:
        """``(key, this value, other's value)`` of every key (SPEC order) where ``other`` differs;
        empty where they are equal."""
        other = SensorConfig.required(other, "key_differences")
        return [(key, getattr(self, key), getattr(other, key)) for key in KEYS
                if getattr(self, key) != getattr(other, key)]

    def differences_text(self, other: "SensorConfig", mine: str, theirs: str) -> str | None:
        """How ``other`` differs, as every refusal of a mismatched file or stream says it:
        ``"threshold = 175 in the calibration, 100 in the stream"`` (``mine`` and ``theirs`` name
        the two; each differing key, "; " between them); None where they are equal."""
        return "; ".join(f"{key} = {a!r} in {mine}, {b!r} in {theirs}"
                         for key, a, b in self.key_differences(other)) or None

    def save(self, path: str | Path) -> None:
        with atomic_output(path) as tmp:
            Path(tmp).write_text(self.to_json() + "\n")

    # -- derived quantities (all integers) ----------------------------------
    @property
    def is_te(self) -> bool:
        return self.mode == "te"

    @property
    def is_msb(self) -> bool:
        """ML camera with the most-significant-bit readout (paper eq. 10)."""
        return self.ml_readout == "msb"

    @property
    def clocks_per_readout(self) -> int:
        """L = F * alpha pixel clocks per readout interval."""
        return self.clocks_per_tick * self.alpha

    @property
    def p_max(self) -> int:
        """Spikes that overflow the TE spike-firing counter: 2^b1."""
        return 1 << self.b1

    @property
    def d(self) -> int:
        """TE payload bits of the readout word: max(b1, b2)."""
        return max(self.b1, self.b2)

    @property
    def word_bits(self) -> int:
        """Width of one readout word: max(b1, b2) + 1 (TE), ml_bits (ML count) or
        bit_length(ml_bits) (ML msb: the word is an msb index 0..ml_bits)."""
        if self.is_te:
            return self.d + 1
        return self.ml_bits.bit_length() if self.is_msb else self.ml_bits

    @property
    def acc_max(self) -> int:
        """Saturation level of the charge accumulator: 2^A - 1."""
        return (1 << self.acc_bits) - 1

    @property
    def input_max(self) -> int:
        """Largest electron count one pixel clock can carry: 2^E - 1."""
        return (1 << self.input_bits) - 1

    @property
    def ml_max(self) -> int:
        return (1 << self.ml_bits) - 1

    @property
    def spike_light(self) -> float:
        """Light of one spike per readout interval, in scene units (1.0 = the design light)."""
        return self.threshold / DESIGN_ELECTRONS

    @property
    def top_light(self) -> float:
        """The most light a readout word can tell, in scene units: a pixel fires at most once a
        clock (less where one clock's input, 2^E - 1, is below the threshold), and an ML count at
        most 2^ml_bits - 1 times; brighter light reads as this. At least 1 with the SPEC's default
        thresholds at L = 240; below 1 where a configuration cannot read its design light (e.g.
        ``ml_bits`` 9 or more, or TE ``clocks_per_tick`` 1, at L = 240)."""
        electrons = self.clocks_per_readout * min(self.threshold, self.input_max)
        if not self.is_te and not self.is_msb:
            electrons = min(electrons, self.ml_max * self.threshold)
        return electrons / DESIGN_ELECTRONS

    def _shown_keys(self) -> tuple[str, ...]:
        keys = ("b1", "b2", "alpha", "clocks_per_tick", "threshold", "acc_bits", "input_bits")
        return keys if self.is_te else keys + ("ml_bits",)

    def __str__(self) -> str:   # short, for test ids, logs and the dataset store's array names
        mode = self.mode + ("-msb" if self.is_msb else "")
        return mode + "-" + "-".join(f"{k}{getattr(self, k)}" for k in self._shown_keys())

    def describe(self) -> str:
        """The configuration as messages show it to a user: ``te (b1=4, b2=4, alpha=15, ...)``
        (``str`` glues key and value, ``b14``, which reads as b1 = 14)."""
        mode = self.mode + ("-msb" if self.is_msb else "")
        return f"{mode} (" + ", ".join(f"{k}={getattr(self, k)}" for k in self._shown_keys()) + ")"


def load_config(spec: str | Path) -> SensorConfig:
    """``"te"`` / ``"ml"`` / ``"ml-msb"`` name presets; anything else is a JSON file path."""
    if isinstance(spec, SensorConfig):
        return spec
    if not isinstance(spec, (str, os.PathLike)):
        hint = " (a dict of keys: SensorConfig.from_dict)" if isinstance(spec, dict) else ""
        raise ConfigError(f"configuration {spec!r}: must be a preset's name or a JSON file's path, "
                          f"not {type(spec).__name__}{hint}")
    if str(spec) in PRESETS:
        return SensorConfig.preset(str(spec))
    path = Path(spec)
    try:
        check_input_file(str(spec) if not isinstance(spec, Path) else spec, "configuration")
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read configuration file {str(path)!r}: {exc.strerror}") from None
    except TespikeError as exc:
        if not path.exists() and not path.suffix:       # a mistyped preset, not a missing file
            raise ConfigError(f"configuration {str(spec)!r} is neither a preset ({', '.join(PRESETS)}) "
                              "nor an existing JSON file") from None
        raise ConfigError(str(exc)) from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f"configuration file {str(path)!r} is {len(data)} bytes; "
                          f"a configuration is at most {MAX_CONFIG_BYTES} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"configuration file {str(path)!r} is not UTF-8 text "
                          f"(byte {exc.start}: {data[exc.start:exc.start + 1]!r})") from None
    try:
        return SensorConfig.from_json(text)
    except ConfigError as exc:
        raise ConfigError(f"configuration file {str(path)!r}: {exc}") from None
