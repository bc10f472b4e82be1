"""Ray-cast renderer of tapered capsules: shaded RGB images and exact silhouette masks.

Source: the body skin of DESIGN §3 (capsules / truncated cones per bone, as the cylinder and
cone models of EA-vs-PF §3.1 and the surface model of ISA §13.4.2) and the silhouettes that the
energy compares (EA-vs-PF Eq. 4-5). The solid of a capsule with end points ``p0, p1`` and end radii
``r0, r1`` is the **convex hull of the two balls** ``B(p0, r0)`` and ``B(p1, r1)``, i.e. the union of
the balls ``B((1-s) p0 + s p1, (1-s) r0 + s r1)`` for ``s in [0, 1]`` (a "round cone": a truncated
cone tangent to both spheres plus two spherical caps; with ``r0 = r1`` an ordinary capsule). A
point ``X`` lies inside iff ``min_s |X - p(s)| - r(s) <= 0``; a ray hits it iff
``min_s dist(ray, p(s)) - r(s) <= 0``. The silhouette energy must use this same solid.

Each pixel centre ``(u, v)`` (integer coordinates, OpenCV / CameraInfo convention) is back-projected
to a world ray with the lens distortion removed (:meth:`Camera.ray`), so the mask is exact for the
distorted camera too: a pixel is foreground iff its ray hits a solid in front of the camera. The
nearest hit over all solids (a z-buffer along the ray) gives occlusion between limbs. Rays are
intersected analytically with both spheres and with the tangent cone restricted to its band
``y in [r0 sin a, L + r1 sin a]`` (``y`` along the axis, ``sin a = (r0 - r1) / L``); the nearest
valid hit is the entry point into the hull. A camera inside a solid does not see that solid.

Speed: the image is cut into 8x8-pixel tiles, each with a cone bounding its pixel rays; a capsule
is tested only in tiles whose cone meets one of up to four spheres bounding it, only in tiles of a
32x32-pixel super-tile whose cone it meets, and only at the pixels of a tile's 4x4-pixel sub-tiles whose
cone it meets (the culling never leaves out a capsule a pixel's ray hits, so every pixel is the same).
A mask alone (:func:`render_mask`) stops at a pixel's first hit, trying the capsule that hit the
previous pixel of the tile first. Kernels are numba,
single-threaded and releasing the GIL (one body view takes ~0.5 ms; render views or frames in parallel
threads if needed: a multi-threaded kernel per view was slower and erratic on a loaded 2-core
machine). Per-camera rays are cached (keyed by the camera's geometry).

Shading: ``colour * min(1, 0.2 + 0.45 max(0, n.l) + 0.35 max(0, -n.d))`` with ``n`` the surface
normal, ``l`` the unit light direction and ``d`` the viewing ray (the last term darkens limb
outlines, so overlapping limbs of one colour stay distinguishable).
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numba
import numpy as np

from .background import canvas, clothing_colors
from .camera import Camera
from .capsule_solid import capsule_contains, capsule_data
from .errors import VisionError

__all__ = ["render", "render_mask", "render_labels", "render_labels_at", "capsule_data", "capsule_contains",
           "clear_ray_cache", "pixel_rays", "ray_tiles", "raycast_at", "TILE"]

#: tile edge in pixels for the culling
TILE = 8
#: super-tile edge in tiles: a capsule is tested against a tile's cone only if it meets its super-tile's
SUPER = 4
#: sub-tile edge in pixels (a quarter of a tile): a tile's pixels are tested only against the candidates whose
#: bounding spheres meet their sub-tile's cone
SUB = TILE // 2
_CACHE: "OrderedDict[bytes, tuple]" = OrderedDict()
_CACHE_SIZE = 32
_AMBIENT, _DIFFUSE, _VIEW = 0.2, 0.45, 0.35
#: default background grey when ``background`` is None
DEFAULT_GREY = 48


# ---------------------------------------------------------------------- per-camera data
def clear_ray_cache() -> None:
    """Forget the cached per-camera rays (they are rebuilt on the next call, ~10 ms at 320x240)."""
    _CACHE.clear()


def _camera_data(camera: Camera) -> tuple:
    """(origin, dirs (H*W, 3), tile axes (T, 3), tile cos, tile sin, optical axis, then the same three cone
    arrays of the super-tiles and of the sub-tiles) for ``camera``, cached."""
    key = camera.key()
    hit = _CACHE.get(key)
    if hit is not None:
        _CACHE.move_to_end(key)
        return hit
    H, W = camera.height, camera.width
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    origin, d = camera.ray(u, v)  # (H, W, 3)
    cones = []
    for size in (TILE, TILE * SUPER, SUB):  # tiles, super-tiles of SUPER x SUPER tiles, sub-tiles
        nty, ntx = -(-H // size), -(-W // size)
        iy = np.minimum(np.arange(nty * size), H - 1)
        ix = np.minimum(np.arange(ntx * size), W - 1)
        dp = d[iy][:, ix].reshape(nty, size, ntx, size, 3)
        axis = dp.sum(axis=(1, 3))
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        cos_min = np.einsum("yaxbk,yxk->yaxb", dp, axis).min(axis=(1, 3))  # (nty, ntx): widest ray of each
        theta = np.arccos(np.clip(cos_min, -1.0, 1.0)) + 1e-6
        cones.append((np.ascontiguousarray(axis.reshape(-1, 3)), np.cos(theta).ravel(), np.sin(theta).ravel()))
    data = (np.ascontiguousarray(origin), np.ascontiguousarray(d.reshape(-1, 3)), *cones[0], camera.R[2].copy(),
            *cones[1], *cones[2])
    _CACHE[key] = data
    if len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return data


# ---------------------------------------------------------------------- numba kernels
@numba.njit(cache=True, inline="always")
def _sphere_t(ox, oy, oz, dx, dy, dz, cx, cy, cz, r):  # pragma: no cover - compiled
    px, py, pz = ox - cx, oy - cy, oz - cz
    b = px * dx + py * dy + pz * dz
    c = px * px + py * py + pz * pz - r * r
    disc = b * b - c
    if disc < 0.0:
        return np.inf
    t = -b - np.sqrt(disc)
    return t if t > 0.0 else np.inf


@numba.njit(cache=True)
def _hit_t(ox, oy, oz, dx, dy, dz, cp):  # pragma: no cover - compiled
    """Ray parameter of the entry into the hull of two balls (inf: no hit in front)."""
    ax, ay, az = cp[0], cp[1], cp[2]
    t = _sphere_t(ox, oy, oz, dx, dy, dz, ax, ay, az, cp[7])
    t2 = _sphere_t(ox, oy, oz, dx, dy, dz, cp[13], cp[14], cp[15], cp[8])
    if t2 < t:
        t = t2
    if cp[12] == 0.0:
        return t
    ux, uy, uz, L, ra, rb, s, cc = cp[3], cp[4], cp[5], cp[6], cp[7], cp[8], cp[9], cp[11]
    qx, qy, qz = ox - ax, oy - ay, oz - az
    y0 = qx * ux + qy * uy + qz * uz
    yd = dx * ux + dy * uy + dz * uz
    qd = qx * dx + qy * dy + qz * dz
    qq = qx * qx + qy * qy + qz * qz
    w = y0 - ra * s
    A = cc - yd * yd                     # A t^2 + 2 B t + Cq = 0: rho^2 cos^2 a = (ra - y sin a)^2
    B = cc * qd - yd * w
    Cq = cc * (qq - ra * ra) - w * w
    ylo, yhi = ra * s, L + rb * s
    if abs(A) < 1e-12:
        if abs(B) > 1e-300:
            tc = -Cq / (2.0 * B)
            if 0.0 < tc < t:
                y = y0 + tc * yd
                if ylo <= y <= yhi:
                    t = tc
        return t
    disc = B * B - A * Cq
    if disc < 0.0:
        return t
    sq = np.sqrt(disc)
    r1, r2 = (-B - sq) / A, (-B + sq) / A
    if r1 > r2:
        r1, r2 = r2, r1
    for tc in (r1, r2):
        if 0.0 < tc < t:
            y = y0 + tc * yd
            if ylo <= y <= yhi:
                t = tc
                break
    return t


@numba.njit(cache=True, inline="always")
def _sphere_hit(ox, oy, oz, dx, dy, dz, cx, cy, cz, r):  # pragma: no cover - compiled
    """:func:`_sphere_t` is finite (the same arithmetic, without the root's value)."""
    px, py, pz = ox - cx, oy - cy, oz - cz
    b = px * dx + py * dy + pz * dz
    c = px * px + py * py + pz * pz - r * r
    disc = b * b - c
    if disc < 0.0:
        return False
    return -b - np.sqrt(disc) > 0.0


@numba.njit(cache=True)
def _any_hit(ox, oy, oz, dx, dy, dz, cp):  # pragma: no cover - compiled
    """:func:`_hit_t` is finite: the same three tests on the same numbers (so the same answer), stopping at
    the first that hits; the tangent cone, the likeliest hit of a long capsule, first."""
    if cp[12] != 0.0:
        ax, ay, az = cp[0], cp[1], cp[2]
        ux, uy, uz, L, ra, rb, s, cc = cp[3], cp[4], cp[5], cp[6], cp[7], cp[8], cp[9], cp[11]
        qx, qy, qz = ox - ax, oy - ay, oz - az
        y0 = qx * ux + qy * uy + qz * uz
        yd = dx * ux + dy * uy + dz * uz
        qd = qx * dx + qy * dy + qz * dz
        qq = qx * qx + qy * qy + qz * qz
        w = y0 - ra * s
        A = cc - yd * yd
        B = cc * qd - yd * w
        Cq = cc * (qq - ra * ra) - w * w
        ylo, yhi = ra * s, L + rb * s
        if abs(A) < 1e-12:
            if abs(B) > 1e-300:
                tc = -Cq / (2.0 * B)
                if 0.0 < tc < np.inf:
                    y = y0 + tc * yd
                    if ylo <= y <= yhi:
                        return True
        else:
            disc = B * B - A * Cq
            if disc >= 0.0:
                sq = np.sqrt(disc)
                r1, r2 = (-B - sq) / A, (-B + sq) / A
                for tc in (r1, r2):
                    if 0.0 < tc < np.inf:
                        y = y0 + tc * yd
                        if ylo <= y <= yhi:
                            return True
    if _sphere_hit(ox, oy, oz, dx, dy, dz, cp[0], cp[1], cp[2], cp[7]):
        return True
    return _sphere_hit(ox, oy, oz, dx, dy, dz, cp[13], cp[14], cp[15], cp[8])


@numba.njit(cache=True)
def _normal(px, py, pz, cp):  # pragma: no cover - compiled
    """Outward unit normal of the hull surface at the surface point ``p``."""
    ax, ay, az = cp[0], cp[1], cp[2]
    ux, uy, uz, L, ra, rb, s, ca = cp[3], cp[4], cp[5], cp[6], cp[7], cp[8], cp[9], cp[10]
    qx, qy, qz = px - ax, py - ay, pz - az
    if cp[12] == 0.0:
        if ra >= rb:
            return qx / ra, qy / ra, qz / ra
        return (px - cp[13]) / rb, (py - cp[14]) / rb, (pz - cp[15]) / rb
    y = qx * ux + qy * uy + qz * uz
    if y < ra * s:
        nx, ny, nz = qx, qy, qz
    elif y > L + rb * s:
        nx, ny, nz = px - cp[13], py - cp[14], pz - cp[15]
    else:
        rx, ry, rz = qx - y * ux, qy - y * uy, qz - y * uz
        rn = np.sqrt(rx * rx + ry * ry + rz * rz)
        if rn < 1e-15:
            return ux, uy, uz
        nx, ny, nz = ca * rx / rn + s * ux, ca * ry / rn + s * uy, ca * rz / rn + s * uz
    n = np.sqrt(nx * nx + ny * ny + nz * nz)
    return nx / n, ny / n, nz / n


@numba.njit(cache=True, inline="always")
def _nearest_hit(o, dx, dy, dz, caps, cand, nc, first):  # pragma: no cover - compiled
    """Ray parameter and index of the nearest of the ``nc`` candidate capsules the ray meets (``first``:
    of the first one met; ``(inf, -1)``: none)."""
    best_t = np.inf
    best_c = -1
    for j in range(nc):
        c = cand[j]
        t = _hit_t(o[0], o[1], o[2], dx, dy, dz, caps[c])
        if t < best_t:
            best_t = t
            best_c = c
            if first:
                break
    return best_t, best_c


@numba.njit(cache=True, inline="always")
def _tile_candidates_of(o, axis, cos_t, sin_t, bs, nb, among, n_among, cand):  # pragma: no cover - compiled
    """Those of the capsules ``among[:n_among]`` whose bounding spheres meet the tile's ray cone (apex ``o``,
    ``axis``, half-angle cosine/sine), in order, into ``cand``; returns their count."""
    nc = 0
    for i in range(n_among):
        c = among[i]
        for k in range(nb[c]):
            vx, vy, vz = bs[c, k, 0] - o[0], bs[c, k, 1] - o[1], bs[c, k, 2] - o[2]
            R = bs[c, k, 3]
            dist2 = vx * vx + vy * vy + vz * vz
            if dist2 <= R * R:
                cand[nc] = c
                nc += 1
                break
            proj = vx * axis[0] + vy * axis[1] + vz * axis[2]
            perp = np.sqrt(max(0.0, dist2 - proj * proj))
            if proj * cos_t + perp * sin_t < 0.0:
                continue
            if perp * cos_t - proj * sin_t <= R:
                cand[nc] = c
                nc += 1
                break
    return nc


@numba.njit(cache=True, nogil=True)
def _raycast(o, dirs, H, W, axes, tcos, tsin, saxes, scos, ssin, qaxes, qcos, qsin, caps, bs, nb, mode, colors,
             light, zaxis, out_rgb, out_mask, out_label, out_depth):  # pragma: no cover - compiled
    """mode 0: mask only (any hit); 1: nearest hit -> label + depth; 2: nearest hit -> label, depth, shaded rgb.

    A capsule is a tile's candidate when its bounding spheres meet the tile's ray cone, tested only for the
    capsules that meet the cone of the tile's super-tile (which holds every pixel ray of the tile: a capsule
    left out there hits none of them, so every pixel comes out as without the super-tiles); the same again
    from each tile's candidates for its four sub-tiles (``qaxes``, ``qcos``, ``qsin``)."""
    ntx = (W + 7) // 8
    nty = (H + 7) // 8
    sw = 8 * SUPER
    nsx = (W + sw - 1) // sw
    nqx, nqy = (W + SUB - 1) // SUB, (H + SUB - 1) // SUB
    C = caps.shape[0]
    scand = np.empty(C, np.int64)
    cand = np.empty(C, np.int64)
    qcand = np.empty(C, np.int64)
    all_caps = np.arange(C)
    for st in range(saxes.shape[0]):
        ns = _tile_candidates_of(o, saxes[st], scos[st], ssin[st], bs, nb, all_caps, C, scand)
        if ns == 0:
            continue
        sy, sx = st // nsx, st % nsx
        for ty in range(sy * SUPER, min(sy * SUPER + SUPER, nty)):
            for tx in range(sx * SUPER, min(sx * SUPER + SUPER, ntx)):
                tile = ty * ntx + tx
                nc = _tile_candidates_of(o, axes[tile], tcos[tile], tsin[tile], bs, nb, scand, ns, cand)
                if nc == 0:
                    continue
                last = -1
                for qy in range(2 * ty, min(2 * ty + 2, nqy)):
                    for qx in range(2 * tx, min(2 * tx + 2, nqx)):
                        q = qy * nqx + qx
                        nq = _tile_candidates_of(o, qaxes[q], qcos[q], qsin[q], bs, nb, cand, nc, qcand)
                        if nq == 0:
                            continue
                        if mode == 0:
                            last = _mask_tile(o, dirs, H, W, qx, qy, caps, qcand, nq, last, out_mask)
                        else:
                            _raycast_tile(o, dirs, H, W, qx, qy, caps, qcand, nq, mode, colors, light, zaxis,
                                          out_rgb, out_mask, out_label, out_depth)


@numba.njit(cache=True, inline="always")
def _mask_tile(o, dirs, H, W, tx, ty, caps, cand, nc, last, out_mask):  # pragma: no cover - compiled
    """Mode 0 of :func:`_raycast` on one sub-tile (``tx``, ``ty`` in sub-tiles): a pixel is set when any of its
    ``nc`` candidate capsules is hit, capsule ``last`` (the last hit of the tile, -1: none) tried first, as
    neighbours share one (a hit of any capsule is the answer, candidate or not); returns the last hit."""
    for py in range(ty * SUB, min(ty * SUB + SUB, H)):
        for px in range(tx * SUB, min(tx * SUB + SUB, W)):
            p = py * W + px
            dx, dy, dz = dirs[p, 0], dirs[p, 1], dirs[p, 2]
            if last >= 0 and _any_hit(o[0], o[1], o[2], dx, dy, dz, caps[last]):
                out_mask[py, px] = 255
                continue
            for j in range(nc):
                c = cand[j]
                if c != last and _any_hit(o[0], o[1], o[2], dx, dy, dz, caps[c]):
                    out_mask[py, px] = 255
                    last = c
                    break
    return last


@numba.njit(cache=True, inline="always")
def _raycast_tile(o, dirs, H, W, tx, ty, caps, cand, nc, mode, colors, light, zaxis,
                  out_rgb, out_mask, out_label, out_depth):  # pragma: no cover - compiled
    """Modes 1 and 2 of :func:`_raycast` on one sub-tile (``tx``, ``ty`` in sub-tiles) against its ``nc``
    candidate capsules."""
    for py in range(ty * SUB, min(ty * SUB + SUB, H)):
        for px in range(tx * SUB, min(tx * SUB + SUB, W)):
            p = py * W + px
            dx, dy, dz = dirs[p, 0], dirs[p, 1], dirs[p, 2]
            best_t, best_c = _nearest_hit(o, dx, dy, dz, caps, cand, nc, False)
            if best_c < 0:
                continue
            out_mask[py, px] = 255
            out_label[py, px] = best_c
            out_depth[py, px] = best_t * (dx * zaxis[0] + dy * zaxis[1] + dz * zaxis[2])
            if mode == 2:
                hx, hy, hz = o[0] + best_t * dx, o[1] + best_t * dy, o[2] + best_t * dz
                nx, ny, nz = _normal(hx, hy, hz, caps[best_c])
                dl = nx * light[0] + ny * light[1] + nz * light[2]
                dv = -(nx * dx + ny * dy + nz * dz)
                shade = 0.2 + 0.45 * max(dl, 0.0) + 0.35 * max(dv, 0.0)
                if shade > 1.0:
                    shade = 1.0
                for k in range(3):
                    out_rgb[py, px, k] = np.uint8(min(255.0, colors[best_c, k] * shade + 0.5))


@numba.njit(cache=True, nogil=True)
def raycast_at(o, dirs, W, axes, tcos, tsin, caps, bs, nb, zaxis, px, py, out_label,
               out_depth):  # pragma: no cover - compiled
    """Mode 1 of :func:`_raycast` at the pixels ``(px[i], py[i])`` only: the same tile candidates, the same
    nearest hit, the same label and depth. A tile's candidates are found again only when the tile
    changes (a contour's pixels come tile by tile)."""
    ntx = (W + 7) // 8
    C = caps.shape[0]
    cand = np.empty(C, np.int64)
    all_caps = np.arange(C)
    last, nc = -1, 0
    for i in range(px.shape[0]):
        tile = (py[i] // 8) * ntx + px[i] // 8
        if tile != last:
            nc = _tile_candidates_of(o, axes[tile], tcos[tile], tsin[tile], bs, nb, all_caps, C, cand)
            last = tile
        p = py[i] * W + px[i]
        dx, dy, dz = dirs[p, 0], dirs[p, 1], dirs[p, 2]
        best_t, best_c = _nearest_hit(o, dx, dy, dz, caps, cand, nc, False)
        if best_c < 0:
            continue
        out_label[i] = best_c
        out_depth[i] = best_t * (dx * zaxis[0] + dy * zaxis[1] + dz * zaxis[2])


# ---------------------------------------------------------------------- public API
def _prepare(camera: Any, endpoints: Any, radii: Any, capsules: tuple | None = None):
    if not isinstance(camera, Camera):
        raise VisionError(f"camera: expected a Camera, received {type(camera).__name__}")
    caps, bs, nb = capsule_data(endpoints, radii) if capsules is None else capsules
    return _camera_data(camera), caps, bs, nb


def _run(camera, cd, caps, bs, nb, mode, colors, light, rgb):
    o, dirs, axes, tcos, tsin, zaxis, saxes, scos, ssin, qaxes, qcos, qsin = cd
    H, W = camera.height, camera.width
    mask = np.zeros((H, W), np.uint8)
    if mode == 0:       # the mask only: the kernel never writes labels or depths
        label, depth = np.full((1, 1), -1, np.int32), np.full((1, 1), np.nan, np.float32)
    else:
        label = np.full((H, W), -1, np.int32)
        depth = np.full((H, W), np.nan, np.float32)
    if caps.shape[0]:
        _raycast(o, dirs, H, W, axes, tcos, tsin, saxes, scos, ssin, qaxes, qcos, qsin, caps, bs, nb, mode, colors,
                 light, zaxis, rgb, mask, label, depth)
    return mask, label, depth


def render(camera: Camera, endpoints: Any, radii: Any, colors: Any = None, *, background: Any = None,
           light_dir: Any = (0.3, -0.4, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Render shaded capsules over a background, with the exact silhouette.

    Parameters
    ----------
    camera : Camera
        The view (lens distortion included, see the module docstring).
    endpoints : (C, 2, 3) array_like
        End points ``p0, p1`` of each capsule, world metres.
    radii : (C, 2) array_like
        Radii ``r0, r1`` at the two ends (> 0), metres.
    colors : (C, 3) array_like of uint8, optional
        RGB per capsule; default :func:`clothing_colors` ``(C)``.
    background : (H, W, 3) uint8, optional
        Image behind the body (e.g. :func:`make_background`); default uniform grey 48.
    light_dir : (3,) array_like
        Direction towards the light, world frame (normalised here).

    Returns
    -------
    rgb : (H, W, 3) uint8
        The image (RGB order).
    mask : (H, W) uint8
        255 where a pixel-centre ray hits a capsule, else 0.
    """
    cd, caps, bs, nb = _prepare(camera, endpoints, radii)
    C = caps.shape[0]
    H, W = camera.height, camera.width
    if colors is None:
        col = clothing_colors(C).astype(np.float64)
    else:
        col = np.asarray(colors)
        if col.shape != (C, 3):
            raise VisionError(f"colors: expected shape ({C}, 3), received shape {col.shape}")
        if not np.issubdtype(col.dtype, np.integer) or col.min(initial=0) < 0 or col.max(initial=0) > 255:
            raise VisionError(f"colors: expected integers in [0, 255] (uint8), received dtype {col.dtype}")
        col = col.astype(np.float64)
    rgb = canvas(background, H, W, DEFAULT_GREY)
    light = np.asarray(light_dir, dtype=np.float64)
    if light.shape != (3,) or not np.all(np.isfinite(light)) or np.linalg.norm(light) == 0:
        raise VisionError(f"light_dir: expected a finite non-zero (3,) vector, received {light_dir!r}")
    light = light / np.linalg.norm(light)
    mask, _, _ = _run(camera, cd, caps, bs, nb, 2, col, light, rgb)
    return rgb, mask


def render_mask(camera: Camera, endpoints: Any, radii: Any, *, capsules: tuple | None = None) -> np.ndarray:
    """The silhouette only: ``(H, W)`` uint8, 255 where a pixel-centre ray hits a capsule (any hit);
    ``capsules``: :func:`capsule_data` of ``endpoints``, ``radii`` if already made."""
    cd, caps, bs, nb = _prepare(camera, endpoints, radii, capsules)
    dummy = np.zeros((1, 1, 3), np.uint8)
    mask, _, _ = _run(camera, cd, caps, bs, nb, 0, np.zeros((max(1, caps.shape[0]), 3)), np.zeros(3), dummy)
    return mask


def render_labels(camera: Camera, endpoints: Any, radii: Any) -> tuple[np.ndarray, np.ndarray]:
    """Index of the visible capsule and its depth per pixel.

    Returns
    -------
    labels : (H, W) int32
        Index of the nearest capsule hit by the pixel-centre ray, -1 for background.
    depth : (H, W) float32
        Camera-frame z of that hit (metres), NaN for background.
    """
    cd, caps, bs, nb = _prepare(camera, endpoints, radii)
    dummy = np.zeros((1, 1, 3), np.uint8)
    _, label, depth = _run(camera, cd, caps, bs, nb, 1, np.zeros((max(1, caps.shape[0]), 3)), np.zeros(3), dummy)
    return label, depth


def render_labels_at(camera: Camera, endpoints: Any, radii: Any, pixels: Any, *,
                     capsules: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`render_labels` at some pixels only, the same numbers: ``labels (k,)`` int32 and ``depth (k,)``
    float32 at the integer pixels ``pixels (k, 2)`` ``(u, v)`` (inside the image). Where a silhouette's
    contour is all that is wanted, :func:`render_mask` (which stops at a ray's first hit) and this cost
    less than labelling every pixel. ``capsules``: :func:`capsule_data` if already made."""
    cd, caps, bs, nb = _prepare(camera, endpoints, radii, capsules)
    pix = np.asarray(pixels)
    if pix.ndim != 2 or pix.shape[1] != 2 or not np.issubdtype(pix.dtype, np.integer):
        raise VisionError(f"pixels: expected integer (u, v) rows of shape (k, 2), received {pix.dtype} {pix.shape}")
    u, v = np.ascontiguousarray(pix[:, 0], np.int64), np.ascontiguousarray(pix[:, 1], np.int64)
    if len(u) and (u.min() < 0 or v.min() < 0 or u.max() >= camera.width or v.max() >= camera.height):
        raise VisionError(f"pixels: expected u in [0, {camera.width}) and v in [0, {camera.height}), received "
                          f"u {u.min()}..{u.max()}, v {v.min()}..{v.max()}")
    label = np.full(len(u), -1, np.int32)
    depth = np.full(len(u), np.nan, np.float32)
    if caps.shape[0] and len(u):
        o, dirs, axes, tcos, tsin, zaxis = cd[:6]
        raycast_at(o, dirs, camera.width, axes, tcos, tsin, caps, bs, nb, zaxis, u, v, label, depth)
    return label, depth


def ray_tiles(camera: Camera) -> tuple:
    """The renderer's cached per-camera data that :func:`raycast_at` takes (compiled callers label pixels with it
    directly): ``(origin (3,), directions (H*W, 3), tile axes (T, 3), tile cos (T,), tile sin (T,), optical axis
    (3,))``, as :func:`pixel_rays` and the 8x8-pixel tiles' ray cones. Read-only."""
    if not isinstance(camera, Camera):
        raise VisionError(f"camera: expected a Camera, received {type(camera).__name__}")
    return _camera_data(camera)[:6]


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The renderer's cached rays of ``camera``'s pixel centres: ``origin (3,)`` (the camera centre),
    ``directions (H*W, 3)`` (unit, world frame, lens distortion removed; row ``v * W + u`` is pixel
    ``(u, v)``: :meth:`Camera.ray` there) and the optical axis ``(3,)`` (depth = distance × its dot with the
    direction). Read-only: shared by every render of this camera."""
    if not isinstance(camera, Camera):
        raise VisionError(f"camera: expected a Camera, received {type(camera).__name__}")
    o, dirs, _, _, _, zaxis = _camera_data(camera)[:6]
    return o, dirs, zaxis
