"""A camera window over a panorama: exact sub-pixel pan, tilt, rotation and zoom.

Coordinates are in source pixels with pixel centres on integers. Output pixel
(r, c) of an ``height x width`` window centred on ``(cy, cx)`` looks at source
point ``centre + R(angle) @ ((r, c) - window centre) / zoom``. The source is
sampled bilinearly: at a half-pixel offset the value is the mean of the two
neighbours, so a linear ramp is reproduced exactly and a pan of v pixels per
frame moves the image by exactly v. Longitude (x) wraps around the panorama
(equirectangular images are periodic in x), so a pan never reaches an edge;
latitude (y) is clamped at the poles' rows.

When the window zooms out (zoom < 1) one output pixel covers more than one
source pixel and bare bilinear sampling would alias; :func:`render_window`
then averages an ``s x s`` grid of sub-samples per output pixel (a box
filter the size of the output pixel), with ``s = ceil(1 / zoom)``.
"""

from __future__ import annotations

import math

import numpy as np

from tespike.golden.errors import InputError, is_positive_number


def sample_bilinear(image: np.ndarray, ys: np.ndarray, xs: np.ndarray, *, wrap_x: bool = True) -> np.ndarray:
    """Bilinear samples of a 2-D ``image`` at float coordinates (float64 result).

    ``x`` wraps modulo the width when ``wrap_x`` (panorama longitude), else it
    is clamped like ``y``.
    """
    image = np.asarray(image, np.float64)
    height, width = image.shape
    ys = np.clip(np.asarray(ys, np.float64), 0.0, height - 1.0)
    xs = np.asarray(xs, np.float64)
    if wrap_x:
        xs = np.mod(xs, width)
    else:
        xs = np.clip(xs, 0.0, width - 1.0)
    y0 = np.floor(ys)
    x0 = np.floor(xs)
    fy = ys - y0
    fx = xs - x0
    y0 = y0.astype(np.intp)
    x0 = x0.astype(np.intp)
    y1 = np.minimum(y0 + 1, height - 1)
    x1 = (x0 + 1) % width if wrap_x else np.minimum(x0 + 1, width - 1)
    x0 = x0 % width if wrap_x else x0
    top = image[y0, x0] * (1.0 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1.0 - fx) + image[y1, x1] * fx
    return top * (1.0 - fy) + bottom * fy


def window_coords(height: int, width: int, cy: float, cx: float, angle: float = 0.0,
                  zoom: float = 1.0, *, offset: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Source coordinates (ys, xs), each (height, width), of a rotated, zoomed window.

    ``angle`` turns the window (radians), ``zoom`` > 0 (2 = twice
    magnified), ``offset`` a sub-sample position inside the output pixel.
    """
    if not is_positive_number(zoom):
        raise InputError(f"zoom = {zoom!r} must be a finite number > 0")
    v = np.arange(height, dtype=np.float64)[:, None] - (height - 1) / 2.0 + offset[0]
    u = np.arange(width, dtype=np.float64)[None, :] - (width - 1) / 2.0 + offset[1]
    cos, sin = math.cos(angle), math.sin(angle)
    xs = cx + (cos * u + sin * v) / zoom
    ys = cy + (-sin * u + cos * v) / zoom
    return np.broadcast_to(ys, (height, width)), np.broadcast_to(xs, (height, width))


def render_window(image: np.ndarray, height: int, width: int, cy: float, cx: float,
                  angle: float = 0.0, zoom: float = 1.0, *, wrap_x: bool = True) -> np.ndarray:
    """One frame of a camera window (see the module docstring), float64 (height, width)."""
    steps = max(1, math.ceil(1.0 / zoom - 1e-9))
    if steps == 1:
        ys, xs = window_coords(height, width, cy, cx, angle, zoom)
        return sample_bilinear(image, ys, xs, wrap_x=wrap_x)
    total = np.zeros((height, width))
    grid = (np.arange(steps) + 0.5) / steps - 0.5
    for dy in grid:
        for dx in grid:
            ys, xs = window_coords(height, width, cy, cx, angle, zoom, offset=(dy, dx))
            total += sample_bilinear(image, ys, xs, wrap_x=wrap_x)
    return total / steps ** 2
