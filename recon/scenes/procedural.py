"""Procedural HDR scenes of the project's own making (no outside data).

Every scene is an analytic function of continuous image coordinates, sampled
at pixel centres, so motion is exact at any sub-pixel speed. Building blocks:

- a log-normal texture: ``exp(sigma * T)`` with T a sum of random plane waves
  (periods 3 to 96 pixels, unit standard deviation), moving at a constant
  velocity; times anti-aliased discs 0.25x to 3x brighter or darker (edges);
- light sources: Gaussian spots (sigma 1 to 2.5 px) moving on their own
  straight paths, with peak gains over the background median;
- a sun: a disc 1e6 above the background median with a 1e-4/(1 + (d/R)^2)^1.5 glow;
- near-black regions (a dark object: 1e-4 of what lies behind) and zero-light regions
  (exactly 0.0, an occluder fixed in the frame).

Every generator takes a numpy ``Generator``; callers make it from a seed with
:func:`tespike.recon.scenes.scene_rng`. Results are float64 ``(K, H, W)``, not yet
normalised (the registry divides by the sequence maximum).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tespike.golden.errors import InputError


@dataclasses.dataclass(frozen=True)
class Texture:
    """Sum of plane waves, cos(2 pi f . p + phase), scaled to unit standard deviation."""

    freqs: np.ndarray     # (n, 2) cycles per pixel, (fy, fx)
    phases: np.ndarray    # (n,)
    amps: np.ndarray      # (n,), sum(amps^2) / 2 == 1

    def __call__(self, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
        out = np.zeros(np.broadcast_shapes(np.shape(ys), np.shape(xs)))
        for (fy, fx), phase, amp in zip(self.freqs, self.phases, self.amps):
            out += amp * np.cos(2 * np.pi * (fy * ys + fx * xs) + phase)
        return out


def random_texture(rng: np.random.Generator, waves: int = 32, min_period: float = 3.0,
                   max_period: float = 96.0) -> Texture:
    periods = np.exp(rng.uniform(math.log(min_period), math.log(max_period), waves))
    angles = rng.uniform(0, np.pi, waves)
    freqs = np.stack([np.sin(angles), np.cos(angles)], axis=1) / periods[:, None]
    amps = periods ** 0.5                       # more contrast at coarse scales
    amps = amps / math.sqrt(np.sum(amps ** 2) / 2)
    return Texture(freqs, rng.uniform(0, 2 * np.pi, waves), amps)


def random_velocity(rng: np.random.Generator, low: float = 0.3, high: float = 1.5) -> np.ndarray:
    """(vy, vx) pixels per frame, speed uniform in [low, high], any direction."""
    speed = rng.uniform(low, high)
    angle = rng.uniform(0, 2 * np.pi)
    return np.array([speed * math.sin(angle), speed * math.cos(angle)])


def _grid(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    return (np.arange(height, dtype=np.float64)[:, None], np.arange(width, dtype=np.float64)[None, :])


def _disc_coverage(ys, xs, cy, cx, radius) -> np.ndarray:
    """Anti-aliased disc: 1 inside, 0 outside, a one-pixel linear edge."""
    distance = np.hypot(ys - cy, xs - cx)
    return np.clip(radius - distance + 0.5, 0.0, 1.0)


def textured_background(rng: np.random.Generator, frames: int, height: int, width: int,
                        sigma: float = 0.7, discs: int = 4) -> np.ndarray:
    """Moving log-normal texture with a few brighter/darker discs; median about 1."""
    texture = random_texture(rng)
    velocity = random_velocity(rng)
    size = max(1.0, min(height, width))
    disc_params = [(rng.uniform(0, height), rng.uniform(0, width), rng.uniform(0.08, 0.25) * size,
                    math.exp(rng.uniform(math.log(0.25), math.log(3.0)))) for _ in range(discs)]
    ys, xs = _grid(height, width)
    out = np.empty((frames, height, width))
    for k in range(frames):
        py, px = ys - velocity[0] * k, xs - velocity[1] * k
        frame = np.exp(sigma * texture(py, px))
        for cy, cx, radius, gain in disc_params:
            frame *= 1.0 + (gain - 1.0) * _disc_coverage(py, px, cy, cx, radius)
        out[k] = frame
    return out / np.median(out)


def moving_spots(rng: np.random.Generator, frames: int, height: int, width: int,
                 count: int) -> np.ndarray:
    """``count`` Gaussian spots of unit peak on straight paths: (count, K, H, W)."""
    ys, xs = _grid(height, width)
    out = np.empty((count, frames, height, width))
    for i in range(count):
        cy, cx = rng.uniform(0.15, 0.85) * height, rng.uniform(0.15, 0.85) * width
        spread = rng.uniform(1.0, 2.5)
        velocity = random_velocity(rng, 0.2, 1.0)
        for k in range(frames):
            py, px = cy + velocity[0] * k, cx + velocity[1] * k
            out[i, k] = np.exp(-((ys - py) ** 2 + (xs - px) ** 2) / (2 * spread ** 2))
    return out


def light_sources_scene(rng, frames, height, width, gains=(1e2, 1e3, 1e4, 1e5)) -> np.ndarray:
    """Textured background with moving light sources ``gains`` x its median (1e2 .. 1e5)."""
    background = textured_background(rng, frames, height, width)
    spots = moving_spots(rng, frames, height, width, len(gains))
    return background + np.tensordot(np.asarray(gains, np.float64), spots, axes=1)


def moderate_scene(rng, frames, height, width, ratio: float | None = None) -> np.ndarray:
    """"Moderately HDR": peak / median of the sequence = ``ratio`` (default uniform in 100..300).

    A lower-contrast texture plus two or three moving highlights whose common
    gain is found by bisection so that the ratio is met to 0.1 %.
    """
    if ratio is None:
        ratio = float(rng.uniform(100.0, 300.0))
    background = textured_background(rng, frames, height, width, sigma=0.6)
    top = background.max()
    if top > ratio / 2:                          # keep the highlights the brightest thing
        background = background ** (math.log(ratio / 2) / math.log(top))
        background /= np.median(background)
    weights = rng.uniform(0.4, 1.0, int(rng.integers(2, 4)))
    spots = np.tensordot(weights, moving_spots(rng, frames, height, width, len(weights)), axes=1)

    def excess(gain: float) -> float:
        scene = background + gain * spots
        return scene.max() / np.median(scene) - ratio

    low, high = 0.0, ratio
    while excess(high) < 0:
        high *= 2
        if high > 1e12 * ratio:
            raise InputError(f"scene 'moderate': a {height} x {width} frame is too small for a peak of "
                             f"{ratio:.0f} x the median (the highlights cover too much of it)")
    for _ in range(32):
        mid = 0.5 * (low + high)
        if excess(mid) < 0:
            low = mid
        else:
            high = mid
    return background + high * spots


def sun_scene(rng, frames, height, width, sun_gain: float = 1e6, dark_gain: float = 1e-4) -> np.ndarray:
    """Stiff case: a sun ``sun_gain`` x the background median with glow, a near-black
    region (``dark_gain`` x background) and a zero-light occluder (exactly 0)."""
    background = textured_background(rng, frames, height, width)
    ys, xs = _grid(height, width)
    size = max(1.0, min(height, width))
    radius = max(1.5, 0.04 * size)
    start = np.array([rng.uniform(0.25, 0.75) * height, rng.uniform(0.25, 0.75) * width])
    velocity = random_velocity(rng, 0.2, 0.8)
    dark = (rng.uniform(0, height), rng.uniform(0, width), rng.uniform(0.12, 0.2) * size)
    dark_velocity = random_velocity(rng)
    # zero-light occluder: a band along one edge of the frame, fixed on screen
    edge = int(rng.integers(4))
    band = int(round(0.12 * min(height, width)))  # none in frames under 5 pixels
    zero = np.zeros((height, width), bool)
    if band:
        zero[{0: np.s_[:band, :], 1: np.s_[-band:, :], 2: np.s_[:, :band], 3: np.s_[:, -band:]}[edge]] = True
    out = np.empty_like(background)
    for k in range(frames):
        cy, cx = start + velocity * k
        distance = np.hypot(ys - cy, xs - cx)
        disc = _disc_coverage(ys, xs, cy, cx, radius)
        glow = 1e-4 / (1 + (distance / radius) ** 2) ** 1.5
        py, px = ys - dark_velocity[0] * k, xs - dark_velocity[1] * k
        shade = 1.0 - (1.0 - dark_gain) * _disc_coverage(py, px, *dark)
        frame = (background[k] + sun_gain * glow) * shade + sun_gain * disc
        frame[zero] = 0.0
        out[k] = frame
    return out


def decades_scene(rng, frames, height, width, decades: float = 12.0) -> np.ndarray:
    """Stiff case: a horizontal log ramp over ``decades`` decades in every frame,
    moving sideways (wrapping), with a mild texture and a zero-light top band."""
    texture = random_texture(rng)
    speed = rng.uniform(0.3, 1.0) * (1 if rng.integers(2) else -1)
    ys, xs = _grid(height, width)
    band = height // 8                          # no band below 8 rows
    out = np.empty((frames, height, width))
    for k in range(frames):
        position = np.mod(xs - speed * k, width) / max(1, width - 1)
        frame = 10.0 ** (-decades * position) * np.exp(0.2 * texture(ys, xs - speed * k))
        frame = np.broadcast_to(frame, (height, width)).copy()
        if band:
            frame[:band] = 0.0
        out[k] = frame
    return out
