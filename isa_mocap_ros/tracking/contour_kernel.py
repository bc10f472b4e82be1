"""Compiled steps of the contour stage (:mod:`.contour`): the back-projection of a rendered silhouette's
contour pixels onto the capsules, and the matching of model contour points to the image contour.

Both do per view, in one compiled call, what :meth:`.contour.ContourFit.model_points` and
:meth:`.contour.ContourFit.correspondences` (the numpy reference, kept and tested against these) do with
a dozen array operations each:

* :func:`back_project`: the hit point ``X = o + (z / (d·ẑ)) d`` of each contour pixel's ray (``z`` the
  renderer's camera-frame depth, ``d`` the pixel's unit ray, ``ẑ`` the optical axis), stored in the frame
  of the joint that carries its capsule: ``R_fᵀ (X − p_f)``;
* :func:`compose_root`, :func:`finish_step`: the step's new pose ``x + δ`` with the root rotation composed on the
  left, ``log(exp(δ_r) exp(r))`` nearest the old one, clipped to the limits (:mod:`isa_mocap_ros.geometry.so3`'s
  numbers: :mod:`~isa_mocap_ros.geometry.so3_kernel`; the logarithm's angle is numpy's ``arctan2`` between the two);
* :func:`match`: each model point moved with its joint (``X = p_f + R_f l``), projected with the lens
  distortion (as :meth:`~isa_mocap_ros.vision.Camera.project`), paired with the closest image contour
  pixel within ``max_px`` (an exact search of the integer pixels around it in an index image that holds
  each contour pixel's row: the nearest neighbour a k-d tree gives, without building one per frame).

Pure numba (no ROS).
"""
from __future__ import annotations

from importlib import import_module

import numba
import numpy as np

from ..geometry.so3_kernel import exp_into, log_args, log_into, matmul3, nearest_rotvec_into
from ..numba_cache import register_dependent_cache
from ..vision.outline import project_point
from ..vision.render import raycast_at

__all__ = ["back_project", "contour_points", "match", "mark_pixels", "outline_box", "compose_root", "finish_step"]

# numba keys a cached function on its own file only: the functions here compile the rotations, the projection and the
# ray cast of these modules into their machine code, so an edit there must also miss this module's cache
register_dependent_cache(__file__, tuple(import_module(f.__module__) for f in (exp_into, project_point, raycast_at)))


@numba.njit(cache=True)
def back_project(px, py, label, depth, o, dirs, W, zaxis, cap_frames, R, P,
                 frames, local):  # pragma: no cover - compiled
    """Rows ``frames (k,)``, ``local (k, 3)`` of the contour pixels ``(px, py)`` whose ray hit capsule
    ``label`` at camera-frame depth ``depth`` (float32, as the renderer gives it); pixels without a hit
    (label < 0) are left out. Returns the number of rows written."""
    k = 0
    for i in range(px.shape[0]):
        c = label[i]
        if c < 0:
            continue
        p = py[i] * W + px[i]
        dx, dy, dz = dirs[p, 0], dirs[p, 1], dirs[p, 2]
        s = np.float64(depth[i]) / (dx * zaxis[0] + dy * zaxis[1] + dz * zaxis[2])
        X0, X1, X2 = o[0] + s * dx, o[1] + s * dy, o[2] + s * dz
        f = cap_frames[c]
        e0, e1, e2 = X0 - P[f, 0], X1 - P[f, 1], X2 - P[f, 2]
        for r in range(3):                          # R^T (X - p)
            local[k, r] = R[f, 0, r] * e0 + R[f, 1, r] * e1 + R[f, 2, r] * e2
        frames[k] = f
        k += 1
    return k


@numba.njit(cache=True)
def contour_points(contour, n_points, o, dirs, axes, tcos, tsin, zaxis, W, caps, bs, nb, cap_frames, R, P, px, py, label,
                   depth, frames, local):  # pragma: no cover - compiled
    """The model contour points of one view in one call: at most ``n_points`` of the silhouette's contour pixels
    ``contour (k, 2)`` ``(u, v)``, evenly spaced (rows ``floor(i k / n_points)``), labelled with the visible
    capsule and its depth (:func:`~isa_mocap_ros.vision.render.raycast_at`, the renderer's per-camera data ``o``
    … ``zaxis``: :func:`~isa_mocap_ros.vision.render.ray_tiles`, ``W`` the image width; capsules ``caps``, ``bs``, ``nb``:
    :func:`~isa_mocap_ros.vision.capsule_data`) and back-projected (:func:`back_project`) into ``frames``,
    ``local``; ``px`` … ``depth`` are scratch of ``n_points`` rows. Returns the number of rows written."""
    k = contour.shape[0]
    m = min(k, n_points)
    q = k / n_points
    for i in range(m):
        j = int(np.floor(i * q)) if k > n_points else i
        px[i] = contour[j, 0]
        py[i] = contour[j, 1]
        label[i] = -1
        depth[i] = np.nan
    raycast_at(o, dirs, W, axes, tcos, tsin, caps, bs, nb, zaxis, px[:m], py[:m], label[:m], depth[:m])
    return back_project(px[:m], py[:m], label[:m], depth[:m], o, dirs, W, zaxis, cap_frames, R, P, frames, local)


@numba.njit(cache=True)
def mark_pixels(index, pix, value_is_row):  # pragma: no cover - compiled
    """``index[v, u] ← row`` for each contour pixel ``pix[row] = (u, v)`` (``value_is_row`` False: ← -1,
    clearing the marks of an earlier frame)."""
    for i in range(pix.shape[0]):
        index[pix[i, 1], pix[i, 0]] = i if value_is_row else -1


@numba.njit(cache=True)
def match(frames, local, R, P, cam_R, cam_t, K4, D8, hasd, index, max_px, lines_n, lines_m, out_f, out_l, out_n,
          out_m, out_d, k0):  # pragma: no cover - compiled
    """For each model point (joint frame ``frames[i]``, position ``local[i]`` in it) of a pose with joint
    rotations ``R`` and positions ``P``: the closest image contour pixel (``index``: its row at each contour
    pixel, -1 elsewhere) within ``max_px`` of the point's projection (``cam_R``, ``cam_t``;
    ``K4 = (fx, fy, cx, cy)``; ``D8``: the OpenCV distortion (k1, k2, p1, p2, k3, k4, k5, k6), used when
    ``hasd``). Each pair found is appended from row ``k0`` on: the point's ``out_f``, ``out_l``, the
    pixel's Plücker line ``out_n``, ``out_m`` (rows of ``lines_n``, ``lines_m``) and their distance
    ``out_d``; returns the row after the last one written."""
    H, W = index.shape
    r = int(np.ceil(max_px))
    lim = max_px * max_px
    k = k0
    for i in range(frames.shape[0]):
        f = frames[i]
        X = np.empty(3)
        for a in range(3):
            X[a] = P[f, a] + R[f, a, 0] * local[i, 0] + R[f, a, 1] * local[i, 1] + R[f, a, 2] * local[i, 2]
        u, v, _ = project_point(X[0], X[1], X[2], cam_R, cam_t, K4, D8, hasd)
        if not (np.isfinite(u) and np.isfinite(v)):
            continue
        cu, cv = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
        if cu < -r or cv < -r or cu >= W + r or cv >= H + r:
            continue
        best, row = np.inf, -1
        for yy in range(max(0, cv - r - 1), min(H, cv + r + 2)):
            dyy = yy - v
            if dyy * dyy > lim:
                continue
            for xx in range(max(0, cu - r - 1), min(W, cu + r + 2)):
                j = index[yy, xx]
                if j < 0:
                    continue
                dxx = xx - u
                d2 = dxx * dxx + dyy * dyy
                if d2 < best:
                    best, row = d2, j
        if row >= 0 and best <= lim:
            out_f[k] = f
            for a in range(3):
                out_l[k, a] = local[i, a]
                out_n[k, a] = lines_n[row, a]
                out_m[k, a] = lines_m[row, a]
            out_d[k] = np.sqrt(best)
            k += 1
    return k


@numba.njit(cache=True)
def compose_root(x, delta, Rc):  # pragma: no cover - compiled
    """``Rc ← exp_so3(δ[3:6]) exp_so3(x[3:6])`` (the root rotation perturbed on the left); returns
    :func:`~isa_mocap_ros.geometry.so3_kernel.log_args` of it (the caller takes ``θ = numpy.arctan2(s, c)``)."""
    A = np.empty((3, 3))
    B = np.empty((3, 3))
    exp_into(delta[3], delta[4], delta[5], A)
    exp_into(x[3], x[4], x[5], B)
    matmul3(A, B, Rc)
    return log_args(Rc)


@numba.njit(cache=True)
def finish_step(out, x, Rc, theta, lower, upper):  # pragma: no cover - compiled
    """``out`` (``x + δ``) in place: its root rotation ``nearest_rotvec(log_so3(Rc), x[3:6])`` (``theta``: the
    logarithm's angle), then clipped to ``[lower, upper]``."""
    w = np.empty(3)
    r = np.empty(3)
    log_into(Rc, theta, w)
    nearest_rotvec_into(w, x[3:6], r)
    out[3], out[4], out[5] = r[0], r[1], r[2]
    for i in range(out.size):
        out[i] = min(max(out[i], lower[i]), upper[i])


@numba.njit(cache=True)
def outline_box(E, radii, cam_R, cam_t, K4, D8, hasd, H, W):  # pragma: no cover - compiled
    """``(y0, y1, x0, x1)``: rows ``y0:y1`` and columns ``x0:x1`` of an ``(H, W)`` image holding every pixel that
    :func:`~isa_mocap_ros.vision.outline.fill_capsules` (margin 0) draws for the capsules ``E``, ``radii`` in this camera,
    with at least one row and column of undrawn pixels around them or the image's border (``y1 <= y0``: none drawn):
    the union of the boxes of the end discs it fills the hulls of (the same projection and the same capsules left
    out), grown by a pixel."""
    y0, y1, x0, x1 = H, 0, W, 0
    for c in range(E.shape[0]):
        ok = True
        lo_u, hi_u, lo_v, hi_v = np.inf, -np.inf, np.inf, -np.inf
        for e in range(2):
            u, v, zc = project_point(E[c, e, 0], E[c, e, 1], E[c, e, 2], cam_R, cam_t, K4, D8, hasd)
            if not zc > 1e-3:
                ok = False
                break
            r = K4[0] * radii[c, e] / zc
            if not (np.isfinite(u) and np.isfinite(v) and np.isfinite(r)):
                ok = False
                break
            u = min(max(u, -1e6), 1e6)
            v = min(max(v, -1e6), 1e6)
            r = min(max(r, 0.0), 1e6)
            lo_u, hi_u = min(lo_u, u - r), max(hi_u, u + r)
            lo_v, hi_v = min(lo_v, v - r), max(hi_v, v + r)
        if not ok:
            continue
        a, b = max(0, int(np.floor(lo_v)) - 1), min(H, int(np.floor(hi_v)) + 2)
        if b > a:
            y0, y1 = min(y0, a), max(y1, b)
        a, b = max(0, int(np.floor(lo_u)) - 1), min(W, int(np.floor(hi_u)) + 2)
        if b > a:
            x0, x1 = min(x0, a), max(x1, b)
    if y1 <= y0 or x1 <= x0:
        return 0, 0, 0, 0
    return y0, y1, x0, x1
