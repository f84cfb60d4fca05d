"""Sizes and switches of the reconstruction network, in one dataclass.

``NetSizes.preset("cpu")`` is the shipped CPU default (sized for about a
second per 384 x 512 frame on two cores); ``NetSizes.preset("paper")`` has
the paper's parameter count (6.479 M, its Table 10) to within 5 %, measured
by ``tests/test_recon_net_model.py``. The six ablation cases of the paper's
Table 3 are :meth:`NetSizes.ablation`.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from tespike.golden.errors import InputError

from ..learning.sizes import PyramidSizes, SubstreamSizes

#: Switches of the paper's Table 3, in its column order.
SWITCHES = ("gradient", "dcn", "similarity", "motion_bias", "refine")
#: Output heads: ``blend`` (recon/learning/head.py: a per-pixel choice among training-free estimates plus a
#: correction, the default) or ``mean`` (a correction to the key sub-stream's mean; weights made before it).
HEADS = ("blend", "mean")


@dataclasses.dataclass(frozen=True)
class NetSizes(PyramidSizes, SubstreamSizes):
    """Every size of the network (paper section 5, appendix A.1).

    Input: ``substreams`` sub-streams (eq. 4) of ``window`` readouts each, their
    centres ``stride`` readouts apart around the key moment: 5 x 13 readouts 12
    apart span (5 - 1) * 12 + 13 = 61 readouts, the span of the paper's deep methods.
    ``unshuffle``: the stream enters at full resolution and is folded
    (pixel-unshuffle) by this factor before the first convolution; features
    live at 1 / unshuffle of the frame and are unfolded at the end (a CPU size
    choice: no pixel is dropped, every convolution costs unshuffle^2 less).
    ``channels``: feature width; ``levels``: pyramid levels of SPA (3 in the
    paper); ``dcn_kernel``, ``max_offset``, ``mu``: as :class:`PyramidSizes`;
    ``heads``: attention heads of LIR; ``attention_window``: side of the
    neighbourhood over which LIR's K^T Q is averaged; ``head``: one of
    :data:`HEADS`; the switches of :data:`SWITCHES`.
    """

    PAPER: ClassVar[dict] = {"unshuffle": 1, "channels": 120, "heads": 4}
    LABEL: ClassVar[str] = "network"

    heads: int = 2
    attention_window: int = 15
    head: str = "blend"
    gradient: bool = True
    dcn: bool = True
    similarity: bool = True
    motion_bias: bool = True
    refine: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        need = self._need
        self._need_substreams()
        self._need_ints("heads", "attention_window")
        need("attention_window", self.attention_window % 2 == 1, "odd")
        need("channels", self.channels % 4 == 0 and self.channels % self.heads == 0,
             "a multiple of 4 and of heads")
        need("head", self.head in HEADS, "one of " + ", ".join(HEADS))
        for key in SWITCHES:
            need(key, type(getattr(self, key)) is bool, "true or false")

    def ablation(self, case: int) -> "NetSizes":
        """The paper's Table 3 case 1..6 (MSFE always; then gradient, DCNs, SP, MBP, LIR)."""
        if type(case) is not int or not 1 <= case <= 6:
            raise InputError(f"ablation case {case!r}: must be 1..6 (paper Table 3)")
        on = SWITCHES[:case - 1]
        return dataclasses.replace(self, **{key: key in on for key in SWITCHES})
