"""Multi-view consistency of the foreground: the visual-hull filter (pure numpy/numba, no ROS).

A foreground pixel of one view can belong to the person only if some point of its viewing ray is
foreground in every *other* view that sees it: the person occupies one 3-D region, seen by all
cameras. What one camera reports and the others cannot confirm — an object in front of that camera
alone (ISA §13.4.2's occluding rectangles are drawn into each image independently), a shadow or a
reflection in one view — has no such point, and :func:`hull_filter` removes it. This is the
visual-hull (shape-from-silhouette) test, applied per pixel: a pixel is kept when a point of its
ray inside the search box projects into the (slightly dilated) foreground of all the other views.

It complements the gate (:mod:`.gate`), which keeps whole the connected components that touch the
predicted silhouette: an occluder overlapping the person in one view is part of the person's
component there, so the gate keeps it, whole, and the energy's second term (EA-vs-PF Eq. 4-5)
pulls the limbs into it. The filter cuts it away wherever the other views see empty space.

Details:

* The ray of pixel ``(i, j)`` (pixel centres at integer coordinates, lens distortion removed,
  :meth:`Camera.ray`) is sampled every ``step_m`` metres inside the axis-aligned ``box``
  (the tracker's: the predicted pose's joints grown by ``pad``); a pixel whose ray misses the box
  is dropped.
* A sample is confirmed by view ``b`` when it projects onto view ``b``'s foreground dilated by
  ``dilate_px`` (calibration error, the segmentation's ragged border, the ray's sampling), or
  outside view ``b``'s image or behind it (view ``b`` cannot tell); ``misses`` views may fail to
  confirm it (a hole in one view's mask then costs nothing).
* Views that are None (missing, or skipped by the tracker) neither confirm nor deny; with fewer
  than two views the masks come back unchanged.
* ``keep``: pixels kept without confirmation — the tracker passes the predicted silhouette grown by a
  few pixels, where the person is expected, so a hole in another view's mask (pixel noise) does not
  cut the person; only what lies beyond it must be confirmed.
* Lens distortion: the other views' masks are resampled onto their undistorted pinhole image
  (``cv2.remap``, nearest; the maps computed once per camera), so the kernel projects without
  distortion; a pinhole pixel the real camera does not see abstains, like a point off the image.

Cost: linear in the foreground pixels tested, a small share of a tracked frame's time (``bench speed``'s
profile); pixels in ``keep`` are not tested (the tracker's kept silhouette holds most of the person).
:func:`hull_filter_numpy` is the reference (the same masks, tested), vectorized and slow.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from .gate import GateError, GateResult, pose_joints, view_masks

__all__ = ["hull_filter", "hull_filter_numpy", "pose_box", "prepare_cameras"]

try:  # pragma: no cover - numba is a dependency; the reference runs without it
    import numba
except ImportError:  # pragma: no cover
    numba = None


def pose_box(model, pose, pad: float, *, joints=None) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box ``(lo, hi)`` of the model's joints at ``pose`` (``joints``: their positions
    :func:`.gate.pose_joints` if known), grown by ``pad`` metres."""
    P = pose_joints(model, pose) if joints is None else joints
    return P.min(axis=0) - pad, P.max(axis=0) + pad


def _check(masks, cameras, box, dilate_px, step_m, misses, copy: bool = True):
    masks, cameras = list(masks), list(cameras)
    if len(masks) != len(cameras):
        raise GateError(f"masks: expected {len(cameras)} (one per camera), received {len(masks)}")
    for name, v in (("dilate_px", dilate_px), ("misses", misses)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise GateError(f"{name}: expected an integer >= 0, received {v!r}")
    if not (isinstance(step_m, (int, float, np.floating)) and np.isfinite(step_m) and step_m > 0):
        raise GateError(f"step_m: expected a finite number > 0, received {step_m!r}")
    lo, hi = (np.asarray(b, dtype=float) for b in box)
    if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GateError(f"box: expected two finite 3-vectors (lo, hi), received shapes {lo.shape}, {hi.shape}")
    if np.any(hi < lo):
        raise GateError(f"box: expected lo <= hi, received lo {lo.tolist()} and hi {hi.tolist()}")
    fg = [None if f is None else f.view(np.uint8) for f in view_masks(masks, cameras)] if copy \
        else view_masks(masks, cameras, uint8=True)
    return fg, cameras, lo, hi


def _check_keep(keep, fg, cameras, copy: bool = True):
    """``keep`` as a list of bool arrays (or None per view), checked against the masks (``copy=False``: uint8
    masks as they are, nonzero = kept, :func:`.gate.view_masks` with ``uint8``)."""
    if keep is None:
        return [None] * len(fg)
    keep = list(keep)
    if len(keep) != len(fg):
        raise GateError(f"keep: expected {len(fg)} masks or None (one per camera), received {len(keep)}")
    return view_masks(keep, cameras, "keep", uint8=not copy)


def _as255(f: np.ndarray) -> np.ndarray:
    """A nonzero-is-foreground uint8 mask as 0/255 (a new array)."""
    return np.where(f != 0, np.uint8(255), np.uint8(0))


def _box(f: np.ndarray) -> np.ndarray:
    """``(j0, j1, i0, i1)``: the rows and columns of ``f``'s foreground (its bounding box; empty: zeros)."""
    import cv2

    i0, j0, w, h = cv2.boundingRect(f)
    return np.array([j0, j0 + h, i0, i0 + w], dtype=np.int64)


def _support(fg, cameras, dilate_px):
    """Per view: the dilated foreground resampled onto the undistorted pinhole image (uint8 0/1; a
    pinhole pixel the real camera does not see is 1: that view cannot tell)."""
    import cv2

    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate_px + 1, 2 * dilate_px + 1))
    out = []
    for cam, f in zip(cameras, fg):
        if f is None:
            out.append(None)
            continue
        d = cv2.dilate(f, ker) if dilate_px > 0 else f.copy()
        if cam.has_distortion:
            mu, mv = _MAPS(cam)
            d = cv2.remap(d, mu, mv, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=1)
        out.append(np.ascontiguousarray(d))
    return out


def _support_into(S, has, fg, cameras, dilate_px, boxes) -> None:
    """:func:`_support` written into ``S (V, H, W)`` (zeros; nonzero = support) and ``has``: a view without lens
    distortion dilated within its foreground box ``boxes[v]`` (:func:`_box`) grown by ``dilate_px`` only (beyond it
    the dilation is 0: the same pixels)."""
    import cv2

    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate_px + 1, 2 * dilate_px + 1))
    for v, (cam, f) in enumerate(zip(cameras, fg)):
        if f is None:
            continue
        has[v] = True
        if cam.has_distortion:
            d = _support([f], [cam], dilate_px)[0]
            S[v, :d.shape[0], :d.shape[1]] = d
            continue
        j0, j1, i0, i1 = (int(b) for b in boxes[v])
        if j1 <= j0:
            continue                    # no foreground: no support
        j0, i0 = max(j0 - dilate_px, 0), max(i0 - dilate_px, 0)
        j1, i1 = min(j1 + dilate_px, f.shape[0]), min(i1 + dilate_px, f.shape[1])
        S[v, j0:j1, i0:i1] = cv2.dilate(f[j0:j1, i0:i1], ker) if dilate_px > 0 else f[j0:j1, i0:i1]


def _pinhole_map(cam):
    """``cv2.remap`` maps: pixel p of the pinhole image shows what the real (distorted) camera images
    at ``project(p's ray)``."""
    jj, ii = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    x, y = (ii - cam.cx) / cam.fx, (jj - cam.cy) / cam.fy
    Xc = np.stack([x, y, np.ones_like(x)], axis=-1)
    uv = cam.project(cam.center + (Xc @ cam.R))                # world points on each pinhole ray
    uv = np.where(np.isfinite(uv), uv, -1e6)
    return uv[..., 0].astype(np.float32), uv[..., 1].astype(np.float32)


def _rays(cam):
    """World unit directions ``(H, W, 3)`` of the pixel centres of ``cam`` (distortion removed)."""
    jj, ii = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    return np.ascontiguousarray(cam.ray(ii, jj)[1])


def _stack(cameras):
    K = np.zeros((len(cameras), 4))
    R = np.zeros((len(cameras), 3, 3))
    t = np.zeros((len(cameras), 3))
    for v, c in enumerate(cameras):
        K[v] = (c.fx, c.fy, c.cx, c.cy)
        R[v] = c.R
        t[v] = np.asarray(c.t, dtype=float).ravel()
    return K, R, t


def _entry_exit(c, d, lo, hi):
    """Ray ``c + s d`` (``d``: (..., 3)) against the box: ``(s0, s1)`` arrays, s0 > s1 when it misses."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (lo - c) / d
        b = (hi - c) / d
    near = np.where(d == 0, np.where((c >= lo) & (c <= hi), -np.inf, np.inf), np.minimum(a, b))
    far = np.where(d == 0, np.where((c >= lo) & (c <= hi), np.inf, -np.inf), np.maximum(a, b))
    return np.maximum(near.max(axis=-1), 0.0), far.min(axis=-1)


if numba is not None:
    @numba.njit(cache=True)
    def _carve_numba(a, fg, skip, dirs, c, S, WH, has, K, R, t, lo, hi, step, misses, box):  # pragma: no cover
        """View ``a``'s kept pixels: ``fg``'s foreground within ``box = (j0, j1, i0, i1)`` (rows, columns; it holds
        every foreground pixel) kept where ``skip`` says so or some sample of its ray in the box ``lo, hi`` projects
        onto the support ``S`` of every other view ``has`` (at most ``misses`` failing)."""
        V = S.shape[0]
        H, W = fg.shape
        out = np.zeros((H, W), np.uint8)
        for j in range(box[0], box[1]):
            for i in range(box[2], box[3]):
                if fg[j, i] == 0:
                    continue
                if skip[j, i]:              # kept without confirmation (``keep``)
                    out[j, i] = 255
                    continue
                s0 = 0.0
                s1 = np.inf
                hit = True
                for k in range(3):
                    dk = dirs[j, i, k]
                    if dk == 0.0:
                        if c[k] < lo[k] or c[k] > hi[k]:
                            hit = False
                    else:
                        u0 = (lo[k] - c[k]) / dk
                        u1 = (hi[k] - c[k]) / dk
                        if u0 > u1:
                            u0, u1 = u1, u0
                        s0 = max(s0, u0)
                        s1 = min(s1, u1)
                if not hit or s0 > s1:
                    continue
                n = int(np.floor((s1 - s0) / step)) + 1
                for q in range(n):
                    s = s0 + q * step
                    X0 = c[0] + s * dirs[j, i, 0]
                    X1 = c[1] + s * dirs[j, i, 1]
                    X2 = c[2] + s * dirs[j, i, 2]
                    miss = 0
                    for b in range(V):
                        if b == a or not has[b]:
                            continue
                        z = R[b, 2, 0] * X0 + R[b, 2, 1] * X1 + R[b, 2, 2] * X2 + t[b, 2]
                        if z <= 1e-9:
                            continue
                        xc = R[b, 0, 0] * X0 + R[b, 0, 1] * X1 + R[b, 0, 2] * X2 + t[b, 0]
                        yc = R[b, 1, 0] * X0 + R[b, 1, 1] * X1 + R[b, 1, 2] * X2 + t[b, 1]
                        u = K[b, 0] * (xc / z) + K[b, 2]
                        w = K[b, 1] * (yc / z) + K[b, 3]
                        iu = int(np.floor(u + 0.5))
                        iw = int(np.floor(w + 0.5))
                        if iu < 0 or iw < 0 or iu >= WH[b, 0] or iw >= WH[b, 1]:
                            continue
                        if S[b, iw, iu] == 0:
                            miss += 1
                            if miss > misses:
                                break
                    if miss <= misses:
                        out[j, i] = 255
                        break
        return out


class _PerCamera:
    """``fn(cam)`` computed once per camera (it depends on the calibration only)."""

    def __init__(self, fn) -> None:
        self._fn = fn
        self._cache: dict = {}

    def __call__(self, cam):
        key = cam.key()
        r = self._cache.get(key)
        if r is None:
            if len(self._cache) > 64:
                self._cache.clear()
            r = self._cache[key] = self._fn(cam)
        return r


_RAYS = _PerCamera(_rays)
_MAPS = _PerCamera(_pinhole_map)


class _Rig:
    """The kernel's numbers of a list of cameras (:func:`_stack`'s ``K, R, t``, the image sizes ``WH``, the largest
    ``HW``, the centres), made once per list of camera geometries (:data:`_RIGS`)."""

    def __init__(self, cameras) -> None:
        self.K, self.R, self.t = _stack(cameras)
        self.WH = np.array([(c.width, c.height) for c in cameras], dtype=np.int64)
        self.HW = (max(c.height for c in cameras), max(c.width for c in cameras))
        self.centers = [np.asarray(c.center, dtype=float) for c in cameras]


class _PerRig:
    """``_Rig(cameras)`` cached by the cameras' geometries."""

    def __init__(self) -> None:
        self._cache: dict = {}

    def __call__(self, cameras) -> _Rig:
        key = tuple(c.key() for c in cameras)
        r = self._cache.get(key)
        if r is None:
            if len(self._cache) > 16:
                self._cache.clear()
            r = self._cache[key] = _Rig(cameras)
        return r


_RIGS = _PerRig()


def _no_skip(shape) -> np.ndarray:
    """A zero ``skip`` image (nothing kept without confirmation) of ``shape``, shared (the kernel only reads it)."""
    z = _ZEROS.get(shape)
    if z is None:
        z = _ZEROS[shape] = np.zeros(shape, np.uint8)
    return z


_ZEROS: dict = {}


def prepare_cameras(cameras: Sequence) -> None:
    """Build the filter's per-camera data of ``cameras`` now (each pixel's ray, the pinhole maps of a distorted
    camera; ~20 ms per 320x240 camera), so the first frame filtered does not: they depend on the calibration only
    and are cached per camera geometry."""
    for cam in cameras:
        _RAYS(cam)
        if cam.has_distortion:
            _MAPS(cam)


def hull_filter(masks: Sequence, cameras: Sequence, box, *, dilate_px: int = 2, step_m: float = 0.02,
                misses: int = 0, keep: Sequence | None = None) -> GateResult:
    """Keep the foreground pixels that the other views confirm (see the module docstring).

    Parameters
    ----------
    masks : sequence of (H, W) array_like or None
        One per camera, nonzero = foreground; None views pass through (and confirm nothing).
    cameras : sequence of Camera
    box : (lo, hi)
        The search box in world coordinates (metres), e.g. :func:`pose_box` of the prediction.
    dilate_px : int
        The other views' foreground is dilated by this many pixels before it confirms a point.
    step_m : float
        Sampling step along each ray, metres.
    misses : int
        How many of the other views may fail to confirm a point.
    keep : sequence of (H, W) array_like or None, optional
        Per view, pixels kept without confirmation (nonzero; e.g. the predicted silhouette, where the
        person is expected: a hole in another view's mask then costs nothing there); None = none.

    Returns
    -------
    GateResult
        The filtered masks (uint8 0/255), and the pixels each view lost.

    Raises
    ------
    GateError
        A bad argument (names it, the expected and the received value).
    """
    if numba is None:  # pragma: no cover
        return hull_filter_numpy(masks, cameras, box, dilate_px=dilate_px, step_m=step_m, misses=misses, keep=keep)
    fg, cameras, lo, hi = _check(masks, cameras, box, dilate_px, step_m, misses, copy=False)
    kp = _check_keep(keep, fg, cameras, copy=False)
    V = len(fg)
    total = np.array([0 if f is None else int(np.count_nonzero(f)) for f in fg], dtype=np.int64)
    if sum(f is not None for f in fg) < 2:
        return GateResult([None if f is None else _as255(f) for f in fg], np.zeros(V, np.int64), total)
    # each view's foreground box (rows j0:j1, columns i0:i1): the kernel scans it, the support is dilated there
    boxes = [None if f is None else _box(f) for f in fg]
    rig = _RIGS(cameras)
    H, W = rig.HW
    S = np.zeros((V, H, W), np.uint8)
    has = np.zeros(V, np.bool_)
    _support_into(S, has, fg, cameras, dilate_px, boxes)
    out, lost = [], np.zeros(V, np.int64)
    for v, (cam, f) in enumerate(zip(cameras, fg)):
        if f is None:
            out.append(None)
            continue
        if total[v] == 0:
            out.append(_as255(f))
            continue
        skip = _no_skip(f.shape) if kp[v] is None else kp[v]
        kept = _carve_numba(v, f, skip, _RAYS(cam), rig.centers[v], S, rig.WH, has, rig.K, rig.R, rig.t, lo, hi,
                            float(step_m), int(misses), boxes[v])
        out.append(kept)
        lost[v] = total[v] - int(np.count_nonzero(kept))
    return GateResult(out, lost, total)


def hull_filter_numpy(masks: Sequence, cameras: Sequence, box, *, dilate_px: int = 2, step_m: float = 0.02,
                      misses: int = 0, keep: Sequence | None = None) -> GateResult:
    """:func:`hull_filter` in plain numpy (the reference the tests hold the kernel to)."""
    fg, cameras, lo, hi = _check(masks, cameras, box, dilate_px, step_m, misses)
    kp = _check_keep(keep, fg, cameras)
    V = len(fg)
    total = np.array([0 if f is None else int(np.count_nonzero(f)) for f in fg], dtype=np.int64)
    if sum(f is not None for f in fg) < 2:
        return GateResult([None if f is None else f * np.uint8(255) for f in fg], np.zeros(V, np.int64), total)
    sup = _support(fg, cameras, dilate_px)
    K, R, t = _stack(cameras)
    out, lost = [], np.zeros(V, np.int64)
    for a, (cam, f) in enumerate(zip(cameras, fg)):
        if f is None:
            out.append(None)
            continue
        jj, ii = np.nonzero(f)
        dirs = _rays(cam)[jj, ii]                                  # (P, 3)
        c = np.asarray(cam.center, dtype=float)
        s0, s1 = _entry_exit(c, dirs, lo, hi)
        ok = np.zeros(len(jj), bool)
        hit = s1 >= s0
        n = np.where(hit, np.floor(np.where(hit, s1 - s0, 0.0) / step_m).astype(np.int64) + 1, 0)
        for q in range(int(n.max(initial=0))):
            live = (q < n) & ~ok
            if not live.any():
                continue
            s = s0 + q * step_m
            X0, X1, X2 = (c[k] + s * dirs[:, k] for k in range(3))
            miss = np.zeros(len(jj), np.int64)
            for b in range(V):
                if b == a or sup[b] is None:
                    continue
                Rb, tb = R[b], t[b]
                z = Rb[2, 0] * X0 + Rb[2, 1] * X1 + Rb[2, 2] * X2 + tb[2]
                xc = Rb[0, 0] * X0 + Rb[0, 1] * X1 + Rb[0, 2] * X2 + tb[0]
                yc = Rb[1, 0] * X0 + Rb[1, 1] * X1 + Rb[1, 2] * X2 + tb[1]
                with np.errstate(divide="ignore", invalid="ignore"):
                    u = K[b, 0] * (xc / z) + K[b, 2]
                    w = K[b, 1] * (yc / z) + K[b, 3]
                iu = np.floor(u + 0.5)
                iw = np.floor(w + 0.5)
                seen = (z > 1e-9) & (iu >= 0) & (iw >= 0) & (iu < cameras[b].width) & (iw < cameras[b].height)
                val = np.zeros(len(jj), bool)
                val[seen] = sup[b][iw[seen].astype(np.int64), iu[seen].astype(np.int64)] > 0
                miss += seen & ~val
            ok |= live & (miss <= misses)
        kept = np.zeros(f.shape, np.uint8)
        kept[jj[ok], ii[ok]] = 255
        if kp[a] is not None:
            kept[(f > 0) & kp[a]] = 255
        out.append(kept)
        lost[a] = total[a] - int(np.count_nonzero(kept))
    return GateResult(out, lost, total)
