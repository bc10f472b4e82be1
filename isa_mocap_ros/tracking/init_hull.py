"""The first frame's mask filter: the person as the largest 3-D blob of the visual hull (pure numpy/OpenCV).

Before the first estimate there is no prediction to gate the masks around (:mod:`.gate`, :mod:`.hull`), so
whatever the segmentation reports — ISA §13.4.2's occluding rectangles, drawn into each image independently,
a shadow, a reflection — reaches the automatic initialization: its root from the masks' centroid rays and its
heading grid score the occluders as body. On the bench's 35-occluder mesh bag the occluders were 65-85 % of a
view's foreground and the initialization faced backwards (7 frames at 220-380 mm until the heading check
switched).

Shape from silhouette, coarsely: the capture volume (:func:`capture_volume`) is cut into ``voxel_m`` cubes;
a cube is kept when every usable view that sees its centre sees foreground there (the masks dilated by
``dilate_px``) and at least ``min_views`` views see it. What one camera alone reports has no such cube; the
person, seen by all, is one connected blob. :func:`person_masks` takes the largest 26-connected blob, grows it
by the cubes within ``pad_m`` that two views confirm and none denies (a limb a third view does not see) connected to
it, and keeps per view the foreground within its projection (each cube drawn as a disc of its projected
half-diagonal plus ``margin_px``). Cost: one compiled pass over the volume's cubes per view (:func:`_carve`; the frame is
the first one, once).
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

import numba

from isa_mocap_ros.vision.camera import project_batch

__all__ = ["capture_volume", "person_masks"]

#: largest side of the capture volume, metres (a rig's cameras farther apart than this look at a part of it)
MAX_SIDE_M = 12.0
#: fewest cubes the largest blob must hold to be taken for the person (a 1.5 m tall person: ~200 at 6 cm)
MIN_CUBES = 20


def capture_volume(cameras: Sequence, *, height_m: float = 2.3) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box ``(lo, hi)`` the rig looks at: in x and y the box of the camera centres and of their
    optical axes' points on the floor (z = 0), at most ``MAX_SIDE_M`` a side around its middle; z from
    -0.2 to ``height_m`` (the world's floor is z = 0, docs/DESIGN.md §3)."""
    pts = []
    for cam in cameras:
        c = cam.center
        pts.append(c[:2])
        axis = cam.R[2]                       # the optical axis in world coordinates
        if axis[2] < -1e-6 and c[2] > 0:
            pts.append((c + axis * (-c[2] / axis[2]))[:2])
    P = np.array(pts)
    lo, hi = P.min(axis=0), P.max(axis=0)
    mid = 0.5 * (lo + hi)
    half = np.minimum(0.5 * (hi - lo), MAX_SIDE_M / 2)
    return (np.array([*(mid - half), -0.2]), np.array([*(mid + half), height_m]))


def person_masks(masks: Sequence, cameras: Sequence, *, voxel_m: float = 0.08, dilate_px: int = 1,
                 margin_px: int = 6, min_views: int = 3, pad_m: float = 0.6, box=None) -> tuple[list, str | None]:
    """The masks cut to the largest blob of the visual hull (see the module docstring).

    Parameters
    ----------
    masks : sequence of (H, W) ndarray or None
        One per camera (None: the view neither confirms nor denies).
    cameras : sequence of Camera
    box : (lo, hi) or None
        The volume searched (default :func:`capture_volume`).

    Returns
    -------
    masks : list
        The masks with the foreground outside the blob's projection set to 0 (same dtype), None kept; unchanged
        when fewer than ``min_views`` views have masks or no blob of ``MIN_CUBES`` cubes is found.
    note : str or None
        What was removed, for ``FrameResult.notes`` (None when nothing was).
    """
    idx = [v for v, m in enumerate(masks) if m is not None]
    if len(idx) < 2:
        return list(masks), None
    min_views = max(2, min(min_views, len(idx)))
    kernel = np.ones((2 * dilate_px + 1, 2 * dilate_px + 1), np.uint8)
    F = {v: cv2.dilate((np.asarray(masks[v]) > 0).astype(np.uint8), kernel) > 0 for v in idx}
    lo, hi = capture_volume(cameras) if box is None else (np.asarray(box[0], float), np.asarray(box[1], float))
    # 1. where the person is: the largest blob of cubes every view that sees them confirms
    G, n, sizes, labels = _blobs(F, cameras, lo, hi, voxel_m, min_views, misses=0)
    if sizes.size == 0 or sizes.max() < MIN_CUBES:
        return list(masks), (f"first-frame hull: no blob of {MIN_CUBES} cubes is foreground in every view that sees "
                             "it; masks kept")
    blob = G[labels == int(np.argmax(sizes)) + 1]
    # 2. its extent: around the blob, cubes two views confirm and no view denies (a limb a third view does not
    # see), connected to it; a grid aligned with the first one, so the blob's cubes are cubes of it
    lo2 = lo + voxel_m * np.floor((blob.min(axis=0) - pad_m - lo) / voxel_m)
    hi2 = blob.max(axis=0) + pad_m
    G2, n2, _, labels2 = _blobs(F, cameras, lo2, hi2, voxel_m, 2, misses=0)
    at = np.rint((blob - lo2) / voxel_m - 0.5).astype(int)
    ok = np.all((at >= 0) & (at < n2), axis=1)
    keep = np.setdiff1d(np.unique(labels2[np.ravel_multi_index(at[ok].T, n2)]), [0])
    C = np.vstack([blob, G2[np.isin(labels2, keep)]])
    out = list(masks)
    removed = []
    half = 0.5 * np.sqrt(3.0) * voxel_m
    for v in idx:
        cam, m = cameras[v], np.asarray(masks[v])
        S = np.zeros(m.shape[:2], np.uint8)
        z = _depth(cam, C)
        front = z > 1e-6
        uv = cam.project(C[front])
        r = np.ceil(max(cam.fx, cam.fy) * half / z[front]).astype(int) + margin_px
        ok = np.isfinite(uv).all(axis=1) & (np.abs(uv) < 1e5).all(axis=1)
        uv, r = uv[ok], r[ok]
        # Python ints once (tolist): ~2352 discs a frame, each numpy scalar converted on its own cost ~2 ms more
        for (u, w), rr in zip(np.rint(uv).astype(int).tolist(), r.tolist()):
            cv2.circle(S, (u, w), rr, 1, -1)
        fg = m > 0
        cut = fg & (S == 0)
        out[v] = np.where(cut, np.zeros((), m.dtype), m)
        removed.append((v, int(cut.sum()), int(fg.sum())))
    text = ", ".join(f"view {v} {c} of {t}" for v, c, t in removed if c)
    if not text:            # nothing beyond the person: no note (the estimator counts notes as problems)
        return out, None
    return out, (f"first-frame hull: the person's blob ({len(blob)} cubes of {voxel_m * 100:.0f} cm) kept; foreground "
                 f"removed: {text or 'none'}")


def _depth(cam, P: np.ndarray) -> np.ndarray:
    """``(N,)`` depth of world points ``P (N, 3)`` in ``cam``, elementwise (a BLAS product of a long thin matrix
    costs more than the work when other processes hold the cores)."""
    R, t = cam.R, cam.t
    return P[:, 0] * R[2, 0] + P[:, 1] * R[2, 1] + P[:, 2] * R[2, 2] + t[2]


def _blobs(F: dict, cameras: Sequence, lo: np.ndarray, hi: np.ndarray, voxel_m: float, min_views: int,
           misses: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cube centres ``G (N, 3)`` of the box ``lo..hi``, the grid's shape, the 26-connected blobs' sizes and each
    cube's blob label (0: not kept). A cube is kept when at least ``min_views`` views see it and at most
    ``misses`` of them (none with fewer than three seeing it) show no foreground there (``F``: dilated masks)."""
    from scipy import ndimage

    n = np.maximum(np.ceil((hi - lo) / voxel_m).astype(int), 1)
    axes = [lo[i] + voxel_m * (np.arange(n[i]) + 0.5) for i in range(3)]
    G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    seen = np.zeros(len(G), np.int16)
    denied = np.zeros(len(G), np.int16)
    views = list(F)
    UV = project_batch([cameras[v] for v in views], G[None])[:, 0]       # compiled: no BLAS call per view
    for j, v in enumerate(views):
        cam = cameras[v]
        # a writable copy of the optical axis whatever the camera's R (a view of a read-only R, as the rigs' cameras
        # have, is typed apart: numba then loaded a second compiled _carve on the first real frame after the warm-up)
        _carve(G, UV[j], np.array(cam.R[2], dtype=np.float64), float(cam.t[2]), cam.width, cam.height,
               np.ascontiguousarray(F[v]), seen, denied)
    allowed = np.where(seen >= 3, misses, 0)
    keep = (seen >= min_views) & (denied <= allowed)
    labels, _ = ndimage.label(keep.reshape(n), structure=np.ones((3, 3, 3), bool))
    labels = labels.ravel()
    return G, n, np.bincount(labels)[1:], labels


@numba.njit(cache=True)
def _carve(G, uv, r2, t2, width, height, F, seen, denied):  # pragma: no cover - compiled
    """One view's vote on the cubes ``G (N, 3)`` projected to ``uv (N, 2)`` (:func:`_carve_reference`, the same
    counts: one pass instead of a dozen numpy temporaries of N): a cube in front of the camera (depth, as
    :func:`_depth`, > 1e-6) whose pixel (rounded half to even) lies in the image adds 1 to ``seen``, and 1 to
    ``denied`` when the dilated mask ``F (H, W)`` shows no foreground there."""
    for i in range(G.shape[0]):
        z = G[i, 0] * r2[0] + G[i, 1] * r2[1] + G[i, 2] * r2[2] + t2
        if not z > 1e-6:
            continue
        u, v = uv[i, 0], uv[i, 1]
        if u > -0.5 and u < width - 0.5 and v > -0.5 and v < height - 0.5:     # NaN (far off a distorted view): out
            seen[i] += 1
            if not F[int(np.rint(v)), int(np.rint(u))]:
                denied[i] += 1


def _carve_reference(G: np.ndarray, uv: np.ndarray, cam, F: np.ndarray, seen: np.ndarray, denied: np.ndarray) -> None:
    """:func:`_carve` in numpy (its reference; tests compare them)."""
    front = np.flatnonzero(_depth(cam, G) > 1e-6)
    uv = uv[front]
    with np.errstate(invalid="ignore"):     # far outside a distorted camera's field: not finite, not seen
        on = (uv[:, 0] > -0.5) & (uv[:, 0] < cam.width - 0.5) & (uv[:, 1] > -0.5) & (uv[:, 1] < cam.height - 0.5)
    inside, uv = front[on], np.rint(uv[on]).astype(int)
    ok = F[uv[:, 1], uv[:, 0]]
    seen[inside] += 1
    denied[inside[~ok]] += 1
