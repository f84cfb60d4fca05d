"""FovVideoVDP (Mantiuk et al., SIGGRAPH 2021; ``pyfvvdp`` 1.2.2) on the project's HDR display.

An HDR visual-difference predictor from the HDR-VDP group, in torch. It is *not*
HDR-VDP-3 (MATLAB only): its unit is the JOD (just-objectionable difference,
10 = no visible difference, lower is worse), not HDR-VDP-3's Q.

Each frame is judged as an image (non-foveated), both frames shown on
:class:`tespike.recon.display.HdrDisplay` (the reference's peak at the display's peak)
through pyfvvdp's linear-EOTF photometry with the same peak and black level and
no ambient light; the display geometry is pyfvvdp's ``standard_hdr_linear``
(30-inch 3840 x 2160 monitor seen from 0.7472 m: 75.4 pixels per degree, one
frame pixel per display pixel).

pyfvvdp is imported only when called: on import it appends its own folder to
``sys.path`` (it imports its modules ``interp`` and ``third_party`` by bare name).
Licence: pyfvvdp is CC BY-NC 4.0 (non-commercial), unlike this MIT project.
"""

from __future__ import annotations

import numpy as np
import torch

from tespike.golden.errors import InputError
from tespike.golden.resources import require_memory
from tespike.recon.display import DEFAULT_DISPLAY, HdrDisplay, check_display
from tespike.recon.settings import check_device
from tespike.recon.metrics import as_frames, display_peak, frame_stacks

#: Memory per pixel of one frame pyfvvdp judges (measured: about 220 bytes at 2048 x 2048).
BYTES_PER_PIXEL = 256
#: Smallest frame side pyfvvdp judges (at 2 and 3 it fails inside with an AttributeError).
MIN_SIDE = 4
#: pyfvvdp's display whose geometry is used (its photometry is replaced by the project's display).
GEOMETRY_DISPLAY = "standard_hdr_linear"


def _metric(display: HdrDisplay, device):
    import warnings
    with warnings.catch_warnings():       # pyfvvdp 1.2.2 uses a scipy.io name SciPy deprecates
        warnings.filterwarnings("ignore", message=".*mat_struct.*", category=DeprecationWarning)
        return _build_metric(display, device)


def _build_metric(display: HdrDisplay, device):
    import pyfvvdp
    from pyfvvdp.fvvdp_display_model import fvvdp_display_photo_eotf

    photometry = fvvdp_display_photo_eotf(display.peak_nits, contrast=display.contrast, EOTF="linear",
                                          E_ambient=0, name="tespike")
    return pyfvvdp.fvvdp(display_name=GEOMETRY_DISPLAY, display_photometry=photometry, heatmap=None,
                         quiet=True, device=torch.device(device))


def fovvideovdp(estimate, reference, *, display: HdrDisplay = DEFAULT_DISPLAY, peak=None,
                device="cpu") -> np.ndarray:
    """Per-frame FovVideoVDP quality in JOD (higher is better, 10 = identical).

    ``peak``: the reference light shown at the display's peak (default: the
    reference's maximum over all the frames given).
    """
    check_display(display)
    check_device(device)
    estimate, reference, single, rshape = frame_stacks(estimate, reference, "FovVideoVDP")
    K, H, W = rshape
    if K == 0 or H < MIN_SIDE or W < MIN_SIDE:         # (pyfvvdp fails inside below 4: a traceback)
        raise InputError(f"FovVideoVDP needs frames of at least {MIN_SIDE} x {MIN_SIDE} pixels, got shape {rshape}")
    peak = display_peak(reference, peak, K, H, W, device)
    require_memory(H * W * BYTES_PER_PIXEL, f"FovVideoVDP of {H} x {W} frames")
    metric = _metric(display, device)
    values = np.empty(K, dtype=np.float64)
    for k in range(K):
        r = as_frames(reference[k], "reference", device)
        if float(r.min()) < 0:
            raise InputError(f"reference holds a negative light value ({float(r.min())})")
        e = as_frames(estimate[k], "estimate", device)
        # linear EOTF: pyfvvdp takes cd/m^2 and adds the black level itself, so pass luminance above black
        lum_r = display.luminance(r[0], peak) - display.black_nits
        lum_e = display.luminance(e[0], peak) - display.black_nits
        with torch.no_grad():
            jod, _ = metric.predict(lum_e.float(), lum_r.float(), dim_order="HW")
        values[k] = float(jod)
    return values.reshape(()) if single else values
