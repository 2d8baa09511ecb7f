"""Rendering pieces shared by the synthetic scenes (numpy + OpenCV only, no ROS).

Textures from smooth value noise, sprites pasted through an affine map with their alpha, and the
camera effects every scene applies last (lighting gain, sensor noise). All randomness comes from
the ``numpy.random.Generator`` passed in, so a scene is a pure function of its seed.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aircraft_docking_tracker.config import param

EPOCH_NS = 1_700_000_000 * 10**9          # first frame stamp of every synthetic scene (fixed: determinism)


@dataclass
class StreamConfig:
    """What every synthetic camera stream has: image size and length (each scene adds its own)."""

    width: int = param(640, "image width [px]", low=160, high=3840)
    height: int = param(480, "image height [px]", low=120, high=2160)
    frames: int = param(300, "number of frames", low=2, high=100000)


def frame_stamp_ns(index: int, fps: float) -> int:
    """Time stamp of frame ``index`` at ``fps`` frames per second."""
    return EPOCH_NS + int(round(index * 1e9 / fps))


def value_noise(rng: np.random.Generator, shape: tuple[int, int], scales=(64, 16, 4),
                weights=(0.6, 0.3, 0.1)) -> np.ndarray:
    """Smooth multi-octave noise in [0, 1], float32, of ``shape`` (h, w)."""
    h, w = shape
    out = np.zeros((h, w), np.float32)
    for scale, weight in zip(scales, weights):
        gh, gw = max(2, h // scale + 2), max(2, w // scale + 2)
        grid = rng.random((gh, gw)).astype(np.float32)
        out += weight * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
    lo, hi = float(out.min()), float(out.max())
    return (out - lo) / max(hi - lo, 1e-6)


def blotches(rng: np.random.Generator, shape: tuple[int, int], colors, scale: int = 8) -> np.ndarray:
    """A camouflage-like pattern: each pixel takes one of ``colors`` by thresholds of smooth noise."""
    noise = value_noise(rng, shape, scales=(scale, max(2, scale // 3)), weights=(0.8, 0.2))
    levels = np.quantile(noise, np.linspace(0, 1, len(colors) + 1)[1:-1])
    index = np.digitize(noise, levels)
    return np.asarray(colors, np.uint8)[index]


def paste_affine(frame: np.ndarray, sprite: np.ndarray, alpha: np.ndarray, affine: np.ndarray):
    """Blend ``sprite`` (h, w, 3 uint8) with ``alpha`` (h, w float32 in [0, 1]) into ``frame`` in place.

    ``affine`` (2x3 or 3x3) maps sprite pixel coordinates to frame pixel coordinates. Only the
    bounding rectangle of the warped sprite is touched. Returns ``(rows, cols, warped_alpha)``,
    the slices of that rectangle and the sprite's alpha there, or None when it misses the frame.
    """
    a = np.asarray(affine, np.float64)[:2]
    h, w = alpha.shape
    corners = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], np.float64) @ a.T
    x0, y0 = np.floor(corners.min(axis=0)).astype(int) - 1
    x1, y1 = np.ceil(corners.max(axis=0)).astype(int) + 1
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, frame.shape[1]), min(y1, frame.shape[0])
    if x1 <= x0 or y1 <= y0:
        return None
    local = a.copy()
    local[:, 2] -= (x0, y0)
    size = (x1 - x0, y1 - y0)
    warped = cv2.warpAffine(sprite, local, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    walpha = cv2.warpAffine(alpha, local, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    rows, cols = slice(y0, y1), slice(x0, x1)
    blend_into(frame[rows, cols], warped, walpha)
    return rows, cols, walpha


def blend_into(dst: np.ndarray, src: np.ndarray, alpha: np.ndarray) -> None:
    """``dst = dst (1 - alpha) + src alpha`` in place (uint8 images, alpha float32 h x w)."""
    a = alpha[..., None]
    dst[...] = np.clip(dst.astype(np.float32) * (1.0 - a) + src.astype(np.float32) * a + 0.5, 0, 255).astype(np.uint8)


def camera_effects(image: np.ndarray, rng: np.random.Generator, gain: float = 1.0,
                   tint=(1.0, 1.0, 1.0), noise_sigma: float = 0.0) -> np.ndarray:
    """Global lighting (gain, per-channel tint) and additive Gaussian sensor noise -> uint8 BGR.

    OpenCV's saturating arithmetic and its generator (seeded from ``rng``, so deterministic) keep
    this a few milliseconds per frame.
    """
    out = cv2.multiply(image, tuple(float(gain * t) for t in tint) + (1.0,))
    if noise_sigma > 0:
        cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
        noise = np.empty(image.shape, np.int16)
        cv2.randn(noise, 0.0, float(noise_sigma))
        out = cv2.add(out, noise, dtype=cv2.CV_8U)
    return out


def rain_streaks(image: np.ndarray, rng: np.random.Generator, count: int, length: float,
                 angle_deg: float = 75.0) -> None:
    """Draw ``count`` light, slanted rain streaks into ``image`` in place (blended at 40 %)."""
    h, w = image.shape[:2]
    layer = np.zeros_like(image)
    start = rng.random((count, 2)) * (w, h)
    d = np.array([np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))]) * length
    lengths = rng.uniform(0.5, 1.0, (count, 1))
    end = start + d * lengths
    for (xa, ya), (xb, yb) in zip(start.astype(int), end.astype(int)):
        cv2.line(layer, (xa, ya), (xb, yb), (200, 200, 205), 1, cv2.LINE_AA)
    cv2.addWeighted(image, 1.0, layer, 0.4, 0.0, dst=image)


def sun_glare(shape: tuple[int, int], center: tuple[float, float], radius: float) -> np.ndarray:
    """A warm additive glare layer (float32, h x w x 3): a bright disc fading with distance."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r = np.hypot(xx - center[0], yy - center[1]) / max(radius, 1.0)
    strength = 1.0 / (1.0 + r * r)
    return strength[..., None] * np.array([120.0, 190.0, 235.0], np.float32)
