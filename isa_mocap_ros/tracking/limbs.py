"""Limb stage: twist-and-hinge proposals that re-open a folded or flipped limb.

Why: when an arm moves fast, the tracker can end with the forearm folded back onto the upper arm while
the real arm is stretched, the upper arm's *direction* right but its rotation about its own axis (the
twist) far off. Stretching the elbow alone raises the energy at every angle (the forearm swings through
the background in the wrong plane) and the right twist is outside the search box (prediction ± 0.5 rad),
so no search step leaves the fold. The figures: ``docs/decisions/007-limb-stage.md``.

The move that leaves it keeps the upper bone's direction and re-draws the two hidden coordinates:

    for a limb with a three-axis base joint ``s`` (shoulder, hip) and a one-DOF hinge child ``h``
    (elbow, knee): turn the base's world rotation ``R_s`` about its bone axis ``a = R_s u`` (``u``
    the hinge's offset direction) by a twist ``φ``: ``R_s' = Rot(a, φ) R_s``; its local rotation
    ``L_s' = R_p^T R_s'`` is re-read as Euler angles in the joint's own axis order; the hinge gets
    ``θ``. ``φ ~ U[−π, π)`` and ``θ ~ U[lower, upper]`` of the hinge.

For the legs the tracker draws the hinge only (``twist=False``, the thigh kept): a knee that the
search box cannot follow (a kick straightens and re-bends it faster than the box moves) is caught by a
knee proposal, and redrawing the hip's twist as well measured worse; a leg folded in the prediction gets
the twist as well (``TrackerConfig.stages.limb_hinge_limbs``).

A limb that moves fast is trailed by the search (its box and spreads are centred on a damped
prediction): **extrapolated proposals** carry the limb's angles further along the motion the frame's
search gave them, ``x + k (x − x_prev)`` for a few factors ``k`` (:meth:`LimbMove.extrapolate`).

Every proposal is evaluated with the rest of the pose held at the estimate; the best one replaces
the limb when its energy is lower than the estimate's (the next frame's search refines it). This is
a proposal distribution over the same energy, not a new energy.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["LIMBS", "Limb", "LimbMove", "intrinsic_euler"]

#: Partition names a limb can have (:attr:`BodyModel.partitions`).
LIMBS = ("left_arm", "right_arm", "left_leg", "right_leg")


@dataclass(frozen=True)
class Limb:
    """One limb of :class:`LimbMove`: its partition name, base joint (three rotation axes), the
    base's DOFs and intrinsic Euler sequence, the hinge's DOF and the unit bone direction from the
    base to the hinge in the base's frame."""

    name: str
    base: int
    base_dofs: tuple
    seq: str
    hinge_dof: int
    axis: np.ndarray

    @property
    def dofs(self) -> list[int]:
        """The DOFs a proposal changes: the base's three and the hinge."""
        return [*self.base_dofs, self.hinge_dof]


class LimbMove:
    """Twist-and-hinge proposals for the limbs of a model (see the module docstring).

    Parameters
    ----------
    model : BodyModel
        Limbs are the model's :data:`LIMBS` partitions whose first joint has three distinct
        rotation axes and a one-DOF child joint (shoulder/elbow, hip/knee in the 28/39-DOF models;
        hip/knee in the 18-DOF one).
    """

    def __init__(self, model) -> None:
        from isa_mocap_ros.body.kinematics import euler_sequence

        self.model = model
        self.limbs: list[Limb] = []
        dof_joint = np.asarray(model.dof_joint)
        for name in LIMBS:
            if name not in model.partitions:
                continue
            joints = sorted({int(dof_joint[k]) for k in model.partitions[name]})
            base = joints[0]
            seq = euler_sequence(model, base)
            hinge = [j for j in joints if int(model.parents[j]) == base and len(model.joint_dofs[j]) == 1]
            if seq is None or not hinge:
                continue
            u = np.array(model.offsets[hinge[0]], dtype=float)
            if not np.linalg.norm(u) > 0:
                continue
            self.limbs.append(Limb(name, base, tuple(int(k) for k in model.joint_dofs[base]), seq,
                                   int(model.joint_dofs[hinge[0]][0]), u / np.linalg.norm(u)))

    def limb(self, name: str) -> Limb:
        """The limb called ``name`` (ValueError naming the model's limbs if it has none such)."""
        for limb in self.limbs:
            if limb.name == name:
                return limb
        raise ValueError(f"limb: expected one of {[v.name for v in self.limbs]}, received {name!r}")

    def proposals(self, x: np.ndarray, limb: Limb, phi: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Poses ``(n, D)``: ``x`` with the limb's base turned by twists ``phi (n,)`` about its
        bone and the hinge at ``theta (n,)``, clipped to the model's limits."""
        from isa_mocap_ros.body.kinematics import forward_kinematics

        m = self.model
        x = np.asarray(x, dtype=float)
        T = forward_kinematics(m, x)[0]
        Rp = T[int(m.parents[limb.base]), :3, :3]
        Rs = T[limb.base, :3, :3]
        a = Rs @ limb.axis
        a = a / np.linalg.norm(a)
        phi = np.asarray(phi, dtype=float)
        K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        # Rot(a, phi) = I + sin(phi) K + (1 - cos(phi)) K^2 (Rodrigues), then the local rotation R_p^T Rot R_s
        turn = np.eye(3) + np.sin(phi)[:, None, None] * K + (1.0 - np.cos(phi))[:, None, None] * (K @ K)
        X = np.repeat(x[None, :], len(phi), axis=0)
        X[:, list(limb.base_dofs)] = intrinsic_euler(Rp.T @ turn @ Rs, limb.seq)
        X[:, limb.hinge_dof] = theta
        return np.clip(X, m.lower, m.upper)

    def extrapolate(self, x: np.ndarray, last: np.ndarray, limb: Limb, factors) -> np.ndarray:
        """Poses ``(len(factors), D)``: ``x`` with the limb's DOFs (base and hinge) carried further along
        their motion since ``last``: ``x + k (x − last)`` for each factor ``k``, clipped to the limits."""
        m = self.model
        x = np.asarray(x, dtype=float)
        d = limb.dofs
        v = x[d] - np.asarray(last, dtype=float)[d]
        X = np.repeat(x[None, :], len(factors), axis=0)
        X[:, d] = x[d] + np.outer(np.asarray(factors, dtype=float), v)
        return np.clip(X, m.lower, m.upper)

    def draw(self, x: np.ndarray, limb: Limb, n: int, rng: np.random.Generator, *, twist: bool = True,
             window: float | None = None) -> np.ndarray:
        """``n`` proposals for ``limb`` around pose ``x``: twist uniform on the circle, hinge
        uniform within its limits (both from ``rng``). ``twist=False``: hinge proposals only (the
        base joint kept; one draw per proposal from ``rng``), uniform within ``window`` radians of
        ``x``'s hinge (and its limits) when ``window`` is given."""
        m, k = self.model, limb.hinge_dof
        if not twist:
            X = np.repeat(np.asarray(x, dtype=float)[None, :], n, axis=0)
            lo, hi = float(m.lower[k]), float(m.upper[k])
            if window is not None:
                lo, hi = max(lo, float(X[0, k]) - window), min(hi, float(X[0, k]) + window)
            X[:, k] = rng.uniform(lo, hi, n)
            return np.clip(X, m.lower, m.upper)
        phi = rng.uniform(-np.pi, np.pi, n)
        theta = rng.uniform(m.lower[k], m.upper[k], n)
        return self.proposals(x, limb, phi, theta)


def intrinsic_euler(L: np.ndarray, seq: str) -> np.ndarray:
    """Angles ``(n, 3)`` of the rotations ``L (n, 3, 3)`` in the intrinsic Tait-Bryan sequence ``seq`` (three distinct
    upper-case axes, scipy's convention: ``L = R_i(q1) R_j(q2) R_k(q3)``, ``q2`` in [-pi/2, pi/2], ``q1``, ``q3`` in
    [-pi, pi]): ``q2 = asin(e L_ik)``, ``q1 = atan2(-e L_jk, L_kk)``, ``q3 = atan2(-e L_ij, L_ii)`` with ``e`` the sign
    of the permutation ``ijk``. Near gimbal lock (``|L_ik|`` within 1e-7 of 1) scipy's reading is taken."""
    i, j, k = ("XYZ".index(c) for c in seq)
    e = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    out = np.empty(L.shape[:-2] + (3,))
    out[..., 1] = np.arcsin(np.clip(e * L[..., i, k], -1.0, 1.0))
    out[..., 0] = np.arctan2(-e * L[..., j, k], L[..., k, k])
    out[..., 2] = np.arctan2(-e * L[..., i, j], L[..., i, i])
    lock = np.abs(L[..., i, k]) > 1.0 - 1e-7
    if np.any(lock):        # scipy sets the third angle to 0 there (and warns that it does: expected here)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            out[lock] = Rotation.from_matrix(L[lock]).as_euler(seq)
    return out
