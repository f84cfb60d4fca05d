"""Colour to light: grayscale conversion and per-sequence normalisation (paper A.2.2).

The paper converts every frame "to grayscale to simulate external light
intensity" without naming the weights, then divides a whole sequence by its
largest pixel so that the brightest pixel is 1.0, the brightest light the
sensor is designed for (SPEC section 6: I = 1 is 42000 electrons per readout).
We use Rec. 709 / sRGB luminance weights by default (the primaries of the HDR
panoramas and of most linear HDR video); Rec. 601 weights (what OpenCV's
``cvtColor(..., COLOR_BGR2GRAY)`` uses) are available by name.
"""

from __future__ import annotations

import numpy as np

from tespike.golden.errors import InputError, is_positive_number

#: Linear-light luminance weights (R, G, B) by name.
LUMA_WEIGHTS = {
    "rec709": (0.2126, 0.7152, 0.0722),
    "rec601": (0.299, 0.587, 0.114),
}
DEFAULT_WEIGHTS = "rec709"
#: Deepest negative value, as a share of an image's peak, that :func:`to_gray` clips at 0
#: (a lossy HDR file's dip below zero); a deeper one is refused.
NEGATIVE_SHARE = 0.01


def check_weights(weights) -> str:
    """``weights``, a name of :data:`LUMA_WEIGHTS`, refused in one line otherwise."""
    if not (isinstance(weights, str) and weights in LUMA_WEIGHTS):
        raise InputError(f"unknown grayscale weights {weights!r} (known: {', '.join(LUMA_WEIGHTS)})")
    return weights


def to_gray(image: np.ndarray, weights: str = DEFAULT_WEIGHTS, *, what: str = "image") -> np.ndarray:
    """Linear RGB ``(..., H, W, 3)`` or gray ``(..., H, W)`` -> float64 luminance ``(..., H, W)``.

    Negative values (a few pixels of lossy-compressed HDR files dip just below
    zero) are clipped at 0 *before* mixing, down to :data:`NEGATIVE_SHARE` of the
    image's peak; deeper ones, and non-finite values, are refused (that is not
    light). A trailing axis of 3 is read as RGB, one of 1 as gray.
    """
    check_weights(weights)
    image = np.asarray(image)
    if image.dtype.kind not in "fiu":
        raise InputError(f"{what}: dtype {image.dtype} is not numeric")
    image = image.astype(np.float64, copy=False)
    if image.size and not np.isfinite(image).all():
        raise InputError(f"{what}: holds non-finite values (NaN or infinity)")
    if image.size and image.min() < -NEGATIVE_SHARE * max(float(image.max()), 0.0):
        raise InputError(f"{what}: holds negative values down to {float(image.min()):.4g}, beyond "
                         f"{NEGATIVE_SHARE:g} of its peak {max(float(image.max()), 0.0):.4g}: not light")
    if image.ndim >= 3 and image.shape[-1] == 3:
        rgb = np.maximum(image, 0.0)
        return rgb @ np.asarray(LUMA_WEIGHTS[weights], np.float64)
    if image.ndim >= 3 and image.shape[-1] == 1:
        return np.maximum(image[..., 0], 0.0)
    if image.ndim >= 2:
        return np.maximum(image, 0.0)
    raise InputError(f"{what}: shape {image.shape} is not an image (H, W) or (H, W, 3)")


def normalise_sequence(frames: np.ndarray, peak: float = 1.0, *, what: str = "sequence") -> np.ndarray:
    """Divide a whole ``(K, H, W)`` sequence by its largest value, times ``peak``.

    One factor for the whole sequence (not per frame), as the paper does, so
    that brightness changes between frames survive. ``peak = 1`` makes the
    brightest pixel the design light. An all-zero sequence cannot be
    normalised and is refused. Returns float32.
    """
    frames = np.asarray(frames, dtype=np.float64)
    if not is_positive_number(peak):
        raise InputError(f"{what}: peak = {peak!r} must be a finite number > 0")
    f32 = np.finfo(np.float32)
    if not float(f32.tiny) <= peak <= float(f32.max):     # the sequence is stored as float32
        raise InputError(f"{what}: peak = {peak!r} is outside float32's normal range "
                         f"{float(f32.tiny):.3g}..{float(f32.max):.3g} (it would become "
                         f"{'infinity' if peak > 1 else 'zero'})")
    if frames.size == 0:
        raise InputError(f"{what}: is empty (shape {frames.shape})")
    if not np.isfinite(frames).all():
        raise InputError(f"{what}: holds non-finite values (NaN or infinity)")
    if frames.min() < 0:
        raise InputError(f"{what}: holds negative light ({frames.min()}); clip or fix it first")
    top = float(frames.max())
    if top <= 0:
        raise InputError(f"{what}: every pixel is 0, so it cannot be normalised by its maximum")
    out = frames * (peak / top)
    darkest = float(np.min(out, where=out > 0, initial=np.inf))    # (no copy of the lit values)
    if darkest < float(f32.tiny):                         # float32 would round it to a subnormal or 0
        raise InputError(f"{what}: peak = {peak!r} puts its darkest lit value at {darkest:.3g}, below "
                         f"float32's normal range (from {float(f32.tiny):.3g}: it would lose precision or become "
                         f"zero); give a peak of at least {peak * float(f32.tiny) / darkest:.3g}")
    return out.astype(np.float32)
