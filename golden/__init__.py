"""Bit-exact numpy reference of the time-encoding (TE) and multi-level (ML) spike camera.

Depends on numpy alone. The pieces: :mod:`tespike.golden.config` (the one configuration
type), :mod:`tespike.golden.sensor` (cycle-exact model), :mod:`tespike.golden.reference` (SPEC's
update rule, literally), :mod:`tespike.golden.decode` (the one decoder),
:mod:`tespike.golden.io` (the files of SPEC section 6), :mod:`tespike.golden.dynamic_range`
(formula and measured dynamic range).
"""

from .config import DESIGN_ELECTRONS, SensorConfig, load_config
from .decode import decode_light, decode_spikes
from .errors import ConfigError, InputError, TespikeError
from .io import load_stream, save_stream
from .sensor import PixelArray, simulate

__all__ = ["DESIGN_ELECTRONS", "SensorConfig", "load_config", "decode_light", "decode_spikes",
           "ConfigError", "InputError", "TespikeError", "load_stream", "save_stream",
           "PixelArray", "simulate"]
