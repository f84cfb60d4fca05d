"""The training-data engine: endless, deterministic, simulated training clips for every learned method.

- :mod:`tespike.recon.engine.deadleaves`: procedural dead-leaves HDR video;
- :mod:`tespike.recon.engine.clips`: the families (dead leaves, panorama paths, user
  folders), drawn peak and length, a clip's stream by golden's fast simulator;
- :mod:`tespike.recon.engine.batches`: clips made ahead on worker processes, the pool
  a step draws from, samples with the inference's edge padding;
- :mod:`tespike.recon.engine.validation`: the held-out validation set and its PSNR-mu (:func:`validation_psnr`).
"""

from .clips import EngineRecipe, make_clip
from .validation import validation_psnr, validation_set

__all__ = ["EngineRecipe", "make_clip", "validation_psnr", "validation_set"]
