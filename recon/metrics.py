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

from golden.errors import InputError

MU = 5000
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


def _frames(x, name: str, device) -> torch.Tensor:
    t = torch.as_tensor(np.asarray(x) if not isinstance(x, torch.Tensor) else x)
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


def _pair(pred, gt, device) -> tuple[torch.Tensor, torch.Tensor, bool]:
    single = np.ndim(pred) == 2 if not isinstance(pred, torch.Tensor) else pred.dim() == 2
    p, g = _frames(pred, "prediction", device), _frames(gt, "ground truth", device)
    if p.shape != g.shape:
        raise InputError(f"prediction shape {tuple(p.shape)} != ground truth shape {tuple(g.shape)}")
    if g.numel() and float(g.min()) < 0:
        raise InputError(f"ground truth holds a negative light value ({float(g.min())})")
    return p, g, single


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
        if not (isinstance(peak, (int, float)) and math.isfinite(peak) and peak > 0):
            raise InputError(f"peak = {peak!r}: must be a finite number > 0")
        if gt.numel() and float(gt.max()) > peak:
            raise InputError(f"peak = {peak!r} is below the ground truth's maximum {float(gt.max())!r}: "
                             "the ground truth would be clipped")
        scale = torch.tensor(float(peak), dtype=torch.float64, device=gt.device)
    return (pred / scale).clamp(0, 1), (gt / scale).clamp(0, 1)


def mu_law(h: torch.Tensor, mu: float = MU) -> torch.Tensor:
    """Tone map T(H) = log(1 + mu H) / log(1 + mu) (paper eq. 11), H in [0, 1]."""
    return torch.log1p(mu * h) / math.log1p(mu)


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
    """SSIM of every window centre at least the filter radius from the border: (K, H - 2r, W - 2r)
    (:func:`ssim` is its mean; tiles of a large frame sum their share of it)."""
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


def psnr_mu(pred, gt, *, mu: float = MU, peak=None, device="cpu") -> np.ndarray:
    """PSNR-mu per frame (dB): normalise by the GT peak, clip, mu-law, PSNR with range 1."""
    p, g, single = _pair(pred, gt, device)
    p, g = normalise(p, g, peak)
    return _out(psnr(mu_law(p, mu), mu_law(g, mu)), single)


def ssim_mu(pred, gt, *, mu: float = MU, peak=None, device="cpu") -> np.ndarray:
    """SSIM-mu per frame: normalise by the GT peak, clip, mu-law, Gaussian SSIM with range 1."""
    p, g, single = _pair(pred, gt, device)
    p, g = normalise(p, g, peak)
    return _out(ssim(mu_law(p, mu), mu_law(g, mu)), single)


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
    if not (isinstance(nits_per_unit, (int, float)) and math.isfinite(nits_per_unit) and nits_per_unit > 0):
        raise InputError(f"nits_per_unit = {nits_per_unit!r}: must be a finite number > 0")
    p, g, single = _pair(pred, gt, device)
    return _out(psnr(pu21_encode(p * nits_per_unit), pu21_encode(g * nits_per_unit), PU21_PEAK), single)


#: name -> per-frame metric function (higher is better for all).
METRICS = {"psnr_mu": psnr_mu, "ssim_mu": ssim_mu, "psnr_pu21": psnr_pu21}
