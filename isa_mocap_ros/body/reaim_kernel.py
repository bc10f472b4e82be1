"""The compiled kernels of the re-aimed moves (:class:`isa_mocap_ros.tracking.reaim.ReaimMove`, whose module
docstring gives the geometry): the pose of new values of the moved joints' DOFs built in kinematic order with the
attached joints re-aimed (:func:`pose_fk`), for a batch (:func:`rebuild`), and the intrinsic Tait-Bryan reading
(:func:`euler`). Here, in ``body/``, so the compiled searches (``optim/compiled_search.py``) can run the move inside
their generation loop. Pure numba (no ROS).
"""
from __future__ import annotations

import numba
import numpy as np

from ..numba_cache import register_dependent_cache
from . import kinematics
from .kinematics import rodrigues_into

__all__ = ["rebuild", "pose_fk", "euler"]

# numba keys a cached function on its own file only: the kernels here compile kinematics' Rodrigues turn into
# their machine code, so an edit there must also miss this module's cache
register_dependent_cache(__file__, (kinematics,))


@numba.njit(cache=True)
def _wrap_near(q, ref):  # pragma: no cover - compiled
    """``q + 2πk`` nearest to ``ref``."""
    return q + 2.0 * np.pi * np.round((ref - q) / (2.0 * np.pi))


@numba.njit(cache=True)
def euler(L, i, j, k, ref, out):  # pragma: no cover - compiled
    """Intrinsic Tait-Bryan angles of ``L`` for axes ``i j k`` (see :func:`isa_mocap_ros.tracking.reaim.euler_angles`)."""
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    v = s * L[i, k]
    v = min(1.0, max(-1.0, v))
    q2 = np.arcsin(v)
    q1 = np.arctan2(-s * L[j, k], L[k, k])
    q3 = np.arctan2(-s * L[i, j], L[i, i])
    a1, a2, a3 = _wrap_near(q1, ref[0]), _wrap_near(q2, ref[1]), _wrap_near(q3, ref[2])
    b1, b2, b3 = _wrap_near(q1 + np.pi, ref[0]), _wrap_near(np.pi - q2, ref[1]), _wrap_near(q3 + np.pi, ref[2])
    da = (a1 - ref[0]) ** 2 + (a2 - ref[1]) ** 2 + (a3 - ref[2]) ** 2
    db = (b1 - ref[0]) ** 2 + (b2 - ref[1]) ** 2 + (b3 - ref[2]) ** 2
    if db < da:
        out[0], out[1], out[2] = b1, b2, b3
    else:
        out[0], out[1], out[2] = a1, a2, a3


@numba.njit(cache=True)
def _rot_axis_right(R, a, q):  # pragma: no cover - compiled
    """``R ← R · R_a(q)`` in place (columns ``a+1``, ``a+2`` rotate, as the forward kinematics)."""
    co, si = np.cos(q), np.sin(q)
    u, v = (a + 1) % 3, (a + 2) % 3
    for r in range(3):
        mu, mv = R[r, u], R[r, v]
        R[r, u] = mu * co + mv * si
        R[r, v] = -mu * si + mv * co


@numba.njit(cache=True)
def _swing_times(gb, jb, jn, Rbj, T):  # pragma: no cover - compiled
    """``T ← Q Rbj``, ``Q`` the smallest rotation taking the unit direction ``gb − jb`` onto the unit
    direction ``gb − jn`` (the identity when they are parallel); no allocation."""
    u0, u1, u2 = gb[0] - jb[0], gb[1] - jb[1], gb[2] - jb[2]
    n = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    u0, u1, u2 = u0 / n, u1 / n, u2 / n
    v0, v1, v2 = gb[0] - jn[0], gb[1] - jn[1], gb[2] - jn[2]
    n = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    v0, v1, v2 = v0 / n, v1 / n, v2 / n
    w0, w1, w2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    sn = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    cs = u0 * v0 + u1 * v1 + u2 * v2
    if sn < 1e-15:
        for r in range(3):
            for c in range(3):
                T[r, c] = Rbj[r, c]
        return
    k0, k1, k2 = w0 / sn, w1 / sn, w2 / sn
    th = np.arctan2(sn, cs)
    st, ct = np.sin(th), 1.0 - np.cos(th)
    # Q = I + sin(th) K + (1 - cos(th)) K^2, K the cross-product matrix of k (K^2 = k k^T - I)
    q00 = 1.0 + ct * (k0 * k0 - 1.0)
    q11 = 1.0 + ct * (k1 * k1 - 1.0)
    q22 = 1.0 + ct * (k2 * k2 - 1.0)
    q01 = -st * k2 + ct * k0 * k1
    q10 = st * k2 + ct * k0 * k1
    q02 = st * k1 + ct * k0 * k2
    q20 = -st * k1 + ct * k0 * k2
    q12 = -st * k0 + ct * k1 * k2
    q21 = st * k0 + ct * k1 * k2
    for c in range(3):
        b0, b1, b2 = Rbj[0, c], Rbj[1, c], Rbj[2, c]
        T[0, c] = q00 * b0 + q01 * b1 + q02 * b2
        T[1, c] = q10 * b0 + q11 * b1 + q12 * b2
        T[2, c] = q20 * b0 + q21 * b1 + q22 * b2


@numba.njit(cache=True)
def rebuild(X, x, Rb, Pb, parents, offsets, ptr, dofs, axes, op, target):  # pragma: no cover - compiled
    """:func:`pose_fk` of every row of ``X`` (angles of the joints with an operation written into ``X``)."""
    J = parents.shape[0]
    R = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    work = np.empty((2, 3, 3))
    vec = np.empty((2, 3))
    for i in range(X.shape[0]):
        pose_fk(X[i], parents, offsets, ptr, dofs, axes, op, target, x, Rb, Pb, R, P, work, vec)


@numba.njit(cache=True)
def pose_fk(xi, parents, offsets, ptr, dofs, axes, op, target, x, Rb, Pb, R, P, work, vec):  # pragma: no cover
    """Forward kinematics of pose ``xi`` into ``R (J, 3, 3)``, ``P (J, 3)`` in kinematic order; a
    joint with an operation (``op``: keep / aim / hinge, against the base pose ``x``'s rotations
    ``Rb`` and centres ``Pb``) gets its angles from it, written into ``xi``, before its rotation is
    composed. ``work (2, 3, 3)``, ``vec (2, 3)``: scratch."""
    J = parents.shape[0]
    T, L = work[0], work[1]
    ref, ang = vec[0], vec[1]
    rodrigues_into(xi[3], xi[4], xi[5], R[0])                   # the root, as the forward kinematics
    for c in range(3):
        P[0, c] = xi[c]
    for j in range(1, J):
        p = parents[j]
        for r in range(3):
            P[j, r] = P[p, r] + R[p, r, 0] * offsets[j, 0] + R[p, r, 1] * offsets[j, 1] + R[p, r, 2] * offsets[j, 2]
        kind = op[j]
        if kind == 1 or kind == 2:
            if kind == 1:                                            # keep the world rotation
                for r in range(3):
                    for c in range(3):
                        T[r, c] = Rb[j, r, c]
            else:                                                    # swing about the child's old centre
                g = target[j]
                _swing_times(Pb[g], Pb[j], P[j], Rb[j], T)
            for r in range(3):                                       # L = R_p^T T
                for c in range(3):
                    L[r, c] = R[p, 0, r] * T[0, c] + R[p, 1, r] * T[1, c] + R[p, 2, r] * T[2, c]
            for q in range(3):
                ref[q] = x[dofs[ptr[j] + q]]
            euler(L, axes[ptr[j]], axes[ptr[j] + 1], axes[ptr[j] + 2], ref, ang)
            for q in range(3):
                xi[dofs[ptr[j] + q]] = ang[q]
        elif kind == 3:                                              # hinge: keep the child bone's direction
            e = target[j]
            a = axes[ptr[j]]
            w0, w1, w2 = Pb[e, 0] - Pb[j, 0], Pb[e, 1] - Pb[j, 1], Pb[e, 2] - Pb[j, 2]
            n = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            for r in range(3):                                       # d = R_p^T w, o = the child's offset
                ref[r] = (R[p, 0, r] * w0 + R[p, 1, r] * w1 + R[p, 2, r] * w2) / n
                ang[r] = offsets[e, r]
            ref[a] = 0.0
            ang[a] = 0.0
            b, c2 = (a + 1) % 3, (a + 2) % 3
            cr = ang[b] * ref[c2] - ang[c2] * ref[b]
            dt = ang[0] * ref[0] + ang[1] * ref[1] + ang[2] * ref[2]
            xi[dofs[ptr[j]]] = _wrap_near(np.arctan2(cr, dt), x[dofs[ptr[j]]])
        for r in range(3):
            for c in range(3):
                R[j, r, c] = R[p, r, c]
        for k in range(ptr[j], ptr[j + 1]):
            _rot_axis_right(R[j], axes[k], xi[dofs[k]])

