"""HDR-VQM (Narwaria, Perreira Da Silva and Le Callet, Signal Processing: Image Communication 35, 2015).

Written here from the paper and the steps of the authors' MIT-licensed MATLAB
reference (github.com/mperreir/HDR-VQM, version 2, July 2015), in torch
(float64, FFT filtering batched over frames and orientations; torch because the
project's other metrics and PU21 encoder are torch, and its FFT runs on any
device). Lower is better; 0 for identical inputs.

1. **Display**: both sequences are shown on :class:`tespike.recon.display.HdrDisplay`
   (the reference's peak at the display's peak, clipped to [black, peak]).
2. **Perceived luminance**: PU21 ('banding_glare') of the emitted luminance.
3. **Subband errors**: log-Gabor filters, 5 scales (wavelengths 3, 9, 27, 81,
   243 pixels) x 4 orientations (0, 45, 90, 135 degrees), radial bandwidth
   sigma_on_f = 0.55, angular sigma = pi / 4 / 1.5 (Kovesi's filter bank as the
   reference builds it, circular FFT filtering). Per subband the magnitudes
   a (reference), b (estimate) give the similarity (2ab + C) / (a^2 + b^2 + C),
   C = 0.2; the error frame is the sum over the 20 subbands (20 where identical).
4. **Short-term tubes**: non-overlapping 64 x 64 pixel blocks over
   ``fixation_frames`` frames (0.6 s at 25 frames/s = 15); each tube's value is
   the sample standard deviation of the error frame inside it.
5. **Pooling**: the mean of the lowest 30 % of the tubes of each fixation,
   then the mean of the lowest 30 % of the fixations (the reference's ``st_pool``,
   1 + round((n - 1) p) values).

Per frame (:func:`hdr_vqm`) is the same with one-frame tubes (step 5's spatial
pooling of each frame). Differences from the reference, and why:

- PU21 replaces the 2008 PU encoding (Aydin et al.), whose look-up table the
  reference loads from a data file; PU21 is its authors' successor and is the
  project's one PU encoder. Both put about 100 cd/m^2 near code 256, so the
  constant C = 0.2 keeps its scale.
- frames are filtered at their own resolution: the reference resizes every frame
  to 512 x 896 (a 1080p SIM2 frame) before filtering; here one frame pixel is one
  pixel of that working grid (so the wavelengths and the 64-pixel block keep
  their meaning), and a frame is not stretched to 16:9;
- blocks at the right and bottom edges that do not fill 64 x 64 keep their own
  pixels (the reference pads the error frame with zeros, which would turn
  "identical" into an error at any other size);
- the display scale comes from the reference alone (the reference scales each
  sequence by its own robust maximum, which forgives a global gain error);
- every full fixation is pooled (the reference's loop leaves the last one out
  when the frame count is a multiple of 15); a sequence shorter than one
  fixation is one tube of all its frames.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from tespike.golden.errors import InputError
from tespike.golden.resources import require_memory
from tespike.recon.display import DEFAULT_DISPLAY, HdrDisplay, check_display
from tespike.recon.settings import check_device
from tespike.recon.metrics import as_frames, display_peak, frame_stacks, pu21_encode

N_SCALES = 5
N_ORIENTATIONS = 4
MIN_WAVELENGTH = 3.0
SCALE_FACTOR = 3.0
SIGMA_ON_F = 0.55
D_THETA_ON_SIGMA = 1.5
SIMILARITY_C = 0.2
BLOCK = 64
#: Smallest frame side scored (a block of one pixel deviates by 0: a 1 x 1 estimate at 1 % of its
#: reference scored 0, "identical"; 4 x 4 is the size FovVideoVDP needs too).
MIN_SIDE = 4
FRAME_RATE = 25.0
FIXATION_S = 0.6
#: Frames of one short-term tube: ceil(25 frames/s x 0.6 s) = 15.
FIXATION_FRAMES = math.ceil(FRAME_RATE * FIXATION_S)
POOL_FRACTION = 0.3
#: Pixels filtered at once (whole frames, at least one: FFT filtering needs the whole frame).
FFT_PIXELS = 1 << 19
#: Memory per pixel of a frame: the filter bank (20 float64) and the per-frame buffers.
BYTES_PER_PIXEL = 20 * 8 + 64
#: Memory per pixel per frame filtered at once: two spectra, the products and magnitudes of one scale.
BYTES_PER_FFT_PIXEL = 2 * 16 + 4 * 16 * 3 + 4 * 8 * 4


def log_gabor_bank(height: int, width: int, device="cpu") -> torch.Tensor:
    """The (scales, orientations, H, W) log-Gabor transfer functions on the unshifted FFT grid."""
    fy = torch.fft.fftfreq(height, dtype=torch.float64, device=device)[:, None]
    fx = torch.fft.fftfreq(width, dtype=torch.float64, device=device)[None, :]
    # Kovesi normalises each axis by its own Nyquist: frequency 0.5 cycles/pixel is radius 1.
    x, y = fx / 0.5, fy / 0.5
    radius = torch.sqrt(x ** 2 + y ** 2)
    radius[0, 0] = 1.0                      # no log(0); the DC value is set to 0 below
    theta = torch.atan2(y.expand_as(radius), x.expand_as(radius))
    sin_t, cos_t = torch.sin(theta), torch.cos(theta)
    theta_sigma = math.pi / N_ORIENTATIONS / D_THETA_ON_SIGMA
    bank = torch.empty(N_SCALES, N_ORIENTATIONS, height, width, dtype=torch.float64, device=device)
    for o in range(N_ORIENTATIONS):
        angle = o * math.pi / N_ORIENTATIONS
        ds = sin_t * math.cos(angle) - cos_t * math.sin(angle)
        dc = cos_t * math.cos(angle) + sin_t * math.sin(angle)
        spread = torch.exp(-torch.atan2(ds, dc).abs() ** 2 / (2 * theta_sigma ** 2))
        for s in range(N_SCALES):
            rfo = (1.0 / (MIN_WAVELENGTH * SCALE_FACTOR ** s)) / 0.5
            radial = torch.exp(-torch.log(radius / rfo) ** 2 / (2 * math.log(SIGMA_ON_F) ** 2))
            radial[0, 0] = 0.0
            bank[s, o] = radial * spread
    return bank


def error_frames(estimate_pu: torch.Tensor, reference_pu: torch.Tensor, bank: torch.Tensor) -> torch.Tensor:
    """(K, H, W) error frames: the subband similarities summed over the bank (step 3)."""
    fe = torch.fft.fft2(estimate_pu)[:, None]
    fr = torch.fft.fft2(reference_pu)[:, None]
    total = torch.zeros_like(estimate_pu)
    for s in range(bank.shape[0]):                     # one scale at a time: bounded memory
        filt = bank[s][None]                           # (1, O, H, W)
        a = torch.fft.ifft2(fr * filt).abs()
        b = torch.fft.ifft2(fe * filt).abs()
        total += ((2 * a * b + SIMILARITY_C) / (a * a + b * b + SIMILARITY_C)).sum(dim=1)
    return total


def block_statistics(errors: torch.Tensor, block: int = BLOCK) -> tuple[torch.Tensor, ...]:
    """Pixel count, mean and sum of squared deviations (M2) of each block of each (F, H, W) frame.

    Returns three (F, blocks) tensors; blocks at the right and bottom edges that
    do not fill ``block`` pixels use the pixels they have.
    """
    F, H, W = errors.shape
    ny, nx = -(-H // block), -(-W // block)
    pad = (0, nx * block - W, 0, ny * block - H)
    e = torch.nn.functional.pad(errors, pad).reshape(F, ny, block, nx, block)
    m = torch.nn.functional.pad(torch.ones_like(errors), pad).reshape(F, ny, block, nx, block)
    n = m.sum(dim=(2, 4))
    mean = e.sum(dim=(2, 4)) / n
    m2 = (((e - mean[:, :, None, :, None]) * m) ** 2).sum(dim=(2, 4))
    return n.reshape(F, -1), mean.reshape(F, -1), m2.reshape(F, -1)


def combine_statistics(n: torch.Tensor, mean: torch.Tensor, m2: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Count, mean and M2 of the union of the frames (axis 0) of each block (Chan et al.'s pairwise rule)."""
    total = n.sum(dim=0)
    grand = (n * mean).sum(dim=0) / total
    return total, grand, m2.sum(dim=0) + (n * (mean - grand) ** 2).sum(dim=0)


def _deviation(n, mean, m2):
    return (m2 / (n - 1).clamp(min=1)).sqrt()


def lowest_mean(values: torch.Tensor, fraction: float = POOL_FRACTION) -> torch.Tensor:
    """Mean of the lowest 1 + round((n - 1) fraction) values along the last axis (the reference's st_pool)."""
    n = values.shape[-1]
    keep = 1 + int(math.floor((n - 1) * fraction + 0.5))
    return values.sort(dim=-1).values[..., :keep].mean(dim=-1)


def hdr_vqm_scores(estimate, reference, *, display: HdrDisplay = DEFAULT_DISPLAY, peak=None,
                   fixation_frames: int = FIXATION_FRAMES, device="cpu") -> tuple[np.ndarray, float]:
    """(per-frame HDR-VQM, sequence HDR-VQM) of (K, H, W) or (H, W) light in scene units.

    ``peak``: the reference light shown at the display's peak (default: the
    reference's maximum over all the frames given).
    """
    check_display(display)
    check_device(device)
    estimate, reference, single, rshape = frame_stacks(estimate, reference, "HDR-VQM")
    if not (isinstance(fixation_frames, int) and fixation_frames >= 1):
        raise InputError(f"fixation_frames = {fixation_frames!r}: must be an integer >= 1")
    K, H, W = rshape
    if K == 0 or H < MIN_SIDE or W < MIN_SIDE:         # (a 1 x 1 frame's deviation is 0 whatever it shows)
        raise InputError(f"HDR-VQM needs frames of at least {MIN_SIDE} x {MIN_SIDE} pixels (its errors are "
                         f"deviations over blocks of pixels), got shape {rshape}")
    peak = display_peak(reference, peak, K, H, W, device)
    per_fft = max(1, FFT_PIXELS // (H * W))
    require_memory(H * W * (BYTES_PER_PIXEL + BYTES_PER_FFT_PIXEL * per_fft),
                   f"HDR-VQM of {H} x {W} frames")
    bank = log_gabor_bank(H, W, device)
    per_frame = torch.empty(K, dtype=torch.float64, device=device)
    fixation = fixation_frames if K >= fixation_frames else K
    stats, tube_values = [], []                  # block statistics of the frames of the open fixation
    for f0 in range(0, K, per_fft):
        f1 = min(K, f0 + per_fft)
        r = as_frames(reference[f0:f1], "reference", device)
        if float(r.min()) < 0:
            raise InputError(f"reference holds a negative light value ({float(r.min())})")
        e = as_frames(estimate[f0:f1], "estimate", device)
        errors = error_frames(pu21_encode(display.luminance(e, peak)), pu21_encode(display.luminance(r, peak)),
                              bank)
        n, mean, m2 = block_statistics(errors)
        per_frame[f0:f1] = lowest_mean(_deviation(n, mean, m2))
        for i, k in enumerate(range(f0, f1)):
            stats.append((n[i], mean[i], m2[i]))
            if (k + 1) % fixation == 0:          # a full fixation: its tubes (a partial one makes none)
                tubes = combine_statistics(*(torch.stack(column) for column in zip(*stats)))
                tube_values.append(lowest_mean(_deviation(*tubes)))
                stats = []
    sequence = float(lowest_mean(torch.stack(tube_values)))
    values = per_frame.cpu().numpy()
    return (values.reshape(()) if single else values), sequence


def hdr_vqm(estimate, reference, **options) -> np.ndarray:
    """Per-frame HDR-VQM (one-frame tubes); see :func:`hdr_vqm_scores` for the options."""
    return hdr_vqm_scores(estimate, reference, **options)[0]


def hdr_vqm_video(estimate, reference, **options) -> float:
    """Sequence HDR-VQM (15-frame tubes, pooled over space then time)."""
    return hdr_vqm_scores(estimate, reference, **options)[1]
