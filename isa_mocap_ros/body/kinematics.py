"""Batch forward kinematics, capsule end points and position Jacobians of a body model.

Source: the kinematic tree of EA-vs-PF §3.1 (a node's transformation moves all its children) with
the root as the rigid body motion of ISA Eq. 13.20. For joint ``j`` with parent ``p``:

    R_j = R_p · R_a1(q1) R_a2(q2) ...      (local axes in the joint's chain order)
    p_j = p_p + R_p · offset_j             (the joint centre is fixed in the parent's frame)

and the root: ``R_0 = exp(ŵ)``, ``p_0 = t`` for the pose ``x = (t, w, q...)``. Two backends:
``"numba"`` (default; a compiled kernel, parallel over poses) and ``"numpy"`` (vectorized over
the ``n`` poses, a Python loop over the ~22 joints; the reference the kernel is tested against).
"""
from __future__ import annotations

import numba
import numpy as np

from ..geometry import exp_so3
from .model import BodyError, BodyModel

__all__ = ["forward_kinematics", "joint_positions", "capsule_endpoints", "position_jacobian", "euler_sequence"]


def euler_sequence(model: BodyModel, joint: int) -> str | None:
    """The intrinsic Euler sequence (e.g. ``"YXZ"``, scipy's upper-case convention) of a joint whose
    local rotation is three rotations about distinct axes in chain order — ``R_a1(q1) R_a2(q2)
    R_a3(q3)`` as above — or None for any other joint (hinges, two-axis joints, the root)."""
    axes = [int(model.dof_axis[k]) for k in model.joint_dofs[joint]]
    if len(axes) != 3 or len(set(axes)) != 3 or min(axes) < 0:
        return None
    return "".join("XYZ"[a] for a in axes)


def _axis_rot(q: np.ndarray, axis: int) -> np.ndarray:
    c, s = np.cos(q), np.sin(q)
    R = np.zeros(q.shape + (3, 3))
    i, k = [(1, 2), (2, 0), (0, 1)][axis]
    R[:, axis, axis] = 1.0
    R[:, i, i] = c
    R[:, k, k] = c
    R[:, i, k] = -s
    R[:, k, i] = s
    return R


def _as_batch(model: BodyModel, X) -> np.ndarray:
    X = model.validate_pose(X, name="X")
    return X[None] if X.ndim == 1 else X


def joint_frames(model: BodyModel, X: np.ndarray, *, want_axes: bool = False):
    """World rotations ``(n, J, 3, 3)``, positions ``(n, J, 3)`` and, optionally, the world axis
    of every joint-angle DOF ``(n, D, 3)`` (rows 0-5 unused)."""
    n = X.shape[0]
    J = len(model.joint_names)
    R = np.empty((n, J, 3, 3))
    P = np.empty((n, J, 3))
    axes = np.zeros((n, model.dof, 3)) if want_axes else None
    R[:, 0] = exp_so3(X[:, 3:6])
    P[:, 0] = X[:, :3]
    parents = model.parents
    offsets = model.offsets
    for j in range(1, J):
        p = parents[j]
        Rp = R[:, p]
        P[:, j] = P[:, p] + Rp @ offsets[j]
        Rj = Rp
        for d in model.joint_dofs[j]:
            a = model.dof_axis[d]
            if want_axes:
                axes[:, d] = Rj[:, :, a]
            Rj = Rj @ _axis_rot(X[:, d], a)
        R[:, j] = Rj
    return R, P, axes


@numba.njit(cache=True, inline="always")
def rodrigues_into(wx, wy, wz, R):  # pragma: no cover - compiled
    """``R (3, 3) ← exp([w]×)`` for the rotation vector ``w`` (Eq. 13.20; Taylor series near 0): the
    root rotation of :func:`_fk_kernel`, for other compiled kernels."""
    t2 = wx * wx + wy * wy + wz * wz
    th = np.sqrt(t2)
    if th < 1e-4:
        A = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    else:
        A = np.sin(th) / th
        B = (1.0 - np.cos(th)) / t2
    R[0, 0] = 1.0 - B * (wy * wy + wz * wz)
    R[1, 1] = 1.0 - B * (wx * wx + wz * wz)
    R[2, 2] = 1.0 - B * (wx * wx + wy * wy)
    R[0, 1] = -A * wz + B * wx * wy
    R[1, 0] = A * wz + B * wx * wy
    R[0, 2] = A * wy + B * wx * wz
    R[2, 0] = -A * wy + B * wx * wz
    R[1, 2] = -A * wx + B * wy * wz
    R[2, 1] = A * wx + B * wy * wz


@numba.njit(cache=True, inline="always", fastmath=False)
def fk_pose_into(X, i, parents, offsets, ptr, dofs, axes, R, P):  # pragma: no cover - compiled
    """Rotations ``R[i]`` and positions ``P[i]`` of pose ``X[i]`` (one pose of :func:`_fk_kernel`; the
    compiled keypoint energy, ``energy.keypoint_kernel``, calls it too)."""
    J = parents.shape[0]
    rodrigues_into(X[i, 3], X[i, 4], X[i, 5], R[i, 0])       # root: Eq. 13.20, Taylor series near 0
    for c in range(3):
        P[i, 0, c] = X[i, c]
    for j in range(1, J):
        p = parents[j]
        for r in range(3):
            P[i, j, r] = P[i, p, r] + R[i, p, r, 0] * offsets[j, 0] + R[i, p, r, 1] * offsets[j, 1] \
                + R[i, p, r, 2] * offsets[j, 2]
            for c in range(3):
                R[i, j, r, c] = R[i, p, r, c]
        for k in range(ptr[j], ptr[j + 1]):
            a = axes[k]
            q = X[i, dofs[k]]
            co = np.cos(q)
            si = np.sin(q)
            u = (a + 1) % 3
            v = (a + 2) % 3
            for r in range(3):          # R ← R · R_a(q): columns u, v rotate
                mu = R[i, j, r, u]
                mv = R[i, j, r, v]
                R[i, j, r, u] = mu * co + mv * si
                R[i, j, r, v] = -mu * si + mv * co


@numba.njit(parallel=True, cache=True, fastmath=False)
def _fk_kernel(X, parents, offsets, ptr, dofs, axes, R, P):  # pragma: no cover - compiled
    for i in numba.prange(X.shape[0]):
        fk_pose_into(X, i, parents, offsets, ptr, dofs, axes, R, P)


@numba.njit(cache=True, fastmath=False)
def _fk_kernel_serial(X, parents, offsets, ptr, dofs, axes, R, P):  # pragma: no cover - compiled
    """:func:`_fk_kernel` on the calling thread (the same operations, so the same bits)."""
    for i in range(X.shape[0]):
        fk_pose_into(X, i, parents, offsets, ptr, dofs, axes, R, P)


@numba.njit(cache=True, fastmath=False)
def _fk_axes_kernel(x, parents, offsets, ptr, dofs, axes, R, P, A):  # pragma: no cover - compiled
    """One pose ``x``: rotations ``R (J, 3, 3)`` and positions ``P (J, 3)`` by :func:`fk_pose_into`'s operations
    (the same bits as :func:`forward_kinematics`), and ``A (D, 3)``: the world axis of each joint-angle DOF
    (column ``a`` of the joint's rotation before that DOF's own rotation, as :func:`joint_frames`)."""
    X = x.reshape(1, x.shape[0])
    RR = R.reshape(1, R.shape[0], 3, 3)
    PP = P.reshape(1, P.shape[0], 3)
    fk_pose_into(X, 0, parents, offsets, ptr, dofs, axes, RR, PP)
    # the axes: replay each joint's chain from its parent's rotation (the same products, in order)
    J = parents.shape[0]
    M = np.empty((3, 3))
    for j in range(1, J):
        p = parents[j]
        for r in range(3):
            for c in range(3):
                M[r, c] = R[p, r, c]
        for k in range(ptr[j], ptr[j + 1]):
            a = axes[k]
            for r in range(3):
                A[dofs[k], r] = M[r, a]
            q = x[dofs[k]]
            co = np.cos(q)
            si = np.sin(q)
            u = (a + 1) % 3
            v = (a + 2) % 3
            for r in range(3):
                mu = M[r, u]
                mv = M[r, v]
                M[r, u] = mu * co + mv * si
                M[r, v] = -mu * si + mv * co


def frames_and_axes(model: BodyModel, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One pose's joint rotations ``(J, 3, 3)``, positions ``(J, 3)`` (the compiled kinematics: the same
    numbers as :func:`forward_kinematics`) and the world axis of every joint-angle DOF ``(D, 3)`` (rows 0-5
    zero), in one compiled call: what a local fit of the pose (the contour stage) needs per step."""
    x = np.ascontiguousarray(model.validate_pose(x, name="x"), dtype=np.float64)
    if x.ndim != 1:
        raise BodyError(f"x: expected one pose of shape ({model.dof},), received shape {x.shape}")
    J = len(model.joint_names)
    R, P, A = np.empty((J, 3, 3)), np.empty((J, 3)), np.zeros((model.dof, 3))
    _fk_axes_kernel(x, *kernel_tables(model), R, P, A)
    return R, P, A


#: Batches smaller than this run on the calling thread: a parallel launch for one pose cost more CPU than
#: the pose (the tracker calls FK on single poses ~14 times a frame; bench speed's profile, docs/nodes.md).
SERIAL_BELOW = 32


def _fk_numba(model: BodyModel, X: np.ndarray):
    tables = kernel_tables(model)
    n, J = X.shape[0], len(model.joint_names)
    R = np.empty((n, J, 3, 3))
    P = np.empty((n, J, 3))
    (_fk_kernel_serial if n < SERIAL_BELOW else _fk_kernel)(np.ascontiguousarray(X), *tables, R, P)
    return R, P


_TABLES: dict = {}


def kernel_tables(model: BodyModel):
    """The compiled kinematics' tables of ``model`` (cached per model object): parents ``(J,)``, offsets
    ``(J, 3)``, a row pointer ``(J+1,)`` into the joint-angle DOF indices ``(K,)`` and their axes ``(K,)`` (0, 1, 2 = x, y, z)."""
    key = id(model)
    hit = _TABLES.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
    ptr = np.zeros(len(model.joint_names) + 1, dtype=np.int64)
    dofs, axes = [], []
    for j in range(len(model.joint_names)):
        ids = model.joint_dofs[j] if j else ()
        dofs += list(ids)
        axes += [int(model.dof_axis[d]) for d in ids]
        ptr[j + 1] = len(dofs)
    tables = (np.asarray(model.parents, dtype=np.int64), np.ascontiguousarray(model.offsets, dtype=float), ptr,
              np.array(dofs, dtype=np.int64), np.array(axes, dtype=np.int64))
    if len(_TABLES) > 64:
        _TABLES.clear()
    _TABLES[key] = (model, tables)
    return tables


def _rot_pos(model: BodyModel, X: np.ndarray, backend: str):
    if backend == "numba":
        return _fk_numba(model, X)
    if backend == "numpy":
        return joint_frames(model, X)[:2]
    raise BodyError(f"backend: expected 'numba' or 'numpy', got {backend!r}")


def forward_kinematics(model: BodyModel, X, *, backend: str = "numba") -> np.ndarray:
    """World transforms of all joints for a batch of poses.

    Parameters
    ----------
    model : BodyModel
    X : (n, D) or (D,) array_like
        Pose vectors (root translation, root rotation vector, joint angles).
    backend : {"numba", "numpy"}
        Compiled kernel (parallel over poses) or the vectorized numpy reference.

    Returns
    -------
    T : (n, J, 4, 4) ndarray
        Homogeneous world transform of each joint frame (``n = 1`` for a single pose).
    """
    X = _as_batch(model, X)
    R, P = _rot_pos(model, X, backend)
    T = np.zeros(R.shape[:2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = P
    T[..., 3, 3] = 1.0
    return T


def joint_positions(model: BodyModel, X, *, backend: str = "numba") -> np.ndarray:
    """Joint centres in the world frame, ``(n, D) -> (n, J, 3)`` metres (see :func:`forward_kinematics`)."""
    X = _as_batch(model, X)
    return _rot_pos(model, X, backend)[1]


def capsule_endpoints(model: BodyModel, X, *, backend: str = "numba") -> np.ndarray:
    """Capsule end points ``(n, C, 2, 3)``; radii in ``model.capsule_radii`` ``(C, 2)``."""
    P = joint_positions(model, X, backend=backend)
    return P[:, model.capsules]


def position_jacobian(model: BodyModel, X, joints) -> tuple[np.ndarray, np.ndarray]:
    """Positions of selected joints and their Jacobian w.r.t. a local pose perturbation.

    The root rotation is perturbed on the left, ``R_0 ← exp(δ̂) R_0`` (δ in the world frame),
    so columns 3-5 are ``∂p/∂δ = -[p - p_0]_×``; columns 0-2 the identity; a joint angle
    ``q_d`` about world axis ``a_d`` at joint centre ``c_d`` gives ``a_d × (p - c_d)`` for the
    joints below it, zero elsewhere.

    Parameters
    ----------
    model : BodyModel
    X : (n, D) array_like
    joints : (K,) int array_like
        Joint indices.

    Returns
    -------
    P : (n, K, 3) ndarray
    Jac : (n, K, 3, D) ndarray
    """
    P, JacDK = _position_jacobian_dk(model, X, joints)
    return P, np.moveaxis(JacDK, 1, 3)


def _position_jacobian_dk(model: BodyModel, X, joints) -> tuple[np.ndarray, np.ndarray]:
    """:func:`position_jacobian` with the Jacobian laid out ``(n, D, K, 3)`` (C-contiguous)."""
    X = _as_batch(model, X)
    joints = np.asarray(joints, dtype=int)
    if joints.ndim != 1 or np.any(joints < 0) or np.any(joints >= len(model.joint_names)):
        raise BodyError(f"joints: expected indices in [0, {len(model.joint_names)}), got {joints}")
    _, Pall, axes = joint_frames(model, X, want_axes=True)
    P = Pall[:, joints]
    n, K = P.shape[:2]
    JacT = np.zeros((n, model.dof, K, 3))
    for c in range(3):
        JacT[:, c, :, c] = 1.0
    u = P - Pall[:, :1]
    # -[u]_x columns: d(δ × u)/dδ
    JacT[:, 4, :, 0], JacT[:, 5, :, 0] = u[..., 2], -u[..., 1]
    JacT[:, 3, :, 1], JacT[:, 5, :, 1] = -u[..., 2], u[..., 0]
    JacT[:, 3, :, 2], JacT[:, 4, :, 2] = u[..., 1], -u[..., 0]
    below = descendant_mask(model)[:, joints]          # (J, K): joint k is below (or at) joint j
    for d in range(6, model.dof):
        j = model.dof_joint[d]
        mask = below[j]
        if not mask.any():
            continue
        lever = P[:, mask] - Pall[:, j][:, None]
        a = axes[:, d][:, None]
        JacT[:, d, mask] = np.stack([a[..., 1] * lever[..., 2] - a[..., 2] * lever[..., 1],
                                     a[..., 2] * lever[..., 0] - a[..., 0] * lever[..., 2],
                                     a[..., 0] * lever[..., 1] - a[..., 1] * lever[..., 0]], axis=-1)
    return P, JacT


def descendant_mask(model: BodyModel) -> np.ndarray:
    """``(J, J)`` bool: ``[j, k]`` is True when joint ``k`` is joint ``j`` or below it in the tree."""
    J = len(model.joint_names)
    M = np.eye(J, dtype=bool)
    for k in range(J):
        p = model.parents[k]
        while p >= 0:
            M[p, k] = True
            p = model.parents[p]
    return M
