"""How far an output pixel of a learned method can look: derived from the modules, not kept by hand.

Tiled inference is exact only if every tile carries, on every side, at least
the method's receptive reach. That reach is computed here from the modules
themselves: a :class:`Support` stands for a tensor inside a forward pass (its
pixel grid and the frame pixels its values may depend on), and every module of
a learned method propagates Supports the way its ``forward`` propagates
tensors:

- leaves by a rule read from their own attributes: :class:`torch.nn.Conv2d`
  (kernel, dilation, stride, padding, at the scale of its input's grid),
  ``PixelUnshuffle`` / ``PixelShuffle`` (the factor), activations and
  per-pixel layers (nothing), :class:`torch.nn.Sequential` (its children in
  order);
- every other module by its own ``support(...)`` method, written beside its
  ``forward`` and mirroring it (the same sub-modules called in the same order
  on the same inputs), with :meth:`Support.upsample`,
  :meth:`Support.taps` (a deformable tap bounded by ``max_offset * tanh``,
  a box filter, a neighbourhood) and :meth:`Support.window` (an all-to-all
  window on a fixed grid) for what is not a module.

Inputs that meet (a concatenation, a sum, a product) take the union of their
supports, so parallel paths count once, as the longest of them, not summed.
A module without a rule or a ``support`` method is refused by name: nothing
is skipped silently. Changing a kernel size, a dilation, ``max_offset``, an
attention window or the number of levels changes the reach with no other edit
(``tests/test_recon_reach.py``).

Geometry: a grid of scale s has pixels of s x s frame pixels, aligned with
the frame (pixel j covers frame pixels s j .. s j + s - 1); a support is the
interval [lo, hi] of frame-pixel displacements, centre to centre, from an
output pixel to the frame pixels it may read, the same on both axes (every
kernel here is square; an uneven one would count its larger side). A
convolution of kernel k, stride t, padding p and dilation d at scale s reads
input pixels whose centres lie s (1/2 - t/2 - p + d i), i = 0 .. k - 1, from
its output pixel's centre; displacements along a path add, and the union of
paths is their hull. Arithmetic is exact (fractions).
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

from torch import nn

#: Layers that act on each pixel alone (their spatial support is their input's).
PER_PIXEL = (nn.LeakyReLU, nn.ReLU, nn.SiLU, nn.GELU, nn.Sigmoid, nn.Tanh, nn.Identity, nn.Dropout)


@dataclasses.dataclass(frozen=True)
class Support:
    """The frame pixels a tensor's value at a pixel may depend on: displacements [lo, hi] at grid ``scale``.

    ``windowed``: (side, scale) when the last operation was an all-to-all
    window on that fixed grid; a second such window on the same grid adds
    nothing (both stay inside the same windows).
    """

    lo: Fraction = Fraction(0)
    hi: Fraction = Fraction(0)
    scale: Fraction = Fraction(1)
    windowed: tuple | None = None

    def extend(self, lo, hi, scale=None) -> "Support":
        """Displacements [lo, hi] in pixels of this grid added; the result on grid ``scale`` (default: this)."""
        s = self.scale
        return Support(self.lo + s * Fraction(lo), self.hi + s * Fraction(hi),
                       s if scale is None else Fraction(scale))

    def conv(self, kernel: int, stride: int = 1, padding: int = 0, dilation: int = 1) -> "Support":
        """A convolution's reach (output on the grid ``stride`` times coarser)."""
        first = Fraction(1, 2) - Fraction(stride, 2) - padding
        return self.extend(first, first + dilation * (kernel - 1), self.scale * stride)

    def unshuffle(self, factor: int) -> "Support":
        """Pixel-unshuffle: a factor x factor block becomes one pixel of a grid factor times coarser."""
        return self.conv(factor, stride=factor)

    def shuffle(self, factor: int) -> "Support":
        """Pixel-shuffle: each pixel becomes factor x factor pixels of a finer grid."""
        half = Fraction(factor - 1, 2 * factor)
        return self.extend(-half, half, self.scale / factor)

    def upsample(self, factor: int = 2) -> "Support":
        """Bilinear upsampling (``align_corners=False``): the two source pixels nearest each output centre."""
        lo = hi = Fraction(0)
        for i in range(factor):
            source = Fraction(2 * i + 1 - factor, 2 * factor)      # in source pixels; neighbours floor, floor + 1
            below = math.floor(source)
            lo, hi = min(lo, below - source), max(hi, below + 1 - source)
        return self.extend(lo, hi, self.scale / factor)

    def taps(self, reach) -> "Support":
        """Reads up to ``reach`` pixels of this grid away on either side (same grid out)."""
        return self.extend(-Fraction(reach), Fraction(reach))

    def sample(self, kernel: int, max_offset) -> "Support":
        """A deformable tap: kernel // 2 plus an offset of at most ``max_offset``, read bilinearly.

        A tap at a distance of at most a = kernel // 2 + max_offset reads the two
        pixels around it: floor(a) + 1 at most (one more than a whole a: rounding
        may push the tap just past it, and the next pixel gets a non-zero weight).
        """
        return self.taps(math.floor(Fraction(kernel // 2) + Fraction(max_offset)) + 1)

    def window(self, side: int) -> "Support":
        """All-to-all inside side x side windows of this grid (aligned with it): side - 1 pixels either way."""
        key = (side, self.scale)
        if self.windowed == key:
            return self
        return dataclasses.replace(self.taps(side - 1), windowed=key)

    def union(self, *others: "Support") -> "Support":
        """Where paths meet: the hull of the supports (all on one grid)."""
        out = self
        for other in others:
            if other.scale != out.scale:
                raise ValueError(f"supports meet on grids of scale {out.scale} and {other.scale}")
            out = Support(min(out.lo, other.lo), max(out.hi, other.hi), out.scale)
        return out

    @property
    def radius(self) -> int:
        """The largest whole number of frame pixels an input can lie from its output (frame grid only)."""
        if self.scale != 1:
            raise ValueError(f"the output is on a grid of scale {self.scale}, not the frame's")
        return math.floor(max(-self.lo, self.hi))


#: The input frame: each value depends on its own pixel.
FRAME = Support()


def union(*supports: Support) -> Support:
    return supports[0].union(*supports[1:])


def _pair(value) -> tuple[int, int]:
    return tuple(value) if isinstance(value, (tuple, list)) else (value, value)


def support(module: nn.Module, *inputs: Support) -> Support:
    """The support of ``module(*inputs)``: its own ``support`` method, else a rule for its type."""
    own = getattr(module, "support", None)
    if own is not None and callable(own):
        return own(*inputs)
    if isinstance(module, nn.Sequential):
        (x,) = inputs
        for child in module:
            x = support(child, x)
        return x
    if isinstance(module, PER_PIXEL):
        return union(*inputs)
    if isinstance(module, nn.Conv2d):
        (x,) = inputs
        if isinstance(module.padding, str):
            raise TypeError(f"no reach rule for {module!r} (padding {module.padding!r})")
        axes = [x.conv(k, s, p, d) for k, s, p, d in zip(_pair(module.kernel_size), _pair(module.stride),
                                                           _pair(module.padding), _pair(module.dilation))]
        if axes[0].scale != axes[1].scale:
            raise TypeError(f"no reach rule for {module!r} (unequal strides)")
        return union(*axes)
    if isinstance(module, nn.PixelUnshuffle):
        return union(*inputs).unshuffle(module.downscale_factor)
    if isinstance(module, nn.PixelShuffle):
        return union(*inputs).shuffle(module.upscale_factor)
    raise TypeError(f"no reach rule for {type(module).__name__}: give it a support() method beside its forward")


def derive_radius(model: nn.Module) -> int:
    """Frame pixels an output pixel of ``model`` (a learned method's module) can reach, an upper bound."""
    return support(model, FRAME).radius
