"""Image distortions of the ISA paper's robustness experiments: random pixel noise and occluders.

Source: Gall et al., "Interacting simulated annealing" (ISA), §13.4.2, Figs. 13.15-13.17: "each
frame was independently distorted by 70% pixel noise, i.e., each pixel value was replaced with
probability 0.7 by a value uniformly sampled from the interval [0, 255]" (also 50%), and "occluding
rectangles of random size, position, and gray value, where the edge lengths were in the range from
1 to 40" (35 rectangles).

Choices where the paper is silent (documented in ``docs/vision.md``):

* Pixel noise acts **per pixel**: with probability ``p`` the whole pixel is replaced, each of its
  channels by an independent uniform integer in ``[0, 255]`` (for a single-channel image: one
  value). ``per_channel=True`` instead decides per channel. A replaced pixel keeps its old value
  only by chance (probability ``256**-channels``).
* Rectangles: width and height independently uniform integers in ``[min_size, max_size]``
  (clipped to the image size), the top-left corner uniform so that the rectangle lies entirely
  inside the image, one uniform grey value in ``[0, 255]`` written to all channels; drawn one after
  the other (later ones cover earlier ones).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .errors import VisionError

__all__ = ["pixel_noise", "occluders"]


def _check_image(img: Any) -> np.ndarray:
    arr = np.asarray(img)
    if arr.dtype != np.uint8 or arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] < 1) or arr.size == 0:
        raise VisionError(f"img: expected a non-empty uint8 image of shape (H, W) or (H, W, C), "
                          f"received {arr.dtype} {arr.shape}")
    return arr


def _check_rng(rng: Any) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise VisionError(f"rng: expected a numpy.random.Generator, received {type(rng).__name__}")
    return rng


def pixel_noise(img: Any, p: float, *, rng: np.random.Generator, per_channel: bool = False) -> np.ndarray:
    """Replace each pixel with probability ``p`` by uniform random values in [0, 255] (ISA §13.4.2).

    Parameters
    ----------
    img : (H, W) or (H, W, C) uint8
        Input image (not modified).
    p : float
        Replacement probability in [0, 1] (the paper uses 0.5 and 0.7).
    rng : numpy.random.Generator
        Source of every random draw.
    per_channel : bool
        Decide per channel instead of per pixel.

    Returns
    -------
    ndarray
        A new image of the same shape and dtype.
    """
    arr = _check_image(img)
    _check_rng(rng)
    try:
        p = float(p)
    except (TypeError, ValueError) as exc:
        raise VisionError(f"p: expected a probability in [0, 1], received {p!r}") from exc
    if not 0.0 <= p <= 1.0:
        raise VisionError(f"p: expected a probability in [0, 1], received {p!r}")
    out = arr.copy()
    if per_channel or arr.ndim == 2:
        hit = rng.random(arr.shape) < p
        out[hit] = rng.integers(0, 256, int(hit.sum()), dtype=np.uint8)
    else:
        hit = rng.random(arr.shape[:2]) < p
        out[hit] = rng.integers(0, 256, (int(hit.sum()), arr.shape[2]), dtype=np.uint8)
    return out


def occluders(img: Any, k: int, *, rng: np.random.Generator, min_size: int = 1, max_size: int = 40,
              return_rects: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Draw ``k`` occluding rectangles of random size, position and grey value (ISA §13.4.2).

    Parameters
    ----------
    img : (H, W) or (H, W, C) uint8
        Input image (not modified).
    k : int
        Number of rectangles (the paper uses 35).
    rng : numpy.random.Generator
        Source of every random draw.
    min_size, max_size : int
        Range of the edge lengths in pixels, inclusive (paper: 1 to 40).
    return_rects : bool
        Also return the rectangles.

    Returns
    -------
    out : ndarray
        A new image of the same shape and dtype.
    rects : (k, 5) int64, only with ``return_rects``
        ``x, y, width, height, grey`` per rectangle (pixels ``[y, y+height) x [x, x+width)``).
    """
    arr = _check_image(img)
    _check_rng(rng)
    for name, v, lo in (("k", k, 0), ("min_size", min_size, 1), ("max_size", max_size, 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise VisionError(f"{name}: expected an integer >= {lo}, received {v!r}")
    if max_size < min_size:
        raise VisionError(f"max_size: expected >= min_size = {min_size}, received {max_size}")
    H, W = arr.shape[:2]
    out = arr.copy()
    rects = np.zeros((int(k), 5), np.int64)
    for i in range(int(k)):
        w = min(int(rng.integers(min_size, max_size + 1)), W)
        h = min(int(rng.integers(min_size, max_size + 1)), H)
        x = int(rng.integers(0, W - w + 1))
        y = int(rng.integers(0, H - h + 1))
        g = int(rng.integers(0, 256))
        out[y:y + h, x:x + w] = g
        rects[i] = (x, y, w, h, g)
    return (out, rects) if return_rects else out
