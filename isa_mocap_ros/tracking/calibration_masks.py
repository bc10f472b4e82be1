"""The shape calibration's masks: foreground the neighbouring frames confirm, cut to the visual hull (numpy/OpenCV).

:func:`hull_masks` cuts each calibration frame's masks to the visual hull's person blob (:mod:`.init_hull`):
foreground one view alone reports goes. On the 35-occluder bags that keeps most occluder pixels near the person
(the four views' rectangles overlap along rays through her, and the coarse hull projects wide around a thin arm:
77-128 % more foreground than the person's own on the slim woman, ``docs/history/issue33_calibration_s30.md``), and
the shape fit, which matches what it is given, fattens the arms. ISA §13.4.2's occluders and pixel noise are drawn
anew in every frame; the person moves a few pixels from one frame to the next. :func:`persistent_masks` keeps, per
calibration frame and view, only the foreground within ``radius_px`` pixels of foreground in both neighbouring
frames of the window (the masks dilated by ``radius_px`` and intersected), so clutter of one frame goes before the
hull cut. Measured: ``docs/history/issue33_calibration_masks_s31.md``.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

__all__ = ["hull_masks", "persistent_masks", "neighbour_keys"]


def hull_masks(masks_per_frame, cameras) -> tuple[list, str | None]:
    """Each frame's masks cut to the largest blob of its visual hull (:func:`.init_hull.person_masks`, what the
    tracker does to its first frame): foreground one view alone reports (an occluder drawn into one image, pixel
    noise) does not enter the shape fit. A view left empty becomes None. Returns the masks and a note on the share
    of foreground removed (None when nothing was)."""
    from .init_hull import person_masks

    out, cut, total = [], 0, 0
    for masks in masks_per_frame:
        kept, _ = person_masks(masks, cameras)
        for m, k in zip(masks, kept):
            if m is not None:
                n = int(np.count_nonzero(m))
                total += n
                cut += n - int(np.count_nonzero(k))
        out.append([None if k is None or not np.any(k) else k for k in kept])
    if not cut:
        return out, None
    return out, (f"calibration masks: the visual hull's person blob kept; {cut} of {total} foreground pixels "
                 f"({100 * cut / max(total, 1):.1f} %) removed over {len(out)} frames")


def neighbour_keys(keys: Sequence[int], key: int) -> tuple[int, int] | None:
    """The two frames of ``keys`` (the window, any order) next to ``key``: the one before and the one after, or the
    two after the first frame and the two before the last; None with fewer than three frames."""
    order = sorted(int(k) for k in keys)
    if len(order) < 3:
        return None
    i = order.index(int(key))
    j = min(max(i, 1), len(order) - 2)          # the middle of three consecutive frames holding i
    return tuple(order[n] for n in (j - 1, j, j + 1) if n != i)


def persistent_masks(masks_of: Mapping[int, Sequence], keys: Sequence[int], radius_px: int) -> tuple[list, str]:
    """The masks of frames ``keys`` keeping only the foreground within ``radius_px`` pixels of foreground in both
    neighbouring frames (:func:`neighbour_keys` among ``masks_of``'s frames).

    Parameters
    ----------
    masks_of : mapping frame key -> sequence of (H, W) ndarray or None
        The window's masks, one per camera (None: a missing view).
    keys : sequence of int
        The frames whose masks are wanted.
    radius_px : int
        How far a pixel may have moved between frames, pixels (>= 1).

    Returns
    -------
    masks : list
        Per key the masks (uint8 0/255; a view whose neighbours lack it stays as given, None kept).
    note : str
        The share of the foreground removed.
    """
    import cv2

    if isinstance(radius_px, bool) or not isinstance(radius_px, (int, np.integer)) or radius_px < 1:
        raise ValueError(f"radius_px: expected an integer >= 1, received {radius_px!r}")
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    grown: dict = {}

    def near(k, v):
        if (k, v) not in grown:
            m = masks_of[k][v]
            grown[k, v] = None if m is None else cv2.dilate((np.asarray(m) > 0).view(np.uint8), disc) > 0
        return grown[k, v]

    out, cut, total = [], 0, 0
    for k in keys:
        nb = neighbour_keys(list(masks_of), k)
        kept = []
        for v, m in enumerate(masks_of[k]):
            if m is None:
                kept.append(None)
                continue
            f = np.asarray(m) > 0
            total += int(np.count_nonzero(f))
            if nb is not None and all(near(n, v) is not None for n in nb):
                g = f & near(nb[0], v) & near(nb[1], v)
                cut += int(np.count_nonzero(f)) - int(np.count_nonzero(g))
                f = g
            kept.append(f.view(np.uint8) * np.uint8(255))
        out.append(kept)
    return out, (f"calibration masks: foreground within {radius_px} px of the neighbouring frames' kept; {cut} of "
                 f"{total} foreground pixels ({100 * cut / max(total, 1):.1f} %) removed over {len(out)} frames")
