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
from .silhouette_kernel import DETERMINISTIC_FASTMATH, SERIAL_PIPELINE, _fk_joint, _fk_one, _to_camera, _to_camera_joint

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
#: ``R0 (J, 3, 3), P0 (J, 3)``, per view the joints in camera coordinates ``CP0 (V, J, 4)``, the fixed capsules'
#: union bitmap ``Ufix`` (as ``fbits``) and its counts ``cnt (V, 2)``: ``|M|``, ``|M and F|``.
RasterStage = namedtuple("RasterStage", "R0 P0 CP0 Ufix cnt")


@intrinsic
def _popcount(typingctx, x):
    """Set bits of the uint64 ``x`` (LLVM's ``ctpop``: one instruction with POPCNT)."""
    sig = types.int64(types.uint64)

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])
    return sig, codegen


# A view's capsule set-up as a struct-of-arrays table over a block of at most ``NC`` capsules (row ``i`` of the
# table at ``S[i NC:]``, column ``k`` for capsule ``cl[k0 + k]``), so that one loop runs several capsules' dependent
# chains (square roots, divisions) side by side in vector lanes: IEEE division and square root round the same in a
# lane as in scalar code. One array with rows a compile-time distance apart, so that LLVM sees that the loop's reads
# and writes never meet within a vector (separate arrays would need a run-time overlap check per pair of rows, too
# many: the loop stayed scalar). Rows: the gathered inputs (the end points' normalized image coordinates, depths and
# radius factors of :func:`.silhouette_kernel._to_camera`, the ball radii); the pixel box (1.0 when the capsule has
# rows and columns in the image, its first pixel row, a multiple of the row stride, last row, first and last column);
# the span loop's constants (:func:`_spans`; float32 values): the tangent segments' row parameters (a segment switched
# off starts at t = 2 and stays there: never in [0, 1]), the discs' row offsets, squared radii and centres in pixels.
NC = 32
S_AX, S_AY, S_BX, S_BY, S_ZA, S_ZB, S_KA, S_KB, S_R0, S_R1 = range(10)
S_OK, S_J0, S_J1, S_U0, S_U1 = range(10, 15)
S_T10, S_T1R, S_X10, S_X1D, S_T20, S_T2R, S_X20, S_X2D, S_DA0, S_DB0, S_RA2, S_RB2, S_AXP, S_BXP = range(15, 29)
S_ROWS = 29

# The set-up loop without ``arcp`` (a division stays a division: with it LLVM may turn the divisions by one value into
# a reciprocal and products, which round differently) and without ``afn``; its own function so that its divisions
# need no zero checks (``error_model="numpy"``: every division here has a nonzero divisor, as in the scalar code it
# replaces), which would keep the loop scalar.
SETUP_FASTMATH = {"contract", "nnan", "ninf", "nsz"}


@numba.njit(cache=True, fastmath=SETUP_FASTMATH, error_model="numpy")
def _setup_caps(CP, caps, radii, cl, k0, nb, fx, cx, fy, cy, W, H, stride, S):  # pragma: no cover - compiled
    """The capsules ``cl[k0:k0 + nb]`` (``nb <= NC``) of one view into the table ``S`` (module constants ``S_*``):
    per capsule the 2-D hull of :func:`.silhouette_kernel._project_cap`, its pixel box and the span loop's constants,
    op for op the arithmetic of the scalar code this replaced (the same bits), without branches (a capsule with
    ``S_OK`` 0 may hold anything else)."""
    nc = numba.uint64(NC)
    for k in range(nb):      # gather (scalar): the end joints' projections
        c = cl[k0 + k]
        ja = caps[c, 0]
        jb = caps[c, 1]
        kk = numba.uint64(k)
        S[S_AX * nc + kk] = CP[ja, 0]
        S[S_AY * nc + kk] = CP[ja, 1]
        S[S_BX * nc + kk] = CP[jb, 0]
        S[S_BY * nc + kk] = CP[jb, 1]
        S[S_ZA * nc + kk] = CP[ja, 2]
        S[S_ZB * nc + kk] = CP[jb, 2]
        S[S_KA * nc + kk] = CP[ja, 3]
        S[S_KB * nc + kk] = CP[jb, 3]
        S[S_R0 * nc + kk] = radii[c, 0]
        S[S_R1 * nc + kk] = radii[c, 1]
    f32 = np.float32
    sf = float(stride)
    y_step = stride / fy        # the row step, normalized
    Hm = H - 1.0
    Wm = W - 1.0
    for k in range(nb):      # vectorized over the capsules
        kk = numba.uint64(k)
        ax = S[S_AX * nc + kk]
        ay = S[S_AY * nc + kk]
        bx0 = S[S_BX * nc + kk]
        by0 = S[S_BY * nc + kk]
        r0 = S[S_R0 * nc + kk]
        r1 = S[S_R1 * nc + kk]
        valid = (S[S_ZA * nc + kk] > 1.001 * r0) & (S[S_ZB * nc + kk] > 1.001 * r1)
        # the 2-D hull (_project_cap)
        ra = r0 * S[S_KA * nc + kk]
        rb = r1 * S[S_KB * nc + kk]
        dx = bx0 - ax
        dy = by0 - ay
        L = np.sqrt(dx * dx + dy * dy)
        long = L > 1e-12
        Ls = L if long else 1.0
        ux = dx / Ls if long else 1.0
        uy = dy / Ls if long else 0.0
        cone = L > abs(ra - rb) * (1.0 + 1e-9) + 1e-15
        sb = (ra - rb) / Ls if cone else 0.0
        ca = np.sqrt(1.0 - sb * sb)     # 1 where there is no cone (sb 0)
        # the pixel box
        bx = ax + L * ux
        by = ay + L * uy
        j0 = max(0.0, np.ceil(fy * min(ay - ra, by - rb) + cy))
        j1 = min(Hm, np.floor(fy * max(ay + ra, by + rb) + cy))
        q = np.ceil(j0 / sf)        # the first row on the stride: the least multiple q s >= j0 (small integers)
        q = q - 1.0 if (q - 1.0) * sf >= j0 else q
        q = q + 1.0 if q * sf < j0 else q
        j0 = q * sf
        u0 = max(0.0, np.floor(fx * min(ax - ra, bx - rb) + cx))
        u1 = min(Wm, np.ceil(fx * max(ax + ra, bx + rb) + cx))
        S[S_OK * nc + kk] = 1.0 if valid & (j1 >= j0) & (u1 >= u0) else 0.0
        S[S_J0 * nc + kk] = j0
        S[S_J1 * nc + kk] = j1
        S[S_U0 * nc + kk] = u0
        S[S_U1 * nc + kk] = u1
        # the span loop's constants: the tangent segments p1 -> q1, p2 -> q2 (tangent points at along r sb,
        # across +-r ca), a segment's row parameter t = t0 + r tr, its x = x0 + t xd pixels
        nx, ny = -uy, ux
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
        e1 = cone & (abs(d1) > 1e-12)   # a level segment: its ends lie on the discs
        e2 = cone & (abs(d2) > 1e-12)
        i1 = 1.0 / (d1 if e1 else 1.0) if e1 else 0.0
        i2 = 1.0 / (d2 if e2 else 1.0) if e2 else 0.0
        S[S_T10 * nc + kk] = f32((y0 - p1y) * i1) if e1 else f32(2.0)      # off: t = 2 + r 0 on every row
        S[S_T1R * nc + kk] = f32(y_step * i1)
        S[S_T20 * nc + kk] = f32((y0 - p2y) * i2) if e2 else f32(2.0)
        S[S_T2R * nc + kk] = f32(y_step * i2)
        S[S_X10 * nc + kk] = f32(fx * p1x + cx)
        S[S_X1D * nc + kk] = f32(fx * (q1x - p1x))
        S[S_X20 * nc + kk] = f32(fx * p2x + cx)
        S[S_X2D * nc + kk] = f32(fx * (q2x - p2x))
        S[S_DA0 * nc + kk] = f32(y0 - ay)     # row minus disc centre, normalized
        S[S_DB0 * nc + kk] = f32(y0 - by)
        S[S_RA2 * nc + kk] = f32(ra * ra)
        S[S_RB2 * nc + kk] = f32(rb * rb)
        S[S_AXP * nc + kk] = f32(fx * ax + cx)
        S[S_BXP * nc + kk] = f32(fx * bx + cx)


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _spans(S, k, nrow, dr, fx32, Wm, I0, I1):  # pragma: no cover - compiled
    """Pixel columns ``I0[r] .. I1[r]`` (inclusive; ``1, 0`` when empty) whose centres lie in the 2-D hull of
    capsule ``k`` of the set-up table (:func:`_setup_caps`) on its ``r``-th counted pixel row, ``r < nrow``
    (computed for whole 8-row vectors: ``I0``, ``I1`` have room); ``dr`` the row step, ``fx32`` the focal length,
    ``Wm`` the last column. The hull is the union of the two discs' chords and the two tangent segments' crossings
    of the row. Float32 over the rows (vectorized)."""
    f32 = np.float32
    nc = numba.uint64(NC)
    kk = numba.uint64(k)
    t10, t1r, x10, x1d = f32(S[S_T10 * nc + kk]), f32(S[S_T1R * nc + kk]), f32(S[S_X10 * nc + kk]), f32(S[S_X1D * nc + kk])
    t20, t2r, x20, x2d = f32(S[S_T20 * nc + kk]), f32(S[S_T2R * nc + kk]), f32(S[S_X20 * nc + kk]), f32(S[S_X2D * nc + kk])
    da0, db0 = f32(S[S_DA0 * nc + kk]), f32(S[S_DB0 * nc + kk])
    ra2, rb2, axp, bxp = f32(S[S_RA2 * nc + kk]), f32(S[S_RB2 * nc + kk]), f32(S[S_AXP * nc + kk]), f32(S[S_BXP * nc + kk])
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
        ok = (t >= zero) & (t <= one)
        lo = min(lo, x) if ok else lo
        hi = max(hi, x) if ok else hi
        t = t20 + rf * t2r
        x = x20 + t * x2d
        ok = (t >= zero) & (t <= one)
        lo = min(lo, x) if ok else lo
        hi = max(hi, x) if ok else hi
        u0 = max(np.ceil(lo), zero)                 # pixel centres u with lo <= u <= hi, in the image
        u1 = min(np.floor(hi), Wm)
        e = u0 <= u1
        k8 = numba.uint64(r)
        I0[k8] = np.int32(u0) if e else np.int32(1)
        I1[k8] = np.int32(u1) if e else np.int32(0)


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _raster_cap(S, k, U, u_off, stride, Hs, dr, fx32, Wm, I0, I1):  # pragma: no cover - compiled
    """OR capsule ``k``'s pixels of the set-up table (:func:`_setup_caps`; every ``stride``-th row) into the bitmap
    ``U[u_off:]`` (``Hs`` sampled rows per word column); returns ``(ok, jj0, jj1, w0, w1)``: whether it has rows
    and columns in the image, its sampled rows and word columns (inclusive)."""
    nc = numba.uint64(NC)
    kk = numba.uint64(k)
    if S[S_OK * nc + kk] == 0.0:
        return False, 0, 0, 0, 0
    j0 = int(S[S_J0 * nc + kk])
    j1 = int(S[S_J1 * nc + kk])
    u0 = int(S[S_U0 * nc + kk])
    u1 = int(S[S_U1 * nc + kk])
    nrow = (j1 - j0) // stride + 1
    jj0 = j0 // stride
    _spans(S, k, nrow, dr, fx32, Wm, I0, I1)
    w0 = u0 >> 6
    w1 = u1 >> 6
    ones = numba.uint64(0xFFFFFFFFFFFFFFFF)
    z64 = numba.uint64(0)
    for w in range(w0, w1 + 1):     # each word column the box meets: OR the rows' bits
        o = u_off + w * Hs + jj0
        b64 = np.int64(64 * w)
        for r in range(nrow):
            k8 = numba.uint64(r)
            a = min(max(np.int64(I0[k8]) - b64, np.int64(0)), np.int64(64))
            b = min(max(np.int64(I1[k8]) - b64 + 1, np.int64(0)), np.int64(64))
            m = (ones << numba.uint64(a)) & (ones if b == 64 else ~(ones << numba.uint64(b)))
            U[numba.uint64(o + r)] |= m if b > a else z64
    return True, jj0, jj0 + nrow - 1, w0, w1


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _raster_caps(CP, caps, radii, cl, n, cam_K, cov_wh, v, stride, S, U, u_off, Hs, nw, I0, I1):  # pragma: no cover
    """OR the capsules ``cl[:n]`` of view ``v`` into ``U[u_off:]`` (blocks of ``NC``: :func:`_setup_caps`, then
    :func:`_raster_cap` each); returns the sampled rows and word columns they touched ``(jlo, jhi, wlo, whi)``
    (``Hs, -1, nw, -1`` for none)."""
    fx, fy, cx, cy = cam_K[v, 0], cam_K[v, 1], cam_K[v, 2], cam_K[v, 3]
    W = float(cov_wh[v, 0])
    H = float(cov_wh[v, 1])
    dr, fx32, Wm = np.float32(stride / fy), np.float32(fx), np.float32(W - 1.0)
    jlo, jhi, wlo, whi = Hs, -1, nw, -1
    for k0 in range(0, n, NC):
        nb = min(NC, n - k0)
        _setup_caps(CP, caps, radii, cl, k0, nb, fx, cx, fy, cy, W, H, stride, S)
        for k in range(nb):
            ok, jj0, jj1, w0, w1 = _raster_cap(S, k, U, u_off, stride, Hs, dr, fx32, Wm, I0, I1)
            if ok:
                jlo, jhi, wlo, whi = min(jlo, jj0), max(jhi, jj1), min(wlo, w0), max(whi, w1)
    return jlo, jhi, wlo, whi


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
    cl = np.arange(C)
    S = np.empty(S_ROWS * NC)               # the capsules' set-up table (_setup_caps)
    U = np.zeros(Hs * nw + 8, np.uint64)    # the union bitmap, cleared while counted
    I0 = np.zeros(Hs + 8, np.int32)
    I1 = np.zeros(Hs + 8, np.int32)
    z64 = numba.uint64(0)
    for i in range(lo, hi):
        _fk_one(X[i], parents, offsets, ptr, dofs, axes, R, P)
        total = 0.0
        for v in range(V):
            _to_camera(P, cam_R, cam_t, v, CP)
            # the union's sampled rows and words
            jlo, jhi, wlo, whi = _raster_caps(CP, caps, radii, cl, C, cam_K, cov_wh, v, stride, S, U, 0, Hs, nw, I0, I1)
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
    Ufix = np.zeros(fbits.shape, np.uint64)
    cnt = np.zeros((V, 2), np.int64)
    I0 = np.zeros(Hs + 8, np.int32)
    I1 = np.zeros(Hs + 8, np.int32)
    cl = np.flatnonzero(~moving)            # the fixed capsules
    S = np.empty(S_ROWS * NC)
    for v in range(V):
        _to_camera(P, cam_R, cam_t, v, CP[v])
        jlo, jhi, wlo, whi = _raster_caps(CP[v], caps, radii, cl, cl.shape[0], cam_K, cov_wh, v, stride, S, Ufix[v], 0,
                                          Hs, nw, I0, I1)
        for w in range(wlo, whi + 1):
            for j in range(jlo, jhi + 1):
                u = Ufix[v, w * Hs + j]
                cnt[v, 0] += _popcount(u)
                cnt[v, 1] += _popcount(u & fbits[v, w * Hs + j])
    return R, P, CP, Ufix, cnt


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
    R0, P0, CP0, Ufix, cnt = stage
    n = X.shape[0]
    V = cam_R.shape[0]
    Hs = (fbits.shape[1] - 8) // nw
    Lv = fbits.shape[1]
    nm = mov_caps.shape[0]
    wsum = 0.0
    for v in range(V):
        wsum += view_w[v]
    for chunk in numba.prange(n_chunks):
        lo = chunk * n // n_chunks
        hi = (chunk + 1) * n // n_chunks
        R = R0.copy()
        P = P0.copy()
        CP = CP0.copy()
        S = np.empty(S_ROWS * NC)           # the moving capsules' set-up table (_setup_caps)
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
                for j in cam_joints:
                    _to_camera_joint(P, cam_R, cam_t, v, CPv, j)
                # the words the moving capsules touched
                jlo, jhi, wlo, whi = _raster_caps(CPv, caps, radii, mov_caps, nm, cam_K, cov_wh, v, stride, S, U,
                                                  v * Lv, Hs, nw, I0, I1)
                cm = cnt[v, 0]
                cmf = cnt[v, 1]
                fv = fbits[v]
                Uf = Ufix[v]
                for w in range(wlo, whi + 1):
                    for j in range(jlo, jhi + 1):   # branch-free: a word they left alone adds 0 (vectorizes)
                        k = numba.uint64(w * Hs + j)
                        kv = numba.uint64(v * Lv) + k
                        f = Uf[k]
                        d = U[kv] ^ f   # the moving capsules' new pixels (u holds f): |u| - |f| = |d|
                        cm += _popcount(d)
                        cmf += _popcount(d & fv[k])
                        U[kv] = f
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
        f = np.asarray(f)
        if f.dtype != np.bool_:
            f = f != 0
        nfg[v] = _pack_rows(f, int(stride), Hs, nw, fbits[v])
    return fbits, nfg, nw


@numba.njit(cache=True)
def _pack_rows(f, stride, Hs, nw, out):  # pragma: no cover - compiled
    """Word ``w * Hs + j`` of ``out`` ← pixels ``64 w … 64 w + 63`` of row ``j * stride`` of the bool image ``f`` (bit
    ``i`` = pixel ``64 w + i``; rows and columns outside ``f`` are 0): :func:`foreground_bits`' words of one view
    (what ``numpy.packbits(..., bitorder="little")`` gives, transposed to word-major). Returns the bits set."""
    H, W = f.shape
    n = 0
    for j in range(Hs):
        y = j * stride
        if y >= H:
            break
        for w in range(nw):
            x0 = 64 * w
            word = numba.uint64(0)
            for i in range(min(64, W - x0)):
                word |= numba.uint64(f[y, x0 + i]) << numba.uint64(i)
            out[w * Hs + j] = word
            n += _popcount(word)
    return n


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
