"""The learned methods' cost beside the paper's Table 10: parameters and FLOPs of one frame.

FLOPs are counted by ``torch.utils.flop_counter`` on the meta device (no
arithmetic is done, so a 384 x 512 frame costs nothing to count):
convolutions, matrix products and einsums, 2 per multiply-add; neither
``grid_sample`` nor elementwise work (as ``benchmarks/bench_baselines.py``).
Should a module not trace on the meta device, it is counted on a real
96 x 128 frame and scaled by the pixel ratio (every layer's cost is
proportional to the pixel count).

The paper's Table 10 (appendix A.2.6: an Intel i7 and an RTX 3090 GPU, frame
size not stated; the TE version of each method) is :data:`PAPER_TABLE10`.
"""

from __future__ import annotations

import dataclasses

import torch

from .baselines import PAPER_PARAMETERS
from .learning.layers import parameter_count

#: Frame the FLOPs are counted on (the project's benchmark frame; Table 10 states none).
FLOP_HEIGHT, FLOP_WIDTH = 384, 512
#: Frame counted on instead (then scaled) by a module the meta device cannot run.
SMALL_HEIGHT, SMALL_WIDTH = 96, 128


@dataclasses.dataclass(frozen=True)
class PaperCost:
    """One row of the paper's Table 10."""

    parameters: float        # count
    flops: float             # FLOPs per frame, as printed (counting convention not stated)
    seconds: float           # testing time per image, GPU


#: Method -> the paper's Table 10 row. The baselines' parameters are
#: :data:`tespike.recon.baselines.PAPER_PARAMETERS` (typed beside the models they size; the
#: baselines cannot import this module, which reaches them through :func:`measure`).
PAPER_TABLE10 = {
    "spk2imgnet": PaperCost(PAPER_PARAMETERS["spk2imgnet"], 1.955e12, 0.418),
    "bsf": PaperCost(PAPER_PARAMETERS["bsf"], 0.887e12, 0.231),
    "mambaspike": PaperCost(PAPER_PARAMETERS["mambaspike"], 1.919e12, 0.004),
    "net": PaperCost(6_479_000, 3.711e12, 0.005),
}


def paper_table10() -> dict[str, PaperCost]:
    """Method -> the paper's Table 10 row: a copy of :data:`PAPER_TABLE10`."""
    return dict(PAPER_TABLE10)


def flops_per_frame(model: torch.nn.Module, height: int = FLOP_HEIGHT, width: int = FLOP_WIDTH) -> int:
    """FLOPs of one (height x width) output frame of a learned module (its span of readouts in)."""
    import copy

    from torch.utils.flop_counter import FlopCounterMode
    span = model.sizes.span
    counter = FlopCounterMode(display=False)
    try:
        meta = copy.deepcopy(model).to("meta")
        with torch.no_grad(), counter:
            meta(torch.empty(1, span, height, width, device="meta"), None, 1.0)   # any one-spike light
        return int(counter.get_total_flops())
    except (NotImplementedError, RuntimeError):
        counter = FlopCounterMode(display=False)
        with torch.no_grad(), counter:
            model(torch.rand(1, span, SMALL_HEIGHT, SMALL_WIDTH), None, 1.0)
        return int(round(counter.get_total_flops() * height * width / (SMALL_HEIGHT * SMALL_WIDTH)))


def measure(methods, config) -> dict[str, dict]:
    """Method -> {"parameters", "flops"} of each learned method of ``methods`` that has shipped
    weights for ``config`` (the sizes of those weights; FLOPs of one 384 x 512 frame)."""
    from .methods import RECON_METHODS, missing_weights
    from .learned import load_learned
    out = {}
    for method in methods:
        if RECON_METHODS[method].frames is None or missing_weights(method, config) is not None:
            continue
        model = load_learned(config, method)
        out[method] = {"parameters": parameter_count(model), "flops": flops_per_frame(model)}
    return out
