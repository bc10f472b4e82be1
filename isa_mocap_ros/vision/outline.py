"""Capsule outlines drawn by scanlines: the 2-D hull of each capsule's two projected end discs, filled.

Source: the pinhole approximation of a capsule's silhouette that the scanline energy counts (EA-vs-PF Eq. 4 on
the pixel grid, ``energy/raster_kernel.py``, docs/energy.md "Scanline raster"): a ball of radius ``r`` at depth
``z`` projects to (about) a disc of pixel radius ``f r / z`` around its centre's projection, and the capsule (the
convex hull of its two end balls) to the convex hull of its two end discs. That hull is convex, so each pixel row
meets it in one interval — the extent of the two discs' chords and of the two outer tangent segments' crossings
of the row — and the pixel centres inside it are set. The union of several capsules is their rows' intervals
OR-ed into one image.

Used where an outline is wanted fast rather than exactly: the mask gate's and the hull filter's predicted
silhouettes grown by a margin (:func:`isa_mocap_ros.tracking.gate.predicted_silhouettes`), the view weights'
visible shares, and the contour stage's model silhouette in a view without lens distortion
(:mod:`isa_mocap_ros.tracking.contour`). The exact silhouette (a ray per pixel against the capsule solids) is
:func:`.render.render_mask`. Pure numpy/numba (no ROS).
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

from .errors import VisionError

__all__ = ["camera_arrays", "capsule_discs", "fill_capsules", "fill_outlines", "outline_mask", "project_point"]

#: Projected coordinates are clipped to ±this many pixels (a capsule end near the camera plane projects far off).
_FAR_PX = 1e6


@numba.njit(cache=True, nogil=True)
def fill_outlines(ends, radii, ok, out, value):  # pragma: no cover - compiled
    """Set ``out[j, u] = value`` at the pixel centres ``(u, j)`` inside the hull of capsule ``c``'s end discs
    (centres ``ends[c, k] = (u, v)``, pixel radii ``radii[c, k]``) for every capsule with ``ok[c]``."""
    for c in range(ends.shape[0]):
        if ok[c]:
            _fill_hull(ends[c, 0, 0], ends[c, 0, 1], ends[c, 1, 0], ends[c, 1, 1], radii[c, 0], radii[c, 1], out,
                       value)


@numba.njit(cache=True, nogil=True)
def fill_capsules(E, radii, cam_R, cam_t, K4, D8, hasd, margin, out, value):  # pragma: no cover - compiled
    """:func:`fill_outlines` of the capsules ``E (C, 2, 3)`` (world), radii ``(C, 2)`` (metres) in a camera
    (``cam_R``, ``cam_t``; ``K4 = (fx, fy, cx, cy)``; ``D8`` the OpenCV distortion (k1, k2, p1, p2, k3, k4, k5,
    k6), applied when ``hasd``), each end disc of pixel radius ``fx r / z + margin``: :func:`capsule_discs`'s
    numbers, projected here (the same arithmetic as :meth:`~.camera.Camera.project`)."""
    uv = np.empty((2, 2))
    rr = np.empty(2)
    for c in range(E.shape[0]):
        ok = True
        for e in range(2):
            u, v, zc = project_point(E[c, e, 0], E[c, e, 1], E[c, e, 2], cam_R, cam_t, K4, D8, hasd)
            if not zc > 1e-3:
                ok = False
                break
            r = K4[0] * radii[c, e] / zc + margin
            if not (np.isfinite(u) and np.isfinite(v) and np.isfinite(r)):
                ok = False
                break
            uv[e, 0] = min(max(u, -_FAR_PX), _FAR_PX)
            uv[e, 1] = min(max(v, -_FAR_PX), _FAR_PX)
            rr[e] = min(max(r, 0.0), _FAR_PX)
        if ok:
            _fill_hull(uv[0, 0], uv[0, 1], uv[1, 0], uv[1, 1], rr[0], rr[1], out, value)


@numba.njit(cache=True, nogil=True, inline="always")
def project_point(X0, X1, X2, cam_R, cam_t, K4, D8, hasd):  # pragma: no cover - compiled
    """The pixel ``(u, v)`` of the world point ``(X0, X1, X2)`` and its camera depth ``z`` (``cam_R``, ``cam_t``;
    ``K4 = (fx, fy, cx, cy)``; ``D8`` the OpenCV distortion (k1, k2, p1, p2, k3, k4, k5, k6), applied when ``hasd``):
    the arithmetic of :meth:`~.camera.Camera.project`, for compiled callers (a point at or behind the camera plane
    gives non-finite or meaningless ``u, v``: callers check ``z``)."""
    xc = X0 * cam_R[0, 0] + X1 * cam_R[0, 1] + X2 * cam_R[0, 2] + cam_t[0]
    yc = X0 * cam_R[1, 0] + X1 * cam_R[1, 1] + X2 * cam_R[1, 2] + cam_t[1]
    zc = X0 * cam_R[2, 0] + X1 * cam_R[2, 1] + X2 * cam_R[2, 2] + cam_t[2]
    x, y = xc / zc, yc / zc
    if hasd:
        k1, k2, p1, p2, k3, k4, k5, k6 = D8[0], D8[1], D8[2], D8[3], D8[4], D8[5], D8[6], D8[7]
        r2 = x * x + y * y
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        x, y = (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)
    return K4[0] * x + K4[2], K4[1] * y + K4[3], zc


@numba.njit(cache=True, nogil=True, inline="always")
def _fill_hull(ax, ay, bx, by, ra, rb, out, value):  # pragma: no cover - compiled
    """Fill the hull of the discs ``((ax, ay), ra)`` and ``((bx, by), rb)`` (pixels) into ``out``."""
    H, W = out.shape
    if ra >= 0.0 and rb >= 0.0:
        dx, dy = bx - ax, by - ay
        L = np.sqrt(dx * dx + dy * dy)
        cone = L > abs(ra - rb) * (1.0 + 1e-9) + 1e-12          # else one disc holds the other
        p1x = p1y = q1x = q1y = p2x = p2y = q2x = q2y = 0.0
        if cone:
            ux, uy = dx / L, dy / L
            nx, ny = -uy, ux
            sb = (ra - rb) / L                                    # tangent points at along r sb, across ±r ca
            ca = np.sqrt(max(0.0, 1.0 - sb * sb))
            ex, ey = sb * ux + ca * nx, sb * uy + ca * ny
            fx, fy = sb * ux - ca * nx, sb * uy - ca * ny
            p1x, p1y, q1x, q1y = ax + ra * ex, ay + ra * ey, bx + rb * ex, by + rb * ey
            p2x, p2y, q2x, q2y = ax + ra * fx, ay + ra * fy, bx + rb * fx, by + rb * fy
        j0 = max(0.0, np.ceil(min(ay - ra, by - rb)))
        j1 = min(H - 1.0, np.floor(max(ay + ra, by + rb)))
        for j in range(int(j0), int(j1) + 1):
            y = float(j)
            lo, hi = np.inf, -np.inf
            lo, hi = _chord(y, ax, ay, ra, lo, hi)                # disc a's chord
            lo, hi = _chord(y, bx, by, rb, lo, hi)                # disc b's chord
            if cone:                                              # the tangent segments' crossings of the row
                lo, hi = _crossing(y, p1x, p1y, q1x, q1y, lo, hi)
                lo, hi = _crossing(y, p2x, p2y, q2x, q2y, lo, hi)
            u0 = max(0.0, np.ceil(lo))
            u1 = min(W - 1.0, np.floor(hi))
            for u in range(int(u0), int(u1) + 1):
                out[j, u] = value


@numba.njit(cache=True, nogil=True, inline="always")
def _chord(y, cx, cy, r, lo, hi):  # pragma: no cover - compiled
    """``(lo, hi)`` widened to the chord of the disc ``((cx, cy), r)`` on the row ``y``, if it meets the row."""
    h = r * r - (y - cy) * (y - cy)
    if h >= 0.0:
        s = np.sqrt(h)
        lo, hi = min(lo, cx - s), max(hi, cx + s)
    return lo, hi


@numba.njit(cache=True, nogil=True, inline="always")
def _crossing(y, px, py, qx, qy, lo, hi):  # pragma: no cover - compiled
    """``(lo, hi)`` widened to where the segment ``(px, py)``-``(qx, qy)`` crosses the row ``y``, if it does (a
    segment along the row adds nothing: its ends lie on the discs' chords)."""
    d = qy - py
    if abs(d) > 1e-12:
        t = (y - py) / d
        if 0.0 <= t <= 1.0:
            x = px + t * (qx - px)
            lo, hi = min(lo, x), max(hi, x)
    return lo, hi


def capsule_discs(camera, endpoints: np.ndarray, radii: np.ndarray, margin_px: float = 0.0):
    """The end discs of capsules ``endpoints (C, 2, 3)`` (world metres, radii ``(C, 2)``) seen by ``camera``:
    ``ends (C, 2, 2)`` pixel centres (:meth:`~.camera.Camera.project`, lens distortion included), ``radii_px
    (C, 2)`` = ``fx r / z + margin_px`` and ``ok (C,)``: both ends in front of the camera (depth > 1 mm) and
    finite."""
    C = endpoints.shape[0]
    flat = endpoints.reshape(-1, 3)
    z = camera.depth(flat).reshape(C, 2)
    uv = camera.project(flat).reshape(C, 2, 2)
    ok = np.all(z > 1e-3, axis=1) & np.all(np.isfinite(uv), axis=(1, 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = camera.fx * radii / z + margin_px
    ok &= np.all(np.isfinite(r), axis=1)
    ends = np.clip(np.where(np.isfinite(uv), uv, 0.0), -_FAR_PX, _FAR_PX)
    r = np.clip(np.where(np.isfinite(r), r, 0.0), 0.0, _FAR_PX)
    return np.ascontiguousarray(ends), np.ascontiguousarray(r), ok


_CAMERAS: dict = {}


def camera_arrays(camera) -> tuple:
    """``(R, t, K4, D8, has_distortion)`` of ``camera`` for :func:`fill_capsules` (C-ordered float64 copies: one
    compiled signature for every camera), made once per camera geometry."""
    key = camera.key()
    hit = _CAMERAS.get(key)
    if hit is None:
        D8 = np.zeros(8)
        D8[: np.size(camera.dist)] = np.ravel(camera.dist)
        hit = (np.array(camera.R, dtype=np.float64, order="C"), np.array(camera.t, dtype=np.float64).reshape(3),
               np.array([camera.fx, camera.fy, camera.cx, camera.cy], dtype=np.float64), D8, bool(camera.has_distortion))
        if len(_CAMERAS) >= 64:
            _CAMERAS.clear()
        _CAMERAS[key] = hit
    return hit


def outline_mask(camera, endpoints: Any, radii: Any, *, margin_px: float = 0.0) -> np.ndarray:
    """The capsules' outline in ``camera`` (module docstring), grown by ``margin_px`` pixels: ``(H, W)`` uint8,
    255 inside."""
    E = np.asarray(endpoints, dtype=np.float64)
    Rr = np.asarray(radii, dtype=np.float64)
    if E.ndim != 3 or E.shape[1:] != (2, 3) or Rr.shape != (E.shape[0], 2):
        raise VisionError(f"endpoints, radii: expected shapes (C, 2, 3) and (C, 2), received {E.shape} and {Rr.shape}")
    if not (np.isfinite(margin_px) and margin_px >= 0):
        raise VisionError(f"margin_px: expected a finite number >= 0, received {margin_px!r}")
    out = np.zeros((camera.height, camera.width), np.uint8)
    if E.shape[0]:
        fill_capsules(np.ascontiguousarray(E), np.ascontiguousarray(Rr), *camera_arrays(camera), float(margin_px), out,
                      np.uint8(255))
    return out
