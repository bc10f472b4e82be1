"""Synthetic backgrounds ("rooms") and clothing colours for the renderer.

Source: issue 3 item 7 (textured, non-uniform backgrounds) and the segmentation set-up of EA-vs-PF
§3.2 (a static background per view, learnt per pixel): a background here is a fixed image per
camera, so a per-pixel background model can learn it from empty frames. Everything is drawn from
the ``rng`` argument, so one seed gives one image.

``kind="textured"``: a room seen from a camera: a wall with a vertical light gradient, low-frequency
colour blotches and a few rectangles (doors, posters, shelves) above a horizon row; below it a floor
with a perspective tile grid (lines converging at a vanishing point on the horizon); then fine
sensor-like noise and a mild vignette. Wall and floor are muted (low saturation), clothing colours
saturated, so a colour background model can tell them apart. ``kind="noise"``: multi-octave smooth
colour noise around a random base colour.
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from .errors import VisionError

__all__ = ["make_background", "clothing_colors", "canvas", "PALETTE", "BACKGROUND_KINDS"]

BACKGROUND_KINDS = ("textured", "noise")

#: default clothing palette (RGB): shirt red, jeans blue, skin, green, yellow, purple, orange, teal,
#: light grey, brown, pink, navy; cycled by :func:`clothing_colors` without ``rng``
PALETTE = np.array([
    (200, 60, 50), (40, 80, 170), (230, 180, 140), (60, 150, 70), (220, 200, 60), (150, 70, 160),
    (240, 130, 40), (60, 170, 180), (185, 185, 195), (120, 70, 40), (230, 100, 150), (35, 45, 110),
], dtype=np.uint8)


def _check_rng(rng: Any) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise VisionError(f"rng: expected a numpy.random.Generator, received {type(rng).__name__}")
    return rng


def _hsv_to_rgb(h: float, s: float, v: float) -> np.ndarray:
    """One colour from OpenCV HSV (h in [0, 180), s, v in [0, 255]) to RGB float."""
    px = np.array([[[h, s, v]]], dtype=np.uint8)
    return cv2.cvtColor(px, cv2.COLOR_HSV2RGB)[0, 0].astype(np.float64)


def _smooth_noise(rng: np.random.Generator, height: int, width: int, cell: int, channels: int = 3) -> np.ndarray:
    """Smooth noise in about [-1, 1]: a random grid of cell ``cell`` px, bicubic upsampled."""
    gh, gw = max(2, height // cell + 2), max(2, width // cell + 2)
    grid = rng.uniform(-1.0, 1.0, (gh, gw, channels)).astype(np.float32)
    up = cv2.resize(grid, (gw * cell, gh * cell), interpolation=cv2.INTER_CUBIC)
    if up.ndim == 2:
        up = up[..., None]
    return up[:height, :width].astype(np.float64)


def make_background(width: int, height: int, *, rng: np.random.Generator, kind: str = "textured") -> np.ndarray:
    """A non-uniform background image, deterministic given ``rng``.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    rng : numpy.random.Generator
        Source of every random draw.
    kind : {"textured", "noise"}
        A synthetic room (wall, floor grid, objects) or smooth colour noise (module docstring).

    Returns
    -------
    (height, width, 3) uint8
        RGB image.
    """
    for f, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise VisionError(f"{f}: expected a positive integer, received {v!r}")
    _check_rng(rng)
    if kind not in BACKGROUND_KINDS:
        raise VisionError(f"kind: expected one of {BACKGROUND_KINDS}, received {kind!r}")
    W, H = int(width), int(height)
    scale = max(W, H) / 320.0
    if kind == "noise":
        base = _hsv_to_rgb(rng.uniform(0, 180), rng.uniform(20, 90), rng.uniform(90, 190))
        img = base + 45.0 * _smooth_noise(rng, H, W, max(2, int(40 * scale))) \
            + 25.0 * _smooth_noise(rng, H, W, max(2, int(12 * scale))) \
            + 10.0 * _smooth_noise(rng, H, W, max(2, int(4 * scale)))
        img += rng.normal(0.0, 3.0, img.shape)
        return np.clip(img + 0.5, 0, 255).astype(np.uint8)

    img = np.zeros((H, W, 3))
    horizon = int(H * rng.uniform(0.42, 0.58))
    # wall: muted colour, lighter at the top, with blotches
    wall = _hsv_to_rgb(rng.uniform(0, 180), rng.uniform(15, 70), rng.uniform(140, 210))
    ramp = np.linspace(1.1, 0.85, max(1, horizon))[:, None, None]
    img[:horizon] = wall * ramp + 14.0 * _smooth_noise(rng, horizon, W, max(2, int(48 * scale)))
    # wall objects: doors, posters, shelves (some striped)
    for _ in range(int(rng.integers(3, 7))):
        w = int(rng.uniform(0.06, 0.22) * W)
        h = int(rng.uniform(0.15, 0.7) * max(1, horizon))
        x0 = int(rng.integers(0, max(1, W - w)))
        y0 = int(rng.integers(0, max(1, horizon - h // 2)))
        col = _hsv_to_rgb(rng.uniform(0, 180), rng.uniform(30, 160), rng.uniform(70, 220))
        y1 = min(horizon, y0 + h)
        img[y0:y1, x0:x0 + w] = col
        if rng.random() < 0.5:
            step = max(2, int(rng.integers(3, 9) * scale))
            img[y0:y1:step, x0:x0 + w] *= 0.8
        cv2.rectangle(img, (x0, y0), (x0 + w - 1, y1 - 1), tuple(float(c) * 0.6 for c in col), 1)
    # floor: muted colour, darker towards the horizon, perspective tile grid
    floor = _hsv_to_rgb(rng.uniform(0, 180), rng.uniform(20, 90), rng.uniform(90, 170))
    fh = H - horizon
    if fh > 0:
        ramp = np.linspace(0.8, 1.05, fh)[:, None, None]
        img[horizon:] = floor * ramp + 10.0 * _smooth_noise(rng, fh, W, max(2, int(24 * scale)))
        line = tuple(float(c) * 0.55 for c in floor)
        vx = W * rng.uniform(0.3, 0.7)
        n_rays = int(rng.integers(10, 18))
        for xb in np.linspace(-1.5 * W, 2.5 * W, n_rays):
            cv2.line(img, (int(vx), horizon), (int(xb), H - 1), line, 1, cv2.LINE_AA)
        # floor lines at distances d0 * q^k project to rows horizon + fh / q^k (dense towards the horizon)
        offset, q = fh * rng.uniform(0.75, 1.0), rng.uniform(1.25, 1.45)
        while offset >= 1.5:
            y = horizon + int(offset)
            cv2.line(img, (0, y), (W - 1, y), line, 1, cv2.LINE_AA)
            offset /= q
        cv2.line(img, (0, horizon), (W - 1, horizon), tuple(float(c) * 0.5 for c in wall), max(1, int(2 * scale)))
    # sensor noise and vignette
    img += rng.normal(0.0, 3.0, img.shape)
    yy, xx = np.mgrid[0:H, 0:W]
    r2 = ((xx - W / 2.0) / (W / 2.0)) ** 2 + ((yy - H / 2.0) / (H / 2.0)) ** 2
    img *= (1.0 - 0.12 * r2)[..., None]
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def clothing_colors(n_capsules: int, *, rng: np.random.Generator | None = None) -> np.ndarray:
    """RGB colours for ``n_capsules`` capsules.

    Parameters
    ----------
    n_capsules : int
        Number of colours ``C >= 0``.
    rng : numpy.random.Generator, optional
        Without it, :data:`PALETTE` cycled (deterministic); with it, random saturated colours
        (OpenCV HSV: hue uniform, saturation 140-230, value 120-230).

    Returns
    -------
    (C, 3) uint8
    """
    if isinstance(n_capsules, bool) or not isinstance(n_capsules, (int, np.integer)) or n_capsules < 0:
        raise VisionError(f"n_capsules: expected a non-negative integer, received {n_capsules!r}")
    n = int(n_capsules)
    if rng is None:
        return PALETTE[np.arange(n) % len(PALETTE)].copy()
    _check_rng(rng)
    hsv = np.stack([rng.uniform(0, 180, n), rng.uniform(140, 230, n), rng.uniform(120, 230, n)], axis=-1)
    return cv2.cvtColor(hsv.astype(np.uint8)[None], cv2.COLOR_HSV2RGB)[0].reshape(n, 3)


def canvas(background: Any, height: int, width: int, grey: int) -> np.ndarray:
    """The ``(height, width, 3)`` uint8 image a renderer draws on: a copy of ``background`` (RGB, that size), or
    ``grey`` everywhere when it is None.

    Raises
    ------
    VisionError
        ``background`` is not uint8 of shape ``(height, width, 3)``.
    """
    if background is None:
        return np.full((height, width, 3), grey, np.uint8)
    bg = np.asarray(background)
    if bg.shape != (height, width, 3) or bg.dtype != np.uint8:
        raise VisionError(f"background: expected uint8 of shape ({height}, {width}, 3), received {bg.dtype} {bg.shape}")
    return bg.copy()
