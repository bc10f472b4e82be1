"""Re-aimed moves: new values for some joints with the limbs below them kept where they were.

Why: the hip joint centres are the worst-estimated joints of a tracked walk, and they set the knee
angle; they hang on the pelvis, whose orientation the silhouette barely sees. The hierarchy's root
partition turns the whole body, and a pelvis move that keeps the children's world *rotations* carries
each thigh with its hip centre, so the knee moves as far as the hip. The move that corrects a hip
centre turns the thigh about the knee (the figures: ``docs/decisions/005-pelvis-stage.md``).

For candidate values of the *moved* joints' DOFs (the root, or the torso partition) the pose is
rebuilt in kinematic order, and every joint hanging directly below them (an *attached* joint: a
joint with DOFs whose parent is moved, or carried rigidly by a moved joint) is **re-aimed**:

    attached three-axis joint ``a`` with a single child ``g`` (thigh → knee, upper arm → elbow,
    lower spine → upper spine): its world rotation becomes ``Q R_a`` with ``Q`` the smallest
    rotation taking the old direction ``g − a`` onto the direction from the *new* centre of ``a``
    to the old centre of ``g`` — the bone swings about ``g``, which stays on its ray (exactly in
    place when the bone length allows), and keeps its twist as far as a swing can;
    then ``g``: a one-DOF hinge (knee, elbow) with a single child ``e`` takes the angle whose
    ``g → e`` direction is closest to the old one in the world (the shank keeps its direction as far
    as the hinge allows); a three-axis ``g`` (the 39-DOF upper spine) keeps its world rotation;
    a ``g`` without DOFs (the 28-DOF chest) passes that on to its three-axis children (neck,
    shoulders).

Other attached three-axis joints keep their world rotations (as in the pelvis move); everything
else keeps its angles. With the root moved this is the pelvis stage's move: the pelvis turns and shifts,
the thighs swing about the knees, the lower spine about the chest, and the legs below the knees, the chest, arms and head stay in the world. With the torso
moved (the **torso stage**) the spine and neck bend and twist while the upper arms swing about the
elbows: the hierarchy fits the torso with the arms held at their angles, so a torso move drags the
arms with it, and the arms (fitted first) hold the torso where they fit.

Angles are read back in each joint's own axis order (intrinsic Tait-Bryan), choosing of the two
equivalent triples the one nearest to the joint's old angles, each angle taken within π of its old
value; nothing is clipped here (the tracker clips to the limits). A compiled kernel (numba) builds
all candidates of a generation in one call.
"""
from __future__ import annotations

from typing import Sequence

import numba
import numpy as np

from isa_mocap_ros.body.kinematics import rodrigues_into

__all__ = ["ReaimMove", "euler_angles"]

#: Operations of the kernel, per joint.
_NONE, _KEEP, _AIM, _HINGE = 0, 1, 2, 3


class ReaimMove:
    """Poses for new values of the moved joints' DOFs with the limbs below re-aimed (module docstring).

    Parameters
    ----------
    model : BodyModel
    joints : sequence of int or str
        The moved joints (indices or names); their DOFs, in DOF order, are :attr:`coords`, the
        columns of the candidates. The root (joint 0) moves its 6 DOFs.

    Raises
    ------
    ValueError
        An unknown joint, or a moved joint without DOFs.
    """

    def __init__(self, model, joints: Sequence) -> None:
        from isa_mocap_ros.body.kinematics import kernel_tables

        self.model = model
        names = list(model.joint_names)
        moved = []
        for j in joints:
            if isinstance(j, str):
                if j not in names:
                    raise ValueError(f"joints: {j!r} is not a joint of model {model.name} ({', '.join(names)})")
                j = names.index(j)
            j = int(j)
            if not 0 <= j < len(names):
                raise ValueError(f"joints: index {j} outside 0..{len(names) - 1}")
            if j and not len(model.joint_dofs[j]):
                raise ValueError(f"joints: {names[j]} has no DOFs to move")
            moved.append(j)
        if not moved:
            raise ValueError("joints: expected at least one joint")
        self.joints = tuple(sorted(set(moved)))
        self.coords = np.array(sorted(d for j in self.joints for d in (range(6) if j == 0 else model.joint_dofs[j])),
                               dtype=np.int64)
        self._tables = kernel_tables(model)
        self.ops = self._plan()
        J = len(names)
        self._op = np.zeros(J, dtype=np.int64)
        self._target = np.full(J, -1, dtype=np.int64)
        for j, (kind, t) in self.ops.items():
            self._op[j] = {"keep": _KEEP, "aim": _AIM, "hinge": _HINGE}[kind]
            self._target[j] = t

    def _plan(self) -> dict:
        """``{joint: (kind, target)}``: ``("keep", -1)``, ``("aim", child)``, ``("hinge", child)``."""
        m = self.model
        J = len(m.joint_names)
        parents = [int(p) for p in m.parents]
        children = [[c for c in range(J) if parents[c] == j] for j in range(J)]
        ndof = [6 if j == 0 else len(m.joint_dofs[j]) for j in range(J)]

        def three_axis(j):
            axes = [int(m.dof_axis[d]) for d in m.joint_dofs[j]] if j else []
            return len(axes) == 3 and len(set(axes)) == 3 and min(axes) >= 0

        def bone(j):            # the single child with a non-zero offset, or None
            kids = [c for c in children[j] if np.linalg.norm(m.offsets[c]) > 1e-9]
            return kids[0] if len(kids) == 1 and len(children[j]) == 1 else None

        carried = [False] * J    # moved, or rigidly on a moved joint
        for j in range(J):       # parents come first (kinematic order)
            carried[j] = j in self.joints or (ndof[j] == 0 and j > 0 and carried[parents[j]])
        ops: dict = {}
        for a in range(1, J):
            if a in self.joints or ndof[a] == 0 or not carried[parents[a]]:
                continue
            if not three_axis(a):
                continue                                # keeps its angles
            g = bone(a)
            if g is None:
                ops[a] = ("keep", -1)
                continue
            ops[a] = ("aim", g)
            if ndof[g] == 1:
                e = bone(g)
                if e is not None:
                    ops[g] = ("hinge", e)
            elif three_axis(g):
                ops[g] = ("keep", -1)
            elif ndof[g] == 0:
                for c in children[g]:
                    if three_axis(c):
                        ops[c] = ("keep", -1)
        return ops

    def around(self, x: np.ndarray):
        """``C (n, len(coords)) -> X (n, D)`` for a fixed pose ``x`` (its forward kinematics computed once)."""
        x = np.array(x, dtype=float)
        coords, tables, op, target = self.coords, self._tables, self._op, self._target
        J = len(self.model.joint_names)
        Rb, Pb = np.empty((J, 3, 3)), np.empty((J, 3))
        _pose_fk(x.copy(), *tables, np.zeros(J, dtype=np.int64), target, x, Rb, Pb, Rb, Pb,   # no operation
                 np.empty((2, 3, 3)), np.empty((2, 3)))

        def poses(C: np.ndarray) -> np.ndarray:
            C = np.atleast_2d(np.asarray(C, dtype=float))
            if C.shape[1] != coords.size:
                raise ValueError(f"candidates: expected {coords.size} columns (the moved DOFs), got {C.shape[1]}")
            X = np.repeat(x[None, :], len(C), axis=0)
            X[:, coords] = C
            _rebuild(X, x, Rb, Pb, *tables, op, target)
            return X
        return poses

    def __call__(self, x: np.ndarray, C: np.ndarray) -> np.ndarray:
        """Poses ``(n, D)``: ``x`` with the moved DOFs set to each row of ``C`` and the attached joints re-aimed."""
        return self.around(x)(C)


def euler_angles(L: np.ndarray, axes: Sequence[int], near: Sequence[float] | None = None) -> np.ndarray:
    """Angles ``(q1, q2, q3)`` with ``L = R_a1(q1) R_a2(q2) R_a3(q3)`` for distinct axes ``a1 a2 a3``
    (0 = x, 1 = y, 2 = z); of the two triples the one nearest to ``near`` (default zeros), each
    angle within π of ``near``'s."""
    out = np.empty(3)
    ref = np.zeros(3) if near is None else np.asarray(near, dtype=float)
    _euler(np.ascontiguousarray(L, dtype=float), int(axes[0]), int(axes[1]), int(axes[2]), ref, out)
    return out


@numba.njit(cache=True)
def _wrap_near(q, ref):  # pragma: no cover - compiled
    """``q + 2πk`` nearest to ``ref``."""
    return q + 2.0 * np.pi * np.round((ref - q) / (2.0 * np.pi))


@numba.njit(cache=True)
def _euler(L, i, j, k, ref, out):  # pragma: no cover - compiled
    """Intrinsic Tait-Bryan angles of ``L`` for axes ``i j k`` (see :func:`euler_angles`)."""
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
def _rebuild(X, x, Rb, Pb, parents, offsets, ptr, dofs, axes, op, target):  # pragma: no cover - compiled
    """:func:`_pose_fk` of every row of ``X`` (angles of the joints with an operation written into ``X``)."""
    J = parents.shape[0]
    R = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    work = np.empty((2, 3, 3))
    vec = np.empty((2, 3))
    for i in range(X.shape[0]):
        _pose_fk(X[i], parents, offsets, ptr, dofs, axes, op, target, x, Rb, Pb, R, P, work, vec)


@numba.njit(cache=True)
def _pose_fk(xi, parents, offsets, ptr, dofs, axes, op, target, x, Rb, Pb, R, P, work, vec):  # pragma: no cover
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
            _euler(L, axes[ptr[j]], axes[ptr[j] + 1], axes[ptr[j] + 2], ref, ang)
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
