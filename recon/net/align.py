"""Similarity-based pyramid alignment (SPA, paper section 5.3, Fig. 3 (b), eq. 5 and 9).

Every reference feature is aligned to the key feature coarse to fine by the
pyramid alignment every learned method shares (:class:`tespike.recon.learning.align.PyramidAlign`)
with the paper's two parts at each level: the similarity predictor SP gates
the upsampled coarser result before it is merged with this level's DCN
output, and the motion bias predictor MBP adds a bias (eq. 9). The aligned
references and the key are fused by two convolutions into ``F~``.
"""

from __future__ import annotations

import torch
from torch import nn

from ..learning.align import PyramidAlign
from ..learning.layers import conv3
from ..reach import Support, support
from .sizes import NetSizes

#: Where weights written before the pyramid was shared kept its parts (SPA's own ``down`` and
#: ``levels``): renamed on loading, so every such file loads unchanged.
FORMER_NAMES = ("down.", "levels.")


class SPA(nn.Module):
    """(N, S, C, h, w) features of S sub-streams (key in the middle) -> fused (N, C, h, w)."""

    def __init__(self, sizes: NetSizes):
        super().__init__()
        c = sizes.channels
        self.act = nn.LeakyReLU(0.1)
        self.align = PyramidAlign(c, sizes.levels if sizes.dcn else 0, sizes.dcn_kernel,
                                  max_offset=sizes.max_offset, similarity=sizes.similarity,
                                  motion_bias=sizes.motion_bias)
        self.fusion = nn.Sequential(conv3(sizes.substreams * c, c), nn.LeakyReLU(0.1), conv3(c, c))
        self.register_load_state_dict_pre_hook(_former_names)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.act(self.fusion(self.align(features).flatten(1, 2)))

    def support(self, features: Support) -> Support:
        """:meth:`forward` on supports (every sub-stream's feature has the same)."""
        return support(self.fusion, self.align.support(features))


def _former_names(module, state_dict, prefix, *_) -> None:
    """Rename, in place, SPA's tensors saved under its former names (``prefix + "down."`` ...)."""
    for key in [k for k in state_dict if k.startswith(tuple(prefix + name for name in FORMER_NAMES))]:
        state_dict[prefix + "align." + key[len(prefix):]] = state_dict.pop(key)
