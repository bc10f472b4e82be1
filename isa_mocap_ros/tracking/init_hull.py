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
half-diagonal plus ``margin_px``). Cost: one compiled vote over the volume's cubes per view (:func:`_vote`; each
cube's pixel per camera, :func:`_pixels`, is kept per rig and capture volume, :func:`_grid`); the frame is the first
one, once.
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
    G, n, sizes, labels = _blobs(F, cameras, lo, hi, voxel_m, min_views, misses=0, cache=True)
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
        # ~600 discs a view, compiled (cv2.circle's filled 8-connected discs pixel for pixel: _discs)
        _discs(S, np.rint(uv).astype(np.int64), r.astype(np.int64))
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


#: the capture volume's grids and their pixels in each camera, by (box, cube size) and camera geometry
#: (:func:`_grid`): the first pass's grid depends on the cameras only
_GRIDS: dict = {}
#: grids kept (a rig's capture volume is one; the warm-up's and the rehearsal's rigs make two)
_GRIDS_KEPT = 4


def _grid(lo: np.ndarray, hi: np.ndarray, voxel_m: float, cams: Sequence, *, cache: bool
          ) -> tuple[np.ndarray, np.ndarray, list]:
    """Cube centres ``G (N, 3)`` of the box ``lo..hi``, the grid's shape ``(3,)`` and, per camera of ``cams``, each
    cube's pixel as a flat index into the camera's image (``(N,)`` int64, -1 where the camera does not see the cube:
    :func:`_pixels`). With ``cache`` the grid and each camera's pixels are kept for the next call with the same box
    and camera geometry: the first pass's capture volume (123,008 cubes × 4 views on bags/demo) is the same every
    initialization, and the start-up rehearsal (:func:`.realtime.rehearse`) builds it before the person comes."""
    key = (np.asarray(lo, np.float64).tobytes(), np.asarray(hi, np.float64).tobytes(), float(voxel_m))
    hit = _GRIDS.get(key) if cache else None
    if hit is None:
        n = np.maximum(np.ceil((hi - lo) / voxel_m).astype(int), 1)
        axes = [lo[i] + voxel_m * (np.arange(n[i]) + 0.5) for i in range(3)]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        hit = (G, n, {})
        if cache:
            if len(_GRIDS) >= _GRIDS_KEPT:
                _GRIDS.clear()
            _GRIDS[key] = hit
    G, n, pixels = hit
    todo = [c for c in cams if c.key() not in pixels]
    if todo:
        # compiled projection, no BLAS call per view; each camera's pixels are computed alone whatever the others in
        # the call (the same numbers either way)
        for c, uv in zip(todo, project_batch(todo, G[None])[:, 0]):
            # a writable copy of the optical axis whatever the camera's R (a view of a read-only R, as the rigs'
            # cameras have, is typed apart: numba then loaded a second compiled kernel on the first real frame)
            pixels[c.key()] = _pixels(G, uv, np.array(c.R[2], dtype=np.float64), float(c.t[2]), c.width, c.height)
    PIX = [pixels[c.key()] for c in cams]
    if not cache:
        pixels.clear()
    return G, n, PIX


def _blobs(F: dict, cameras: Sequence, lo: np.ndarray, hi: np.ndarray, voxel_m: float, min_views: int,
           misses: int, *, cache: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cube centres ``G (N, 3)`` of the box ``lo..hi``, the grid's shape, the 26-connected blobs' sizes and each
    cube's blob label (0: not kept). A cube is kept when at least ``min_views`` views see it and at most
    ``misses`` of them (none with fewer than three seeing it) show no foreground there (``F``: dilated masks).
    ``cache``: the grid and its pixels kept for the next call (:func:`_grid`)."""
    from scipy import ndimage

    views = list(F)
    G, n, PIX = _grid(lo, hi, voxel_m, [cameras[v] for v in views], cache=cache)
    seen = np.zeros(len(G), np.int16)
    denied = np.zeros(len(G), np.int16)
    for j, v in enumerate(views):
        _vote(PIX[j], np.ascontiguousarray(F[v]).ravel(), seen, denied)
    allowed = np.where(seen >= 3, misses, 0)
    keep = (seen >= min_views) & (denied <= allowed)
    labels = np.zeros(len(G), np.int32)
    kept = np.flatnonzero(keep)
    if kept.size == 0:
        return G, n, np.zeros(0, np.int64), labels
    # labelled within the kept cubes' bounding box: the same labels (numbered in the scan order, which the box keeps)
    # for a fraction of the volume (the person's few hundred cubes of 123,008)
    at = np.unravel_index(kept, tuple(n))
    box = tuple(slice(int(a.min()), int(a.max()) + 1) for a in at)
    sub, _ = ndimage.label(keep.reshape(n)[box], structure=np.ones((3, 3, 3), bool))
    labels.reshape(n)[box] = sub
    return G, n, np.bincount(sub.ravel())[1:], labels


@numba.njit(cache=True)
def _pixels(G, uv, r2, t2, width, height):  # pragma: no cover - compiled
    """Each cube's pixel in one view, a flat index ``row * width + column`` into its image (``(N,)`` int64), or -1: a
    cube ``G (N, 3)`` in front of the camera (depth, as :func:`_depth`, > 1e-6) whose projection ``uv (N, 2)``
    (rounded half to even) lies in the image has one; NaN (far off a distorted view) has none."""
    out = np.full(G.shape[0], -1, np.int64)
    for i in range(G.shape[0]):
        z = G[i, 0] * r2[0] + G[i, 1] * r2[1] + G[i, 2] * r2[2] + t2
        if not z > 1e-6:
            continue
        u, v = uv[i, 0], uv[i, 1]
        if u > -0.5 and u < width - 0.5 and v > -0.5 and v < height - 0.5:
            out[i] = int(np.rint(v)) * width + int(np.rint(u))
    return out


@numba.njit(cache=True)
def _vote(pix, F, seen, denied):  # pragma: no cover - compiled
    """One view's vote on the cubes of pixels ``pix`` (:func:`_pixels`): a cube with a pixel adds 1 to ``seen``, and 1
    to ``denied`` when the flat dilated mask ``F (H * W,)`` shows no foreground there."""
    for i in range(pix.shape[0]):
        p = pix[i]
        if p >= 0:
            seen[i] += 1
            if not F[p]:
                denied[i] += 1


def _carve(G, uv, r2, t2, width, height, F, seen, denied) -> None:
    """One view's vote on the cubes ``G (N, 3)`` projected to ``uv (N, 2)`` (``r2``, ``t2``: the camera's optical axis
    and depth offset; ``F (H, W)``: the dilated mask): :func:`_pixels` then :func:`_vote`, what :func:`_blobs` does
    with the pixels kept (:func:`_carve_reference` counts the same; the tests compare them)."""
    _vote(_pixels(G, uv, r2, t2, width, height), np.ascontiguousarray(F).ravel(), seen, denied)


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


@numba.njit(cache=True)
def _discs(S, uv, r):  # pragma: no cover - compiled
    """Filled discs of centres ``uv (N, 2)`` (integer pixels, column and row) and radii ``r (N,)`` set to 1 in ``S (H, W)``
    uint8, clipped to the image: ``cv2.circle(S, (u, v), r, 1, -1)`` for each, pixel for pixel (OpenCV's 8-connected
    filled circle: the midpoint walk of ``drawing.cpp``'s ``Circle``, whose four spans per step are drawn here;
    :func:`_discs_reference` is that call, and the tests compare them)."""
    H, W = S.shape
    for i in range(r.shape[0]):
        cx, cy, radius = uv[i, 0], uv[i, 1], r[i]
        if radius < 0:
            continue
        err, dx, dy, plus, minus = 0, radius, 0, 1, 2 * radius - 1
        while dx >= dy:
            y11, y12, y21, y22 = cy - dy, cy + dy, cy - dx, cy + dx
            x11, x12, x21, x22 = cx - dx, cx + dx, cx - dy, cx + dy
            if x11 < W and x12 >= 0 and y21 < H and y22 >= 0:
                a, b = max(x11, 0), min(x12, W - 1)
                if 0 <= y11 < H:
                    S[y11, a:b + 1] = 1
                if 0 <= y12 < H:
                    S[y12, a:b + 1] = 1
                if x21 < W and x22 >= 0:
                    a, b = max(x21, 0), min(x22, W - 1)
                    if 0 <= y21 < H:
                        S[y21, a:b + 1] = 1
                    if 0 <= y22 < H:
                        S[y22, a:b + 1] = 1
            dy += 1
            err += plus
            plus += 2
            if err > 0:          # OpenCV's branch-free mask: -1 when err > 0
                err -= minus
                dx -= 1
                minus -= 2


def _discs_reference(S: np.ndarray, uv: np.ndarray, r: np.ndarray) -> None:
    """:func:`_discs` with OpenCV (its reference)."""
    for (u, w), rr in zip(np.asarray(uv).tolist(), np.asarray(r).tolist()):
        cv2.circle(S, (u, w), rr, 1, -1)
