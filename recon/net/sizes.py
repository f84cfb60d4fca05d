"""Sizes and switches of the reconstruction network, in one dataclass.

``NetSizes.preset("cpu")`` is the shipped CPU default (sized for about a
second per 384 x 512 frame on two cores); ``NetSizes.preset("paper")`` has
the paper's parameter count (6.479 M, its Table 10) to within 5 %, measured
by ``tests/test_recon_net_model.py``. The six ablation cases of the paper's
Table 3 are :meth:`NetSizes.ablation`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

from tespike.golden.errors import InputError

from ..learning.sizes import SizesMixin, SubstreamSizes
from ..pictures import MU

#: Switches of the paper's Table 3, in its column order.
SWITCHES = ("gradient", "dcn", "similarity", "motion_bias", "refine")
#: Output heads: ``blend`` (recon/learning/head.py: a per-pixel choice among training-free estimates plus a
#: correction, the default) or ``mean`` (a correction to the key sub-stream's mean; weights made before it).
HEADS = ("blend", "mean")


@dataclasses.dataclass(frozen=True)
class NetSizes(SizesMixin, SubstreamSizes):
    """Every size of the network (paper section 5, appendix A.1).

    Input: ``substreams`` sub-streams (eq. 4) of ``window`` readouts each, their
    centres ``stride`` readouts apart around the key moment: 5 x 13 readouts 12
    apart span (5 - 1) * 12 + 13 = 61 readouts, the span of the paper's deep methods.
    ``unshuffle``: the stream enters at full resolution and is folded
    (pixel-unshuffle) by this factor before the first convolution; features
    live at 1 / unshuffle of the frame and are unfolded at the end (a CPU size
    choice: no pixel is dropped, every convolution costs unshuffle^2 less).
    ``channels``: feature width; ``levels``: pyramid levels of SPA (3 in the
    paper); ``dcn_kernel``: taps per side of the deformable convolution;
    ``max_offset``: largest offset of a DCN tap, in pixels of its level
    (offsets are ``max_offset * tanh``, as BasicVSR++ bounds its residues: it
    keeps training stable and the receptive field finite, which makes tiled
    inference exact); ``heads``: attention heads of LIR; ``attention_window``:
    side of the neighbourhood over which LIR's K^T Q is averaged;
    ``mu``: the mu of the mu-law that compresses the HDR range of the decoded
    stream before the first convolution (and expands the output); ``head``:
    one of :data:`HEADS`.
    """

    #: name -> keyword arguments: the shipped CPU size and the paper's.
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {
        "cpu": {},
        "paper": {"unshuffle": 1, "channels": 120, "heads": 4},
    }
    LABEL: ClassVar[str] = "network"

    substreams: int = 5
    window: int = 13
    stride: int = 12
    unshuffle: int = 4
    channels: int = 16
    levels: int = 3
    dcn_kernel: int = 3
    max_offset: float = 8.0
    heads: int = 2
    attention_window: int = 15
    mu: float = MU
    head: str = "blend"
    gradient: bool = True
    dcn: bool = True
    similarity: bool = True
    motion_bias: bool = True
    refine: bool = True

    def __post_init__(self) -> None:
        need = self._need
        self._need_substreams("sub-stream")
        self._need_ints("unshuffle", "channels", "levels", "dcn_kernel", "heads", "attention_window")
        need("dcn_kernel", self.dcn_kernel % 2 == 1, "odd")
        need("attention_window", self.attention_window % 2 == 1, "odd")
        need("channels", self.channels % 4 == 0 and self.channels % self.heads == 0,
             "a multiple of 4 and of heads")
        need("max_offset", float(self.max_offset) > 0, "> 0")
        need("mu", float(self.mu) > 0, "> 0")
        need("head", self.head in HEADS, "one of " + ", ".join(HEADS))
        for key in SWITCHES:
            need(key, type(getattr(self, key)) is bool, "true or false")

    @property
    def pyramid_factor(self) -> int:
        """Frame sizes are padded to a multiple of this (unshuffle and the pyramid's halvings)."""
        return self.unshuffle * (1 << (self.levels - 1))

    def ablation(self, case: int) -> "NetSizes":
        """The paper's Table 3 case 1..6 (MSFE always; then gradient, DCNs, SP, MBP, LIR)."""
        if type(case) is not int or not 1 <= case <= 6:
            raise InputError(f"ablation case {case!r}: must be 1..6 (paper Table 3)")
        on = SWITCHES[:case - 1]
        return dataclasses.replace(self, **{key: key in on for key in SWITCHES})
