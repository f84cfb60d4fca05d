"""Dead-leaves HDR video: an occlusion model built for generalisation.

A scene is a stack of opaque objects drawn back to front (the dead-leaves
model of Matheron, used for natural-image statistics since Lee, Mumford and
Huang 2001): a background plane, then ``objects`` superellipses (discs,
ellipses, rounded rectangles, four-pointed stars) whose sizes follow a power
law ``p(r) ~ r^-size_exponent`` (scale invariance, as in natural images), whose
radiance is log-uniform over ``decades`` decades, each modulated by its own
log-radiance texture (plane waves in the object's frame, so it moves and turns
with it) and drawn with a sharp (one-pixel, anti-aliased) or soft edge.
Every object has its own linear motion and spin; a camera moves over the
whole (sub-pixel pan, rotation about the frame centre, zoom). Small bright
sources (``sources``, gains over the scene's median) ride on top, some of them
flickering sinusoidally (lamps on an AC supply seen at the readout rate).

Rendering is vectorised over frames: one pass per object over the box its
trajectory needs, each frame's box shifted by whole pixels. Output is float64
light (K, H, W), unnormalised (the engine sets the peak).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tespike.golden.errors import InputError, is_count, is_positive_number


@dataclasses.dataclass(frozen=True)
class DeadLeavesParams:
    """Ranges the generator draws from (each drawn once per sequence, then per object)."""

    objects: tuple[int, int] = (60, 300)            # objects over the background
    size_exponent: tuple[float, float] = (2.0, 3.2)  # p(r) ~ r^-alpha
    radius: tuple[float, float] = (1.5, 0.5)         # smallest (pixels), largest (fraction of frame side)
    decades: tuple[float, float] = (1.0, 6.0)        # radiance log-uniform over this many decades
    texture: tuple[float, float] = (0.0, 1.2)        # log-radiance texture amplitude (std)
    soft_fraction: float = 0.35                      # share of objects with a soft edge
    softness: tuple[float, float] = (1.5, 8.0)       # soft edge width (pixels)
    object_speed: tuple[float, float] = (0.0, 2.0)   # pixels per readout (largest of a sequence)
    spin: float = 0.02                               # largest object spin, radians per readout
    camera_speed: tuple[float, float] = (0.0, 1.5)   # pixels per readout
    camera_spin: float = 0.008                       # radians per readout
    camera_zoom: float = 0.006                       # log zoom per readout
    sources: tuple[int, int] = (0, 3)                # small bright sources
    source_gain: tuple[float, float] = (10.0, 1e4)   # x the scene's median, log-uniform
    flicker_fraction: float = 0.4                    # share of sources that flicker
    flicker_period: tuple[float, float] = (3.0, 40.0)  # readouts

    def __post_init__(self) -> None:
        """Every range a (low, high) pair of the numbers its draw can use, refused in one line (a flicker
        period of 0 had made NaN light, a size exponent of 1 or a radius of 0 a ZeroDivisionError when
        drawn, a negative source gain math's domain error, a negative count or radius been taken)."""
        def pair(key, least, positive=False, whole=False, most=math.inf):
            value = getattr(self, key)
            ok = isinstance(value, tuple) and len(value) == 2 and all(
                (is_count(v) if whole else (v == 0 or is_positive_number(v))) for v in value)
            if not ok or not (least <= value[0] <= value[1] <= most) or (positive and value[0] <= 0):
                bound = f"{'0 <' if positive else f'{least:g} <='} low <= high" + (f" <= {most:g}" if most < math.inf else "")
                raise InputError(f"dead leaves {key} = {value!r}: need {'integers' if whole else 'numbers'} {bound}")

        def share(key, most=1.0):
            value = getattr(self, key)
            if not ((value == 0 or is_positive_number(value)) and value <= most):
                raise InputError(f"dead leaves {key} = {value!r}: must be a number in [0, {most:g}]")

        pair("objects", 0, whole=True)
        pair("sources", 0, whole=True)
        pair("size_exponent", 0, positive=True)
        if self.size_exponent[0] <= 1:                   # (p(r) ~ r^-alpha inverted with 1 / (1 - alpha))
            raise InputError(f"dead leaves size_exponent = {self.size_exponent!r}: need 1 < low <= high")
        if not (isinstance(self.radius, tuple) and len(self.radius) == 2
                and is_positive_number(self.radius[0]) and is_positive_number(self.radius[1])
                and self.radius[1] <= 1):
            raise InputError(f"dead leaves radius = {self.radius!r}: need the smallest > 0 pixels and the "
                             "largest a fraction in (0, 1] of the frame side")
        pair("decades", 0, positive=True)
        pair("texture", 0)
        pair("softness", 0, positive=True)
        pair("object_speed", 0)
        pair("camera_speed", 0)
        pair("source_gain", 0, positive=True)
        pair("flicker_period", 0, positive=True)
        share("soft_fraction")
        share("flicker_fraction")
        for key in ("spin", "camera_spin", "camera_zoom"):
            share(key, math.inf)


def _uniform(rng, pair):
    return float(rng.uniform(*pair)) if pair[1] > pair[0] else float(pair[0])


def _log_uniform(rng, pair, size=None):
    return np.exp(rng.uniform(math.log(pair[0]), math.log(pair[1]), size))


def _power_law(rng, alpha: float, low: float, high: float, size: int) -> np.ndarray:
    """Samples of p(r) ~ r^-alpha on [low, high] by inverting its distribution function."""
    u = rng.uniform(size=size)
    a = 1.0 - alpha
    return (low ** a + u * (high ** a - low ** a)) ** (1.0 / a)


def _texture(rng, amplitude: float):
    """Random plane waves (periods 2..64 px) with unit standard deviation times ``amplitude``."""
    waves = int(rng.integers(1, 5))
    periods = _log_uniform(rng, (2.0, 64.0), waves)
    angles = rng.uniform(0, np.pi, waves)
    freqs = 2 * np.pi * np.stack([np.sin(angles), np.cos(angles)], 1) / periods[:, None]
    amps = rng.uniform(0.2, 1.0, waves)
    amps *= amplitude / math.sqrt(np.sum(amps ** 2) / 2)
    return freqs, rng.uniform(0, 2 * np.pi, waves), amps


def _camera(rng, p: DeadLeavesParams, frames: int):
    """Per-frame (dy, dx, angle, zoom) of the camera about the frame centre."""
    t = np.arange(frames, dtype=np.float64)
    speed, heading = _uniform(rng, p.camera_speed), rng.uniform(0, 2 * np.pi)
    kind = rng.uniform()
    spin = rng.uniform(-p.camera_spin, p.camera_spin) if kind < 0.5 else 0.0
    zoom = rng.uniform(-p.camera_zoom, p.camera_zoom) if kind > 0.3 else 0.0
    return speed * math.sin(heading) * t, speed * math.cos(heading) * t, spin * t, np.exp(zoom * t)


def dead_leaves(rng: np.random.Generator, frames: int, height: int, width: int,
                params: DeadLeavesParams = DeadLeavesParams()) -> np.ndarray:
    """A dead-leaves HDR video (K, H, W), float64, > 0, unnormalised."""
    if not isinstance(rng, np.random.Generator):         # (a seed had been an AttributeError)
        raise InputError(f"dead_leaves rng: must be a numpy Generator, not {type(rng).__name__}")
    if not (is_count(frames, 1) and is_count(height, 1) and is_count(width, 1)):
        raise InputError(f"dead leaves of {frames!r} x {height!r} x {width!r}: frames, height and width must be "
                         "integers >= 1")
    if not isinstance(params, DeadLeavesParams):
        raise InputError(f"dead_leaves params: must be DeadLeavesParams, not {type(params).__name__}")
    p = params
    side = float(min(height, width))
    cam_dy, cam_dx, cam_angle, cam_zoom = _camera(rng, p, frames)
    cy0, cx0 = (height - 1) / 2, (width - 1) / 2
    decades = _uniform(rng, p.decades)
    count = int(rng.integers(p.objects[0], p.objects[1] + 1))
    alpha = _uniform(rng, p.size_exponent)
    rmax = max(p.radius[0] * 1.01, p.radius[1] * side)
    radii = np.sort(_power_law(rng, alpha, p.radius[0], rmax, count))[::-1]   # big first: behind
    speed_max = _uniform(rng, p.object_speed)
    t = np.arange(frames, dtype=np.float64)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)

    # background plane: log-radiance texture in world coordinates, seen through the camera
    level = -decades * rng.uniform(0.3, 1.0)
    freqs, phases, amps = _texture(rng, 0.5 * _uniform(rng, p.texture))
    out = np.empty((frames, height, width))
    for k in range(frames):
        wy, wx = _to_world(ys, xs, cy0, cx0, cam_dy[k], cam_dx[k], cam_angle[k], cam_zoom[k])
        out[k] = _wave_sum(wy, wx, freqs, phases, amps)
    out = np.exp(out + math.log(10) * level)
    camera = (cam_dy, cam_dx, cam_angle, cam_zoom)
    for radius in radii:
        _draw_object(rng, out, p, float(radius), decades, speed_max, t, (cy0, cx0), camera)
    median = float(np.median(out))
    for _ in range(int(rng.integers(p.sources[0], p.sources[1] + 1))):
        _add_source(rng, out, p, median, t)
    return out


def _to_world(ys, xs, cy0, cx0, dy, dx, angle, zoom):
    """Frame pixel -> world coordinates under the camera (inverse of the camera's transform)."""
    y, x = (ys - cy0) / zoom, (xs - cx0) / zoom
    c, s = math.cos(angle), math.sin(angle)
    return c * y + s * x + cy0 + dy, -s * y + c * x + cx0 + dx


def _wave_sum(u, v, freqs, phases, amps):
    out = np.zeros(np.broadcast_shapes(np.shape(u), np.shape(v)))
    for (fy, fx), phase, amp in zip(freqs, phases, amps):
        out += amp * np.cos(fy * u + fx * v + phase)
    return out


def _to_frame(wy, wx, cy0, cx0, dy, dx, angle, zoom):
    """World -> frame pixel coordinates under the camera (arrays over frames)."""
    y, x = wy - cy0 - dy, wx - cx0 - dx
    c, s = np.cos(angle), np.sin(angle)
    return (c * y - s * x) * zoom + cy0, (s * y + c * x) * zoom + cx0


def _shape(rng) -> float:
    """Superellipse exponent: ellipse, rounded rectangle or four-pointed star."""
    kind = rng.uniform()
    if kind < 0.4:
        return 2.0
    if kind < 0.75:
        return float(rng.uniform(4.0, 10.0))
    return float(rng.uniform(0.6, 1.0))


def _draw_object(rng, out, p: DeadLeavesParams, radius: float, decades: float, speed_max: float,
                 t: np.ndarray, centre, camera) -> None:
    """Composite one opaque textured superellipse over ``out`` (K, H, W), every frame at once."""
    frames, height, width = out.shape
    cy0, cx0 = centre
    cam_dy, cam_dx, cam_angle, cam_zoom = camera
    # anchor: a random pixel of a random frame, so the object is seen at least there
    k0 = int(rng.integers(frames))
    wy0, wx0 = _to_world(rng.uniform(-radius, height + radius), rng.uniform(-radius, width + radius),
                         cy0, cx0, cam_dy[k0], cam_dx[k0], cam_angle[k0], cam_zoom[k0])
    speed, heading = rng.uniform(0, speed_max), rng.uniform(0, 2 * np.pi)
    wy = wy0 + speed * math.sin(heading) * (t - k0)
    wx = wx0 + speed * math.cos(heading) * (t - k0)
    fy, fx = _to_frame(wy, wx, cy0, cx0, cam_dy, cam_dx, cam_angle, cam_zoom)
    theta = rng.uniform(0, 2 * np.pi) + rng.uniform(-p.spin, p.spin) * t - cam_angle
    aspect = rng.uniform(0.3, 1.0)
    exponent = _shape(rng)
    soft = _uniform(rng, p.softness) if rng.uniform() < p.soft_fraction else 1.0
    half = int(math.ceil(radius * 1.42 * float(cam_zoom.max()) + soft + 1))
    y0 = np.floor(fy).astype(np.int64) - half
    x0 = np.floor(fx).astype(np.int64) - half
    seen = (y0 < height) & (y0 + 2 * half + 2 > 0) & (x0 < width) & (x0 + 2 * half + 2 > 0)
    if not seen.any():
        return
    ks = np.flatnonzero(seen)
    offsets = np.arange(2 * half + 2)
    Y = y0[ks, None, None] + offsets[None, :, None]
    X = x0[ks, None, None] + offsets[None, None, :]
    dy, dx = Y - fy[ks, None, None], X - fx[ks, None, None]
    c, s = np.cos(theta[ks])[:, None, None], np.sin(theta[ks])[:, None, None]
    zoom = cam_zoom[ks, None, None]
    u, v = (c * dy + s * dx) / zoom, (-s * dy + c * dx) / zoom          # object frame, world pixels
    a, b = radius, radius * aspect
    rho = (np.abs(u / a) ** exponent + np.abs(v / b) ** exponent) ** (1.0 / exponent)
    coverage = np.clip(0.5 + (1.0 - rho) * b * zoom / soft, 0.0, 1.0)
    inside = (Y >= 0) & (Y < height) & (X >= 0) & (X < width) & (coverage > 0)
    if not inside.any():
        return
    freqs, phases, amps = _texture(rng, _uniform(rng, p.texture))
    log_light = math.log(10) * -decades * rng.uniform() + _wave_sum(u, v, freqs, phases, amps)
    K, Y, X = np.broadcast_arrays(ks[:, None, None], Y, X)
    index = (K[inside] * height + Y[inside]) * width + X[inside]
    flat = out.reshape(-1)
    cov = coverage[inside]
    flat[index] = flat[index] * (1.0 - cov) + cov * np.exp(log_light[inside])


def _add_source(rng, out, p: DeadLeavesParams, median: float, t: np.ndarray) -> None:
    """Add a small moving Gaussian source, ``source_gain`` x ``median``, maybe flickering."""
    frames, height, width = out.shape
    gain = float(_log_uniform(rng, p.source_gain)) * median
    spread = rng.uniform(0.5, 2.5)
    speed, heading = rng.uniform(0, 1.5), rng.uniform(0, 2 * np.pi)
    cy = rng.uniform(0.1, 0.9) * height + speed * math.sin(heading) * (t - frames / 2)
    cx = rng.uniform(0.1, 0.9) * width + speed * math.cos(heading) * (t - frames / 2)
    level = np.full(frames, gain)
    if rng.uniform() < p.flicker_fraction:
        period, depth = _uniform(rng, p.flicker_period), rng.uniform(0.3, 1.0)
        level *= 1.0 - depth * (0.5 - 0.5 * np.cos(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi)))
    gy = np.exp(-(np.arange(height)[None, :] - cy[:, None]) ** 2 / (2 * spread ** 2))
    gx = np.exp(-(np.arange(width)[None, :] - cx[:, None]) ** 2 / (2 * spread ** 2))
    out += level[:, None, None] * gy[:, :, None] * gx[:, None, :]
