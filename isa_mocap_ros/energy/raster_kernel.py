"""Compiled kernels of the scanline silhouette energy (EA-vs-PF Eq. 4-5 counted on the pixel grid).

``SilhouetteEnergy(method="raster")`` (docs/energy.md, "Scanline raster"). Per pose and view the capsules
are projected as in :mod:`.silhouette_kernel` (the 2-D hull of two discs, the same helpers), and each
hull is **rasterized by scanlines** into the view's union bitmap: the hull is convex (the union of the
discs ``D(a + t (b - a), r_a + t (r_b - r_a))``, ``t`` in [0, 1]), so its intersection with a pixel row is
one interval, the extent of the two disc chords and of the two tangent segments' crossings of the row;
the pixel centres inside it are OR-ed into the row's 64-bit words. Overlapping capsules cost nothing
extra (the OR counts a pixel once), which is what the sampled kernel paid for per overlapping pair.
Then, over the union's rows and words, two population counts give both terms of Eq. 4 exactly on the
pixel grid: ``|M| = popcount(U)``, ``|M ∩ F| = popcount(U & F)``, ``|F|`` fixed per frame::

    f_v = (|M| - |M ∩ F|) / (2 |M|) + (|F| - |M ∩ F|) / (2 |F|)

No random sample. What remains of the exact reference's difference is the disc approximation of the
projected balls (docs/energy.md, IoU 0.998) and, with a row stride ``s > 1``, counting every ``s``-th
pixel row only (``F`` then counted on the same rows). Pinhole views only (a pixel row is a line of the
undistorted plane only without lens distortion): a distorted camera's masks are resampled onto its pinhole twin
first (:mod:`.undistort`), and the kernel counts there.

Layout: a view's bitmap is word-plane major, ``U[w * Hs + j]`` = pixels ``64 w .. 64 w + 63`` of sampled row
``j`` (bit ``i`` = pixel ``64 w + i``), so one capsule's rows in one word column are contiguous and the OR
vectorizes over rows.
"""
from __future__ import annotations

import warnings
from collections import namedtuple

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from ..numba_cache import register_dependent_cache
from . import silhouette_kernel
from .silhouette_kernel import (DETERMINISTIC_FASTMATH, G_AX, G_AY, G_CA, G_COLS, G_CONE, G_LEN, G_RA, G_RB, G_SB,
                                G_UX, G_UY, G_VALID, SERIAL_PIPELINE, _fk_joint, _fk_one, _project_cap, _project_caps,
                                _to_camera, _to_camera_joint)

__all__ = ["Raster", "RasterStage", "raster_batch", "raster_batch_serial", "raster_restrict_prepare", "raster_restricted",
           "foreground_bits", "raster_static"]

# numba keys a cached function on its own file only: the kernels here compile silhouette_kernel's projection into
# their machine code, so an edit there must also miss this module's cache
register_dependent_cache(__file__, (silhouette_kernel,))

# the serial kernel has no parallel loop by design (numba warns at compile time), as in silhouette_kernel
warnings.filterwarnings("ignore", message=r"(?s).*no transformation for parallel execution.*raster_kernel\.py",
                        category=numba.NumbaPerformanceWarning)

#: The frame's foreground for the scanline kernel: ``fbits (V, NW * Hs + 8)`` uint64, the mask's bits of
#: every ``stride``-th row (word-plane major, module docstring; 8 spare words); ``nfg (V,)`` int64 foreground
#: pixels on those rows; ``nw`` words per row (``ceil(Wmax / 64)``); ``stride`` the row stride.
Raster = namedtuple("Raster", "fbits nfg nw stride")

#: What the poses of a restriction share (:func:`raster_restrict_prepare`): forward kinematics of the base pose
#: ``R0 (J, 3, 3), P0 (J, 3)``, per view the joints in camera coordinates ``CP0 (V, J, 4)`` and the capsules'
#: hulls ``G0 (V, C, G_COLS)``, the fixed capsules' union bitmap ``Ufix`` (as ``fbits``) and its counts ``cnt (V,
#: 2)``: ``|M|``, ``|M and F|``.
RasterStage = namedtuple("RasterStage", "R0 P0 CP0 G0 Ufix cnt")


@intrinsic
def _popcount(typingctx, x):
    """Set bits of the uint64 ``x`` (LLVM's ``ctpop``: one instruction with POPCNT)."""
    sig = types.int64(types.uint64)

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])
    return sig, codegen


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _spans(G, c, j0, nrow, stride, fx, cx, fy, cy, W, I0, I1):  # pragma: no cover - compiled
    """Pixel columns ``I0[r] .. I1[r]`` (inclusive; ``1, 0`` when empty) whose centres lie in capsule ``c``'s
    2-D hull (``G``, :func:`.silhouette_kernel._project_cap`) on pixel rows ``j0 + r stride``, ``r < nrow``
    (computed for whole 8-row vectors: ``I0``, ``I1`` have room). Float32 over the rows (vectorized)."""
    f32 = np.float32
    ax, ay, ux, uy, L, ra, rb = G[c, G_AX], G[c, G_AY], G[c, G_UX], G[c, G_UY], G[c, G_LEN], G[c, G_RA], G[c, G_RB]
    bx = ax + L * ux
    by = ay + L * uy
    sb, ca = G[c, G_SB], G[c, G_CA]
    cone = G[c, G_CONE] != 0.0
    nx, ny = -uy, ux
    # the tangent segments p1 -> q1 and p2 -> q2 (tangent points at along r sb, across +-r ca)
    p1x = ax + ra * (sb * ux + ca * nx)
    p1y = ay + ra * (sb * uy + ca * ny)
    q1x = bx + rb * (sb * ux + ca * nx)
    q1y = by + rb * (sb * uy + ca * ny)
    p2x = ax + ra * (sb * ux - ca * nx)
    p2y = ay + ra * (sb * uy - ca * ny)
    q2x = bx + rb * (sb * ux - ca * nx)
    q2y = by + rb * (sb * uy - ca * ny)
    d1 = q1y - p1y
    d2 = q2y - p2y
    y0 = (j0 - cy) / fy         # the first row's centre, normalized
    dyr = stride / fy           # row step, normalized
    i1 = 1.0 / d1 if cone and abs(d1) > 1e-12 else 0.0    # a level segment: its ends lie on the discs
    i2 = 1.0 / d2 if cone and abs(d2) > 1e-12 else 0.0
    # segment k at row r: t = t0 + r tr along it, x = x0 + t xd pixels; t1lo 2 switches a segment off
    t10, t1r = f32((y0 - p1y) * i1), f32(dyr * i1)
    t20, t2r = f32((y0 - p2y) * i2), f32(dyr * i2)
    x10, x1d = f32(fx * p1x + cx), f32(fx * (q1x - p1x))
    x20, x2d = f32(fx * p2x + cx), f32(fx * (q2x - p2x))
    t1lo = f32(0.0) if i1 != 0.0 else f32(2.0)
    t2lo = f32(0.0) if i2 != 0.0 else f32(2.0)
    da0, db0, dr = f32(y0 - ay), f32(y0 - by), f32(dyr)     # row minus disc centre, normalized
    ra2, rb2, fx32 = f32(ra * ra), f32(rb * rb), f32(fx)
    axp, bxp = f32(fx * ax + cx), f32(fx * bx + cx)
    Wm = f32(W - 1.0)
    zero, one, big = f32(0.0), f32(1.0), f32(1e9)
    for r in range((nrow + 7) & ~7):
        rf = f32(np.int32(r))       # the same value; int32 -> float32 is one vector instruction, int64 is not (AVX2)
        lo = big
        hi = -big
        da = da0 + rf * dr
        ha = ra2 - da * da                          # disc a's chord: ax +- fx sqrt(ra^2 - da^2)
        sa = fx32 * np.sqrt(max(ha, zero))
        lo = min(lo, axp - sa) if ha >= zero else lo
        hi = max(hi, axp + sa) if ha >= zero else hi
        db = db0 + rf * dr
        hb = rb2 - db * db
        sq = fx32 * np.sqrt(max(hb, zero))
        lo = min(lo, bxp - sq) if hb >= zero else lo
        hi = max(hi, bxp + sq) if hb >= zero else hi
        t = t10 + rf * t1r                          # the tangent segments' crossings
        x = x10 + t * x1d
        ok = (t >= t1lo) & (t <= one)
        lo = min(lo, x) if ok else lo
        hi = max(hi, x) if ok else hi
        t = t20 + rf * t2r
        x = x20 + t * x2d
        ok = (t >= t2lo) & (t <= one)
        lo = min(lo, x) if ok else lo
        hi = max(hi, x) if ok else hi
        u0 = max(np.ceil(lo), zero)                 # pixel centres u with lo <= u <= hi, in the image
        u1 = min(np.floor(hi), Wm)
        e = u0 <= u1
        k = numba.uint64(r)
        I0[k] = np.int32(u0) if e else np.int32(1)
        I1[k] = np.int32(u1) if e else np.int32(0)


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _raster_cap(G, c, U, u_off, stride, Hs, fx, cx, fy, cy, W, H, I0, I1):  # pragma: no cover - compiled
    """OR capsule ``c``'s pixels (every ``stride``-th row) into the bitmap ``U[u_off:]`` (``Hs`` sampled rows per
    word column); returns ``(ok, jj0, jj1, w0, w1)``: whether it has rows and columns in the image, its sampled
    rows and word columns (inclusive)."""
    if G[c, G_VALID] == 0.0:
        return False, 0, 0, 0, 0
    ax, ay, L, ra, rb = G[c, G_AX], G[c, G_AY], G[c, G_LEN], G[c, G_RA], G[c, G_RB]
    bx = ax + L * G[c, G_UX]
    by = ay + L * G[c, G_UY]
    j0 = max(0, int(np.ceil(fy * min(ay - ra, by - rb) + cy)))
    j1 = min(H - 1, int(np.floor(fy * max(ay + ra, by + rb) + cy)))
    j0 = (j0 + stride - 1) // stride * stride
    if j1 < j0:
        return False, 0, 0, 0, 0
    u0 = max(0, int(np.floor(fx * min(ax - ra, bx - rb) + cx)))
    u1 = min(W - 1, int(np.ceil(fx * max(ax + ra, bx + rb) + cx)))
    if u1 < u0:
        return False, 0, 0, 0, 0
    nrow = (j1 - j0) // stride + 1
    jj0 = j0 // stride
    _spans(G, c, j0, nrow, stride, fx, cx, fy, cy, float(W), I0, I1)
    w0 = u0 >> 6
    w1 = u1 >> 6
    ones = numba.uint64(0xFFFFFFFFFFFFFFFF)
    z64 = numba.uint64(0)
    for w in range(w0, w1 + 1):     # each word column the box meets: OR the rows' bits
        o = u_off + w * Hs + jj0
        b64 = np.int64(64 * w)
        for r in range(nrow):
            k = numba.uint64(r)
            a = min(max(np.int64(I0[k]) - b64, np.int64(0)), np.int64(64))
            b = min(max(np.int64(I1[k]) - b64 + 1, np.int64(0)), np.int64(64))
            m = (ones << numba.uint64(a)) & (ones if b == 64 else ~(ones << numba.uint64(b)))
            U[numba.uint64(o + r)] |= m if b > a else z64
    return True, jj0, jj0 + nrow - 1, w0, w1


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _raster_rows(X, lo, hi, body, views, raster, out):  # pragma: no cover - compiled
    """:func:`raster_batch` of the rows ``lo:hi`` of ``X`` (one work unit, with its own scratch)."""
    parents, offsets, ptr, dofs, axes, caps, radii = body
    cam_R, cam_t, cam_K, cam_D, cam_hasd, cov, cov_wh, view_w = views
    fbits, nfg, nw, stride = raster
    J = parents.shape[0]
    C = caps.shape[0]
    V = cam_R.shape[0]
    Hs = (fbits.shape[1] - 8) // nw         # sampled rows per word column
    wsum = 0.0
    for v in range(V):
        wsum += view_w[v]
    R = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    CP = np.empty((J, 4))
    G = np.empty((C, G_COLS))
    U = np.zeros(Hs * nw + 8, np.uint64)    # the union bitmap, cleared while counted
    I0 = np.zeros(Hs + 8, np.int32)
    I1 = np.zeros(Hs + 8, np.int32)
    z64 = numba.uint64(0)
    for i in range(lo, hi):
        _fk_one(X[i], parents, offsets, ptr, dofs, axes, R, P)
        total = 0.0
        for v in range(V):
            _to_camera(P, cam_R, cam_t, v, CP)
            _project_caps(CP, caps, radii, G)
            fx, fy, cx, cy = cam_K[v, 0], cam_K[v, 1], cam_K[v, 2], cam_K[v, 3]
            W = cov_wh[v, 0]
            H = cov_wh[v, 1]
            jlo, jhi, wlo, whi = Hs, -1, nw, -1     # the union's sampled rows and words
            for c in range(C):
                ok, jj0, jj1, w0, w1 = _raster_cap(G, c, U, 0, stride, Hs, fx, cx, fy, cy, W, H, I0, I1)
                if ok:
                    jlo, jhi, wlo, whi = min(jlo, jj0), max(jhi, jj1), min(wlo, w0), max(whi, w1)
            cm = 0      # |M| and |M and F| on the sampled rows
            cmf = 0
            fv = fbits[v]
            for w in range(wlo, whi + 1):
                for j in range(jlo, jhi + 1):     # branch-free: an empty word adds 0 (vectorizes)
                    k = numba.uint64(w * Hs + j)
                    u = U[k]
                    cm += _popcount(u)
                    cmf += _popcount(u & fv[k])
                    U[k] = z64
            t1 = (cm - cmf) / cm if cm > 0 else 1.0     # no model pixel: Eq. 4's 0/0, its worst value
            t2 = (nfg[v] - cmf) / nfg[v] if nfg[v] > 0 else 1.0
            total += view_w[v] * (0.5 * t1 + 0.5 * t2)
        out[i] = total / wsum


@numba.njit(parallel=True, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def raster_batch(X, body, views, raster, n_chunks, out):  # pragma: no cover - compiled
    """Eq. 5 of poses ``X (n, D)`` into ``out (n,)`` counted on the pixel grid (module docstring);
    ``body``, ``views`` as :func:`.silhouette_kernel.silhouette_batch` (full-resolution pinhole cameras;
    ``cov``, ``cam_D`` unused), ``raster`` a :data:`Raster`; ``n_chunks`` work units in parallel."""
    n = X.shape[0]
    for chunk in numba.prange(n_chunks):
        _raster_rows(X, chunk * n // n_chunks, (chunk + 1) * n // n_chunks, body, views, raster, out)


@numba.njit(parallel=SERIAL_PIPELINE, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def raster_batch_serial(X, body, views, raster, n_chunks, out):  # pragma: no cover - compiled
    """:func:`raster_batch` on the calling thread (a few poses; the same bits); ``n_chunks`` is ignored."""
    _raster_rows(X, 0, X.shape[0], body, views, raster, out)


@numba.njit(parallel=SERIAL_PIPELINE, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def raster_restrict_prepare(x, body, views, raster, moving):  # pragma: no cover - compiled
    """:data:`RasterStage` of the base pose ``x``: what the poses of a restriction share, the capsules not in
    ``moving (C,)`` (bool) rasterized once (the same helpers as :func:`raster_batch`, so the same bits)."""
    parents, offsets, ptr, dofs, axes, caps, radii = body
    cam_R, cam_t, cam_K, cam_D, cam_hasd, cov, cov_wh, view_w = views
    fbits, nfg, nw, stride = raster
    J = parents.shape[0]
    C = caps.shape[0]
    V = cam_R.shape[0]
    Hs = (fbits.shape[1] - 8) // nw
    R = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    _fk_one(x, parents, offsets, ptr, dofs, axes, R, P)
    CP = np.zeros((V, J, 4))
    G = np.zeros((V, C, G_COLS))
    Ufix = np.zeros(fbits.shape, np.uint64)
    cnt = np.zeros((V, 2), np.int64)
    I0 = np.zeros(Hs + 8, np.int32)
    I1 = np.zeros(Hs + 8, np.int32)
    for v in range(V):
        _to_camera(P, cam_R, cam_t, v, CP[v])
        _project_caps(CP[v], caps, radii, G[v])
        jlo, jhi, wlo, whi = Hs, -1, nw, -1
        for c in range(C):
            if not moving[c]:
                ok, jj0, jj1, w0, w1 = _raster_cap(G[v], c, Ufix[v], 0, stride, Hs, cam_K[v, 0], cam_K[v, 2],
                                                   cam_K[v, 1], cam_K[v, 3], cov_wh[v, 0], cov_wh[v, 1], I0, I1)
                if ok:
                    jlo, jhi, wlo, whi = min(jlo, jj0), max(jhi, jj1), min(wlo, w0), max(whi, w1)
        for w in range(wlo, whi + 1):
            for j in range(jlo, jhi + 1):
                u = Ufix[v, w * Hs + j]
                cnt[v, 0] += _popcount(u)
                cnt[v, 1] += _popcount(u & fbits[v, w * Hs + j])
    return R, P, CP, G, Ufix, cnt


@numba.njit(parallel=True, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def raster_restricted(X, restriction, body, views, raster, stage, n_chunks, out):  # pragma: no cover - compiled
    """:func:`raster_batch` for poses ``X (n, D)`` equal to ``x_base`` at ``fixed_dofs`` (the
    :data:`.silhouette_kernel.Restriction` ``restriction``; ``mov_ci``, ``moving_ci`` unused), from the
    :data:`RasterStage` ``stage``: per pose forward kinematics of ``fk_joints``, projection of ``cam_joints`` and of
    the moving capsules, which are OR-ed into a copy of the fixed capsules' bitmap; the counts are the stored ones
    plus the popcount differences of the words they touched (restored after): the same integers as the full
    kernel, so the same bits. A row that differs from ``x_base`` at a fixed coordinate gets ``out = -1``."""
    x_base, fixed_dofs, fk_joints, cam_joints, mov_caps, mov_ci, moving_ci = restriction
    parents, offsets, ptr, dofs, axes, caps, radii = body
    cam_R, cam_t, cam_K, cam_D, cam_hasd, cov, cov_wh, view_w = views
    fbits, nfg, nw, stride = raster
    R0, P0, CP0, G0, Ufix, cnt = stage
    n = X.shape[0]
    V = cam_R.shape[0]
    Hs = (fbits.shape[1] - 8) // nw
    Lv = fbits.shape[1]
    nm = mov_caps.shape[0]
    z64 = numba.uint64(0)
    wsum = 0.0
    for v in range(V):
        wsum += view_w[v]
    for chunk in numba.prange(n_chunks):
        lo = chunk * n // n_chunks
        hi = (chunk + 1) * n // n_chunks
        R = R0.copy()
        P = P0.copy()
        CP = CP0.copy()
        G = G0.copy()
        U = Ufix.copy().reshape(-1)         # view v at v * Lv
        I0 = np.zeros(Hs + 8, np.int32)
        I1 = np.zeros(Hs + 8, np.int32)
        for i in range(lo, hi):
            bad = False
            for d in fixed_dofs:
                bad |= X[i, d] != x_base[d]
            if bad:
                out[i] = -1.0
                continue
            for j in fk_joints:
                _fk_joint(X[i], j, parents, offsets, ptr, dofs, axes, R, P)
            total = 0.0
            for v in range(V):
                CPv = CP[v]
                Gv = G[v]
                for j in cam_joints:
                    _to_camera_joint(P, cam_R, cam_t, v, CPv, j)
                fx, fy, cx, cy = cam_K[v, 0], cam_K[v, 1], cam_K[v, 2], cam_K[v, 3]
                jlo, jhi, wlo, whi = Hs, -1, nw, -1     # the words the moving capsules touched
                for m in range(nm):
                    c = mov_caps[m]
                    _project_cap(CPv, caps, radii, Gv, c)
                    ok, jj0, jj1, w0, w1 = _raster_cap(Gv, c, U, v * Lv, stride, Hs, fx, cx, fy, cy, cov_wh[v, 0],
                                                       cov_wh[v, 1], I0, I1)
                    if ok:
                        jlo, jhi, wlo, whi = min(jlo, jj0), max(jhi, jj1), min(wlo, w0), max(whi, w1)
                cm = cnt[v, 0]
                cmf = cnt[v, 1]
                for w in range(wlo, whi + 1):
                    for j in range(jlo, jhi + 1):
                        k = w * Hs + j
                        u = U[v * Lv + k]
                        f = Ufix[v, k]
                        d = u ^ f   # the moving capsules' new pixels (u holds f): |u| - |f| = |d|
                        if d != z64:    # a word they left alone changes neither count and needs no restoring
                            cm += _popcount(d)
                            cmf += _popcount(d & fbits[v, k])
                            U[v * Lv + k] = f
                t1 = (cm - cmf) / cm if cm > 0 else 1.0
                t2 = (nfg[v] - cmf) / nfg[v] if nfg[v] > 0 else 1.0
                total += view_w[v] * (0.5 * t1 + 0.5 * t2)
            out[i] = total / wsum


def foreground_bits(F: list, stride: int) -> tuple[np.ndarray, np.ndarray, int]:
    """``(fbits, nfg, nw)`` of :data:`Raster` from the foreground masks ``F`` (one bool ``(H, W)`` per view)."""
    H = max(f.shape[0] for f in F)
    W = max(f.shape[1] for f in F)
    nw = (W + 63) // 64
    Hs = -(-H // stride)
    fbits = np.zeros((len(F), nw * Hs + 8), np.uint64)
    nfg = np.zeros(len(F), np.int64)
    for v, f in enumerate(F):
        b = np.zeros((Hs * stride, nw * 64), np.uint8)
        b[:f.shape[0], :f.shape[1]] = f != 0
        b = b[::stride]
        words = np.packbits(b, axis=1, bitorder="little").view("<u8")      # (Hs, nw): bit i = pixel 64 w + i
        fbits[v, :nw * Hs] = words.T.reshape(-1)
        nfg[v] = int(np.count_nonzero(b))
    return fbits, nfg, nw


def raster_static(cameras: list, F: list, stride: int) -> dict:
    """The scanline kernel's inputs of one frame's usable views: ``cameras`` (pinhole, full resolution) and
    their foreground masks ``F``: the :data:`.silhouette_kernel.Views` arrays (``cov``, ``cam_D`` empty) and the
    :data:`Raster` arrays."""
    V = len(cameras)
    fbits, nfg, nw = foreground_bits(F, stride)
    return {"cam_R": np.ascontiguousarray([c.R for c in cameras]), "cam_t": np.ascontiguousarray([c.t for c in cameras]),
            "cam_K": np.ascontiguousarray([[c.fx, c.fy, c.cx, c.cy, 1.0] for c in cameras]),
            "cam_D": np.zeros((V, 8)), "cam_hasd": np.zeros(V, np.bool_), "cov": np.zeros((V, 8), np.uint8),
            "cov_wh": np.array([[c.width, c.height, c.width] for c in cameras], np.int64),
            "fbits": fbits, "nfg": nfg, "nw": nw, "stride": int(stride)}
