"""The HDR display the perceptual metrics (HDR-VQM, FovVideoVDP) assume: scene light -> cd/m^2.

The project's light is in scene units (I = 1 is the sensor's design light), not
in luminance. A perceptual metric judges what a viewer sees on a display, so the
reference and the estimate are both shown on one display, graded once from the
reference: the reference sequence's peak is shown at the display's peak, and the
estimate with the same scale (a too-bright or too-dark estimate stays so). What
the display cannot show is clipped to [black, peak] (negative light to black).
This is HDR-VQM's 'linear' display adaptation (the authors' SIM2 set-up), with
the scale taken from the reference alone instead of from each sequence.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from tespike.golden.errors import InputError, is_positive_number

if TYPE_CHECKING:                   # torch only for the annotations: importing this module stays light
    import torch


@dataclass(frozen=True)
class HdrDisplay:
    """A linear HDR display: ``peak_nits`` white, ``black_nits`` black, no ambient light.

    Defaults: 4000 cd/m^2 peak (the number the project's PU21-PSNR gives I = 1;
    the SIM2 HDR47 display HDR-VQM was built on measures about 4000 to 4500) and
    0.03 cd/m^2 black (the HDR-VQM reference's measured SIM2 black level).
    """

    peak_nits: float = 4000.0
    black_nits: float = 0.03

    def __post_init__(self):
        for name in ("peak_nits", "black_nits"):
            value = getattr(self, name)
            if not is_positive_number(value):
                raise InputError(f"display {name} = {value!r}: must be a finite number > 0")
        if self.black_nits >= self.peak_nits:
            raise InputError(f"display black {self.black_nits} cd/m^2 is not below its peak {self.peak_nits}")

    @property
    def contrast(self) -> float:
        return self.peak_nits / self.black_nits

    def describe(self) -> str:
        return f"linear HDR display, peak {self.peak_nits:g} cd/m^2, black {self.black_nits:g} cd/m^2"

    def luminance(self, light: "torch.Tensor", reference_peak: float) -> "torch.Tensor":
        """Emitted luminance (cd/m^2) of scene light when ``reference_peak`` is shown at the peak."""
        if not (hasattr(light, "clamp") and hasattr(light, "dtype")):   # (a numpy array: no clamp)
            raise InputError(f"display luminance: the light must be a torch tensor, not {type(light).__name__}")
        number = reference_peak if isinstance(reference_peak, (str, bytes)) or not hasattr(
            reference_peak, "__float__") else float(reference_peak)      # (a tensor's or numpy's scalar too)
        if not is_positive_number(number):                                # ('1' had been math's TypeError)
            raise InputError(f"reference peak {reference_peak!r}: must be a finite number > 0, the reference's "
                             "brightest light (an all-zero reference cannot be shown on a display)")
        return (light * (self.peak_nits / reference_peak)).clamp(self.black_nits, self.peak_nits)


def check_display(display) -> HdrDisplay:
    """``display``, an :class:`HdrDisplay`, refused in one line otherwise (a name had been an
    AttributeError of its first field): every metric that shows light on a display checks it."""
    if not isinstance(display, HdrDisplay):
        raise InputError(f"display = {display!r}: must be an HdrDisplay (tespike.recon.display), "
                         f"not {type(display).__name__}")
    return display


#: The one display every perceptual metric of the project uses unless told otherwise.
DEFAULT_DISPLAY = HdrDisplay()
