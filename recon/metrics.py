"""HDR image metrics in torch, batched over frames: PSNR-mu, SSIM-mu (paper A.2.3), PU21-PSNR.

mu-law metrics (the paper's PSNR-mu and SSIM-mu, mu = 5000):

1. both images are divided by the ground truth's peak ``peak`` (by default
   the maximum of each ground-truth frame; pass a number, e.g. the peak of a
   whole sequence as the paper's A.2.2 normalises, to use one scale). The
   prediction is never min-max normalised: a prediction that is too bright or
   too dark stays so;
2. both are clipped to [0, 1]: the ground truth is in [0, 1] by construction;
   clipping the prediction above the ground-truth peak (and below 0) is the
   common choice (a value above the peak has no tone-mapped meaning);
3. tone-mapped with T(H) = log(1 + mu H) / log(1 + mu);
4. PSNR with data range 1; SSIM with a Gaussian window (sigma 1.5, truncated
   at 3.5 sigma: 11 x 11), population covariance, K1 = 0.01, K2 = 0.03, data
   range 1, averaged over the pixels at least 5 from the border, exactly as
   scikit-image's ``structural_similarity(gaussian_weights=True, sigma=1.5,
   use_sample_covariance=False, data_range=1)``.

PU21-PSNR (absolute luminance, Mantiuk & Azimi 2021, 'banding_glare'): scene
light is scaled to cd/m^2 by ``nits_per_unit`` (default 4000: I = 1 is 4000
cd/m^2, a bright outdoor surface; documented in docs/metrics.md), clamped to
PU21's [0.005, 10000] cd/m^2, encoded, and compared with PSNR of peak 256 (the
PU21 code of 100 cd/m^2 is about 256, chosen by its authors to mimic 8-bit SDR).

Every function takes (K, H, W) or (H, W) numpy arrays or tensors and returns a
float64 numpy array of K per-frame values (a 0-d array for one frame).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from tespike.golden.errors import InputError, is_positive_number

from .mulaw import MU, compress
from .settings import check_device

SSIM_SIGMA = 1.5
SSIM_TRUNCATE = 3.5
SSIM_K1, SSIM_K2 = 0.01, 0.03

#: PU21 'banding_glare' parameters (Mantiuk & Azimi 2021, updated 06/02/2020).
PU21_BANDING_GLARE = (0.353487901, 0.3734658629, 8.277049286e-05, 0.9062562627,
                      0.09150303166, 0.9099517204, 596.3148142)
PU21_L_MIN, PU21_L_MAX = 0.005, 10000.0
PU21_PEAK = 256.0
#: cd/m^2 of scene light I = 1 (the sensor's design light) for PU21 metrics.
DEFAULT_NITS_PER_UNIT = 4000.0


def as_frames(x, name: str, device) -> torch.Tensor:
    """A (K, H, W) or (H, W) array or tensor as a float64 tensor on ``device``; ``name`` in refusals."""
    if not isinstance(x, torch.Tensor):
        x = np.asarray(x)
        if x.dtype.kind not in "iuf":      # (objects, strings, bools, complex: torch's TypeError or no error)
            raise InputError(f"{name} dtype {x.dtype} is not a real number type")
        if x.dtype.kind == "f" and x.dtype.itemsize > 8:   # long double: torch has no such type
            x = x.astype(np.float64)
        elif not x.dtype.isnative:         # torch takes native byte order only (big-endian .npy files)
            x = x.astype(x.dtype.newbyteorder("="))
        elif not x.flags.writeable:        # a read-only memory map: copy the (small) band
            x = x.copy()
    t = torch.as_tensor(x).detach()                     # (one that requires grad: numpy() had refused it)
    if t.dtype.is_complex or t.dtype == torch.bool:
        raise InputError(f"{name} dtype {t.dtype} is not a real number type")
    t = t.to(device=device, dtype=torch.float64)
    if t.dim() == 2:
        t = t[None]
    if t.dim() != 3:
        raise InputError(f"{name} shape {tuple(t.shape)} must be (K, H, W) or (H, W)")
    if t.numel() and not bool(torch.isfinite(t).all()):
        raise InputError(f"{name} holds a non-finite value")
    return t


def _out(values: torch.Tensor, single: bool) -> np.ndarray:
    values = values.cpu().numpy().astype(np.float64)
    return values.reshape(()) if single else values


def normalise(pred: torch.Tensor, gt: torch.Tensor, peak=None) -> tuple[torch.Tensor, torch.Tensor]:
    """Divide both by the ground truth's peak (per frame, or the given number); clip to [0, 1]."""
    if peak is None:
        scale = gt.amax(dim=(1, 2), keepdim=True)
        if bool((scale <= 0).any()):
            frame = int(torch.nonzero(scale.flatten() <= 0)[0])
            raise InputError(f"ground-truth frame {frame} is all zero: its peak cannot normalise "
                             "(pass peak= explicitly)")
    else:
        check_peak(peak)
        if gt.numel() and float(gt.max()) > peak:
            raise InputError(f"peak = {peak!r} is below the ground truth's maximum {float(gt.max())!r}: "
                             "the ground truth would be clipped")
        scale = torch.tensor(float(peak), dtype=torch.float64, device=gt.device)
    return (pred / scale).clamp(0, 1), (gt / scale).clamp(0, 1)


def mu_law(h: torch.Tensor, mu: float = MU) -> torch.Tensor:
    """Tone map T(H) = log(1 + mu H) / log(1 + mu) (paper eq. 11), H in [0, 1]: the learned
    methods' own mu-law (:func:`tespike.recon.mulaw.compress`), with the paper's mu by default."""
    return compress(h, mu)


def psnr(x: torch.Tensor, y: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Per-frame PSNR of (K, H, W) float64 tensors; inf for identical frames."""
    mse = ((x - y) ** 2).mean(dim=(1, 2))
    return 10 * torch.log10(data_range ** 2 / mse)


def _gaussian_kernel(sigma: float, truncate: float, device) -> torch.Tensor:
    radius = int(truncate * sigma + 0.5)
    x = torch.arange(-radius, radius + 1, dtype=torch.float64, device=device)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def ssim(x: torch.Tensor, y: torch.Tensor, data_range: float = 1.0, sigma: float = SSIM_SIGMA,
         truncate: float = SSIM_TRUNCATE) -> torch.Tensor:
    """Per-frame mean SSIM of (K, H, W) float64 tensors (scikit-image's Gaussian variant).

    scikit-image filters with 'reflect' padding and then drops the border of
    the filter radius; the pixels it keeps see no padding, so a valid
    (unpadded) separable convolution gives the same numbers.
    """
    return ssim_map(x, y, data_range, sigma, truncate).mean(dim=(1, 2))


def ssim_map(x: torch.Tensor, y: torch.Tensor, data_range: float = 1.0, sigma: float = SSIM_SIGMA,
             truncate: float = SSIM_TRUNCATE) -> torch.Tensor:
    """SSIM of every valid pixel (K, H - 2r, W - 2r) of (K, H, W) float64 tensors (r = window radius)."""
    kernel = _gaussian_kernel(sigma, truncate, x.device)
    win = kernel.numel()
    K, H, W = x.shape
    if H < win or W < win:
        raise InputError(f"SSIM needs frames of at least {win} x {win} pixels, got {H} x {W}")
    kh = kernel.view(1, 1, win, 1)
    kw = kernel.view(1, 1, 1, win)

    def filt(img):
        return torch.nn.functional.conv2d(torch.nn.functional.conv2d(img, kh), kw)

    stack = torch.cat([x, y, x * x, y * y, x * y])[:, None]       # (5K, 1, H, W)
    ux, uy, uxx, uyy, uxy = filt(stack)[:, 0].split(K)
    vx, vy, vxy = uxx - ux * ux, uyy - uy * uy, uxy - ux * uy
    c1, c2 = (SSIM_K1 * data_range) ** 2, (SSIM_K2 * data_range) ** 2
    return ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux ** 2 + uy ** 2 + c1) * (vx + vy + c2))


#: Pixels (frames x rows x columns) one band of a metric converts to float64 at once:
#: the metrics run frame by frame and row band by row band, so their memory is
#: bounded whatever the size of the sequence or of one frame.
CHUNK_PIXELS = 1 << 20


def _shape(x) -> tuple[int, ...]:
    return tuple(x.shape) if isinstance(x, torch.Tensor) else np.shape(x)


def _arrays(*xs):
    """Each of ``xs`` as it is where it is a numpy array (memory maps kept) or a tensor, else as a
    numpy array (nested lists of numbers, as a library caller may pass them)."""
    out = []
    for x in xs:
        if not isinstance(x, (np.ndarray, torch.Tensor)):
            try:
                x = np.asarray(x)
            except ValueError:                           # (a ragged list: numpy's "inhomogeneous shape")
                raise InputError("light given as a list must be numbers arranged as (K, H, W) or (H, W) "
                                 "frames, every row the same length") from None
        out.append(x)
    return tuple(out)


def frame_stacks(estimate, reference, metric: str):
    """(estimate, reference, single, (K, H, W)): (H, W) frames lifted to one-frame stacks, the
    shapes checked equal and three-dimensional; ``single`` says a lone frame was given."""
    estimate, reference = _arrays(estimate, reference)
    eshape, rshape = _shape(estimate), _shape(reference)
    single = len(rshape) == 2
    if single:
        estimate, reference = estimate[None], reference[None]
        eshape, rshape = _shape(estimate), _shape(reference)
    if len(rshape) != 3 or len(eshape) != 3:
        raise InputError(f"{metric} needs (K, H, W) or (H, W) frames, got {eshape} and {rshape}")
    if eshape != rshape:
        raise InputError(f"estimate shape {eshape} != reference shape {rshape}")
    return estimate, reference, single, rshape


def check_peak(peak) -> None:
    """Refuse a given ``peak`` (the light a metric takes as the top of its range) unless a finite number > 0."""
    if not is_positive_number(peak):
        raise InputError(f"peak = {peak!r}: must be a finite number > 0")


def check_mu(mu) -> None:
    """Refuse a mu-law constant (paper eq. 11) unless a finite number > 0 (``log1p(mu)`` divides)."""
    if not is_positive_number(mu):
        raise InputError(f"mu = {mu!r}: the mu-law constant must be a finite number > 0")


def display_peak(reference, peak, K: int, H: int, W: int, device) -> float:
    """The reference light a display metric (HDR-VQM, FovVideoVDP) shows at the display's peak:
    ``peak`` when given, else the reference's maximum over all its K frames (refused if all zero)."""
    if peak is None:
        peak = float(frame_peaks(reference, K, H, W, device).max())
        if peak <= 0:
            raise InputError("the reference is all zero: it has no peak to show on the display")
    else:
        check_peak(peak)
    return peak


def frame_peaks(gt, K: int, H: int, W: int, device) -> torch.Tensor:
    """Per-frame maximum of the ground truth, computed band by band."""
    peaks = torch.empty(K, dtype=torch.float64, device=device)
    for k in range(K):
        rows = max(1, CHUNK_PIXELS // max(1, W))
        top = -math.inf
        for r in range(0, H, rows):
            band = as_frames(gt[k:k + 1, r:r + rows], "ground truth", device)
            if band.numel():
                if float(band.min()) < 0:
                    raise InputError(f"ground truth holds a negative light value ({float(band.min())})")
                top = max(top, float(band.max()))
        peaks[k] = top
    return peaks


def _banded(pred, gt, stat, *, halo: int = 0, peak=None, normalised: bool = True,
            device="cpu") -> np.ndarray:
    """Per-frame mean of ``stat(p, g)`` over the valid pixels, band by band.

    ``pred`` and ``gt`` are (K, H, W) or (H, W) numpy arrays (memory maps welcome)
    or tensors; each band of at most :data:`CHUNK_PIXELS` output pixels is
    converted to float64, checked, normalised by the peak (when ``normalised``)
    and passed to ``stat``, which returns the per-pixel values of the band's
    valid region (its input carries ``halo`` extra rows on each side).
    """
    check_device(device)
    pred, gt = _arrays(pred, gt)
    pshape, gshape = _shape(pred), _shape(gt)
    if len(pshape) != len(gshape):                      # (a stack beside one frame had been paired)
        raise InputError(f"prediction shape {pshape} and ground truth shape {gshape}: both (K, H, W) "
                         "or both (H, W)")
    single = len(pshape) == 2
    if len(pshape) == 2:
        pred = pred[None]
    if len(gshape) == 2:
        gt = gt[None]
    pshape, gshape = _shape(pred), _shape(gt)
    for name, shape in (("prediction", pshape), ("ground truth", gshape)):
        if len(shape) != 3:
            raise InputError(f"{name} shape {shape if not single else shape[1:]} must be (K, H, W) or (H, W)")
    if pshape != gshape:
        raise InputError(f"prediction shape {pshape} != ground truth shape {gshape}")
    if 0 in gshape:                                      # (range()'s "arg 3 must not be zero")
        raise InputError(f"frames of shape {gshape} hold no pixel to score")
    K, H, W = gshape
    if normalised:
        if peak is None:
            scales = frame_peaks(gt, K, H, W, device)
            if K and bool((scales <= 0).any()):
                frame = int(torch.nonzero(scales <= 0)[0])
                raise InputError(f"ground-truth frame {frame} is all zero: its peak cannot normalise "
                                 "(pass peak= explicitly)")
        else:
            check_peak(peak)
            scales = torch.full((K,), float(peak), dtype=torch.float64, device=device)
    out_rows = H - 2 * halo
    frames_per = max(1, CHUNK_PIXELS // max(1, out_rows * W))
    rows_per = out_rows if frames_per > 1 else max(1, CHUNK_PIXELS // max(1, W))
    sums = torch.zeros(K, dtype=torch.float64, device=device)
    count = 0
    for k0 in range(0, K, frames_per):
        k1 = min(K, k0 + frames_per)
        for r0 in range(0, max(out_rows, 0), rows_per):
            r1 = min(out_rows, r0 + rows_per)
            p = as_frames(pred[k0:k1, r0:r1 + 2 * halo], "prediction", device)
            g = as_frames(gt[k0:k1, r0:r1 + 2 * halo], "ground truth", device)
            if g.numel() and float(g.min()) < 0:
                raise InputError(f"ground truth holds a negative light value ({float(g.min())})")
            if normalised:
                if peak is not None and g.numel() and float(g.max()) > peak:
                    raise InputError(f"peak = {peak!r} is below the ground truth's maximum "
                                     f"{float(g.max())!r}: the ground truth would be clipped")
                scale = scales[k0:k1].view(-1, 1, 1)
                p, g = (p / scale).clamp(0, 1), (g / scale).clamp(0, 1)
            values = stat(p, g)
            sums[k0:k1] += values.sum(dim=(1, 2))
            if k0 == 0:
                count += values.shape[1] * values.shape[2]
    return _out(sums / count if count else sums * math.nan, single)


def ssim_window() -> int:
    """Side of SSIM's Gaussian window in pixels (11: sigma 1.5 truncated at 3.5 sigma)."""
    return _gaussian_kernel(SSIM_SIGMA, SSIM_TRUNCATE, "cpu").numel()


def check_ssim_frames(shape) -> None:
    """Refuse frames (shape (..., H, W)) smaller than SSIM's window, in one line."""
    win = ssim_window()
    if len(shape) in (2, 3) and (shape[-2] < win or shape[-1] < win):
        raise InputError(f"SSIM needs frames of at least {win} x {win} pixels, got {shape[-2]} x {shape[-1]}")


def _ssim_stat(mu: float):
    def stat(p, g):
        return ssim_map(mu_law(p, mu), mu_law(g, mu))
    return stat


def psnr_mu(pred, gt, *, mu: float = MU, peak=None, device="cpu") -> np.ndarray:
    """PSNR-mu per frame (dB): normalise by the GT peak, clip, mu-law, PSNR with range 1."""
    check_mu(mu)
    mse = _banded(pred, gt, lambda p, g: (mu_law(p, mu) - mu_law(g, mu)) ** 2, peak=peak, device=device)
    with np.errstate(divide="ignore"):
        return 10 * np.log10(1.0 / mse)


def ssim_mu(pred, gt, *, mu: float = MU, peak=None, device="cpu") -> np.ndarray:
    """SSIM-mu per frame: normalise by the GT peak, clip, mu-law, Gaussian SSIM with range 1."""
    check_mu(mu)
    win = ssim_window()
    shape = _shape(gt)
    check_ssim_frames(shape)
    return _banded(pred, gt, _ssim_stat(mu), halo=win // 2, peak=peak, device=device)


def pu21_encode(luminance: torch.Tensor, params=PU21_BANDING_GLARE) -> torch.Tensor:
    """PU21 code of absolute luminance (cd/m^2), clamped to [0.005, 10000] cd/m^2 first."""
    p0, p1, p2, p3, p4, p5, p6 = params
    y = luminance.clamp(PU21_L_MIN, PU21_L_MAX)
    yp = y ** p3
    return (p6 * (((p0 + p1 * yp) / (1 + p2 * yp)) ** p4 - p5)).clamp(min=0)


def psnr_pu21(pred, gt, *, nits_per_unit: float = DEFAULT_NITS_PER_UNIT, device="cpu") -> np.ndarray:
    """PU21-PSNR per frame (dB) on absolute luminance: light x ``nits_per_unit`` cd/m^2.

    Negative predicted light is clamped with everything below PU21's 0.005
    cd/m^2 (it is darker than the encoding resolves).
    """
    if not is_positive_number(nits_per_unit):          # (True had been taken, numpy's float32 refused)
        raise InputError(f"nits_per_unit = {nits_per_unit!r}: must be a finite number > 0")
    mse = _banded(pred, gt, lambda p, g: (pu21_encode(p * nits_per_unit) - pu21_encode(g * nits_per_unit)) ** 2,
                  normalised=False, device=device)
    with np.errstate(divide="ignore"):
        return 10 * np.log10(PU21_PEAK ** 2 / mse)
