"""Every metric of the project on one reconstruction: per frame, mean, and the sequence values.

:func:`score` is what ``tespike score`` prints and what a results table calls:

```python
from tespike.recon.score import score, columns
result = score(R, I)                    # (K, H, W) light, scene units
result.mean["psnr_mu"], result.per_frame["hdr_vqm"], result.sequence["hdr_vqm"]
```

Conventions of each column (normalisation, display, units) are in
docs/metrics.md; the columns' labels say what they are.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tespike.golden.errors import InputError
from tespike.recon.display import DEFAULT_DISPLAY, HdrDisplay, check_display
from tespike.recon.settings import check_device, names


@dataclass(frozen=True)
class Column:
    """One metric column: its key, the label a table prints, and which way is better."""

    key: str
    label: str
    higher_is_better: bool


#: The metrics' keys, in table order (importing this module does not import torch).
METRIC_KEYS = ("psnr_mu", "ssim_mu", "psnr_pu21", "hdr_vqm", "fovvideovdp")


def check_metrics(names: tuple, what: str) -> tuple:
    """``names``, each one of :data:`METRIC_KEYS` and each once; else one line naming ``what`` (the
    flag and its text, or the argument) and the first name at fault. The one check of metric names."""
    unknown = [m for m in names if m not in METRIC_KEYS]
    if unknown or not names:
        raise InputError(f"{what}: " + (f"{unknown[0]!r} is no metric" if unknown else "names no metric")
                         + f" (choose from {', '.join(METRIC_KEYS)})")
    twice = [m for m in names if names.count(m) > 1]
    if twice:                           # (one column was made of both)
        raise InputError(f"{what}: {twice[0]!r} is named more than once")
    return tuple(names)


def columns(display: HdrDisplay = DEFAULT_DISPLAY) -> tuple[Column, ...]:
    """The columns (in :data:`METRIC_KEYS` order) with their labels for ``display``."""
    check_display(display)
    from tespike.recon.metrics import DEFAULT_NITS_PER_UNIT
    from tespike.recon.mulaw import MU
    shown = f"HDR display {display.peak_nits:g} cd/m^2"
    return (
        Column("psnr_mu", f"PSNR-mu (dB, mu={MU:g})", True),
        Column("ssim_mu", f"SSIM-mu (mu={MU:g})", True),
        Column("psnr_pu21", f"PU21-PSNR (dB, I=1 at {DEFAULT_NITS_PER_UNIT:g} cd/m^2)", True),
        Column("hdr_vqm", f"HDR-VQM ({shown}, lower is better)", False),
        Column("fovvideovdp", f"FovVideoVDP (JOD, {shown})", True),
    )


@dataclass
class Scores:
    """Per-frame values (K,) and their means for each metric; sequence values where a metric has one."""

    columns: tuple[Column, ...]
    per_frame: dict[str, np.ndarray]
    mean: dict[str, float]
    sequence: dict[str, float] = field(default_factory=dict)


def score(estimate, reference, *, metrics=None, display: HdrDisplay = DEFAULT_DISPLAY,
          device="cpu") -> Scores:
    """Score (K, H, W) estimated light against the reference (scene units) with ``metrics`` (default all).

    PSNR-mu and SSIM-mu normalise each frame by the reference frame's peak (the
    project's convention); HDR-VQM and FovVideoVDP show the sequence on
    ``display`` with the reference's peak over these frames at its peak.
    """
    from tespike.recon.fovvideovdp import fovvideovdp
    from tespike.recon.hdrvqm import hdr_vqm_scores
    from tespike.recon.metrics import psnr_mu, psnr_pu21, ssim_mu

    metrics = None if metrics is None else names(metrics, "metrics")
    keys = METRIC_KEYS if metrics is None else check_metrics(metrics, f"metrics {list(metrics)!r}")
    check_display(display)
    check_device(device)
    estimate, reference = np.asarray(estimate), np.asarray(reference)
    if reference.ndim != 3 or estimate.ndim != 3:
        raise InputError(f"estimate {estimate.shape} and reference {reference.shape} must be (K, H, W)")
    if estimate.shape != reference.shape:
        raise InputError(f"estimate shape {estimate.shape} != reference shape {reference.shape}")
    if not reference.size:                   # (the means had been NaN, with numpy's empty-slice warning)
        raise InputError(f"estimate and reference {reference.shape} hold no pixel to score")
    for array, what in ((reference, "reference"), (estimate, "estimate")):
        if array.dtype.kind not in "fiu":
            raise InputError(f"the {what}: dtype {array.dtype} is not real numbers")
    if not np.isfinite(reference).all():
        raise InputError("the reference holds non-finite values (NaN or infinity): it is no light")
    if float(np.min(reference)) < 0:
        raise InputError(f"the reference holds negative light (down to {float(np.min(reference)):.6g}): it "
                         "is no light")
    if not float(np.max(reference)) > 0:
        raise InputError("the reference is all zero: no metric can normalise by its peak")
    per_frame, sequence = {}, {}
    for key in keys:
        if key == "psnr_mu":
            per_frame[key] = psnr_mu(estimate, reference, device=device)
        elif key == "ssim_mu":
            per_frame[key] = ssim_mu(estimate, reference, device=device)
        elif key == "psnr_pu21":
            per_frame[key] = psnr_pu21(estimate, reference, device=device)
        elif key == "hdr_vqm":
            per_frame[key], sequence[key] = hdr_vqm_scores(estimate, reference, display=display, device=device)
        elif key == "fovvideovdp":
            per_frame[key] = fovvideovdp(estimate, reference, display=display, device=device)
    chosen = tuple(c for c in columns(display) if c.key in keys)
    mean = {k: float(np.mean(v)) for k, v in per_frame.items()}
    return Scores(chosen, per_frame, mean, sequence)
