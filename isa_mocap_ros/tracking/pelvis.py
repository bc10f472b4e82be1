"""Pelvis stage: re-fit the root with the root's child joints held still in the world.

Why (measured on the CMU walk, ``docs/tracking.md``): the pelvis is a small part of the silhouette,
so its orientation is weakly observed. Along a sequence the estimated root rotation drifts (20-50°
of pitch within 150 frames) while the spine and hips bend the opposite way, so the torso and the
thighs still fit the masks. That compensated pose is a trap for the §3.3 hierarchy: moving the root
alone turns the whole (well fitted) body and raises the energy 5×, moving any one partition to the
truth raises it as well, although the straight line from the estimate to the truth descends all
the way. The coordinated move that leaves the trap is "turn the pelvis, keep the children":

    for a root candidate ``(t', r')``: every child joint ``c`` of the root with three distinct
    rotation axes gets the local rotation ``L_c' = R(r')^T R(r) L_c``, so its world rotation
    ``R(r) L_c`` is unchanged; its Euler angles are re-read in the joint's own axis order.

Only the pelvis and the joint *centres* at its ends (hips, spine base) move; everything below the
children turns with them rigidly. This is a change of coordinates of the root partition, not a new
energy: the stage minimises the same total energy with the configured algorithm.
"""
from __future__ import annotations

import numba
import numpy as np
from scipy.spatial.transform import Rotation

try:    # scipy >= 1.15: the compiled quaternion kernels behind Rotation's numpy backend
    from scipy.spatial.transform import _rotation_cy as _quat_kernels
    if not all(hasattr(_quat_kernels, f) for f in ("from_rotvec", "from_euler", "from_quat", "as_euler")):
        _quat_kernels = None
except ImportError:                                                     # pragma: no cover
    _quat_kernels = None

__all__ = ["PelvisMove"]


class PelvisMove:
    """Poses for root candidates with the root's children kept in the world (see module docstring).

    Parameters
    ----------
    model : BodyModel
        Children of the root (joint 0) whose DOFs are three rotations about distinct axes are
        compensated (the spine base and both hips of the 28/39-DOF models; the hips of the 18-DOF
        model); others keep their angles.
    """

    def __init__(self, model) -> None:
        from isa_mocap_ros.body.kinematics import euler_sequence

        self.model = model
        self.children: list[tuple[list[int], str]] = []
        for j in range(1, len(model.parents)):
            seq = euler_sequence(model, j) if int(model.parents[j]) == 0 else None
            if seq is not None:
                self.children.append(([int(k) for k in model.joint_dofs[j]], seq))

    def __call__(self, x: np.ndarray, roots: np.ndarray) -> np.ndarray:
        """Poses ``(n, D)``: ``x`` with its root replaced by each row of ``roots (n, 6)`` and the
        compensated child angles (not clipped to the limits)."""
        return self.around(x)(roots)

    def around(self, x: np.ndarray, *, compiled: bool | None = None):
        """``roots -> poses`` for a fixed ``x`` (what :meth:`__call__` computes, with the parts that
        depend on ``x`` only — its root rotation and the children's local rotations — computed once;
        the pelvis stage calls it once per generation).

        ``compiled`` (default: when available) calls the compiled quaternion kernels that scipy's
        :class:`~scipy.spatial.transform.Rotation` runs for numpy arrays (``_rotation_cy``, scipy >=
        1.15) directly, as ``Rotation`` calls them (``from_rotvec``; ``*`` is the Hamilton product
        then ``from_quat(normalize=True)``; ``as_euler``), with the inverse and the product written
        out (:func:`_compose_quat`, compiled): the same numbers bit for bit (``test/test_pelvis.py``)
        without ``Rotation``'s per-call overhead (0.18 → 0.04 ms a call for 50 roots)."""
        x = np.array(x, dtype=float)
        if compiled is None:
            compiled = _quat_kernels is not None
        elif compiled and _quat_kernels is None:
            raise ValueError("compiled: expected False, received True (this scipy has no "
                             "spatial.transform._rotation_cy kernels)")
        if compiled:
            return self._around_compiled(x)
        root = Rotation.from_rotvec(x[3:6])                                              # R(r)
        local = [(dofs, seq, Rotation.from_euler(seq, x[dofs])) for dofs, seq in self.children]   # L_c

        def poses(roots: np.ndarray) -> np.ndarray:
            roots = np.atleast_2d(np.asarray(roots, dtype=float))
            X = np.repeat(x[None, :], len(roots), axis=0)
            X[:, :6] = roots
            if local:
                turn = Rotation.from_rotvec(roots[:, 3:6]).inv() * root                 # R(r')^T R(r)
                for dofs, seq, L in local:
                    X[:, dofs] = (turn * L).as_euler(seq)
            return X
        return poses

    def _around_compiled(self, x: np.ndarray):
        """:meth:`around` on scipy's compiled quaternion kernels (same operations, same numbers)."""
        qk = _quat_kernels
        root = np.asarray(qk.from_rotvec(x[None, 3:6]))                                  # R(r), (1, 4)
        k = len(self.children)
        dofs = [d for d, _ in self.children]
        seqs = [s for _, s in self.children]
        # L_c of every child, (k, 4); each composed with all n turns in one product below
        L = np.concatenate([np.asarray(qk.from_euler(s, x[None, d])) for d, s in self.children]) \
            if k else np.zeros((0, 4))
        one_seq = len(set(seqs)) == 1

        def poses(roots: np.ndarray) -> np.ndarray:
            roots = np.atleast_2d(np.asarray(roots, dtype=float))
            n = len(roots)
            X = np.repeat(x[None, :], n, axis=0)
            X[:, :6] = roots
            if k and n:
                inv = np.asarray(qk.from_rotvec(np.ascontiguousarray(roots[:, 3:6]))) * _CONJUGATE
                turn = qk.from_quat(_compose_quat(inv, root), normalize=True, copy=False,
                                    scalar_first=False)                         # R(r')^T R(r)
                q = qk.from_quat(_compose_quat(np.asarray(turn), L), normalize=True, copy=False,
                                 scalar_first=False)                      # R(r')^T R(r) L_c, (k n, 4)
                if one_seq:
                    e = np.asarray(qk.as_euler(q, seqs[0]))
                    for c in range(k):
                        X[:, dofs[c]] = e[c * n:(c + 1) * n]
                else:
                    q = np.asarray(q)
                    for c in range(k):
                        X[:, dofs[c]] = qk.as_euler(q[c * n:(c + 1) * n], seqs[c])
            return X
        return poses


#: ``q * _CONJUGATE`` is the inverse of unit quaternions ``q (n, 4)`` (scalar last), as
#: ``Rotation.inv`` computes it (the sign of the vector part flipped: exact).
_CONJUGATE = np.array([-1.0, -1.0, -1.0, 1.0])


@numba.njit(cache=True)
def _compose_quat(p, q):  # pragma: no cover - compiled
    """Hamilton products ``p_i q_c`` of quaternions ``p (n, 4)`` and ``q (k, 4)`` (scalar last),
    ``(k n, 4)`` with row ``c n + i``, by the operations of scipy's ``_compose_quat_single`` in its
    order (``w_p v_q + w_q v_p + v_p × v_q``, ``w_p w_q - v_p · v_q`` left to right; products and
    sums only, rounded one by one as in C: no fused multiply-add without fastmath), so the same
    doubles as ``Rotation.__mul__`` before its normalisation."""
    n, k = p.shape[0], q.shape[0]
    r = np.empty((k * n, 4))
    for c in range(k):
        q0, q1, q2, q3 = q[c, 0], q[c, 1], q[c, 2], q[c, 3]
        for i in range(n):
            p0, p1, p2, p3 = p[i, 0], p[i, 1], p[i, 2], p[i, 3]
            o = c * n + i
            r[o, 0] = p3 * q0 + q3 * p0 + (p1 * q2 - p2 * q1)
            r[o, 1] = p3 * q1 + q3 * p1 + (p2 * q0 - p0 * q2)
            r[o, 2] = p3 * q2 + q3 * p2 + (p0 * q1 - p1 * q0)
            r[o, 3] = p3 * q3 - p0 * q0 - p1 * q1 - p2 * q2
    return r
