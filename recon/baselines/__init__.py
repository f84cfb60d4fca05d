"""The learned baselines of the paper's Table 1, re-implemented from their papers (docs/baselines.md).

Each takes (N, span, H, W) decoded light (the project's stream format into
every learned method, TE and ML alike) and returns (N, 1, H, W) light at the
key moment ``span // 2``; how far an output pixel reaches is derived from each
module (``support`` methods beside ``forward``, :mod:`tespike.recon.reach`;
:func:`tespike.recon.learned.method_radius` for every learned method).
"""

from __future__ import annotations

from torch import nn

from .bsf import BSF, BSFSizes
from .mambaspike import MambaSpike, MambaSpikeOneBranchSizes, MambaSpikeSizes
from .spk2imgnet import Spk2ImgNet, Spk2ImgNetSizes

#: method name -> (model class, sizes class).
BASELINES: dict[str, tuple[type[nn.Module], type]] = {
    "spk2imgnet": (Spk2ImgNet, Spk2ImgNetSizes),
    "bsf": (BSF, BSFSizes),
    "mambaspike": (MambaSpike, MambaSpikeSizes),
    "mambaspike1": (MambaSpike, MambaSpikeOneBranchSizes),
}

#: Parameters of each method in the paper's Table 10 (its TE version: MambaSpike of one parsing branch);
#: the whole table is :data:`tespike.recon.complexity.PAPER_TABLE10`, built on these.
PAPER_PARAMETERS = {"spk2imgnet": 3_760_000, "bsf": 2_071_000, "mambaspike": 4_418_000, "mambaspike1": 4_418_000}

__all__ = ["BASELINES", "PAPER_PARAMETERS", "Spk2ImgNet", "Spk2ImgNetSizes", "BSF",
           "BSFSizes", "MambaSpike", "MambaSpikeSizes",
           "MambaSpikeOneBranchSizes"]
