"""Where an RTL stream first differs from the golden model's: one report for every caller."""

from __future__ import annotations

import dataclasses

import numpy as np

from tespike.golden.errors import InputError


@dataclasses.dataclass(frozen=True)
class Difference:
    """How many words of ``total`` differ, and the first (readout, row, column) with both words."""

    count: int
    total: int
    readout: int
    row: int
    col: int
    rtl: int
    golden: int

    def text(self, corner: tuple[int, int] | None = None) -> str:
        """One sentence; ``corner``: the crop's top-left in a larger frame, also named."""
        where = f"pixel ({self.row}, {self.col})"
        if corner is not None:
            where = (f"crop pixel ({self.row}, {self.col}) = frame pixel "
                     f"({corner[0] + self.row}, {corner[1] + self.col})")
        return (f"{self.count} of {self.total} words differ; first at readout {self.readout}, {where}: "
                f"RTL word {self.rtl}, golden word {self.golden}")


def first_difference(rtl, golden) -> Difference | None:
    """``None`` if the (K, H, W) word arrays are equal, else the first difference; arrays that are
    not two integer (K, H, W) arrays of one shape are refused in one line (numpy's broadcast or
    unpacking error before)."""
    rtl, golden = np.asarray(rtl), np.asarray(golden)
    for array, what in ((rtl, "RTL"), (golden, "golden")):
        if array.ndim != 3 or array.dtype.kind not in "iu":
            raise InputError(f"{what} words: must be an integer (K, H, W) array, not {array.dtype} {array.shape}")
    if rtl.shape != golden.shape:
        raise InputError(f"RTL words {rtl.shape} and golden words {golden.shape} differ in shape")
    differ = rtl != golden
    count = int(np.count_nonzero(differ))
    if count == 0:
        return None
    k, r, c = (int(i) for i in np.argwhere(differ)[0])
    return Difference(count, int(golden.size), k, r, c, int(rtl[k, r, c]), int(golden[k, r, c]))
