"""Z-buffered triangle rasterizer: shaded RGB images and exact silhouettes of a triangle mesh.

Source: the standard scan conversion with edge functions and a depth buffer; used for the skinned
human meshes of ``isa-mocap synth --body mesh`` (DESIGN §6), rendered into the same rig and
backgrounds as the capsule renderer (:mod:`.render`).

Vertices are projected with the camera model (lens distortion included: :meth:`Camera.project`);
inside a triangle the image position is linear (triangles of a body mesh cover a few pixels, so
the distortion's curvature inside one is far below a pixel). A pixel centre ``(u, v)`` (integer
coordinates, OpenCV convention) is covered by a triangle when its three edge functions have the
same sign (top-left rule for shared edges); the nearest triangle wins, by ``1/z`` interpolated
linearly in the image (perspective-correct depth). Triangles with a vertex behind ``near_m`` are
skipped.

Shading is flat per triangle with the capsule renderer's formula,
``colour * min(1, 0.2 + 0.45 max(0, n.l) + 0.35 |n.d|)``, ``n`` the face normal, ``l`` the light
direction and ``d`` the unit ray to the face's centroid. The kernel is numba, single-threaded.
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

from .background import canvas
from .camera import Camera
from .errors import VisionError

__all__ = ["render_mesh", "mesh_mask"]

_NEAR_M = 0.05


@numba.njit(cache=True, nogil=True)
def _raster(uv, inv_z, tris, shade_rgb, H, W, out_rgb, out_mask, zbuf, mode):  # pragma: no cover - compiled
    """mode 0: mask only; 1: mask + rgb (z-buffered)."""
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        if inv_z[a] <= 0.0 or inv_z[b] <= 0.0 or inv_z[c] <= 0.0:
            continue
        x0, y0 = uv[a, 0], uv[a, 1]
        x1, y1 = uv[b, 0], uv[b, 1]
        x2, y2 = uv[c, 0], uv[c, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0 or not np.isfinite(area):
            continue
        if area < 0.0:                        # orient counter-clockwise in (u, v)
            x1, y1, x2, y2 = x2, y2, x1, y1
            b, c = c, b
            area = -area
        umin = max(int(np.ceil(min(x0, min(x1, x2)))), 0)
        umax = min(int(np.floor(max(x0, max(x1, x2)))), W - 1)
        vmin = max(int(np.ceil(min(y0, min(y1, y2)))), 0)
        vmax = min(int(np.floor(max(y0, max(y1, y2)))), H - 1)
        if umin > umax or vmin > vmax:
            continue
        za, zb, zc = inv_z[a], inv_z[b], inv_z[c]
        for py in range(vmin, vmax + 1):
            for px in range(umin, umax + 1):
                # barycentric edge functions
                w0 = (x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)
                w1 = (x0 - x2) * (py - y2) - (y0 - y2) * (px - x2)
                w2 = (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                # top-left rule: a pixel exactly on an edge belongs to one triangle only
                if (w0 == 0.0 and not ((y2 - y1) < 0.0 or ((y2 - y1) == 0.0 and (x2 - x1) > 0.0))) or \
                        (w1 == 0.0 and not ((y0 - y2) < 0.0 or ((y0 - y2) == 0.0 and (x0 - x2) > 0.0))) or \
                        (w2 == 0.0 and not ((y1 - y0) < 0.0 or ((y1 - y0) == 0.0 and (x1 - x0) > 0.0))):
                    continue
                iz = (w0 * za + w1 * zb + w2 * zc) / area
                out_mask[py, px] = 255
                if mode == 0:
                    continue
                if iz > zbuf[py, px]:
                    zbuf[py, px] = iz
                    for k in range(3):
                        out_rgb[py, px, k] = shade_rgb[t, k]


def _project(camera: Camera, verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    Pc = camera.to_camera(verts)
    z = Pc[:, 2]
    inv_z = np.where(z > _NEAR_M, 1.0 / np.maximum(z, _NEAR_M), -1.0)
    uv = np.asarray(camera.project(verts), dtype=np.float64)
    uv = np.where(np.isfinite(uv), uv, 1e9)
    return np.ascontiguousarray(uv), inv_z


def _check(verts: Any, tris: Any) -> tuple[np.ndarray, np.ndarray]:
    V = np.asarray(verts, dtype=np.float64)
    T = np.asarray(tris)
    if V.ndim != 2 or V.shape[1] != 3:
        raise VisionError(f"verts: expected shape (N, 3), received {V.shape}")
    if T.ndim != 2 or T.shape[1] != 3 or not np.issubdtype(T.dtype, np.integer):
        raise VisionError(f"tris: expected integer shape (T, 3), received {T.dtype} {T.shape}")
    if T.size and (T.min() < 0 or T.max() >= len(V)):
        raise VisionError(f"tris: expected vertex indices in [0, {len(V)}), received [{T.min()}, {T.max()}]")
    return np.ascontiguousarray(V), np.ascontiguousarray(T, dtype=np.int64)


def render_mesh(camera: Camera, verts: Any, tris: Any, colors: Any, *, background: Any = None,
                light_dir: Any = (0.3, -0.4, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Render a triangle mesh, flat-shaded, over a background, with its exact silhouette.

    Parameters
    ----------
    camera : Camera
    verts : (N, 3) array_like
        Vertex positions, world metres.
    tris : (T, 3) int array_like
        Vertex indices per triangle.
    colors : (T, 3) uint8 array_like
        RGB per triangle.
    background : (H, W, 3) uint8, optional
        Default uniform grey 48.
    light_dir : (3,) array_like
        Direction towards the light, world frame.

    Returns
    -------
    rgb : (H, W, 3) uint8
    mask : (H, W) uint8
        255 where a pixel centre is covered by a triangle, else 0.
    """
    V, T = _check(verts, tris)
    col = np.asarray(colors)
    if col.shape != (len(T), 3):
        raise VisionError(f"colors: expected shape ({len(T)}, 3), received {col.shape}")
    H, W = camera.height, camera.width
    rgb = canvas(background, H, W, 48)
    light = np.asarray(light_dir, dtype=np.float64)
    light = light / np.linalg.norm(light)
    A, B, C = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    n = np.cross(B - A, C - A)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    d = (A + B + C) / 3.0 - camera.center
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    nd = np.einsum("ij,ij->i", n, d)
    n = np.where(nd[:, None] > 0, -n, n)           # the normal facing the camera
    shade = np.minimum(1.0, 0.2 + 0.45 * np.maximum(n @ light, 0.0) + 0.35 * np.abs(nd))
    shade_rgb = np.minimum(255.0, col.astype(np.float64) * shade[:, None] + 0.5).astype(np.uint8)
    uv, inv_z = _project(camera, V)
    mask = np.zeros((H, W), np.uint8)
    zbuf = np.zeros((H, W), np.float64)
    _raster(uv, inv_z, T, shade_rgb, H, W, rgb, mask, zbuf, 1)
    return rgb, mask


def mesh_mask(camera: Camera, verts: Any, tris: Any) -> np.ndarray:
    """The silhouette ``(H, W)`` uint8 (0/255) of a triangle mesh (see :func:`render_mesh`)."""
    V, T = _check(verts, tris)
    H, W = camera.height, camera.width
    uv, inv_z = _project(camera, V)
    mask = np.zeros((H, W), np.uint8)
    _raster(uv, inv_z, T, np.zeros((len(T), 3), np.uint8), H, W, np.zeros((1, 1, 3), np.uint8), mask,
            np.zeros((1, 1)), 0)
    return mask
