"""Compiled kernels of the fast silhouette energy (EA-vs-PF Eq. 4-5) and its forward kinematics.

Everything here is numba (``cache=True``); :mod:`.silhouette` prepares the arrays. Geometry is done
in the **normalized undistorted image plane** of each camera (``x = X_c / Z_c``, ``y = Y_c / Z_c``).
Per particle and view:

1. forward kinematics (same recursion as :mod:`isa_mocap_ros.body.kinematics`, positions only);
2. each capsule (hull of the balls ``B(p0, r0)``, ``B(p1, r1)``, docs/vision.md) is projected to the
   2-D hull of two discs: centres ``p_k`` projected, radii ``rho_k = (r_k / z_k) sqrt(l_k / z_k)``
   (``z_k`` depth, ``l_k`` distance of the ball centre from the camera; the disc has the area of
   the ball's projected ellipse to first order in ``r / l``);
3. term 1 of Eq. 4 (model pixels not on foreground) from a fixed template of stratified points in
   each capsule's bounding rectangle: a point counts for the silhouette if it lies in its own
   capsule's 2-D hull, in no *earlier* capsule's hull (capsules in a fixed order, biggest first,
   so overlaps count once) and inside the image; it is weighted by ``area(rectangle) / k_c``
   (so the weighted count estimates the silhouette area without bias); the term is the weighted
   mean of ``1 - F(p)`` with ``F`` the (area-averaged, downsampled) foreground coverage at ``p``;
4. term 2 (foreground pixels not covered) from a fixed sample of foreground pixel centres (drawn
   per frame, sorted by y and binned so that each capsule visits only the run of points in its
   box's y range), tested against the capsules' 2-D hulls with a branch-free (vectorized) test;
   or, when no sample is given (``fg_n[v] == 0``), from the template points as
   ``1 - (integral of F over the silhouette) / |F|``.

``f_v = term1 / 2 + term2 / 2``; a view where the model covers no sampled point gets term 1 = 1/2
(Eq. 4 is undefined there; the exact reference makes the same choice). The output is the mean
over the views passed in (Eq. 5), weighted by ``view_w`` (all ones: Eq. 5 to the bit).
"""
from __future__ import annotations

import warnings

import numba
import numpy as np

from collections import namedtuple

from isa_mocap_ros.body import kinematics
from isa_mocap_ros.body.kinematics import rodrigues_into
from isa_mocap_ros.numba_cache import register_dependent_cache

# ---------------------------------------------------------------------- argument bundles
# The kernels take their arrays in a few named tuples (numba types each as a tuple of its arrays' types
# and unpacks it at compile time: the same machine code as separate arguments, measured, docs/energy.md).
#: The body: kinematic tables (``body.kinematics.kinematic_tables``) and capsules. ``parents (J,)``,
#: ``offsets (J, 3)``, ``ptr (J + 1,)``, ``dofs``, ``axes``; ``caps (C, 2)`` int64 joint indices; ``radii
#: (C, 2)`` float64 metres.
Body = namedtuple("Body", "parents offsets ptr dofs axes caps radii")
#: The views of the current masks: ``cam_R, cam_t (V, 3, 3), (V, 3)`` world -> camera; ``cam_K (V, 5)`` fx,
#: fy, cx, cy of the downsampled camera and the scale of ``cov``; ``cam_D (V, 8)``; ``cam_hasd (V,)`` bool;
#: ``cov (V, Hmax * Wmax + 8)`` foreground coverage of the downsampled mask, rows of ``Wmax``, times ``1 /
#: cam_K[v, 4]`` (uint8 0/1 at full resolution, float32 fractions when downsampled), then 8 zeros (the
#: last one is the pixel that points not counted read); ``cov_wh (V, 3)`` int64 width, height of the
#: downsampled image and ``Wmax``; ``view_w (V,)`` float64 weights of the views, >= 0 with a positive sum
#: (Eq. 5 becomes ``sum_v w_v f_v / sum_v w_v``; all ones: Eq. 5 itself, to the bit).
Views = namedtuple("Views", "cam_R cam_t cam_K cam_D cam_hasd cov cov_wh view_w")
#: Term 1's template: ``order (C,)`` int64 processing order of the capsules (a point counts for the first
#: one containing it); ``tmpl_a, tmpl_s (T + 8,)`` float32 template points (8 padding points at the end),
#: along the capsule axis in [0, 1] and across it in [-1, 1]; capsule ``c`` owns ``tmpl_ptr[c]:tmpl_ptr[c
#: + 1]`` (``tmpl_ptr (C + 1,)``), laid out as ``tmpl_na[c]`` strata along the axis (in increasing order)
#: of equally many points each.
Template = namedtuple("Template", "order tmpl_a tmpl_s tmpl_ptr tmpl_na")
#: Term 2's foreground sample: ``fg_x, fg_y (V * S * Ms,)`` float32 normalized foreground sample points in
#: ``S`` vertical strips (x quantiles) per view, strip ``r = v S + s`` at ``r Ms``, sorted by y; ``Ms`` a
#: multiple of 8, padded with points far outside the image; ``fg_n (V,)`` int64 sample size per view
#: (``fg_n[v] == 0`` selects the area estimate of term 2 for view ``v``); ``fg_tab (V S, NB + 1)`` int64,
#: ``fg_tab[r, b]`` = first point of strip ``r`` with ``y >= y0 + b dy`` (the strip's count at NB);
#: ``fg_bins (V S, 2)`` ``y0, 1 / dy`` of those bins; ``fg_xr (V S, 2)`` x range of each strip; ``fg_area
#: (V,)`` area of the foreground in the normalized plane (full-resolution pixels).
Foreground = namedtuple("Foreground", "fg_x fg_y fg_n fg_tab fg_bins fg_xr fg_area")
#: A restriction (:func:`silhouette_restricted`): the base pose ``x_base (D,)``, the coordinates fixed at
#: it ``fixed_dofs``, the joints to recompute ``fk_joints`` (rotating or moving, tree order) and to project
#: ``cam_joints`` (moving), the moving capsules ``mov_caps`` (processing order), their processing
#: positions ``mov_ci`` (ascending) and the positions' moving flags ``moving_ci (C,)``.
Restriction = namedtuple("Restriction", "x_base fixed_dofs fk_joints cam_joints mov_caps mov_ci moving_ci")
#: What the poses of a restriction share (:func:`restrict_prepare`'s result; its docstring).
Stage = namedtuple("Stage", "R0 P0 CP0 G0 G320 box0 BX0_ t1 s_px s_py s_idx s_f s_pre u_x u_y u_pre base_hit")

# Columns of a view's capsule table ``G (C, G_COLS)`` (:func:`_project_cap`), in the capsule's 2-D frame:
# start point a, unit axis u, length, radii at a and b, sine and cosine of the tangent angle, the
# capsule's extent along u (after clipping to the image), half width, and flags. Module-level ints are
# compile-time constants to numba.
G_AX, G_AY = 0, 1          # projected start point a (normalised image coordinates)
G_UX, G_UY = 2, 3          # unit axis from a to b
G_LEN = 4                  # projected length |b - a|
G_RA, G_RB = 5, 6          # projected radii at a and b
G_SB, G_CA = 7, 8          # sine / cosine of the tangent lines' angle (cone); 0 / 1 when one disc holds the other
G_YLO, G_YHI = 9, 10       # extent along the axis (lower, upper), clipped to the image
G_XMAX = 11                # half width across the axis
G_VALID = 12               # 1.0: a bounded projection; 0.0: skipped (a ball reaching the camera plane)
G_CONE = 13                # 1.0: tangent lines exist (a truncated cone between the discs)
G_COLS = 14
# ``G32`` repeats columns 0-8 in float32, then (:func:`_hull32`):
G32_CA_LEN = 9             # cos * L, -1 when one disc holds the other
G32_RA2, G32_RB2 = 10, 11  # squared radii
G32_COLS = 12

__all__ = ["fk_positions_batch", "silhouette_batch", "silhouette_batch_serial", "project_capsules", "inside_points", "Body", "Views", "Template",
           "Foreground", "Restriction", "Stage"]

# numba keys a cached function on its own file only: the kernels here compile kinematics' Rodrigues turn into
# their machine code, so an edit there must also miss this module's cache
register_dependent_cache(__file__, (kinematics,))


@numba.njit(cache=True, inline="always")
def _fk_joint(x, j, parents, offsets, ptr, dofs, axes, R, P):  # pragma: no cover - compiled
    """Position ``P[j]`` and world rotation ``R[j]`` of joint ``j > 0`` from its parent's (one step of
    :func:`_fk_one`; the restricted kernel recomputes only the joints that move)."""
    p = parents[j]
    for r in range(3):
        P[j, r] = P[p, r] + R[p, r, 0] * offsets[j, 0] + R[p, r, 1] * offsets[j, 1] + R[p, r, 2] * offsets[j, 2]
        for c in range(3):
            R[j, r, c] = R[p, r, c]
    for k in range(ptr[j], ptr[j + 1]):
        a = axes[k]
        q = x[dofs[k]]
        co = np.cos(q)
        si = np.sin(q)
        u = (a + 1) % 3
        v = (a + 2) % 3
        for r in range(3):  # R <- R . R_a(q): columns u, v rotate
            mu = R[j, r, u]
            mv = R[j, r, v]
            R[j, r, u] = mu * co + mv * si
            R[j, r, v] = -mu * si + mv * co


@numba.njit(cache=True, inline="always")
def _fk_one(x, parents, offsets, ptr, dofs, axes, R, P):  # pragma: no cover - compiled
    """Joint positions ``P (J, 3)`` of pose ``x``; ``R (J, 3, 3)`` is scratch (world rotations)."""
    rodrigues_into(x[3], x[4], x[5], R[0])                      # the root, as body.kinematics
    P[0, 0], P[0, 1], P[0, 2] = x[0], x[1], x[2]
    for j in range(1, parents.shape[0]):
        _fk_joint(x, j, parents, offsets, ptr, dofs, axes, R, P)


@numba.njit(parallel=True, cache=True)
def fk_positions_batch(X, parents, offsets, ptr, dofs, axes):  # pragma: no cover - compiled
    """Joint positions ``(n, J, 3)`` of poses ``X (n, D)`` (tested against ``body.joint_positions``)."""
    n = X.shape[0]
    J = parents.shape[0]
    out = np.empty((n, J, 3))
    for i in numba.prange(n):
        R = np.empty((J, 3, 3))
        _fk_one(X[i], parents, offsets, ptr, dofs, axes, R, out[i])
    return out


@numba.njit(cache=True, inline="always")
def _to_camera(P, Rs, ts, v, CP):  # pragma: no cover - compiled
    """Joints ``P (J, 3)`` seen from camera ``v`` into ``CP (J, 4)``: normalized image point x / z,
    y / z, depth z, and ``sqrt(l / z) / z`` (``l`` the distance from the camera; ``z > 0`` only), the
    factor that turns a ball radius into the radius of its projected disc."""
    for j in range(P.shape[0]):
        _to_camera_joint(P, Rs, ts, v, CP, j)


@numba.njit(cache=True, inline="always")
def _to_camera_joint(P, Rs, ts, v, CP, j):  # pragma: no cover - compiled
    """Joint ``j`` of :func:`_to_camera`."""
    x = Rs[v, 0, 0] * P[j, 0] + Rs[v, 0, 1] * P[j, 1] + Rs[v, 0, 2] * P[j, 2] + ts[v, 0]
    y = Rs[v, 1, 0] * P[j, 0] + Rs[v, 1, 1] * P[j, 1] + Rs[v, 1, 2] * P[j, 2] + ts[v, 1]
    z = Rs[v, 2, 0] * P[j, 0] + Rs[v, 2, 1] * P[j, 1] + Rs[v, 2, 2] * P[j, 2] + ts[v, 2]
    iz = 1.0 / z if z > 0.0 else 0.0
    CP[j, 0] = x * iz
    CP[j, 1] = y * iz
    CP[j, 2] = z
    CP[j, 3] = iz * np.sqrt(np.sqrt(x * x + y * y + z * z) * iz)


@numba.njit(cache=True, inline="always")
def _project_caps(CP, caps, radii, G):  # pragma: no cover - compiled
    """2-D hulls of the capsules in one view into ``G (C, G_COLS)`` from the joints in camera
    coordinates ``CP (J, 4)`` (see :func:`_to_camera`); returns nothing.

    ``G[c]``: ax, ay, ux, uy, L, ra, rb, sb, ca, ylo, yhi, xmax, valid, cone
    and the bounding box is derived from it by the caller.
    """
    for c in range(caps.shape[0]):
        _project_cap(CP, caps, radii, G, c)


@numba.njit(cache=True, inline="always")
def _project_cap(CP, caps, radii, G, c):  # pragma: no cover - compiled
    """Capsule ``c`` of :func:`_project_caps`."""
    ja = caps[c, 0]
    jb = caps[c, 1]
    za = CP[ja, 2]
    zb = CP[jb, 2]
    r0 = radii[c, 0]
    r1 = radii[c, 1]
    if za <= 1.001 * r0 or zb <= 1.001 * r1:
        G[c, G_VALID] = 0.0  # a ball reaching the camera plane: no bounded projection; skipped
        return
    ax = CP[ja, 0]
    ay = CP[ja, 1]
    bx = CP[jb, 0]
    by = CP[jb, 1]
    ra = r0 * CP[ja, 3]
    rb = r1 * CP[jb, 3]
    dx = bx - ax
    dy = by - ay
    L = np.sqrt(dx * dx + dy * dy)
    if L > 1e-12:
        ux = dx / L
        uy = dy / L
    else:
        ux = 1.0
        uy = 0.0
    G[c, G_AX], G[c, G_AY], G[c, G_UX], G[c, G_UY], G[c, G_LEN], G[c, G_RA], G[c, G_RB] = ax, ay, ux, uy, L, ra, rb
    if L > abs(ra - rb) * (1.0 + 1e-9) + 1e-15:
        sb = (ra - rb) / L
        G[c, G_SB] = sb
        G[c, G_CA] = np.sqrt(1.0 - sb * sb)
        G[c, G_CONE] = 1.0
    else:
        G[c, G_SB] = 0.0
        G[c, G_CA] = 1.0
        G[c, G_CONE] = 0.0
    G[c, G_YLO] = min(-ra, L - rb)
    G[c, G_YHI] = max(ra, L + rb)
    G[c, G_XMAX] = max(ra, rb)
    G[c, G_VALID] = 1.0


@numba.njit(cache=True, inline="always")
def _slab(a, u, b0, b1, lo, hi):  # pragma: no cover - compiled
    """The parameters ``t`` in ``[lo, hi]`` with ``a + t u`` in ``[b0, b1]`` (one coordinate of a
    segment clipped against a box): ``(meets, lo, hi)``, ``meets`` False for a segment parallel to
    the slab and outside it."""
    if u != 0.0:
        ta = (b0 - a) / u
        tb = (b1 - a) / u
        return True, max(lo, min(ta, tb)), min(hi, max(ta, tb))
    return not (a < b0 or a > b1), lo, hi


@numba.njit(cache=True, inline="always")
def _clip_cap(G, c, v, cam_K, cov_wh, cam_hasd):  # pragma: no cover - compiled
    """Capsule ``c``'s template rectangle in view ``v`` shortened, along its axis, to the part that
    can meet the image (pinhole views; a lens-distorted view keeps it whole).

    Term 1 counts only template points inside the image, so for a capsule that leaves the image
    the points off it are wasted: with few left, the estimate of ``|M|`` and of its uncovered part
    is noisy (a body 5 % inside a view got 0.5 where the exact count gives 0.08). The axis points
    whose cross-section (half width ``G[c, G_XMAX]``) lies entirely outside the image are cut off: the
    axis is clipped against the image grown by that half width, so no point that lands in the image
    is lost and the estimate stays unbiased, with all of the capsule's points where they count.
    A capsule inside the image, or missing it altogether, keeps its rectangle to the bit."""
    if cam_hasd[v] or G[c, G_VALID] == 0.0:
        return
    xm = G[c, G_XMAX]
    fx = cam_K[v, 0]
    fy = cam_K[v, 1]
    x0 = (-0.5 - cam_K[v, 2]) / fx - xm         # pixel u in [-0.5, W - 0.5): _t1_points' test
    x1 = (cov_wh[v, 0] - 0.5 - cam_K[v, 2]) / fx + xm
    y0 = (-0.5 - cam_K[v, 3]) / fy - xm
    y1 = (cov_wh[v, 1] - 0.5 - cam_K[v, 3]) / fy + xm
    ax, ay, ux, uy = G[c, G_AX], G[c, G_AY], G[c, G_UX], G[c, G_UY]
    meets, lo, hi = _slab(ax, ux, x0, x1, G[c, G_YLO], G[c, G_YHI])
    if not meets:
        return
    meets, lo, hi = _slab(ay, uy, y0, y1, lo, hi)
    if not meets:
        return
    if hi - lo <= 1e-9 * (G[c, G_YHI] - G[c, G_YLO]):
        return                                   # misses the image: no point counts anyway
    G[c, G_YLO] = lo
    G[c, G_YHI] = hi


@numba.njit(cache=True, inline="always")
def _inside_local(xl, yl, G, c):  # pragma: no cover - compiled
    """Point with axis coordinate ``yl`` and |across| ``xl`` (frame of capsule ``c``) inside its 2-D hull."""
    L = G[c, G_LEN]
    ra = G[c, G_RA]
    rb = G[c, G_RB]
    if G[c, G_CONE] == 0.0:  # one disc contains the other: the bigger disc (testing both is harmless)
        if xl * xl + yl * yl <= ra * ra:
            return True
        return xl * xl + (yl - L) * (yl - L) <= rb * rb
    sb = G[c, G_SB]
    ca = G[c, G_CA]
    k = -xl * sb + yl * ca      # Quilez' uneven capsule: which part of the boundary is nearest
    if k < 0.0:
        return xl * xl + yl * yl <= ra * ra
    if k > ca * L:
        return xl * xl + (yl - L) * (yl - L) <= rb * rb
    return xl * ca + yl * sb <= ra


@numba.njit(cache=True, inline="always")
def _inside(px, py, G, c):  # pragma: no cover - compiled
    """Normalized point ``(px, py)`` inside the 2-D hull of capsule ``c``."""
    dx = px - G[c, G_AX]
    dy = py - G[c, G_AY]
    yl = dx * G[c, G_UX] + dy * G[c, G_UY]
    xl = abs(-dx * G[c, G_UY] + dy * G[c, G_UX])
    return _inside_local(xl, yl, G, c)


@numba.njit(cache=True)
def project_capsules(P, caps, radii, Rs, ts, v):  # pragma: no cover - compiled
    """Python-callable wrapper of the projection into view ``v`` of ``Rs (V, 3, 3)``, ``ts (V, 3)``
    (tests): ``G (C, G_COLS)`` for joint positions ``P (J, 3)``."""
    G = np.zeros((caps.shape[0], G_COLS))
    CP = np.empty((P.shape[0], 4))
    _to_camera(P, Rs, ts, v, CP)
    _project_caps(CP, caps, radii, G)
    return G


@numba.njit(cache=True)
def inside_points(G, pts):  # pragma: no cover - compiled
    """``(m,)`` bool: normalized points ``pts (m, 2)`` inside the union of the 2-D hulls ``G`` (tests)."""
    out = np.zeros(pts.shape[0], np.bool_)
    for i in range(pts.shape[0]):
        for c in range(G.shape[0]):
            if G[c, G_VALID] != 0.0 and _inside(pts[i, 0], pts[i, 1], G, c):
                out[i] = True
                break
    return out


@numba.njit(cache=True, inline="always")
def _lookup(x, y, v, K, D, hasd, cov, W, H, stride):  # pragma: no cover - compiled
    """Foreground coverage of view ``v`` at the normalized point ``(x, y)``; -1 outside the image."""
    if hasd[v]:
        r2 = x * x + y * y
        radial = ((1.0 + r2 * (D[v, 0] + r2 * (D[v, 1] + r2 * D[v, 4])))
                  / (1.0 + r2 * (D[v, 5] + r2 * (D[v, 6] + r2 * D[v, 7]))))
        xd = x * radial + 2.0 * D[v, 2] * x * y + D[v, 3] * (r2 + 2.0 * x * x)
        yd = y * radial + D[v, 2] * (r2 + 2.0 * y * y) + 2.0 * D[v, 3] * x * y
        x = xd
        y = yd
    u = K[v, 0] * x + K[v, 2] + 0.5
    w = K[v, 1] * y + K[v, 3] + 0.5
    if u < 0.0 or w < 0.0 or u >= W or w >= H:
        return -1.0
    return cov[v, int(w) * stride + int(u)] * K[v, 4]


@numba.njit(cache=True, inline="always")
def _hull32(G, G32, c):  # pragma: no cover - compiled
    """Single-precision parameters of capsule ``c``'s 2-D hull for the point tests into ``G32[c]``:
    ax, ay, ux, uy, L, ra, rb, sb, ca, ca L (-1 when one disc holds the other), ra^2, rb^2."""
    for k in range(G32_CA_LEN):
        G32[c, k] = G[c, k]
    G32[c, G32_CA_LEN] = G[c, G_CA] * G[c, G_LEN] if G[c, G_CONE] != 0.0 else -1.0
    G32[c, G32_RA2] = G[c, G_RA] * G[c, G_RA]
    G32[c, G32_RB2] = G[c, G_RB] * G[c, G_RB]


@numba.njit(cache=True, inline="always")
def _mark_hull(X, Y, Fl, k0, k1, ax, ay, ux, uy, L, ra, sb, ca, caL, ra2, rb2, val):  # pragma: no cover - compiled
    """``Fl[k] = val`` for ``k`` in ``k0:k1`` where ``(X[k], Y[k])`` is inside the 2-D hull with
    float32 parameters ``ax ... rb2`` (see :func:`_hull32`); branch-free (vectorizes). Index bounds
    rather than slices: a slice costs reference counting.

    The 2-D hull is the union of disc a, disc b and the part of the strip between the normals at
    the tangent points that lies inside the tangent lines (the same set as :func:`_inside_local`;
    with ``ca L = -1`` no point is in the strip, as there when one disc holds the other)."""
    zero = np.float32(0.0)
    for j in range(k1 - k0):
        k = numba.uint64(k0 + j)   # unsigned: no negative-index wraparound, so the loop vectorizes
        dx = X[k] - ax
        dy = Y[k] - ay
        yl = dx * ux + dy * uy
        xr = dy * ux - dx * uy
        x2 = xr * xr
        xl = abs(xr)
        q = yl * ca - xl * sb
        yb = yl - L
        inside = ((x2 + yl * yl <= ra2) | (x2 + yb * yb <= rb2)
                  | ((q >= zero) & (q <= caL) & (xl * ca + yl * sb <= ra)))
        Fl[k] = val if inside else Fl[k]


@numba.njit(cache=True, inline="always")
def _mark_run(X, Y, Fl, k0, k1, G32, c, val):  # pragma: no cover - compiled
    """:func:`_mark_hull` with the hull of capsule ``c`` in ``G32``."""
    _mark_hull(X, Y, Fl, k0, k1, G32[c, G_AX], G32[c, G_AY], G32[c, G_UX], G32[c, G_UY], G32[c, G_LEN], G32[c, G_RA], G32[c, G_SB],
               G32[c, G_CA], G32[c, G32_CA_LEN], G32[c, G32_RA2], G32[c, G32_RB2], val)


@numba.njit(cache=True, inline="always")
def _bin(y, y0, inv_dy, nb):  # pragma: no cover - compiled
    """Bin of ``y`` among ``nb`` bins of width ``1 / inv_dy`` from ``y0``, clamped to ``[0, nb]``."""
    b = (y - y0) * inv_dy
    if b <= 0.0:
        return 0
    if b >= nb:
        return nb
    return int(b)


@numba.njit(cache=True, inline="always")
def _cap_box(G, G32, box, c):  # pragma: no cover - compiled
    """Single-precision hull of capsule ``c`` (:func:`_hull32`) and its bounding box ``box[c]``: x0, x1,
    y0, y1 (an empty box, x0 > x1, for a capsule left out of the view)."""
    if G[c, G_VALID] == 0.0:
        box[c, 0] = 1.0
        box[c, 1] = -1.0
        box[c, 2] = 1.0
        box[c, 3] = -1.0
        return
    _hull32(G, G32, c)
    ax, ay, L = G[c, G_AX], G[c, G_AY], G[c, G_LEN]
    bx = ax + L * G[c, G_UX]
    by = ay + L * G[c, G_UY]
    ra, rb = G[c, G_RA], G[c, G_RB]
    box[c, 0] = min(ax - ra, bx - rb)
    box[c, 1] = max(ax + ra, bx + rb)
    box[c, 2] = min(ay - ra, by - rb)
    box[c, 3] = max(ay + ra, by + rb)


@numba.njit(cache=True, inline="always")
def _eb_set(EB, ci, G, box, c):  # pragma: no cover - compiled
    """Column ``ci`` (processing position) of ``EB (11, C + 8)``: capsule ``c``'s box (rows 0-3: x0, x1,
    y0, y1) and hull ``G[c, 0:7]`` (rows 4-10: ax, ay, ux, uy, L, ra, rb; zeros when it is left out of
    the view, so that no stale value is computed on), the earlier capsules of :func:`_earlier_runs`."""
    for a in range(4):
        EB[a, ci] = box[c, a]
    if G[c, G_VALID] == 0.0:
        for a in range(7):
            EB[4 + a, ci] = 0.0
    else:
        for a in range(7):
            EB[4 + a, ci] = G[c, a]


@numba.njit(cache=True, inline="always")
def _earlier_runs(ci, G, c, EB, ylo, xm, na, na_ly, S, OK):  # pragma: no cover - compiled
    """:func:`_earlier_run` of capsule ``c`` (position ``ci``) against every earlier position at once,
    branch-free over whole 8-lane vectors (``EB`` from :func:`_eb_set`): ``OK[ei]`` 1 where ``ei < ci``,
    the boxes meet and the capsule reaches ``c``'s rectangle, with ``S[0, ei], S[1, ei]`` its ``sa, ta``
    and ``S[2, ei], S[3, ei]`` the strata bounds ``s0, s1`` (the same operations as there, so the same
    values)."""
    dax, day, dux, duy = G[c, G_AX], G[c, G_AY], G[c, G_UX], G[c, G_UY]
    bx0, bx1, by0, by1 = EB[0, ci], EB[1, ci], EB[2, ci], EB[3, ci]
    for j in range((ci + 7) & ~7):
        k = numba.uint64(j)
        dxa = EB[4, k] - dax
        dya = EB[5, k] - day
        dxb = dxa + EB[8, k] * EB[6, k]
        dyb = dya + EB[8, k] * EB[7, k]
        rea = EB[9, k]
        reb = EB[10, k]
        ta = dya * dux - dxa * duy
        tb = dyb * dux - dxb * duy
        sa = dxa * dux + dya * duy
        sb2 = dxb * dux + dyb * duy
        s0 = (min(sa - rea, sb2 - reb) - ylo) * na_ly - 1e-4
        s1 = (max(sa + rea, sb2 + reb) - ylo) * na_ly + 1e-4
        ok = ((j < ci) & (EB[0, k] <= bx1) & (bx0 <= EB[1, k]) & (EB[2, k] <= by1) & (by0 <= EB[3, k])
              & (min(ta - rea, tb - reb) <= xm) & (max(ta + rea, tb + reb) >= -xm) & (s1 >= 0.0) & (s0 < na))
        S[0, k] = sa
        S[1, k] = ta
        S[2, k] = s0
        S[3, k] = s1
        OK[k] = 1 if ok else 0


@numba.njit(cache=True, inline="always")
def _earlier_run(G, c, e, ylo, xm, na, na_ly):  # pragma: no cover - compiled
    """Earlier capsule ``e`` seen from capsule ``c``'s frame: ``(reaches, i0, i1, sa, ta)``, the run of
    strata ``i0..i1`` of ``c`` that ``e``'s extent along ``c``'s axis reaches (``reaches`` False when
    its extent across misses ``c``'s rectangle, or along it every stratum) and ``e``'s first centre in
    ``c``'s frame (along, across)."""
    dax, day, dux, duy = G[c, G_AX], G[c, G_AY], G[c, G_UX], G[c, G_UY]
    dxa = G[e, G_AX] - dax
    dya = G[e, G_AY] - day
    dxb = dxa + G[e, G_LEN] * G[e, G_UX]
    dyb = dya + G[e, G_LEN] * G[e, G_UY]
    rea = G[e, G_RA]
    reb = G[e, G_RB]
    ta = dya * dux - dxa * duy
    tb = dyb * dux - dxb * duy
    if min(ta - rea, tb - reb) > xm or max(ta + rea, tb + reb) < -xm:
        return False, 0, 0, 0.0, 0.0
    sa = dxa * dux + dya * duy
    sb2 = dxb * dux + dyb * duy
    s0 = (min(sa - rea, sb2 - reb) - ylo) * na_ly - 1e-4
    s1 = (max(sa + rea, sb2 + reb) - ylo) * na_ly + 1e-4
    if s1 < 0.0 or s0 >= na:
        return False, 0, 0, 0.0, 0.0
    i0 = int(s0) if s0 > 0.0 else 0
    i1 = min(int(s1), na - 1)
    return True, i0, i1, sa, ta


@numba.njit(cache=True, inline="always")
def _mark_earlier(X, Y, Fl, k0, k1, G, G32, c, e, sa, ta, val):  # pragma: no cover - compiled
    """``Fl[k] = val`` for the points ``k0:k1`` (frame coordinates of capsule ``c``: ``X`` along, ``Y``
    across) inside the hull of capsule ``e`` (a rotation into ``c``'s frame: the rest of its
    parameters stays; ``sa, ta`` from :func:`_earlier_run`)."""
    dux, duy = G[c, G_UX], G[c, G_UY]
    _mark_hull(X, Y, Fl, k0, k1, np.float32(sa), np.float32(ta), np.float32(G[e, G_UX] * dux + G[e, G_UY] * duy),
               np.float32(G[e, G_UY] * dux - G[e, G_UX] * duy), G32[e, G_LEN], G32[e, G_RA], G32[e, G_SB],
               G32[e, G_CA], G32[e, G32_CA_LEN], G32[e, G32_RA2], G32[e, G32_RB2], val)


@numba.njit(cache=True, inline="always")
def _t1_points(ci, c, v, G, G32, EB, order, tmpl_a, tmpl_s, tmpl_ptr, tmpl_na, cam_K, cov_wh,
               cam_hasd, zpix, PX, PY, IDX, NEAR, S, OK, all_pairs):  # pragma: no cover - compiled
    """Term 1, capsule ``c`` at position ``ci`` of ``order`` in view ``v``: its template points in its
    bounding rectangle, ``PX`` along and ``PY`` across its axis, and ``IDX``: for a point inside its
    hull and in the hull of no earlier capsule whose box (``EB``, :func:`_eb_set`) meets its own, its
    pixel (pinhole; ``zpix`` outside the image) or 0 (lens distortion: looked up later), for the
    others ``zpix`` (the zero pixel after the mask). ``NEAR``, ``S``, ``OK`` are scratch.

    ``all_pairs`` (a constant): the earlier capsules in one vector pass (:func:`_earlier_runs`; the full
    kernel), else box tests first and :func:`_earlier_run` on the few that meet (the restricted kernel,
    where it is measured faster); the same strata either way."""
    zero = np.float32(0.0)
    hasd = cam_hasd[v]
    Wf = np.float32(cov_wh[v, 0])
    Hf = np.float32(cov_wh[v, 1])
    Wst = np.int32(cov_wh[v, 2])
    ylo = G[c, G_YLO]
    ly = G[c, G_YHI] - ylo
    xm = G[c, G_XMAX]
    k0 = tmpl_ptr[c]
    nk = tmpl_ptr[c + 1] - k0
    na = tmpl_na[c]
    ns = nk // na
    nkp = (nk + 7) & ~7     # padded: points nk.. are dropped (IDX = zpix)
    L, ra, sb, ca = G32[c, G_LEN], G32[c, G_RA], G32[c, G_SB], G32[c, G_CA]
    caL, ra2, rb2 = G32[c, G32_CA_LEN], G32[c, G32_RA2], G32[c, G32_RB2]
    # the pixel as an affine map of the point's frame coordinates (pinhole)
    u0 = np.float32(cam_K[v, 0] * G[c, G_AX] + cam_K[v, 2] + 0.5)
    uya = np.float32(cam_K[v, 0] * G[c, G_UX])
    uxs = np.float32(-cam_K[v, 0] * G[c, G_UY])
    w0 = np.float32(cam_K[v, 1] * G[c, G_AY] + cam_K[v, 3] + 0.5)
    wya = np.float32(cam_K[v, 1] * G[c, G_UY])
    wxs = np.float32(cam_K[v, 1] * G[c, G_UX])
    ylo32 = np.float32(ylo)
    ly32 = np.float32(ly)
    xm32 = np.float32(xm)
    for k in range(nkp):    # own hull test in the capsule's frame (PX along, PY across)
        kk = numba.uint64(k0 + k)   # unsigned: no wraparound test, the loop vectorizes
        yl = ylo32 + tmpl_a[kk] * ly32
        xs = tmpl_s[kk] * xm32
        xl = abs(xs)
        x2 = xs * xs
        q = yl * ca - xl * sb
        yb = yl - L
        inside = ((x2 + yl * yl <= ra2) | (x2 + yb * yb <= rb2)
                  | ((q >= zero) & (q <= caL) & (xl * ca + yl * sb <= ra)))
        PX[k] = yl
        PY[k] = xs
        u = u0 + yl * uya + xs * uxs    # pixel of the point (pinhole)
        w = w0 + yl * wya + xs * wxs
        ok = (u >= zero) & (w >= zero) & (u < Wf) & (w < Hf)
        pix = np.int32(0) if hasd else np.int32(w) * Wst + np.int32(u)
        IDX[k] = pix if inside & (ok | hasd) else zpix
    for k in range(nk, nkp):
        IDX[numba.uint64(k)] = zpix
    na_ly = na / ly     # strata per unit length along the axis
    # earlier capsules whose boxes meet c's and that reach its rectangle: capsule e in c's frame, its
    # extent along c's axis selects a run of strata
    nn = 0
    if all_pairs:   # all pairs at once, then a branch-free compaction
        _earlier_runs(ci, G, c, EB, ylo, xm, na, na_ly, S, OK)
        for ei in range(ci):
            NEAR[numba.uint64(nn)] = ei
            nn += OK[ei]
        for q in range(nn):
            ei = numba.uint64(NEAR[q])
            s0 = S[2, ei]
            i0 = int(s0) if s0 > 0.0 else 0
            i1 = min(int(S[3, ei]), na - 1)
            ka = i0 * ns            # whole vectors from the first stratum on (scratch has slack)
            _mark_earlier(PX, PY, IDX, ka, ka + (((i1 + 1) * ns - ka + 7) & ~7), G, G32, c, order[ei], S[0, ei],
                          S[1, ei], zpix)
    else:
        bx0, bx1, by0, by1 = EB[0, ci], EB[1, ci], EB[2, ci], EB[3, ci]
        for ei in range(ci):
            NEAR[nn] = ei
            nn += (EB[0, ei] <= bx1) & (bx0 <= EB[1, ei]) & (EB[2, ei] <= by1) & (by0 <= EB[3, ei])
        for q in range(nn):
            e = order[NEAR[q]]
            reach, i0, i1, sa, ta = _earlier_run(G, c, e, ylo, xm, na, na_ly)
            if reach:
                ka = i0 * ns
                _mark_earlier(PX, PY, IDX, ka, ka + (((i1 + 1) * ns - ka + 7) & ~7), G, G32, c, e, sa, ta, zpix)


@numba.njit(cache=True, inline="always")
def _t1_lookup(G, c, px, py, v, cam_K, cam_D, cam_hasd, cov, cov_wh):  # pragma: no cover - compiled
    """Foreground coverage at the point of capsule ``c``'s frame ``px`` along, ``py`` across (float32);
    -1 outside the image (the lens-distortion path of term 1)."""
    yl = np.float64(px)
    xs = np.float64(py)
    return _lookup(G[c, G_AX] + yl * G[c, G_UX] - xs * G[c, G_UY], G[c, G_AY] + yl * G[c, G_UY] + xs * G[c, G_UX],
                   v, cam_K, cam_D, cam_hasd, cov, cov_wh[v, 0], cov_wh[v, 1], cov_wh[v, 2])


@numba.njit(cache=True, inline="always")
def _t1_count(c, v, nk, G, PX, PY, IDX, zpix, cam_K, cam_D, cam_hasd, cov, cov_wh):  # pragma: no cover - compiled
    """Term 1 of capsule ``c`` from :func:`_t1_points`: ``(count, sum of F)`` over its kept points
    inside the image (in template order)."""
    cnt = 0.0
    fsum = 0.0
    if cam_hasd[v]:
        for k in range(nk):
            if IDX[k] != zpix:
                f = _t1_lookup(G, c, PX[k], PY[k], v, cam_K, cam_D, cam_hasd, cov, cov_wh)
                if f >= 0.0:
                    cnt += 1.0
                    fsum += f
    else:
        # one branch-free read per point: the points not counted read the zero pixel after the mask,
        # so the sum is that of the kept points, in the same order
        icnt = 0
        isum = cov[v, 0] - cov[v, 0]    # an integer for the uint8 mask: 1-cycle additions
        for k in range(nk):
            j = IDX[numba.uint64(k)]
            icnt += j != zpix
            isum += cov[v, numba.uint32(j)]
        cnt = float(icnt)
        fsum = float(isum) * cam_K[v, 4]
    return cnt, fsum


@numba.njit(cache=True, inline="always")
def _t1_weight(G, c, nk):  # pragma: no cover - compiled
    """Weight of one template point of capsule ``c``: its rectangle's area over ``nk`` points."""
    ly = G[c, G_YHI] - G[c, G_YLO]
    return ly * 2.0 * G[c, G_XMAX] / nk


@numba.njit(cache=True, inline="always")
def _scratch_len(tmpl_ptr):  # pragma: no cover - compiled
    """Length of the per-capsule point scratch: the biggest capsule's points in whole 8-lane vectors."""
    kmax = 1
    for c in range(tmpl_ptr.shape[0] - 1):
        kmax = max(kmax, tmpl_ptr[c + 1] - tmpl_ptr[c])
    return (kmax + 7) & ~7      # runs of whole 8-lane vectors: no scalar remainder loops


@numba.njit(cache=True, inline="always")
def _t2_runs(c, box, v, n_strips, fg_x, fg_y, fg_tab, fg_bins, fg_xr, fg_ms, flag, G32):  # pragma: no cover - compiled
    """Term 2, capsule ``c`` in view ``v``: ``flag`` 1 for the foreground points inside its hull, tested
    in each strip its box meets in x, on the run of points in its box's y range (whole vectors)."""
    nb = fg_tab.shape[1] - 1
    r0 = v * n_strips
    for r in range(r0, r0 + n_strips):
        if box[c, 0] > fg_xr[r, 1] or box[c, 1] < fg_xr[r, 0]:
            continue
        k0 = fg_tab[r, _bin(box[c, 2], fg_bins[r, 0], fg_bins[r, 1], nb)]
        k1 = fg_tab[r, min(nb, _bin(box[c, 3], fg_bins[r, 0], fg_bins[r, 1], nb) + 1)]
        if k1 > k0:
            _mark_run(fg_x, fg_y, flag, r * fg_ms + (k0 & ~7), r * fg_ms + min(fg_ms, (k1 + 7) & ~7),
                      G32, c, np.float32(1.0))


# fastmath without "reassoc": with reassociation the freshly compiled kernel and the one loaded from
# numba's cache gave energies differing in the last bit (measured), so a process that compiled it
# and one that loaded it (estimator node vs `isa-mocap track`, bench workers) disagreed; ~5 % slower.
DETERMINISTIC_FASTMATH = {"contract", "nnan", "ninf", "nsz", "arcp", "afn"}

# The serial kernels compiled through numba's parallel pipeline with every transformation off: no loop
# becomes a parfor (nothing launches threads), yet the same kernel runs ~2.3x fewer CPU cycles than under a
# plain ``njit`` (measured: 1500 poses 62 -> 27 CPU ms, 4 poses 170 -> 77 CPU µs; the parallel kernel's
# body already ran at the faster rate), with the same bits. The parallel pipeline lowers the inlined helpers
# differently (most likely fewer reference-count operations on the array views in the loops).
SERIAL_PIPELINE = {"comprehension": False, "reduction": False, "inplace_binop": False, "setitem": False,
                   "numpy": False, "stencil": False, "fusion": False, "prange": False}
# numba warns at compile time that such a kernel has no parallel loop: by design here (this module's only)
warnings.filterwarnings("ignore", message=r"(?s).*no transformation for parallel execution.*silhouette_kernel\.py",
                        category=numba.NumbaPerformanceWarning)


@numba.njit(cache=True, inline="always", fastmath=DETERMINISTIC_FASTMATH)
def _batch_rows(X, lo, hi, body, views, tmpl, fg, out):  # pragma: no cover - compiled
    """:func:`silhouette_batch` of the rows ``lo:hi`` of ``X`` (one work unit, with its own scratch)."""
    parents, offsets, ptr, dofs, axes, caps, radii = body
    cam_R, cam_t, cam_K, cam_D, cam_hasd, cov, cov_wh, view_w = views
    order, tmpl_a, tmpl_s, tmpl_ptr, tmpl_na = tmpl
    fg_x, fg_y, fg_n, fg_tab, fg_bins, fg_xr, fg_area = fg
    J = parents.shape[0]
    C = caps.shape[0]
    V = cam_R.shape[0]
    zero = np.float32(0.0)
    n_strips = fg_tab.shape[0] // V
    fg_ms = fg_x.shape[0] // fg_tab.shape[0]
    wsum = 0.0
    for v in range(V):
        wsum += view_w[v]
    R = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    CP = np.empty((J, 4))
    G = np.empty((C, G_COLS))
    G32 = np.empty((C, G32_COLS), np.float32)
    box = np.empty((C, 4))
    EB = np.zeros((11, C + 8))     # the capsules in processing order (whole vectors)
    S = np.zeros((4, C + 8))
    OK = np.zeros(C + 8, np.int64)
    NEAR = np.empty(C, np.int64)
    flag = np.empty(max(1, fg_x.shape[0]), np.float32)
    kmax = _scratch_len(tmpl_ptr)
    PX = np.zeros(kmax + 8, np.float32)     # a point's frame coordinates: along, across
    PY = np.zeros(kmax + 8, np.float32)
    IDX = np.empty(kmax, np.int32)     # a point's pixel, zpix when not counted
    zpix = np.int32(cov.shape[1] - 1)
    for i in range(lo, hi):
        _fk_one(X[i], parents, offsets, ptr, dofs, axes, R, P)
        total = 0.0
        for v in range(V):
            _to_camera(P, cam_R, cam_t, v, CP)
            _project_caps(CP, caps, radii, G)
            for c in range(C):
                _clip_cap(G, c, v, cam_K, cov_wh, cam_hasd)
                _cap_box(G, G32, box, c)
            for ci in range(C):     # boxes and hulls in processing order, for the overlap candidates
                _eb_set(EB, ci, G, box, order[ci])
            # term 1: model silhouette points not on foreground. Points of capsule c in its
            # bounding rectangle; kept if inside c's hull and in no earlier capsule's hull
            num = 0.0
            den = 0.0
            for ci in range(C):
                c = order[ci]
                if G[c, G_VALID] == 0.0:
                    continue
                _t1_points(ci, c, v, G, G32, EB, order, tmpl_a, tmpl_s, tmpl_ptr, tmpl_na,
                           cam_K, cov_wh, cam_hasd, zpix, PX, PY, IDX, NEAR, S, OK, True)
                nk = tmpl_ptr[c + 1] - tmpl_ptr[c]
                cnt, fsum = _t1_count(c, v, nk, G, PX, PY, IDX, zpix, cam_K, cam_D, cam_hasd, cov, cov_wh)
                w = _t1_weight(G, c, nk)
                den += w * cnt
                num += w * (cnt - fsum)
            t1 = num / den if den > 0.0 else 1.0
            if fg_n[v] == 0:
                # term 2 from the same points: |F minus M| / |F| = 1 - (integral of F over M) / |F|
                t2 = 1.0 - (den - num) / fg_area[v]
                t2 = min(1.0, max(0.0, t2))
            else:
                # term 2: foreground points not covered by the model; the points are sorted by y,
                # so a capsule's box meets a contiguous run of them in each strip
                r0 = v * n_strips
                for k in range(n_strips * fg_ms):
                    flag[numba.uint64(r0 * fg_ms + k)] = zero
                for ci in range(C):
                    c = order[ci]
                    if G[c, G_VALID] == 0.0:
                        continue
                    _t2_runs(c, box, v, n_strips, fg_x, fg_y, fg_tab, fg_bins, fg_xr, fg_ms, flag, G32)
                # the padding is never inside a hull: count whole strips (an integer count of the
                # 0/1 flags, vectorized: the same value as their sum in order)
                hit = 0
                for k in range(n_strips * fg_ms):
                    hit += flag[numba.uint64(r0 * fg_ms + k)] != zero
                t2 = 1.0 - float(hit) / fg_n[v]
            total += view_w[v] * (0.5 * t1 + 0.5 * t2)
        out[i] = total / wsum


@numba.njit(parallel=True, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def silhouette_batch(X, body, views, tmpl, fg, n_chunks, out):  # pragma: no cover - compiled
    """Fast Eq. 5 for poses ``X (n, D)`` into ``out (n,)``.

    Parameters
    ----------
    X : (n, D) float64, finite rows only
    body : :data:`Body`;  views : :data:`Views`;  tmpl : :data:`Template`;  fg : :data:`Foreground`
    n_chunks : int, work units of the parallel loop
    out : (n,) float64
    """
    n = X.shape[0]
    for chunk in numba.prange(n_chunks):
        _batch_rows(X, chunk * n // n_chunks, (chunk + 1) * n // n_chunks, body, views, tmpl, fg, out)


@numba.njit(parallel=SERIAL_PIPELINE, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def silhouette_batch_serial(X, body, views, tmpl, fg, n_chunks, out):  # pragma: no cover - compiled
    """:func:`silhouette_batch` on the calling thread, for a few poses (a parallel launch costs more than
    a pose; the same operations, so the same bits); ``n_chunks`` is ignored."""
    _batch_rows(X, 0, X.shape[0], body, views, tmpl, fg, out)


#: Batches of fewer poses than this go to :func:`silhouette_batch_serial` (:class:`.silhouette.SilhouetteEnergy`).
SERIAL_BELOW = 8


# ---------------------------------------------------------------------- restricted evaluation
# Poses that equal a base pose outside some coordinates (a stage of the hierarchical optimizer):
# :func:`restrict_prepare` computes once what depends only on the fixed capsules, and
# :func:`silhouette_restricted` per pose only what the moving capsules change. The same helpers and
# the same summation order as :func:`silhouette_batch`, so the values are the same bits.

@numba.njit(cache=True, inline="always")
def _t1_recount(v, s0, s1, ALIVE, s_idx, s_f, cam_K, cam_hasd, cov):  # pragma: no cover - compiled
    """:func:`_t1_count` over the stored points ``s0:s1`` of a fixed capsule that are still ``ALIVE``
    (in template order, as there: the same additions in the same order)."""
    zero = np.float32(0.0)
    cnt = 0.0
    fsum = 0.0
    if cam_hasd[v]:
        for s in range(s0, s1):
            if ALIVE[s] != zero:
                cnt += 1.0
                fsum += s_f[s]
    else:
        icnt = 0
        isum = cov[v, 0] - cov[v, 0]
        for s in range(s0, s1):
            if ALIVE[s] != zero:
                icnt += 1
                isum += cov[v, s_idx[s]]
        cnt = float(icnt)
        fsum = float(isum) * cam_K[v, 4]
    return cnt, fsum


@numba.njit(parallel=SERIAL_PIPELINE, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def restrict_prepare(x, body, views, tmpl, fg, moving):  # pragma: no cover - compiled
    """What the poses of a stage share, from the base pose ``x`` and ``moving (C,)`` (bool: capsules
    whose end joints move); the bundles as :func:`silhouette_batch`. Returns a tuple (:data:`Stage`):

    ``R (J, 3, 3), P (J, 3)`` forward kinematics of ``x``; per view ``CP (V, J, 4)``, ``G (V, C, G_COLS)``,
    ``G32 (V, C, G32_COLS)``, ``box (V, C, 4)``, ``BX (V, 4, C)`` (the boxes in processing order);
    ``t1 (V, C, 3)``: weight, count and foreground sum of each fixed capsule's term-1 points that lie
    in its hull, in no earlier *fixed* capsule's hull and inside the image; those points themselves,
    view ``v`` at ``v T``: ``s_px, s_py`` (frame coordinates), ``s_idx`` (pixel), ``s_f`` (coverage,
    lens-distortion path), with ``s_pre (V, T + C)``: capsule ``c``'s entry ``tmpl_ptr[c] + c + k`` is the
    number of them before its template point ``k`` (``k = 0 .. nk``); the foreground sample points no
    fixed capsule covers, ``u_x, u_y`` (strip ``r`` at ``r Ms``, in sample order) with
    ``u_pre (V S, Ms + 1)`` (those before sample point ``k`` of the strip) and ``base_hit (V,)``, the
    sample points the fixed capsules cover."""
    parents, offsets, ptr, dofs, axes, caps, radii = body
    cam_R, cam_t, cam_K, cam_D, cam_hasd, cov, cov_wh, view_w = views
    order, tmpl_a, tmpl_s, tmpl_ptr, tmpl_na = tmpl
    fg_x, fg_y, fg_n, fg_tab, fg_bins, fg_xr, fg_area = fg
    J = parents.shape[0]
    C = caps.shape[0]
    V = cam_R.shape[0]
    T = tmpl_ptr[C]
    n_strips = fg_tab.shape[0] // V
    fg_ms = fg_x.shape[0] // fg_tab.shape[0]
    nb = fg_tab.shape[1] - 1
    zero = np.float32(0.0)
    R = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    _fk_one(x, parents, offsets, ptr, dofs, axes, R, P)
    CP = np.zeros((V, J, 4))
    G = np.zeros((V, C, G_COLS))
    G32 = np.zeros((V, C, G32_COLS), np.float32)
    box = np.zeros((V, C, 4))
    BX = np.zeros((V, 4, C))
    BXf = np.zeros((11, C + 8))
    S = np.zeros((4, C + 8))
    OK = np.zeros(C + 8, np.int64)
    t1 = np.zeros((V, C, 3))
    s_px = np.zeros(V * T + 8, np.float32)
    s_py = np.zeros(V * T + 8, np.float32)
    s_idx = np.zeros(V * T + 8, np.int32)
    s_f = np.zeros(V * T + 8)
    s_pre = np.zeros((V, T + C), np.int64)
    u_x = np.full(fg_x.shape[0], np.float32(1e6))
    u_y = np.full(fg_x.shape[0], np.float32(1e6))
    u_pre = np.zeros((fg_tab.shape[0], fg_ms + 1), np.int64)
    base_hit = np.zeros(V)
    NEAR = np.empty(C, np.int64)
    flag = np.zeros(max(1, fg_x.shape[0]), np.float32)
    kmax = _scratch_len(tmpl_ptr)
    PX = np.zeros(kmax + 8, np.float32)
    PY = np.zeros(kmax + 8, np.float32)
    IDX = np.zeros(kmax, np.int32)
    zpix = np.int32(cov.shape[1] - 1)
    for v in range(V):
        _to_camera(P, cam_R, cam_t, v, CP[v])
        _project_caps(CP[v], caps, radii, G[v])
        for c in range(C):
            _clip_cap(G[v], c, v, cam_K, cov_wh, cam_hasd)
            _cap_box(G[v], G32[v], box[v], c)
        for ci in range(C):
            c = order[ci]
            for a in range(4):
                BX[v, a, ci] = box[v, c, a]
            _eb_set(BXf, ci, G[v], box[v], c)
            if moving[c]:       # only the fixed capsules are earlier capsules here
                BXf[0, ci], BXf[1, ci], BXf[2, ci], BXf[3, ci] = 1.0, -1.0, 1.0, -1.0
        pos = 0
        off = v * T
        for ci in range(C):
            c = order[ci]
            k0 = tmpl_ptr[c]
            nk = tmpl_ptr[c + 1] - k0
            q0 = k0 + c
            if moving[c] or G[v, c, 12] == 0.0:
                for k in range(nk + 1):
                    s_pre[v, q0 + k] = pos
                continue
            _t1_points(ci, c, v, G[v], G32[v], BXf, order, tmpl_a, tmpl_s, tmpl_ptr,
                       tmpl_na, cam_K, cov_wh, cam_hasd, zpix, PX, PY, IDX, NEAR, S, OK, True)
            cnt, fsum = _t1_count(c, v, nk, G[v], PX, PY, IDX, zpix, cam_K, cam_D, cam_hasd, cov, cov_wh)
            t1[v, c, 0] = _t1_weight(G[v], c, nk)
            t1[v, c, 1] = cnt
            t1[v, c, 2] = fsum
            for k in range(nk):
                s_pre[v, q0 + k] = pos
                if IDX[k] == zpix:
                    continue
                f = 0.0
                keep = True
                if cam_hasd[v]:
                    f = _t1_lookup(G[v], c, PX[k], PY[k], v, cam_K, cam_D, cam_hasd, cov, cov_wh)
                    keep = f >= 0.0
                if keep:
                    s_px[off + pos] = PX[k]
                    s_py[off + pos] = PY[k]
                    s_idx[off + pos] = IDX[k]
                    s_f[off + pos] = f
                    pos += 1
            s_pre[v, q0 + nk] = pos
        if fg_n[v] == 0:
            continue
        r0 = v * n_strips
        for k in range(n_strips * fg_ms):
            flag[r0 * fg_ms + k] = zero
        for ci in range(C):
            c = order[ci]
            if moving[c] or G[v, c, 12] == 0.0:
                continue
            _t2_runs(c, box[v], v, n_strips, fg_x, fg_y, fg_tab, fg_bins, fg_xr, fg_ms, flag, G32[v])
        hit = 0.0
        for k in range(n_strips * fg_ms):
            hit += flag[r0 * fg_ms + k]
        base_hit[v] = hit
        for r in range(r0, r0 + n_strips):
            m = fg_tab[r, nb]       # the strip's points (the rest is padding)
            j = 0
            for k in range(fg_ms):
                u_pre[r, k] = j
                if k < m and flag[r * fg_ms + k] == zero:
                    u_x[r * fg_ms + j] = fg_x[r * fg_ms + k]
                    u_y[r * fg_ms + j] = fg_y[r * fg_ms + k]
                    j += 1
            u_pre[r, fg_ms] = j
    return R, P, CP, G, G32, box, BX, t1, s_px, s_py, s_idx, s_f, s_pre, u_x, u_y, u_pre, base_hit


@numba.njit(parallel=True, cache=True, fastmath=DETERMINISTIC_FASTMATH)
def silhouette_restricted(X, restriction, body, views, tmpl, fg, stage, n_chunks, out):  # pragma: no cover - compiled
    """:func:`silhouette_batch` for poses ``X (n, D)`` equal to ``x_base`` at ``fixed_dofs`` (the
    :data:`Restriction` ``restriction``), from the stage data of :func:`restrict_prepare` (the
    :data:`Stage` ``stage``; the other bundles as :func:`silhouette_batch`). Per pose: forward kinematics of the
    joints ``fk_joints`` (those that rotate or move, in tree order), projection of ``cam_joints`` (those
    that move) and of the moving capsules ``mov_caps`` (at processing positions ``mov_ci``, ascending;
    ``moving_ci (C,)`` flags the positions); term 1 in full for a moving capsule, for a fixed one its
    stored points tested against the earlier moving capsules whose boxes meet its own (usually none:
    the stored sums); term 2 from the stored count plus the uncovered points the moving capsules
    cover. A row that differs from ``x_base`` at a fixed coordinate gets ``out = -1``."""
    x_base, fixed_dofs, fk_joints, cam_joints, mov_caps, mov_ci, moving_ci = restriction
    parents, offsets, ptr, dofs, axes, caps, radii = body
    cam_R, cam_t, cam_K, cam_D, cam_hasd, cov, cov_wh, view_w = views
    order, tmpl_a, tmpl_s, tmpl_ptr, tmpl_na = tmpl
    fg_x, fg_y, fg_n, fg_tab, fg_bins, fg_xr, fg_area = fg
    R0, P0, CP0, G0, G320, box0, BX0_, t1, s_px, s_py, s_idx, s_f, s_pre, u_x, u_y, u_pre, base_hit = stage
    n = X.shape[0]
    C = caps.shape[0]
    V = cam_R.shape[0]
    T = tmpl_ptr[C]
    nm = mov_caps.shape[0]
    one = np.float32(1.0)
    zero = np.float32(0.0)
    n_strips = fg_tab.shape[0] // V
    fg_ms = u_x.shape[0] // fg_tab.shape[0]
    nb = fg_tab.shape[1] - 1
    wsum = 0.0
    for v in range(V):
        wsum += view_w[v]
    first_moving = mov_ci[0] if nm > 0 else C
    S = np.zeros((4, 1))    # not used (the moving capsules' earlier ones: box tests first)
    OK = np.zeros(1, np.int64)
    for chunk in numba.prange(n_chunks):
        lo = chunk * n // n_chunks
        hi = (chunk + 1) * n // n_chunks
        R = R0.copy()
        P = P0.copy()
        CP = CP0.copy()
        G = G0.copy()
        G32 = G320.copy()
        box = box0.copy()
        BX = BX0_.copy()
        NEAR = np.empty(C, np.int64)
        kmax = _scratch_len(tmpl_ptr)
        PX = np.zeros(kmax + 8, np.float32)
        PY = np.zeros(kmax + 8, np.float32)
        IDX = np.empty(kmax, np.int32)
        zpix = np.int32(cov.shape[1] - 1)
        ALIVE = np.zeros(V * T + 8, np.float32)
        flag = np.zeros(u_x.shape[0], np.float32)
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
                G32v = G32[v]
                boxv = box[v]
                EB = BX[v]
                BX0 = EB[0]
                BX1 = EB[1]
                BY0 = EB[2]
                BY1 = EB[3]
                for j in cam_joints:
                    _to_camera_joint(P, cam_R, cam_t, v, CPv, j)
                for m in range(nm):
                    c = mov_caps[m]
                    _project_cap(CPv, caps, radii, Gv, c)
                    _clip_cap(Gv, c, v, cam_K, cov_wh, cam_hasd)
                    _cap_box(Gv, G32v, boxv, c)
                    ci = mov_ci[m]
                    BX0[ci], BX1[ci], BY0[ci], BY1[ci] = boxv[c, 0], boxv[c, 1], boxv[c, 2], boxv[c, 3]
                num = 0.0
                den = 0.0
                off = v * T
                for ci in range(C):
                    c = order[ci]
                    if Gv[c, 12] == 0.0:
                        continue
                    nk = tmpl_ptr[c + 1] - tmpl_ptr[c]
                    if moving_ci[ci]:
                        _t1_points(ci, c, v, Gv, G32v, EB, order, tmpl_a, tmpl_s, tmpl_ptr, tmpl_na,
                                   cam_K, cov_wh, cam_hasd, zpix, PX, PY, IDX, NEAR, S, OK, False)
                        cnt, fsum = _t1_count(c, v, nk, Gv, PX, PY, IDX, zpix, cam_K, cam_D, cam_hasd, cov, cov_wh)
                        w = _t1_weight(Gv, c, nk)
                    else:
                        w = t1[v, c, 0]
                        cnt = t1[v, c, 1]
                        fsum = t1[v, c, 2]
                        q0 = tmpl_ptr[c] + c
                        sb0 = s_pre[v, q0]
                        sb1 = s_pre[v, q0 + nk]
                        if first_moving < ci and sb1 > sb0:
                            ylo = Gv[c, 9]
                            xm = Gv[c, 11]
                            na = tmpl_na[c]
                            ns = nk // na
                            na_ly = na / (Gv[c, 10] - ylo)
                            bx0, bx1, by0, by1 = BX0[ci], BX1[ci], BY0[ci], BY1[ci]
                            marked = False
                            for m in range(nm):
                                ei = mov_ci[m]
                                if ei >= ci:
                                    break
                                if not ((BX0[ei] <= bx1) & (bx0 <= BX1[ei]) & (BY0[ei] <= by1) & (by0 <= BY1[ei])):
                                    continue
                                e = order[ei]
                                reach, i0, i1, sa, ta = _earlier_run(Gv, c, e, ylo, xm, na, na_ly)
                                if not reach:
                                    continue
                                ka = i0 * ns    # the points the full kernel tests: whole vectors from stratum i0
                                kb = min(nk, ka + (((i1 + 1) * ns - ka + 7) & ~7))
                                p0 = s_pre[v, q0 + ka]
                                p1 = s_pre[v, q0 + kb]
                                if p1 > p0:
                                    if not marked:
                                        for s in range(off + sb0, off + sb1):
                                            ALIVE[s] = one
                                        marked = True
                                    _mark_earlier(s_px, s_py, ALIVE, off + p0, off + p1, Gv, G32v, c, e, sa, ta, zero)
                            if marked:
                                cnt, fsum = _t1_recount(v, off + sb0, off + sb1, ALIVE, s_idx, s_f, cam_K, cam_hasd,
                                                        cov)
                    den += w * cnt
                    num += w * (cnt - fsum)
                t1v = num / den if den > 0.0 else 1.0
                if fg_n[v] == 0:
                    t2 = 1.0 - (den - num) / fg_area[v]
                    t2 = min(1.0, max(0.0, t2))
                else:
                    r0 = v * n_strips
                    for r in range(r0, r0 + n_strips):
                        for k in range(u_pre[r, fg_ms]):
                            flag[r * fg_ms + k] = zero
                    for m in range(nm):
                        c = mov_caps[m]
                        if Gv[c, 12] == 0.0:
                            continue
                        for r in range(r0, r0 + n_strips):   # the runs of _t2_runs, among the uncovered points
                            if boxv[c, 0] > fg_xr[r, 1] or boxv[c, 1] < fg_xr[r, 0]:
                                continue
                            k0 = fg_tab[r, _bin(boxv[c, 2], fg_bins[r, 0], fg_bins[r, 1], nb)]
                            k1 = fg_tab[r, min(nb, _bin(boxv[c, 3], fg_bins[r, 0], fg_bins[r, 1], nb) + 1)]
                            if k1 > k0:
                                p0 = u_pre[r, k0 & ~7]
                                p1 = u_pre[r, min(fg_ms, (k1 + 7) & ~7)]
                                if p1 > p0:
                                    _mark_run(u_x, u_y, flag, r * fg_ms + p0, r * fg_ms + p1, G32v, c, one)
                    ihit = 0
                    for r in range(r0, r0 + n_strips):
                        for k in range(u_pre[r, fg_ms]):
                            ihit += flag[r * fg_ms + k] != zero
                    t2 = 1.0 - (base_hit[v] + float(ihit)) / fg_n[v]
                total += view_w[v] * (0.5 * t1v + 0.5 * t2)
            out[i] = total / wsum
