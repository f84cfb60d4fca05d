"""Bit-exact numpy reference of the time-encoding (TE) and multi-level (ML) spike camera.

Depends on numpy alone. The rooms:

- the camera: :mod:`.config` (the one configuration type), :mod:`.reference` (SPEC's
  update rule, literally), :mod:`.sensor` (the cycle-exact model, ``tespike golden``:
  :func:`simulate` runs it on per-clock electrons), :mod:`.decode` (the one decoder),
  :mod:`.beats` (the streaming readout's lanes), :mod:`.dynamic_range`;
- light to electrons: :mod:`.light` (the front end), :mod:`.noise` (a sensor's
  non-idealities), :mod:`.stimulus` (a scene's per-clock electrons, the naive loop's
  input), :mod:`.fastsim` (light to words, exact in distribution: what
  ``tespike simulate`` runs, :func:`tespike.golden.fastsim.simulate_scene`), :mod:`.poisson`;
- the hardware's switching: :mod:`.toggles` (the pixel's registers), :mod:`.activity`
  (every register of a generated top);
- files and resources: :mod:`.io` (the files of SPEC section 6), :mod:`.atomic`,
  :mod:`.paths`, :mod:`.resources`, :mod:`.errors`.
"""

from .config import DESIGN_ELECTRONS, SensorConfig, load_config
from .decode import decode_light, decode_spikes
from .errors import ConfigError, InputError, TespikeError
from .io import load_stream, save_stream
from .sensor import PixelArrayModel, simulate

__all__ = ["DESIGN_ELECTRONS", "SensorConfig", "load_config", "decode_light", "decode_spikes",
           "ConfigError", "InputError", "TespikeError", "load_stream", "save_stream",
           "PixelArrayModel", "simulate"]
